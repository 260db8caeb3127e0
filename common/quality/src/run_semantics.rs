//! Semantic outputs of a finished run (docs/METHOD.md §9): `labels.json` (the global Label-Class
//! table with Gaussian counts from map.ply), mIoU / accuracy of label maps rendered from the
//! map at held-out poses (frames that were not keyframes), and `miou_raw`: the segmenter's
//! own per-keyframe label maps (segments/*.png) scored the same way. Both use one global
//! one-to-one matching of labels to ground-truth instances over the sequence. A segmenter that
//! draws fresh ids every frame (SAM, `geometry`) cannot score there, so `miou_raw_per_frame`
//! scores each keyframe map with a matching of its own (as `opengs bench segment --quality`).

use std::collections::BTreeSet;
use std::path::Path;

use image::{ImageBuffer, Rgb};
use opengs_datasets::{RgbdFrame, RgbdSource};
use opengs_eval::RunDir;
use opengs_eval::{read_label_png, read_tum_trajectory, LabelConfusion, SegmentationScore};
use opengs_perception::quality::frame_quality;
use opengs_semantics::GlobalLabelTable;
use opengs_splat::{label_color, render, Camera, GaussianMap, RenderRequest, DEFAULT_NEAR};
use serde::Serialize;

use crate::{merge_metrics_json, png_positions, read_map, FrameMatcher};

/// Label-map PNGs written per run (evenly spread over the scored frames).
const LABEL_PNGS: usize = 6;

/// What [`evaluate_run_semantics`] found.
#[derive(Debug, Clone, Serialize)]
pub struct SemanticReport {
    /// Labels rendered from the map at held-out poses.
    pub map: Option<SegmentationScore>,
    /// The segmenter's per-keyframe label maps.
    pub raw: Option<SegmentationScore>,
    /// The same maps, each matched to the truth on its own: mean per-frame mIoU.
    pub raw_per_frame_miou: Option<f64>,
    /// Global labels in labels.json.
    pub labels: usize,
    /// Labels carried by at least one Gaussian of the final map.
    pub map_labels: usize,
}

/// Writes labels.json and semantics.json, merges the scores into metrics.json.
pub fn evaluate_run_semantics(
    run_dir: &Path,
    source: &mut dyn RgbdSource,
    every_n: usize,
) -> anyhow::Result<SemanticReport> {
    let run = RunDir::new(run_dir);
    let map = read_map(&run.map())?;
    let counts = map.count_per_label();
    let labels = match GlobalLabelTable::load(&run.label_table())? {
        Some(table) => {
            let records = table.records(|id| counts.get(&id).copied().unwrap_or(0) as u64);
            std::fs::write(run.labels(), serde_json::to_string_pretty(&records)? + "\n")?;
            records.len()
        }
        None => 0,
    };
    let keyframes = read_keyframes(&run.keyframes())?;
    let map_score = score_map(run_dir, &map, source, every_n, &keyframes)?;
    let (raw, raw_per_frame_miou) = score_segments(&run.segments_dir(), source)?;
    let report = SemanticReport {
        map: map_score,
        raw,
        raw_per_frame_miou,
        labels,
        map_labels: counts.keys().filter(|&&l| l != 0).count(),
    };
    std::fs::write(
        run.semantics(),
        serde_json::to_string_pretty(&report)? + "\n",
    )?;
    let mut entries = serde_json::Map::new();
    if let Some(s) = &report.map {
        entries.insert("miou".into(), s.miou.into());
        entries.insert("acc".into(), s.acc.into());
        entries.insert("semantic_frames".into(), s.frames.into());
    }
    if let Some(s) = &report.raw {
        entries.insert("miou_raw".into(), s.miou.into());
        entries.insert("acc_raw".into(), s.acc.into());
        entries.insert("semantic_frames_raw".into(), s.frames.into());
    }
    if let Some(m) = report.raw_per_frame_miou {
        entries.insert("miou_raw_per_frame".into(), m.into());
    }
    entries.insert("labels".into(), report.labels.into());
    entries.insert("map_labels".into(), report.map_labels.into());
    merge_metrics_json(&run.metrics(), entries)?;
    Ok(report)
}

/// Keyframe seqs written by the mapper (absent file: none known).
fn read_keyframes(path: &Path) -> anyhow::Result<BTreeSet<u64>> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(BTreeSet::new()),
        Err(e) => return Err(anyhow::anyhow!("{}: {e}", path.display())),
    };
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            l.trim()
                .parse::<u64>()
                .map_err(|e| anyhow::anyhow!("{} line {}: {e}", path.display(), i + 1))
        })
        .collect()
}

/// The frame's instance labels where it has depth ([`RgbdFrame::labels_where_measured`]).
fn truth_of(frame: &RgbdFrame) -> Option<Vec<u32>> {
    Some(
        frame
            .labels_where_measured()?
            .into_iter()
            .map(u32::from)
            .collect(),
    )
}

/// Renders labels at one held-out pose (not a keyframe) in every `every_n` of trajectory.txt.
fn score_map(
    run_dir: &Path,
    map: &GaussianMap,
    source: &mut dyn RgbdSource,
    every_n: usize,
    keyframes: &BTreeSet<u64>,
) -> anyhow::Result<Option<SegmentationScore>> {
    let run = RunDir::new(run_dir);
    let trajectory = read_tum_trajectory(&run.trajectory())?;
    let k = source.intrinsics();
    let mut matcher = FrameMatcher::new(source);
    let mut confusion = LabelConfusion::new();
    let every_n = every_n.max(1);
    let starts: Vec<usize> = (every_n / 2..trajectory.len()).step_by(every_n).collect();
    // Spread over the slots, chosen up front so no label map has to be kept for later.
    let pngs = png_positions(starts.len(), LABEL_PNGS);
    let renders = run.renders_dir();
    for (slot, &start) in starts.iter().enumerate() {
        // Held-out poses only: the first non-keyframe at or after `start`.
        let mut found = None;
        for p in trajectory.iter().skip(start).take(every_n.div_ceil(2)) {
            if let Some(frame) = matcher.frame_at(p.timestamp)? {
                if !keyframes.contains(&(frame.index as u64)) {
                    found = Some((p, frame));
                    break;
                }
            }
        }
        let Some((p, frame)) = found else {
            continue;
        };
        let Some(truth) = truth_of(&frame) else {
            return Ok(None); // the dataset has no instance labels
        };
        let camera = Camera::from_pose(k, &p.pose, DEFAULT_NEAR);
        let request = RenderRequest {
            labels: true,
            ..RenderRequest::default()
        };
        let predicted = render(map, &camera, &request)
            .output
            .labels
            .unwrap_or_default();
        confusion
            .add_frame(&predicted, &truth)
            .map_err(|e| anyhow::anyhow!("frame {}: {e}", frame.index))?;
        if pngs.contains(&slot) {
            std::fs::create_dir_all(&renders)?;
            let path = renders.join(format!("labels_{:06}.png", frame.index));
            write_label_pair_png(&path, k.width, k.height, &predicted, &truth)?;
        }
    }
    Ok(confusion.score())
}

/// Scores the segmenter's saved label maps against the ground truth of their frames.
/// The segmenter's keyframe maps: one matching over all of them, and the mean of a matching
/// per map.
fn score_segments(
    dir: &Path,
    source: &mut dyn RgbdSource,
) -> anyhow::Result<(Option<SegmentationScore>, Option<f64>)> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok((None, None));
    };
    let mut files: Vec<(usize, std::path::PathBuf)> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let path = e.path();
            let index = path.file_stem()?.to_str()?.parse::<usize>().ok()?;
            (path.extension()? == "png").then_some((index, path))
        })
        .collect();
    files.sort();
    let mut confusion = LabelConfusion::new();
    let mut per_frame = Vec::new();
    for (index, path) in files {
        if index >= source.len() {
            anyhow::bail!("{}: frame {index} is not in the dataset", path.display());
        }
        let frame = source.frame(index)?;
        let Some(truth) = truth_of(&frame) else {
            return Ok((None, None));
        };
        let (_, _, predicted) = read_label_png(&path).map_err(|e| anyhow::anyhow!(e))?;
        confusion
            .add_frame(&predicted, &truth)
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        // Instance ids are u16 in the datasets, so this never saturates.
        let truth16: Vec<u16> = truth
            .iter()
            .map(|&t| u16::try_from(t).unwrap_or(u16::MAX))
            .collect();
        per_frame.extend(frame_quality(&predicted, &truth16).map(|q| q.miou));
    }
    let mean =
        (!per_frame.is_empty()).then(|| per_frame.iter().sum::<f64>() / per_frame.len() as f64);
    Ok((confusion.score(), mean))
}

/// Rendered labels | ground-truth instances, each colourised with the stable label colours.
fn write_label_pair_png(
    path: &Path,
    width: u32,
    height: u32,
    predicted: &[u32],
    truth: &[u32],
) -> anyhow::Result<()> {
    let img = ImageBuffer::from_fn(width * 2, height, |x, y| {
        let (map, x) = if x < width {
            (predicted, x)
        } else {
            (truth, x - width)
        };
        Rgb(label_color(map[(y * width + x) as usize]))
    });
    img.save(path)
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn truth_is_scored_only_where_the_frame_has_depth() {
        let frame = RgbdFrame {
            index: 0,
            timestamp: 0.0,
            width: 2,
            height: 2,
            rgb: vec![0; 12],
            depth: vec![5000, 0, 5000, 0],
            depth_scale: 5000.0,
            gt_pose: None,
            labels: Some(vec![3, 3, 7, 0]),
        };
        assert_eq!(truth_of(&frame), Some(vec![3, 0, 7, 0]));
        // A depth image of another size masks nothing.
        let odd = RgbdFrame {
            depth: vec![0; 3],
            ..frame.clone()
        };
        assert_eq!(truth_of(&odd), Some(vec![3, 3, 7, 0]));
        let unlabelled = RgbdFrame {
            labels: None,
            ..frame
        };
        assert_eq!(truth_of(&unlabelled), None);
    }
}
