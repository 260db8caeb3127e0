//! Camera model and rigid-body poses shared by every stage.
//!
//! Conventions (docs/METHOD.md §2): pinhole intrinsics in the OpenCV pixel
//! convention (pixel (u, v) has its centre at integer coordinates), poses
//! stored camera-to-world as in TUM and Replica files, camera looking down +z.

mod intrinsics;
pub mod memory;
mod ply;
mod pose;
mod rigid_fit;

pub use intrinsics::Intrinsics;
pub use ply::{read_vertex_table, PlyError, VertexTable};
pub use pose::{format_tum_pose, parse_tum_pose, pose_from_tum, pose_to_tum, Pose, PoseParseError};
pub use rigid_fit::rigid_fit;

pub use nalgebra;
