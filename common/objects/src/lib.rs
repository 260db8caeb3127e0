//! Object-level work on a finished map (the paper's §IV.C): every Gaussian carries one object
//! label, so an object is the set of Gaussians with its label. Plain data in and out, no IPC.
//!
//! - [`list_objects`]: one [`ObjectSummary`] per label (class from the run's `labels.json`
//!   through a [`Catalog`], Gaussian count, [`Extent`]: centroid, axis-aligned and oriented
//!   box from the opacity-weighted means with strays trimmed, approximate volume), largest first.
//! - [`pick_pixel`], [`pick_box`]: the point and box prompts, by GS Voting on a render.
//! - [`Selection`]: labels checked against the map; [`split`] cuts the map into the
//!   selected Gaussians and the rest (extract, remove), both in map order and bit-exact.
//! - [`RigidMotion`] and [`apply`]: move or rotate the selected Gaussians (mean and rotation;
//!   scale, opacity and SH band 0 unchanged); [`refuse_higher_bands`] refuses files whose
//!   colour has SH bands the map cannot carry.
//! - [`compare_edit`]: before/after renders of one view side by side, the object outlined, and
//!   what its former pixels show now.

mod catalog;
mod compare;
mod error;
mod extent;
mod inventory;
mod motion;
mod prompt;
mod selection;
mod sh_guard;

pub use catalog::Catalog;
pub use compare::{compare_edit, EditComparison, EditEffect};
pub use error::{ObjectError, Result};
pub use extent::{extent_of, Aabb, Extent, OrientedBox};
pub use inventory::{indices_per_label, list_objects, ObjectSummary};
pub use motion::{apply, RigidMotion};
pub use prompt::{pick_box, pick_pixel, BoxPick, BoxVote, LabelWeight, PixelBox, PixelPick};
pub use selection::{require_labels, split, Selection};
pub use sh_guard::{ply_sh_degree, refuse_higher_bands};
