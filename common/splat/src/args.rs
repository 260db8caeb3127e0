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
    Ok((dim(w, "width")?, dim(h, "height")?))
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
    if !(fx > 0.0 && fy > 0.0 && cx.is_finite() && cy.is_finite()) {
        return Err(format!(
            "intrinsics: fx, fy must be > 0 and cx, cy finite (got '{text}')"
        ));
    }
    Ok(Intrinsics::new(fx, fy, cx, cy, width, height))
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
        assert_eq!(
            parse_size_list("640x480, 1200x680"),
            Ok(vec![(640, 480), (1200, 680)])
        );
    }
}
