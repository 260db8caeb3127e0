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
