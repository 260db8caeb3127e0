//! Line-oriented text files shared by the TUM and Replica readers.

use std::path::Path;

use crate::DatasetError;

/// Non-empty, non-comment lines of a text file's contents with 1-based line numbers.
pub(crate) fn data_lines(text: &str) -> Vec<(usize, String)> {
    text.lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
        .map(|(i, l)| (i, l.to_string()))
        .collect()
}

/// Parses every whitespace-separated field of a line as f64.
pub(crate) fn parse_numbers(
    path: &Path,
    line_no: usize,
    line: &str,
) -> Result<Vec<f64>, DatasetError> {
    line.split_whitespace()
        .map(|t| {
            t.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    DatasetError::parse(path, line_no, format!("'{t}' is not a finite number"))
                })
        })
        .collect()
}

/// Index of the entry in sorted `times` nearest to `t`, if within `max_dt`.
pub(crate) fn nearest_within(times: &[f64], t: f64, max_dt: f64) -> Option<usize> {
    let i = times.partition_point(|&x| x < t);
    let mut best: Option<usize> = None;
    for j in [i.wrapping_sub(1), i] {
        if j < times.len() && best.is_none_or(|b| (times[j] - t).abs() < (times[b] - t).abs()) {
            best = Some(j);
        }
    }
    best.filter(|&j| (times[j] - t).abs() <= max_dt)
}
