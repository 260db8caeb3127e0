//! Label maps as 16-bit grayscale PNG (raw ids), for saved segmenter outputs and renders.

use std::path::Path;

use image::{ImageBuffer, Luma};

/// Writes a row-major `width × height` label map; ids above 65535 are an error.
pub fn write_label_png(path: &Path, width: u32, height: u32, labels: &[u32]) -> Result<(), String> {
    if labels.len() != width as usize * height as usize {
        return Err(format!(
            "{}: {} labels for a {width}x{height} image",
            path.display(),
            labels.len()
        ));
    }
    let mut raw = Vec::with_capacity(labels.len());
    for &l in labels {
        raw.push(
            u16::try_from(l)
                .map_err(|_| format!("{}: label {l} does not fit a 16-bit PNG", path.display()))?,
        );
    }
    let img: ImageBuffer<Luma<u16>, Vec<u16>> =
        ImageBuffer::from_raw(width, height, raw).ok_or("image buffer size")?;
    img.save(path)
        .map_err(|e| format!("{}: {e}", path.display()))
}

/// Reads a label map written by [`write_label_png`] (any 8/16-bit grayscale PNG works).
pub fn read_label_png(path: &Path) -> Result<(u32, u32, Vec<u32>), String> {
    let img = image::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let img = match img {
        image::DynamicImage::ImageLuma16(i) => i,
        image::DynamicImage::ImageLuma8(i) => image::DynamicImage::ImageLuma8(i).into_luma16(),
        other => {
            return Err(format!(
                "{}: expected a grayscale label PNG, found {:?}",
                path.display(),
                other.color()
            ))
        }
    };
    let (w, h) = img.dimensions();
    Ok((w, h, img.into_raw().into_iter().map(u32::from).collect()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_errors() {
        let dir = std::env::temp_dir().join(format!("opengs-label-png-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("l.png");
        write_label_png(&path, 3, 2, &[0, 1, 65535, 7, 7, 300]).unwrap();
        assert_eq!(
            read_label_png(&path).unwrap(),
            (3, 2, vec![0, 1, 65535, 7, 7, 300])
        );
        assert!(write_label_png(&path, 1, 1, &[70000])
            .unwrap_err()
            .contains("70000"));
        assert!(write_label_png(&path, 2, 2, &[1]).is_err());
        std::fs::write(&path, b"not a png").unwrap();
        assert!(read_label_png(&path).unwrap_err().contains("l.png"));
        std::fs::remove_dir_all(&dir).ok();
    }
}
