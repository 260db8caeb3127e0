//! The bridge stage: carries chosen services of a run between hosts over Zenoh ([`link`] says
//! what and how; [`zenoh_link`], with the `zenoh` feature, does it).

pub mod link;
#[cfg(feature = "zenoh")]
pub mod zenoh_link;
