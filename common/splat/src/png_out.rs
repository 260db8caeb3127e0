//! PNG files of a render (`opengs render`): colour, depth (mm), labels (colourised and raw).

use std::path::Path;

use image::{ImageBuffer, Luma, Rgb};

use crate::output::RenderOutput;

/// A stable, well-spread colour for a label (0 → black).
pub fn label_color(label: u32) -> [u8; 3] {
    if label == 0 {
        return [0, 0, 0];
    }
    // splitmix-style integer hash: neighbouring ids get unrelated colours.
    let mut h = label as u64 ^ 0x9E37_79B9_7F4A_7C15;
    h = (h ^ (h >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h = (h ^ (h >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    h ^= h >> 31;
    // Keep channels away from black so labels never look like background.
    [
        64 + (h & 0xBF) as u8,
        64 + ((h >> 8) & 0xBF) as u8,
        64 + ((h >> 16) & 0xBF) as u8,
    ]
}

/// Writes `color.png` (8-bit RGB), `depth.png` (16-bit mm), and, if the render has labels,
/// `labels.png` (colourised) and `labels_u16.png` (raw ids) into `dir` (created if missing).
/// Returns the paths written.
pub fn write_render_pngs(
    out: &RenderOutput,
    dir: &Path,
) -> Result<Vec<std::path::PathBuf>, image::ImageError> {
    std::fs::create_dir_all(dir)?;
    let (w, h) = (out.width, out.height);
    let mut written = Vec::new();

    let to_u8 = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    let color =
        ImageBuffer::<Rgb<u8>, _>::from_fn(w, h, |x, y| Rgb(out.color[out.index(x, y)].map(to_u8)));
    let path = dir.join("color.png");
    color.save(&path)?;
    written.push(path);

    let depth = ImageBuffer::<Luma<u16>, _>::from_fn(w, h, |x, y| {
        Luma([(out.depth[out.index(x, y)] * 1000.0)
            .round()
            .clamp(0.0, 65535.0) as u16])
    });
    let path = dir.join("depth.png");
    depth.save(&path)?;
    written.push(path);

    if let Some(labels) = &out.labels {
        let lab = |x: u32, y: u32| labels[out.index(x, y)];
        let path = dir.join("labels.png");
        ImageBuffer::<Rgb<u8>, _>::from_fn(w, h, |x, y| Rgb(label_color(lab(x, y)))).save(&path)?;
        written.push(path);
        let path = dir.join("labels_u16.png");
        // Labels are capped far below 65535 (docs/METHOD.md §5: 2000 per run); saturate just in
        // case.
        ImageBuffer::<Luma<u16>, _>::from_fn(w, h, |x, y| Luma([lab(x, y).min(65535) as u16]))
            .save(&path)?;
        written.push(path);
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_four_pngs_with_expected_values() {
        let out = RenderOutput {
            width: 2,
            height: 1,
            color: vec![[1.0, 0.5, 0.0], [0.0; 3]],
            depth: vec![1.2345, 0.0],
            silhouette: vec![1.0, 0.0],
            final_transmittance: vec![0.0, 1.0],
            n_contrib: vec![1, 0],
            labels: Some(vec![3, 0]),
            top_k: None,
            visible_per_label: None,
        };
        let dir = std::env::temp_dir().join(format!("opengs-splat-png-{}", std::process::id()));
        let files = write_render_pngs(&out, &dir).expect("write pngs");
        assert_eq!(files.len(), 4);
        let depth = image::open(dir.join("depth.png"))
            .expect("read")
            .into_luma16();
        assert_eq!(depth.get_pixel(0, 0)[0], 1235);
        let color = image::open(dir.join("color.png"))
            .expect("read")
            .into_rgb8();
        assert_eq!(color.get_pixel(0, 0).0, [255, 128, 0]);
        let raw = image::open(dir.join("labels_u16.png"))
            .expect("read")
            .into_luma16();
        assert_eq!((raw.get_pixel(0, 0)[0], raw.get_pixel(1, 0)[0]), (3, 0));
        let lab = image::open(dir.join("labels.png"))
            .expect("read")
            .into_rgb8();
        assert_eq!(lab.get_pixel(0, 0).0, label_color(3));
        assert_eq!(lab.get_pixel(1, 0).0, [0, 0, 0]);
        assert_ne!(label_color(3), label_color(4));
        std::fs::remove_dir_all(&dir).ok();
    }
}
