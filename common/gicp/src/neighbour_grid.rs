//! Exact nearest neighbour *within a radius* by a hashed voxel grid.
//!
//! Why: correspondences and the overlap test only care about target points
//! within a few centimetres. With cells of side 2·radius, a ball of that
//! radius touches at most 2×2×2 cells: 8 hash look-ups and a short
//! contiguous scan, cheaper than a general kd-tree descent.

use nalgebra::Point3;

/// Points bucketed by cubic cells of side `cell`, stored contiguously per cell.
pub struct NeighbourGrid {
    inv_cell: f64,
    /// Open-addressing table of occupied cells: key and range into `points`.
    slots: Vec<Slot>,
    mask: usize,
    /// Point coordinates sorted by cell, and their original indices.
    coords: Vec<[f64; 3]>,
    indices: Vec<u32>,
}

#[derive(Clone, Copy)]
struct Slot {
    key: [i32; 3],
    start: u32,
    end: u32,
}

const EMPTY: Slot = Slot {
    key: [i32::MIN; 3],
    start: 0,
    end: 0,
};

#[inline]
fn hash(key: [i32; 3]) -> usize {
    // Teschner et al.'s spatial hash primes.
    ((key[0] as i64 as u64).wrapping_mul(73_856_093)
        ^ (key[1] as i64 as u64).wrapping_mul(19_349_669)
        ^ (key[2] as i64 as u64).wrapping_mul(83_492_791)) as usize
}

impl NeighbourGrid {
    /// A grid whose queries are exact up to distance `radius` (> 0).
    pub fn new(points: &[Point3<f64>], radius: f64) -> Self {
        let inv_cell = 1.0 / (2.0 * radius);
        let key_of = |p: &Point3<f64>| -> [i32; 3] {
            [
                (p.x * inv_cell).floor() as i32,
                (p.y * inv_cell).floor() as i32,
                (p.z * inv_cell).floor() as i32,
            ]
        };
        let mut order: Vec<([i32; 3], u32)> = points
            .iter()
            .enumerate()
            .map(|(i, p)| (key_of(p), i as u32))
            .collect();
        order.sort_unstable();
        let cells = order.chunk_by(|a, b| a.0 == b.0).count();
        let capacity = (cells * 2).next_power_of_two().max(16);
        let mut grid = Self {
            inv_cell,
            slots: vec![EMPTY; capacity],
            mask: capacity - 1,
            coords: order
                .iter()
                .map(|&(_, i)| {
                    let p = points[i as usize];
                    [p.x, p.y, p.z]
                })
                .collect(),
            indices: order.iter().map(|&(_, i)| i).collect(),
        };
        let mut start = 0;
        for run in order.chunk_by(|a, b| a.0 == b.0) {
            let key = run[0].0;
            let mut h = hash(key) & grid.mask;
            while grid.slots[h].key != EMPTY.key {
                h = (h + 1) & grid.mask;
            }
            grid.slots[h] = Slot {
                key,
                start: start as u32,
                end: (start + run.len()) as u32,
            };
            start += run.len();
        }
        grid
    }

    #[inline]
    fn cell(&self, key: [i32; 3]) -> Option<&Slot> {
        let mut h = hash(key) & self.mask;
        loop {
            let slot = &self.slots[h];
            if slot.key == key {
                return Some(slot);
            }
            if slot.key == EMPTY.key {
                return None;
            }
            h = (h + 1) & self.mask;
        }
    }

    /// Nearest point within `max_sq_dist` (≤ radius²): `(index, squared distance)`.
    #[inline]
    pub fn nearest_within(&self, q: &Point3<f64>, max_sq_dist: f64) -> Option<(usize, f64)> {
        // Per axis, the two cells the ball can reach: its own (first, so
        // the best distance shrinks early) and the one beyond the nearer
        // face, with the squared gap from the query to that face.
        let cell_side = 1.0 / self.inv_cell;
        let span = |x: f64| -> ([i32; 2], [f64; 2]) {
            let c = x * self.inv_cell;
            let k = c.floor();
            let f = c - k;
            if f < 0.5 {
                ([k as i32, k as i32 - 1], [0.0, (f * cell_side).powi(2)])
            } else {
                (
                    [k as i32, k as i32 + 1],
                    [0.0, ((1.0 - f) * cell_side).powi(2)],
                )
            }
        };
        let ((kx, gx), (ky, gy), (kz, gz)) = (span(q.x), span(q.y), span(q.z));
        let mut best = (u32::MAX, max_sq_dist);
        for (x, gap_x) in kx.into_iter().zip(gx) {
            for (y, gap_y) in ky.into_iter().zip(gy) {
                for (z, gap_z) in kz.into_iter().zip(gz) {
                    // Skip cells whose box is farther than the best so far.
                    if gap_x + gap_y + gap_z > best.1 {
                        continue;
                    }
                    let Some(slot) = self.cell([x, y, z]) else {
                        continue;
                    };
                    for i in slot.start as usize..slot.end as usize {
                        let c = &self.coords[i];
                        let d = (c[0] - q.x).powi(2) + (c[1] - q.y).powi(2) + (c[2] - q.z).powi(2);
                        if d <= best.1 {
                            best = (self.indices[i], d);
                        }
                    }
                }
            }
        }
        (best.0 != u32::MAX).then_some((best.0 as usize, best.1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::PointTree;
    use rand::{Rng, SeedableRng};

    #[test]
    fn agrees_with_the_kd_tree_within_the_radius() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let points: Vec<_> = (0..5000)
            .map(|_| {
                Point3::new(
                    rng.gen_range(-1.0..1.0),
                    rng.gen_range(-1.0..1.0),
                    rng.gen_range(-0.1..0.1),
                )
            })
            .collect();
        let grid = NeighbourGrid::new(&points, 0.05);
        let tree = PointTree::new(&points);
        for _ in 0..2000 {
            let q = Point3::new(
                rng.gen_range(-1.2..1.2),
                rng.gen_range(-1.2..1.2),
                rng.gen_range(-0.2..0.2),
            );
            let expected = tree.nearest_within(&q, 0.05 * 0.05);
            let got = grid.nearest_within(&q, 0.05 * 0.05);
            assert_eq!(got.map(|g| g.1), expected.map(|e| e.1), "query {q:?}");
        }
    }
}
