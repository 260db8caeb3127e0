//! Binary frame-size masks as bit sets, with their area and box.

#[derive(Debug, Clone, PartialEq)]
pub struct BitMask {
    words: Vec<u64>,
    pub area: usize,
    /// Inclusive pixel bounds (x0, y0, x1, y1); meaningless when area is 0.
    pub bbox: [usize; 4],
}

impl BitMask {
    /// No pixel of a `len`-pixel frame.
    pub fn zeros(len: usize) -> Self {
        Self {
            words: vec![0u64; len.div_ceil(64)],
            area: 0,
            bbox: [usize::MAX, usize::MAX, 0, 0],
        }
    }

    /// Adds pixel (x, y) of a `width`-wide frame (once per pixel).
    pub fn insert(&mut self, x: usize, y: usize, width: usize) {
        let i = y * width + x;
        self.words[i / 64] |= 1 << (i % 64);
        self.area += 1;
        self.bbox = [
            self.bbox[0].min(x),
            self.bbox[1].min(y),
            self.bbox[2].max(x),
            self.bbox[3].max(y),
        ];
    }

    /// Pixels whose value passes `inside`, row-major `width` wide.
    #[cfg(test)]
    pub fn from_fn(values: &[f32], width: usize, inside: impl Fn(f32) -> bool) -> Self {
        let mut words = vec![0u64; values.len().div_ceil(64)];
        let mut area = 0;
        let mut bbox = [usize::MAX, usize::MAX, 0, 0];
        for (i, &v) in values.iter().enumerate() {
            if inside(v) {
                words[i / 64] |= 1 << (i % 64);
                area += 1;
                let (x, y) = (i % width, i / width);
                bbox = [
                    bbox[0].min(x),
                    bbox[1].min(y),
                    bbox[2].max(x),
                    bbox[3].max(y),
                ];
            }
        }
        Self { words, area, bbox }
    }

    pub fn contains(&self, i: usize) -> bool {
        self.words[i / 64] >> (i % 64) & 1 == 1
    }

    #[cfg(test)]
    pub fn intersection(&self, other: &Self) -> usize {
        self.words
            .iter()
            .zip(&other.words)
            .map(|(a, b)| (a & b).count_ones() as usize)
            .sum()
    }

    #[cfg(test)]
    pub fn iou(&self, other: &Self) -> f32 {
        if !self.boxes_overlap(other) {
            return 0.0;
        }
        let inter = self.intersection(other);
        let union = self.area + other.area - inter;
        if union == 0 {
            0.0
        } else {
            inter as f32 / union as f32
        }
    }

    #[cfg(test)]
    fn boxes_overlap(&self, o: &Self) -> bool {
        self.area > 0
            && o.area > 0
            && self.bbox[0] <= o.bbox[2]
            && o.bbox[0] <= self.bbox[2]
            && self.bbox[1] <= o.bbox[3]
            && o.bbox[1] <= self.bbox[3]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iou_of_overlapping_squares() {
        // 10x10 image, squares [0,5)² and [2,7)²: intersection 9, union 41.
        let square = |o: usize| -> Vec<f32> {
            (0..100)
                .map(|i| {
                    let (x, y) = (i % 10, i / 10);
                    if (o..o + 5).contains(&x) && (o..o + 5).contains(&y) {
                        1.0
                    } else {
                        -1.0
                    }
                })
                .collect()
        };
        let a = BitMask::from_fn(&square(0), 10, |v| v > 0.0);
        let b = BitMask::from_fn(&square(2), 10, |v| v > 0.0);
        assert_eq!((a.area, a.bbox), (25, [0, 0, 4, 4]));
        assert_eq!(a.intersection(&b), 9);
        assert!((a.iou(&b) - 9.0 / 41.0).abs() < 1e-6);
        assert!(a.contains(44) && !a.contains(45));
    }
}
