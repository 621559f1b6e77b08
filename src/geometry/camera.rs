//! Pinhole intrinsics with per-pyramid-level scaling.

use nalgebra::{Point2, Point3};

/// Pinhole intrinsics in pixels (0-based pixel centres, docs/method.md "Conventions"). Lens
/// distortion is [`super::distortion::CameraModel`]'s; odometry and detection see undistorted
/// images only.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinholeIntrinsics {
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point column, pixels (0-based).
    pub cx: f64,
    /// Principal point row, pixels (0-based).
    pub cy: f64,
}

impl PinholeIntrinsics {
    /// Intrinsics from their four values.
    pub const fn new(fx: f64, fy: f64, cx: f64, cy: f64) -> Self {
        Self { fx, fy, cx, cy }
    }

    /// True when every value is finite and both focal lengths are positive.
    pub fn is_valid(&self) -> bool {
        self.fx.is_finite()
            && self.fy.is_finite()
            && self.cx.is_finite()
            && self.cy.is_finite()
            && self.fx > 0.0
            && self.fy > 0.0
    }

    /// Projects a point in the camera frame to a pixel; `None` unless `z > 0`.
    #[inline]
    pub fn project(&self, point_in_camera: &Point3<f64>) -> Option<Point2<f64>> {
        let z = point_in_camera.z;
        if z <= 0.0 {
            return None;
        }
        Some(Point2::new(
            self.fx * point_in_camera.x / z + self.cx,
            self.fy * point_in_camera.y / z + self.cy,
        ))
    }

    /// Back-projects pixel (x, y) at depth `depth_m` (along +z) into the camera frame.
    #[inline]
    pub fn back_project(&self, x: f64, y: f64, depth_m: f64) -> Point3<f64> {
        Point3::new(
            (x - self.cx) / self.fx * depth_m,
            (y - self.cy) / self.fy * depth_m,
            depth_m,
        )
    }

    /// Intrinsics of the image halved `level` times by 2×2 averaging.
    ///
    /// A 2×2 box mean puts the centre of coarse pixel j at fine coordinate 2j + 0.5, so
    /// f ← f/2 and c ← (c + 0.5)/2 − 0.5 per halving (as the authors' release does).
    pub fn at_level(&self, level: u32) -> Self {
        let mut k = *self;
        for _ in 0..level {
            k = Self {
                fx: k.fx * 0.5,
                fy: k.fy * 0.5,
                cx: (k.cx + 0.5) * 0.5 - 0.5,
                cy: (k.cy + 0.5) * 0.5 - 0.5,
            };
        }
        k
    }

    /// Row-major 3×3 camera matrix K.
    pub fn k_row_major(&self) -> [f64; 9] {
        [self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0]
    }
}

/// Published intrinsics of the datasets occmask knows (docs/method.md "Datasets"), all 640×480.
pub mod presets {
    use super::PinholeIntrinsics;

    /// TUM RGB-D freiburg1 colour camera.
    pub const TUM_FR1: PinholeIntrinsics = PinholeIntrinsics::new(517.3, 516.5, 318.6, 255.3);
    /// TUM RGB-D freiburg2 colour camera.
    pub const TUM_FR2: PinholeIntrinsics = PinholeIntrinsics::new(520.9, 521.0, 325.1, 249.7);
    /// TUM RGB-D freiburg3 colour camera.
    pub const TUM_FR3: PinholeIntrinsics = PinholeIntrinsics::new(535.4, 539.2, 320.1, 247.6);
    /// ICSL sequences (the authors' `main.m`).
    pub const ICSL: PinholeIntrinsics = PinholeIntrinsics::new(537.6, 539.0, 316.1, 245.5);
    /// LARR RGB-D dataset (dataset page, exact values).
    pub const LARR: PinholeIntrinsics = PinholeIntrinsics::new(
        544.258_254_821_151_9,
        546.087_882_395_195_8,
        326.860_452_181_942_4,
        236.121_014_917_259_4,
    );
    /// Bonn RGB-D Dynamic Dataset (one calibration for the whole dataset, published with it;
    /// its distortion is [`crate::geometry::distortion::presets::BONN`]).
    pub const BONN: PinholeIntrinsics =
        PinholeIntrinsics::new(542.822841, 542.576870, 315.593520, 237.756098);
    /// The ROS / TUM default Kinect intrinsics.
    pub const KINECT_DEFAULT: PinholeIntrinsics = PinholeIntrinsics::new(525.0, 525.0, 319.5, 239.5);
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn project_inverts_back_project() {
        let k = presets::TUM_FR3;
        for &(x, y, z) in &[(0.0, 0.0, 0.5), (639.0, 479.0, 4.0), (320.3, 100.7, 1.25)] {
            let p = k.back_project(x, y, z);
            let uv = k.project(&p).unwrap();
            assert_relative_eq!(uv.x, x, epsilon = 1e-9);
            assert_relative_eq!(uv.y, y, epsilon = 1e-9);
            assert_relative_eq!(p.z, z);
        }
    }

    #[test]
    fn projection_needs_positive_depth() {
        let k = presets::KINECT_DEFAULT;
        assert!(k.project(&Point3::new(0.1, 0.1, 0.0)).is_none());
        assert!(k.project(&Point3::new(0.1, 0.1, -1.0)).is_none());
    }

    #[test]
    fn level_scaling_keeps_box_mean_centres() {
        // The centre of coarse pixel (0,0) is the mean of fine pixels 0 and 1, i.e. fine 0.5:
        // a ray through fine x = 0.5 must hit coarse x = 0.
        let k = presets::TUM_FR2;
        let k1 = k.at_level(1);
        let p = k.back_project(0.5, 0.5, 2.0);
        let uv = k1.project(&p).unwrap();
        assert_relative_eq!(uv.x, 0.0, epsilon = 1e-9);
        assert_relative_eq!(uv.y, 0.0, epsilon = 1e-9);
        assert_eq!(k.at_level(0), k);
        let k3 = k.at_level(3);
        assert_relative_eq!(k3.fx, k.fx / 8.0);
        assert_relative_eq!(k3.cx, (k.cx + 0.5) / 8.0 - 0.5, epsilon = 1e-12);
    }
}
