//! Colour maps for the side-by-side PNGs (colorous): Turbo for depth, Inferno for error.

fn eval(gradient: colorous::Gradient, v: f32) -> [u8; 3] {
    let v = if v.is_finite() {
        v.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let c = gradient.eval_continuous(v as f64);
    [c.r, c.g, c.b]
}

/// Near → far as dark → blue → green → yellow → dark red (Turbo).
pub fn depth_color(v: f32) -> [u8; 3] {
    eval(colorous::TURBO, v)
}

/// Small → large error as black → purple → orange → light yellow (Inferno).
pub fn error_color(v: f32) -> [u8; 3] {
    eval(colorous::INFERNO, v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ends_and_clamping() {
        let (black, top) = (error_color(0.0), error_color(1.0));
        assert!(black.iter().all(|&c| c < 10), "{black:?}");
        assert!(top[0] > 240 && top[1] > 240, "{top:?}");
        assert_eq!(error_color(7.0), top);
        assert_eq!(error_color(f32::NAN), black);
        // Turbo: near is dark, the middle green, far red.
        let (near, mid, far) = (depth_color(0.0), depth_color(0.5), depth_color(1.0));
        assert!(
            near.iter().map(|&c| c as u32).sum::<u32>() < 120,
            "{near:?}"
        );
        assert!(mid[1] > mid[0] && mid[1] > mid[2], "{mid:?}");
        assert!(far[0] > far[1] && far[0] > far[2], "{far:?}");
    }
}
