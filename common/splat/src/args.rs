//! Parsers for command-line values shared by `opengs render`, `opengs objects` and `opengs bench render`.

use opengs_geometry::Intrinsics;

/// Parses `WxH` (e.g. `640x480`).
pub fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let (w, h) = text
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("size '{text}' is not WIDTHxHEIGHT (e.g. 640x480)"))?;
    let dim = |s: &str, what: &str| -> Result<u32, String> {
        match s.trim().parse::<u32>() {
            Ok(v) if v > 0 => Ok(v),
            _ => Err(format!(
                "size '{text}': {what} '{s}' is not a positive integer"
            )),
        }
    };
    let (w, h) = (dim(w, "width")?, dim(h, "height")?);
    // Pixel indices are u32 throughout the renderer.
    if w as u64 * h as u64 > u32::MAX as u64 {
        return Err(format!(
            "size '{text}' is {} pixels; a render has at most {} (e.g. 65535x65535)",
            w as u64 * h as u64,
            u32::MAX
        ));
    }
    Ok((w, h))
}

/// Bytes per pixel a render and its PNGs take at least: colour, depth, silhouette,
/// transmittance, contributor count, labels (32) and the PNG buffers (16).
const RENDER_BYTES_PER_PIXEL: u64 = 48;

/// `Err` when a `width`×`height` render (with `top_k` Gaussians per pixel kept) does not fit
/// in the memory available, checked before any image buffer is allocated.
pub fn check_render_size(width: u32, height: u32, top_k: Option<usize>) -> Result<(), String> {
    // Top-K: a 2-byte count and at most K (id, f16 weight) entries per pixel.
    let per_pixel = RENDER_BYTES_PER_PIXEL as u128 + top_k.map_or(0, |k| 2 + 6 * k as u128);
    opengs_geometry::memory::check_memory(
        &format!("a {width}x{height} render"),
        width as u128 * height as u128 * per_pixel,
    )
}

/// Parses `fx fy cx cy` and combines it with an image size.
pub fn parse_intrinsics(text: &str, width: u32, height: u32) -> Result<Intrinsics, String> {
    let vals: Vec<f64> = text
        .split(|c: char| c.is_whitespace() || c == ',')
        .filter(|t| !t.is_empty())
        .map(|t| {
            t.parse::<f64>()
                .map_err(|_| format!("intrinsics: '{t}' is not a number"))
        })
        .collect::<Result<_, _>>()?;
    let [fx, fy, cx, cy] = vals[..] else {
        return Err(format!(
            "intrinsics need 4 numbers 'fx fy cx cy', got {}",
            vals.len()
        ));
    };
    let k = Intrinsics::new(fx, fy, cx, cy, width, height);
    k.validate()
        .map_err(|e| format!("intrinsics '{text}': {e}"))?;
    Ok(k)
}

/// Parses a comma-separated list of sizes, e.g. `640x480,1200x680`.
pub fn parse_size_list(text: &str) -> Result<Vec<(u32, u32)>, String> {
    text.split(',').map(|s| parse_size(s.trim())).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_rejects() {
        assert_eq!(parse_size("640x480"), Ok((640, 480)));
        assert!(parse_size("640").is_err());
        assert!(parse_size("0x480").is_err());
        let k = parse_intrinsics("525 525 319.5 239.5", 640, 480).expect("valid");
        assert_eq!((k.cx, k.width), (319.5, 640));
        assert!(parse_intrinsics("525 525 319.5", 640, 480).is_err());
        assert!(parse_intrinsics("525 a 319.5 2", 640, 480).is_err());
        assert!(parse_intrinsics("-1 525 319.5 2", 640, 480).is_err());
        assert!(parse_intrinsics("inf 525 319.5 2", 640, 480).is_err());
        let e = parse_size("100000x100000").expect_err("too many pixels");
        assert!(e.contains("10000000000 pixels"), "{e}");
        let e = check_render_size(60000, 60000, Some(50)).expect_err("too big");
        assert!(e.starts_with("a 60000x60000 render would need"), "{e}");
        assert!(check_render_size(640, 480, Some(50)).is_ok());
        assert_eq!(
            parse_size_list("640x480, 1200x680"),
            Ok(vec![(640, 480), (1200, 680)])
        );
    }
}
