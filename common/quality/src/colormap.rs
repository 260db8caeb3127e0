//! Colour maps for the side-by-side PNGs: one for depth, one for error.

/// Piecewise-linear map through `stops` (evenly spaced over [0, 1]).
fn ramp(stops: &[[f32; 3]], v: f32) -> [u8; 3] {
    let v = if v.is_finite() {
        v.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = v * (stops.len() - 1) as f32;
    let i = (x.floor() as usize).min(stops.len() - 2);
    let f = x - i as f32;
    std::array::from_fn(|c| {
        let a = stops[i][c];
        let b = stops[i + 1][c];
        ((a + (b - a) * f) * 255.0).round() as u8
    })
}

/// Near → far as blue → cyan → green → yellow → red (turbo-like; reads well in print).
pub fn depth_color(v: f32) -> [u8; 3] {
    const STOPS: [[f32; 3]; 5] = [
        [0.19, 0.07, 0.55],
        [0.10, 0.65, 0.95],
        [0.30, 0.90, 0.35],
        [0.98, 0.85, 0.15],
        [0.75, 0.05, 0.05],
    ];
    ramp(&STOPS, v)
}

/// Small → large error as black → red → yellow → white ("hot").
pub fn error_color(v: f32) -> [u8; 3] {
    const STOPS: [[f32; 3]; 4] = [
        [0.0, 0.0, 0.0],
        [0.85, 0.0, 0.0],
        [1.0, 0.85, 0.0],
        [1.0, 1.0, 1.0],
    ];
    ramp(&STOPS, v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ends_and_clamping() {
        assert_eq!(error_color(0.0), [0, 0, 0]);
        assert_eq!(error_color(1.0), [255, 255, 255]);
        assert_eq!(error_color(7.0), [255, 255, 255]);
        assert_eq!(error_color(f32::NAN), [0, 0, 0]);
        assert_eq!(depth_color(1.0), [191, 13, 13]);
    }
}
