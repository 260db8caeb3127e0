//! Step 4f: what lies flat on a surface, pixel by pixel. Step 4e ([`super::raised`]) finds a
//! keyboard on a desk from its patches, but a patch is 16 pixels wide: a keyboard 2 m away is
//! a band a few patches high, every patch straddling its edge, and a stack of books is one
//! segment whose books no boundary rule tells apart (each book's edge is a 1–3 cm step, under
//! the noise allowance, and every face between them is convex). Per pixel the cue is plain:
//! the top of each book, and of the keyboard, is a face parallel to the surface they lie on,
//! at its own height above it.
//!
//! ```text
//!   host H:   a segment whose plane holds ≥ HOST_SHARE of the frame and ≥ HOST_INLIERS of
//!             H's pixels (as in step 4e); plane (n_H, c_H), n_H facing the camera
//!   ref(S)  = S when S is a host, else the host S shares the most pixel borders with
//!   rise(i) = n_H·(xᵢ − c_H),  H = ref(segment of i)
//!   level(i) ⇔ nᵢ·n_H ≥ cos LEVEL_ANGLE  and  min_raise·zᵢ ≤ rise(i) ≤ MAX_LEVEL
//!   faces   = connected sets of level pixels of one segment, neighbours within
//!             ½·min_raise·z of each other in rise
//!   in a host:      a face of ≥ min_share of the frame, ≤ ½ of the host, filling
//!                   ≥ MIN_FILL of the rectangle of its second moments (12·√det Σ), is an
//!                   object (the keyboard)
//!   in another S:   faces of ≥ min_level_share of the frame grouped by mean rise (within
//!                   min_raise·z); two or more groups → S is a stack: each group is one
//!                   object, and every other pixel of S joins the lowest group whose top
//!                   is at or above it (a book's side lies under its own top)
//! ```
//!
//! Only within `MAX_LEVEL` of the host: a sofa's seat and arms, or a bookshelf's boards, are
//! levels of one object far above the floor; flat things stacked on a desk are not.

use super::coplanar::Plane;
use super::flat_objects::MAX_HOST_SHARE;
use super::regions::NO_SEGMENT;
use crate::classic::normals::SurfaceGeometry;
use crate::classic::union_find::UnionFind;

/// Highest face counted as lying on a host (metres): a stack of three thick books, not a
/// chair's seat over the floor.
const MAX_LEVEL: f32 = 0.12;
/// Largest angle (radians) between a face's pixel normal and its host's normal.
const LEVEL_ANGLE: f32 = 0.4;
/// Smallest share of the rectangle of its second moments an object on a host fills: a
/// keyboard seen at any angle (≈ 1), not a strip blended along an occluding edge.
const MIN_FILL: f64 = 0.5;

/// Thresholds of the pixel-level split.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LevelRules {
    /// Smallest object on a host, as a share of the frame's pixels with depth; 0 turns the
    /// split inside hosts off.
    pub min_share: f32,
    /// Smallest face of a stack, as a share of the frame's pixels with depth; 0 turns the
    /// stack split off.
    pub min_level_share: f32,
    /// Smallest height above the host, per metre of depth.
    pub min_raise: f32,
}

/// One face: connected level pixels of one segment.
#[derive(Debug, Clone, Copy)]
struct Face {
    segment: u32,
    pixels: u32,
    rise_sum: f64,
    depth_sum: f64,
    /// Sums of x, y, x², y², xy over the pixels: the face's second moments.
    moments: [f64; 5],
}

impl Face {
    fn rise(&self) -> f32 {
        (self.rise_sum / f64::from(self.pixels.max(1))) as f32
    }
    fn depth(&self) -> f32 {
        (self.depth_sum / f64::from(self.pixels.max(1))) as f32
    }
    /// Area of the rectangle with the face's second moments (12·√det Σ: a filled rectangle's,
    /// at any angle), at least one pixel.
    fn moment_area(&self) -> f64 {
        let n = f64::from(self.pixels.max(1));
        let [sx, sy, sxx, syy, sxy] = self.moments;
        let (mx, my) = (sx / n, sy / n);
        // + 1/12 per axis: a pixel is a unit square, not a point.
        let vxx = sxx / n - mx * mx + 1.0 / 12.0;
        let vyy = syy / n - my * my + 1.0 / 12.0;
        let vxy = sxy / n - mx * my;
        12.0 * (vxx * vyy - vxy * vxy).max(0.0).sqrt()
    }
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl LevelRules {
    /// Faces sorted by mean rise and grouped where each is within min_raise·z of the last.
    fn group_by_height(&self, faces: &[Face], mut ks: Vec<usize>) -> Vec<Vec<usize>> {
        ks.sort_by(|&a, &b| faces[a].rise().total_cmp(&faces[b].rise()).then(a.cmp(&b)));
        let mut groups: Vec<Vec<usize>> = Vec::new();
        for k in ks {
            let f = &faces[k];
            let joins = groups
                .last()
                .and_then(|g| g.last())
                .is_some_and(|&p| f.rise() - faces[p].rise() <= self.min_raise * f.depth());
            match groups.last_mut() {
                Some(g) if joins => g.push(k),
                _ => groups.push(vec![k]),
            }
        }
        groups
    }

    /// Splits objects off hosts and stacks into objects in `segments` (one per coarse pixel,
    /// `NO_SEGMENT` for none); `host_planes[s]` is segment `s`'s plane when it is a host.
    /// Returns, for every new segment (numbered from `count` on), the segment it came from.
    pub(super) fn split(
        &self,
        segments: &mut [u32],
        count: usize,
        geo: &SurfaceGeometry,
        width: usize,
        host_planes: &[Option<Plane>],
        sets: &mut UnionFind,
    ) -> Vec<u32> {
        let n = segments.len();
        let mut parents = Vec::new();
        if (self.min_share <= 0.0 && self.min_level_share <= 0.0) || width == 0 {
            return parents;
        }
        let valid = |i: usize| segments[i] != NO_SEGMENT && geo.points[i][2] > 0.0;
        let total = (0..n).filter(|&i| valid(i)).count() as f64;
        let reference = reference_hosts(segments, width, count, host_planes);
        // Height above its host's plane of every pixel with one, and whether it is level.
        let (rise, level): (Vec<Option<f32>>, Vec<bool>) = (0..n)
            .map(|i| {
                let plane = valid(i)
                    .then(|| reference[segments[i] as usize])
                    .flatten()
                    .and_then(|h| host_planes[h as usize]);
                let Some(plane) = plane else {
                    return (None, false);
                };
                let p = geo.points[i];
                let c = plane.centroid;
                let r = dot(plane.normal, [p[0] - c[0], p[1] - c[1], p[2] - c[2]]);
                let level = dot(geo.normals[i], plane.normal) >= LEVEL_ANGLE.cos()
                    && r >= self.min_raise * p[2]
                    && r <= MAX_LEVEL;
                (Some(r), level)
            })
            .unzip();
        // Faces: level neighbours of one segment at one height.
        sets.reset(n, 0.0);
        let same_face = |a: usize, b: usize| {
            level[a]
                && level[b]
                && segments[a] == segments[b]
                && match (rise[a], rise[b]) {
                    (Some(ra), Some(rb)) => {
                        (ra - rb).abs() <= 0.5 * self.min_raise * geo.points[a][2]
                    }
                    _ => false,
                }
        };
        for i in 0..n {
            if (i + 1) % width != 0 && same_face(i, i + 1) {
                sets.join(i as u32, i as u32 + 1);
            }
            if i + width < n && same_face(i, i + width) {
                sets.join(i as u32, (i + width) as u32);
            }
        }
        let mut face_of = vec![u32::MAX; n];
        let mut faces: Vec<Face> = Vec::new();
        let mut index_of_root = std::collections::HashMap::new();
        for i in (0..n).filter(|&i| level[i]) {
            let root = sets.find(i as u32);
            let k = *index_of_root.entry(root).or_insert_with(|| {
                faces.push(Face {
                    segment: segments[i],
                    pixels: 0,
                    rise_sum: 0.0,
                    depth_sum: 0.0,
                    moments: [0.0; 5],
                });
                faces.len() - 1
            });
            let (x, y) = ((i % width) as f64, (i / width) as f64);
            let f = &mut faces[k];
            f.pixels += 1;
            f.rise_sum += f64::from(rise[i].unwrap_or(0.0));
            f.depth_sum += f64::from(geo.points[i][2]);
            for (m, v) in f.moments.iter_mut().zip([x, y, x * x, y * y, x * y]) {
                *m += v;
            }
            face_of[i] = k as u32;
        }
        let mut segment_pixels = vec![0u64; count];
        for &s in segments.iter().filter(|&&s| s != NO_SEGMENT) {
            segment_pixels[s as usize] += 1;
        }
        // New segment of each face, if it becomes one.
        let mut face_segment: Vec<Option<u32>> = vec![None; faces.len()];
        let mut next = count as u32;
        // Objects on a host.
        let min_object = f64::from(self.min_share) * total;
        for (k, f) in faces.iter().enumerate() {
            let s = f.segment as usize;
            if self.min_share <= 0.0 || host_planes[s].is_none() {
                continue;
            }
            let pixels = f64::from(f.pixels);
            if pixels >= min_object
                && pixels <= MAX_HOST_SHARE * segment_pixels[s] as f64
                && pixels >= MIN_FILL * f.moment_area()
            {
                face_segment[k] = Some(next);
                parents.push(f.segment);
                next += 1;
            }
        }
        // Stacks: per non-host segment, its faces grouped by height.
        let min_level = f64::from(self.min_level_share) * total;
        // Per stacked segment, its levels' (mean rise, segment), lowest first.
        let mut stack_levels: std::collections::HashMap<u32, Vec<(f32, u32)>> = Default::default();
        if self.min_level_share > 0.0 {
            let mut by_segment: std::collections::BTreeMap<u32, Vec<usize>> = Default::default();
            for (k, f) in faces.iter().enumerate() {
                if host_planes[f.segment as usize].is_none() && f64::from(f.pixels) >= min_level {
                    by_segment.entry(f.segment).or_default().push(k);
                }
            }
            // Stacks of their own: faces at two heights or more.
            let stacks: Vec<(u32, Vec<usize>)> = by_segment
                .into_iter()
                .filter(|(_, own)| self.group_by_height(&faces, own.clone()).len() >= 2)
                .collect();
            // Faces left in a host beside a stack standing on it: the bottom book of a stack is
            // often in its desk's segment (a 3 cm step), its exposed top a U round the books
            // above, which no fill test admits as an object of its own. A box's top and a strip
            // blended along its edge are no stack, so they take none.
            let mut beside: std::collections::BTreeMap<u32, Vec<usize>> = Default::default();
            let is_stack = |s: u32| stacks.iter().any(|(t, _)| *t == s);
            if !stacks.is_empty() {
                for i in 0..n {
                    let right = ((i + 1) % width != 0).then_some(i + 1);
                    let down = (i + width < n).then_some(i + width);
                    for j in [right, down].into_iter().flatten() {
                        for (a, b) in [(i, j), (j, i)] {
                            let (k, s) = (face_of[a], segments[b]);
                            if k == u32::MAX
                                || s == NO_SEGMENT
                                || face_segment[k as usize].is_some()
                            {
                                continue;
                            }
                            let f = &faces[k as usize];
                            let adopts = is_stack(s)
                                && reference[s as usize] == Some(f.segment)
                                && host_planes[f.segment as usize].is_some()
                                && f64::from(f.pixels) >= min_level;
                            if adopts {
                                let list = beside.entry(s).or_default();
                                if !list.contains(&(k as usize)) {
                                    list.push(k as usize);
                                }
                            }
                        }
                    }
                }
            }
            for (s, own) in stacks {
                let extra = beside.get(&s).into_iter().flatten();
                let all: Vec<usize> = own.iter().chain(extra).copied().collect();
                let groups = self.group_by_height(&faces, all);
                let mut levels = Vec::with_capacity(groups.len());
                for (g, group) in groups.iter().enumerate() {
                    // The lowest level keeps the segment's id.
                    let id = if g == 0 {
                        s
                    } else {
                        parents.push(s);
                        next += 1;
                        next - 1
                    };
                    let (mut sum, mut pixels) = (0.0f64, 0u32);
                    for &k in group {
                        face_segment[k] = Some(id);
                        sum += faces[k].rise_sum;
                        pixels += faces[k].pixels;
                    }
                    levels.push(((sum / f64::from(pixels.max(1))) as f32, id));
                }
                stack_levels.insert(s, levels);
            }
        }
        for i in 0..n {
            let s = segments[i];
            if s == NO_SEGMENT {
                continue;
            }
            // Level pixels of a face that became a segment; `face_of` is u32::MAX for the rest.
            if let Some(id) = face_segment.get(face_of[i] as usize).copied().flatten() {
                segments[i] = id;
            } else if let (Some(levels), Some(r)) = (stack_levels.get(&s), rise[i]) {
                // Under the lowest top at or above it, within the noise allowance.
                let tolerance = self.min_raise * geo.points[i][2];
                let level = levels
                    .iter()
                    .find(|(top, _)| *top >= r - tolerance)
                    .or(levels.last());
                if let Some(&(_, id)) = level {
                    segments[i] = id;
                }
            }
        }
        parents
    }
}

/// For each segment, the host it is measured against: itself when it is a host, else the
/// host it shares the most 4-neighbour pixel borders with (`None` when it touches none).
fn reference_hosts(
    segments: &[u32],
    width: usize,
    count: usize,
    host_planes: &[Option<Plane>],
) -> Vec<Option<u32>> {
    let mut contact: std::collections::HashMap<(u32, u32), u32> = Default::default();
    let n = segments.len();
    let is_host = |s: u32| s != NO_SEGMENT && host_planes[s as usize].is_some();
    for i in 0..n {
        let right = ((i + 1) % width != 0).then_some(i + 1);
        let down = (i + width < n).then_some(i + width);
        for j in [right, down].into_iter().flatten() {
            let (a, b) = (segments[i], segments[j]);
            if a == b || a == NO_SEGMENT || b == NO_SEGMENT {
                continue;
            }
            if is_host(b) {
                *contact.entry((a, b)).or_default() += 1;
            }
            if is_host(a) {
                *contact.entry((b, a)).or_default() += 1;
            }
        }
    }
    let mut best: Vec<Option<(u32, u32)>> = vec![None; count];
    for (&(s, h), &c) in &contact {
        let slot = &mut best[s as usize];
        // Ties go to the lower host id, so the answer does not depend on the map's order.
        if slot.is_none_or(|(bh, bc)| c > bc || (c == bc && h < bh)) {
            *slot = Some((h, c));
        }
    }
    (0..count)
        .map(|s| {
            if host_planes[s].is_some() {
                Some(s as u32)
            } else {
                best[s].map(|(h, _)| h)
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn face_of_pixels(pixels: impl Iterator<Item = (f64, f64)>) -> Face {
        let mut f = Face {
            segment: 0,
            pixels: 0,
            rise_sum: 0.0,
            depth_sum: 0.0,
            moments: [0.0; 5],
        };
        for (x, y) in pixels {
            f.pixels += 1;
            for (m, v) in f.moments.iter_mut().zip([x, y, x * x, y * y, x * y]) {
                *m += v;
            }
        }
        f
    }

    #[test]
    fn a_rectangle_fills_its_moment_rectangle_at_any_angle_and_an_l_does_not() {
        // 40 × 10 pixels, straight: 12·√det Σ = 12·√((40²/12)(10²/12)) = 400.
        let straight = face_of_pixels((0..400).map(|i| ((i % 40) as f64, (i / 40) as f64)));
        assert!(
            (straight.moment_area() - 400.0).abs() < 1e-6,
            "{}",
            straight.moment_area()
        );
        // The same rectangle turned 30°, sampled on the grid: within a few percent of its area.
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        let turned = face_of_pixels(
            (-40..40)
                .flat_map(|y| (-40..40).map(move |x| (x, y)))
                .filter_map(|(x, y)| {
                    let (x, y) = (f64::from(x), f64::from(y));
                    let (u, v) = (c * x + s * y, -s * x + c * y);
                    (u.abs() < 20.0 && v.abs() < 5.0).then_some((x, y))
                }),
        );
        let fill = f64::from(turned.pixels) / turned.moment_area();
        assert!((fill - 1.0).abs() < 0.05, "fill {fill}");
        // An L of two 40 × 4 arms: a strip bent round a corner, far from filling its rectangle.
        let l = face_of_pixels(
            (0..40)
                .flat_map(|x| (0..4).map(move |y| (x as f64, y as f64)))
                .chain((4..40).flat_map(|y| (0..4).map(move |x| (x as f64, y as f64)))),
        );
        let fill = f64::from(l.pixels) / l.moment_area();
        assert!(fill < 0.5, "fill {fill}");
    }
}
