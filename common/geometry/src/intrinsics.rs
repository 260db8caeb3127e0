use nalgebra::{Point3, Vector2};

/// Pinhole camera with image size, OpenCV pixel convention.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub width: u32,
    pub height: u32,
}

impl Intrinsics {
    pub fn new(fx: f64, fy: f64, cx: f64, cy: f64, width: u32, height: u32) -> Self {
        Self {
            fx,
            fy,
            cx,
            cy,
            width,
            height,
        }
    }

    /// `Err` saying what is wrong when the camera cannot project: focal lengths must be finite
    /// and > 0, the principal point finite, the image at least 1×1.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.fx.is_finite() && self.fx > 0.0 && self.fy.is_finite() && self.fy > 0.0) {
            return Err(format!(
                "focal lengths fx = {}, fy = {} must be finite and > 0",
                self.fx, self.fy
            ));
        }
        if !(self.cx.is_finite() && self.cy.is_finite()) {
            return Err(format!(
                "principal point cx = {}, cy = {} must be finite",
                self.cx, self.cy
            ));
        }
        if self.width == 0 || self.height == 0 {
            return Err(format!(
                "image size {}x{} must be at least 1x1",
                self.width, self.height
            ));
        }
        Ok(())
    }

    /// Projects a camera-frame point to pixel coordinates; `None` behind the camera.
    pub fn project(&self, p: &Point3<f64>) -> Option<Vector2<f64>> {
        if p.z <= 0.0 {
            return None;
        }
        Some(Vector2::new(
            self.fx * p.x / p.z + self.cx,
            self.fy * p.y / p.z + self.cy,
        ))
    }

    /// Back-projects pixel (u, v) at metric depth `z` into the camera frame.
    pub fn backproject(&self, u: f64, v: f64, z: f64) -> Point3<f64> {
        Point3::new((u - self.cx) * z / self.fx, (v - self.cy) * z / self.fy, z)
    }

    /// Same camera at a different resolution (e.g. half-resolution optimisation).
    pub fn scaled(&self, factor: f64) -> Self {
        // Pixel centres are at integer coordinates, so the principal point maps
        // through (c + 0.5) * s - 0.5.
        Self {
            fx: self.fx * factor,
            fy: self.fy * factor,
            cx: (self.cx + 0.5) * factor - 0.5,
            cy: (self.cy + 0.5) * factor - 0.5,
            width: ((self.width as f64) * factor).round() as u32,
            height: ((self.height as f64) * factor).round() as u32,
        }
    }

    /// Horizontal and vertical tangent of half the field of view.
    pub fn tan_half_fov(&self) -> (f64, f64) {
        (
            self.width as f64 / (2.0 * self.fx),
            self.height as f64 / (2.0 * self.fy),
        )
    }

    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn validate_names_the_bad_value() {
        assert!(Intrinsics::new(525.0, 525.0, 319.5, 239.5, 640, 480)
            .validate()
            .is_ok());
        let e = Intrinsics::new(0.0, 525.0, 319.5, 239.5, 640, 480)
            .validate()
            .expect_err("fx 0");
        assert!(e.contains("fx = 0"), "{e}");
        assert!(Intrinsics::new(525.0, f64::INFINITY, 1.0, 1.0, 640, 480)
            .validate()
            .is_err());
        assert!(Intrinsics::new(525.0, 525.0, f64::NAN, 1.0, 640, 480)
            .validate()
            .is_err());
        assert!(Intrinsics::new(525.0, 525.0, 1.0, 1.0, 0, 480)
            .validate()
            .is_err());
    }

    #[test]
    fn project_backproject_round_trip() {
        let k = Intrinsics::new(525.0, 525.0, 319.5, 239.5, 640, 480);
        let p = k.backproject(100.0, 50.0, 2.0);
        let uv = k.project(&p).expect("in front");
        assert_relative_eq!(uv.x, 100.0, epsilon = 1e-9);
        assert_relative_eq!(uv.y, 50.0, epsilon = 1e-9);
        assert!(k.project(&Point3::new(0.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn half_resolution_principal_point() {
        let k = Intrinsics::new(600.0, 600.0, 599.5, 339.5, 1200, 680);
        let h = k.scaled(0.5);
        assert_eq!((h.width, h.height), (600, 340));
        assert_relative_eq!(h.cx, 299.5);
        assert_relative_eq!(h.cy, 169.5);
        assert_relative_eq!(h.fx, 300.0);
    }
}
