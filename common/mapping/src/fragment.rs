//! Does a label the consensus absorbs whole lie on its host's surface? (docs/METHOD.md §5.5)
//!
//! The consensus sees 2D label maps only: a strip of floor and a cup on a desk both lie wholly
//! inside one segment. In 3D they differ: the strip lies in the floor, the cup stands 5 cm proud
//! of the desk. For each Gaussian of the fragment the host's surface nearby is the plane
//! through its `K` nearest host Gaussians:
//!
//!   c = (1/K) Σ μ_j,   n = normalise(Σ ± a_j)   (a_j: shortest axis of host Gaussian j,
//!                                               signs aligned to a_1)
//!   offset = |(μ − c) · n|
//!
//! The fragment lies on its host when the median offset is at most [`FRAGMENT_MAX_OFFSET_M`].

use nalgebra::{Point3, Vector3};
use opengs_gicp::PointTree;
use opengs_splat::{quat_to_matrix, GaussianMap};

/// Host Gaussians that define the local plane (few enough to stay local on a curved host).
pub const FRAGMENT_NEIGHBOURS: usize = 8;
/// Largest median offset (m) of a fragment from its host's surface: above the 0.4–2 cm of
/// strips of floor measured against the floor, below the 4.5–6 cm of cups and books on a desk.
pub const FRAGMENT_MAX_OFFSET_M: f32 = 0.02;

/// Median distance of the Gaussians labelled `fragment` from the local surface of those
/// labelled `host`; `None` when either label has no Gaussian.
pub fn median_offset_from_host(map: &GaussianMap, fragment: u32, host: u32) -> Option<f32> {
    median_offset(map, &map.indices_with_label(fragment), host)
}

/// True when `fragment` lies on `host`'s surface, or has no Gaussian left to move.
pub fn lies_on_host(map: &GaussianMap, fragment: u32, host: u32) -> bool {
    let fragment_ids = map.indices_with_label(fragment);
    fragment_ids.is_empty()
        || median_offset(map, &fragment_ids, host).is_some_and(|d| d <= FRAGMENT_MAX_OFFSET_M)
}

/// [`median_offset_from_host`] for the Gaussians `fragment_ids`.
fn median_offset(map: &GaussianMap, fragment_ids: &[u32], host: u32) -> Option<f32> {
    let host_ids = map.indices_with_label(host);
    if host_ids.is_empty() || fragment_ids.is_empty() {
        return None;
    }
    let point = |i: u32| {
        let m = map.mean(i as usize);
        Point3::new(f64::from(m.x), f64::from(m.y), f64::from(m.z))
    };
    let tree = PointTree::new(&host_ids.iter().map(|&i| point(i)).collect::<Vec<_>>());
    let mut offsets: Vec<f32> = fragment_ids
        .iter()
        .map(|&i| {
            let p = point(i);
            let near = tree.knn(&p, FRAGMENT_NEIGHBOURS);
            let (mut centre, mut normal) = (Vector3::zeros(), Vector3::zeros());
            let mut first: Option<Vector3<f64>> = None;
            for &(j, _) in &near {
                let g = host_ids[j] as usize;
                let a = shortest_axis(map, g);
                let reference = *first.get_or_insert(a);
                normal += if a.dot(&reference) < 0.0 { -a } else { a };
                centre += point(host_ids[j]).coords;
            }
            centre /= near.len() as f64;
            let n = normal.try_normalize(1e-12).unwrap_or_else(Vector3::z);
            ((p.coords - centre).dot(&n)).abs() as f32
        })
        .collect();
    offsets.sort_unstable_by(f32::total_cmp);
    Some(offsets[offsets.len() / 2])
}

/// Unit axis of Gaussian `i` along its smallest scale: its surface normal.
fn shortest_axis(map: &GaussianMap, i: usize) -> Vector3<f64> {
    let s = map.scale(i);
    let k = (0..3).min_by(|&a, &b| s[a].total_cmp(&s[b])).unwrap_or(2);
    let r = quat_to_matrix(map.rotations[i]);
    Vector3::new(f64::from(r[0][k]), f64::from(r[1][k]), f64::from(r[2][k]))
}
