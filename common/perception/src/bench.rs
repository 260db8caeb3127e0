//! Timing of the weight-free segmenters on synthetic 640×480 frames.

use std::time::Instant;

use opengs_datasets::{open_dataset, DatasetKind, DatasetSpec};

use crate::{PerceptionError, SegmenterInput, SegmenterKind};

/// Median and minimum wall time of one segmenter over the bench frames.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentTiming {
    pub segmenter: SegmenterKind,
    pub frames: usize,
    pub median_ms: f64,
    pub min_ms: f64,
}

/// Times classic and prior on `frames` synthetic frames spread over the loop,
/// each segmented `repeats` times (the first run of each frame is a warm-up).
pub fn time_segmenters(
    frames: usize,
    repeats: usize,
) -> Result<Vec<SegmentTiming>, PerceptionError> {
    let mut source = open_dataset(&DatasetSpec::new(DatasetKind::Synthetic))?;
    let k = source.intrinsics();
    let classes = source.class_table();
    let step = (source.len() / frames.max(1)).max(1);
    let frames: Vec<_> = (0..frames.max(1))
        .map(|i| source.frame((i * step) % source.len()))
        .collect::<Result<_, _>>()?;
    [SegmenterKind::Classic, SegmenterKind::Prior]
        .into_iter()
        .map(|kind| {
            let mut segmenter = kind.create()?;
            let mut times = Vec::new();
            for frame in &frames {
                let input = SegmenterInput::from_frame(frame, k, &classes);
                segmenter.segment(&input)?;
                for _ in 0..repeats.max(1) {
                    let start = Instant::now();
                    let out = segmenter.segment(&input)?;
                    times.push(start.elapsed().as_secs_f64() * 1e3);
                    std::hint::black_box(out);
                }
            }
            times.sort_unstable_by(f64::total_cmp);
            Ok(SegmentTiming {
                segmenter: kind,
                frames: frames.len(),
                median_ms: times[times.len() / 2],
                min_ms: times[0],
            })
        })
        .collect()
}

/// Prints the median milliseconds per 640×480 frame of each segmenter.
pub fn print_segment_bench(frames: usize, repeats: usize) -> Result<(), PerceptionError> {
    for t in time_segmenters(frames, repeats)? {
        println!(
            "segment/{:<8} median {:7.2} ms  min {:7.2} ms  per 640x480 frame ({} frames x {} runs, {} cores available)",
            t.segmenter.as_str(),
            t.median_ms,
            t.min_ms,
            t.frames,
            repeats.max(1),
            available_cores(),
        );
    }
    Ok(())
}

fn available_cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}
