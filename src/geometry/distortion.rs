//! Lens distortion (Brown–Conrady with the rational radial term, OpenCV's model) and the camera
//! model that combines it with pinhole intrinsics.
//!
//! The model maps an undistorted normalised point (x, y) = (X/Z, Y/Z) to a distorted one:
//!
//! ```text
//! r² = x² + y²,  radial = (1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² + k5 r⁴ + k6 r⁶)
//! x_d = x · radial + 2 p1 x y + p2 (r² + 2 x²)
//! y_d = y · radial + p1 (r² + 2 y²) + 2 p2 x y
//! ```
//!
//! and the pixel is `(fx x_d + cx, fy y_d + cy)`. ROS `CameraInfo` `plumb_bob` D is
//! `[k1, k2, p1, p2, k3]`, `rational_polynomial` D is `[k1, k2, p1, p2, k3, k4, k5, k6]`; Foxglove
//! `CameraCalibration` uses the same names and order. Distorting is closed-form; undistorting
//! inverts it by Newton's method.

use crate::image_buf::ImageSize;

use super::camera::PinholeIntrinsics;

/// Newton iterations of [`LensDistortion::undistort`]: from the distorted point as the start,
/// Kinect-class distortion (|k1| ≤ 0.3) converges to 1e-12 in 4–6 steps; the margin covers
/// strong wide-angle lenses near the image corners.
const UNDISTORT_MAX_ITERATIONS: usize = 30;
/// Convergence threshold of [`LensDistortion::undistort`] in normalised units: 1e-12 is
/// 5e-10 px at a 500 px focal length, far below anything measurable.
const UNDISTORT_TOLERANCE: f64 = 1e-12;

/// Brown–Conrady distortion coefficients (see the module documentation for the formula).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LensDistortion {
    /// Radial numerator, r².
    pub k1: f64,
    /// Radial numerator, r⁴.
    pub k2: f64,
    /// Radial numerator, r⁶.
    pub k3: f64,
    /// Radial denominator, r² (`rational_polynomial` only).
    pub k4: f64,
    /// Radial denominator, r⁴.
    pub k5: f64,
    /// Radial denominator, r⁶.
    pub k6: f64,
    /// Tangential.
    pub p1: f64,
    /// Tangential.
    pub p2: f64,
}

/// Why distortion coefficients were refused (the I/O layer adds the topic).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnsupportedDistortion(pub String);

impl LensDistortion {
    /// `plumb_bob`: D = [k1, k2, p1, p2, k3].
    pub const fn plumb_bob(k1: f64, k2: f64, p1: f64, p2: f64, k3: f64) -> Self {
        Self {
            k1,
            k2,
            k3,
            k4: 0.0,
            k5: 0.0,
            k6: 0.0,
            p1,
            p2,
        }
    }

    /// Coefficients from a ROS / Foxglove distortion model name and D. `None` when every
    /// coefficient is zero (or D is empty): the camera is a pinhole.
    ///
    /// # Errors
    /// [`UnsupportedDistortion`] for other models with non-zero D (fisheye models), for more
    /// coefficients than the model has, or non-finite values.
    pub fn from_ros(model: &str, d: &[f64]) -> Result<Option<Self>, UnsupportedDistortion> {
        if d.iter().all(|&v| v == 0.0) {
            return Ok(None);
        }
        if !d.iter().all(|v| v.is_finite()) {
            return Err(UnsupportedDistortion(format!(
                "distortion coefficients must be finite, found {d:?}"
            )));
        }
        // Writers often trim trailing zeros (e.g. 4 coefficients for plumb_bob).
        let max = match model {
            "plumb_bob" | "" => 5,
            "rational_polynomial" => 8,
            other => {
                return Err(UnsupportedDistortion(format!(
                    "distortion model {other:?} with D = {d:?} is not supported (supported: \
                     plumb_bob, rational_polynomial)"
                )))
            }
        };
        if d.len() > max {
            return Err(UnsupportedDistortion(format!(
                "distortion model {model:?} has at most {max} coefficients, found {}: {d:?}",
                d.len()
            )));
        }
        let at = |i: usize| d.get(i).copied().unwrap_or(0.0);
        Ok(Some(Self {
            k1: at(0),
            k2: at(1),
            p1: at(2),
            p2: at(3),
            k3: at(4),
            k4: at(5),
            k5: at(6),
            k6: at(7),
        }))
    }

    /// The coefficients in ROS order with the model name: `plumb_bob` when the denominator
    /// terms are zero, else `rational_polynomial`.
    pub fn to_ros(&self) -> (&'static str, Vec<f64>) {
        let Self {
            k1,
            k2,
            k3,
            k4,
            k5,
            k6,
            p1,
            p2,
        } = *self;
        if k4 == 0.0 && k5 == 0.0 && k6 == 0.0 {
            ("plumb_bob", vec![k1, k2, p1, p2, k3])
        } else {
            ("rational_polynomial", vec![k1, k2, p1, p2, k3, k4, k5, k6])
        }
    }

    /// The distorted normalised point of the undistorted (x, y).
    #[inline]
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let r2 = x * x + y * y;
        let radial = self.radial(r2).0;
        (
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        )
    }

    /// Radial factor and its derivative with respect to r²; the factor is NaN where the
    /// denominator is not positive (outside the model's domain).
    #[inline]
    fn radial(&self, r2: f64) -> (f64, f64) {
        let num = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        let den = 1.0 + r2 * (self.k4 + r2 * (self.k5 + r2 * self.k6));
        if den <= 0.0 {
            return (f64::NAN, f64::NAN);
        }
        let dnum = self.k1 + r2 * (2.0 * self.k2 + 3.0 * r2 * self.k3);
        let dden = self.k4 + r2 * (2.0 * self.k5 + 3.0 * r2 * self.k6);
        (num / den, (dnum * den - num * dden) / (den * den))
    }

    /// [`Self::distort`] and its 2×2 Jacobian `[[∂xd/∂x, ∂xd/∂y], [∂yd/∂x, ∂yd/∂y]]`.
    fn distort_with_jacobian(&self, x: f64, y: f64) -> ((f64, f64), [[f64; 2]; 2]) {
        let r2 = x * x + y * y;
        let (radial, d_radial) = self.radial(r2);
        let (p1, p2) = (self.p1, self.p2);
        let xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
        let yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
        let cross = 2.0 * x * y * d_radial + 2.0 * p1 * x + 2.0 * p2 * y;
        let jacobian = [
            [
                radial + 2.0 * x * x * d_radial + 2.0 * p1 * y + 6.0 * p2 * x,
                cross,
            ],
            [
                cross,
                radial + 2.0 * y * y * d_radial + 6.0 * p1 * y + 2.0 * p2 * x,
            ],
        ];
        ((xd, yd), jacobian)
    }

    /// The undistorted normalised point whose distortion is (xd, yd), by Newton's method
    /// from (xd, yd). `None` when it does not converge or converges where the model folds over
    /// (non-positive Jacobian determinant: beyond the radius where a real lens's image ends,
    /// polynomial models map several rays to one point).
    pub fn undistort(&self, xd: f64, yd: f64) -> Option<(f64, f64)> {
        let (mut x, mut y) = (xd, yd);
        for _ in 0..UNDISTORT_MAX_ITERATIONS {
            let ((fx, fy), j) = self.distort_with_jacobian(x, y);
            let (ex, ey) = (fx - xd, fy - yd);
            let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
            if !(det.is_finite() && det > 0.0 && ex.is_finite() && ey.is_finite()) {
                return None;
            }
            if ex * ex + ey * ey < UNDISTORT_TOLERANCE * UNDISTORT_TOLERANCE {
                return Some((x, y));
            }
            x -= (j[1][1] * ex - j[0][1] * ey) / det;
            y -= (j[0][0] * ey - j[1][0] * ex) / det;
        }
        None
    }
}

/// A camera: image size, pinhole intrinsics and optional lens distortion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraModel {
    /// Image size, pixels.
    pub size: ImageSize,
    /// Pinhole part (K).
    pub intrinsics: PinholeIntrinsics,
    /// Lens distortion; `None` = a pinhole camera.
    pub distortion: Option<LensDistortion>,
}

impl CameraModel {
    /// A pinhole camera.
    pub const fn pinhole(size: ImageSize, intrinsics: PinholeIntrinsics) -> Self {
        Self {
            size,
            intrinsics,
            distortion: None,
        }
    }

    /// The same camera without distortion (the pinhole image undistortion produces).
    pub fn undistorted(&self) -> Self {
        Self {
            distortion: None,
            ..*self
        }
    }

    /// The normalised undistorted ray (X/Z, Y/Z) of pixel (u, v); `None` where the distortion
    /// cannot be inverted.
    #[inline]
    pub fn ray(&self, u: f64, v: f64) -> Option<(f64, f64)> {
        let k = &self.intrinsics;
        let (xd, yd) = ((u - k.cx) / k.fx, (v - k.cy) / k.fy);
        match &self.distortion {
            None => Some((xd, yd)),
            Some(d) => d.undistort(xd, yd),
        }
    }

    /// The pixel of the normalised undistorted point (x, y) (distortion applied).
    #[inline]
    pub fn pixel(&self, x: f64, y: f64) -> (f64, f64) {
        let (xd, yd) = match &self.distortion {
            None => (x, y),
            Some(d) => d.distort(x, y),
        };
        let k = &self.intrinsics;
        (k.fx * xd + k.cx, k.fy * yd + k.cy)
    }
}

/// Published calibrations with distortion, for `--camera` presets.
pub mod presets {
    use super::LensDistortion;

    /// Bonn RGB-D Dynamic Dataset, one calibration for the whole dataset (published with it).
    pub const BONN: LensDistortion =
        LensDistortion::plumb_bob(0.039903, -0.099343, -0.000730, -0.000144, 0.0);
    /// TUM RGB-D freiburg1 colour camera (the calibration shipped with TUM's ROS bags).
    pub const TUM_FR1: LensDistortion =
        LensDistortion::plumb_bob(0.262383, -0.953104, -0.005358, 0.002628, 1.163314);
    /// TUM RGB-D freiburg2 colour camera (TUM's calibration page).
    pub const TUM_FR2: LensDistortion =
        LensDistortion::plumb_bob(0.231222, -0.784899, -0.003257, -0.000105, 0.917205);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::camera::presets as k_presets;

    /// Curated lenses: Kinect-class barrel (TUM fr1, a strong k3), Bonn's mild lens, a
    /// rational wide-angle lens with tangential terms, and pincushion.
    fn lenses() -> Vec<LensDistortion> {
        let v = vec![
            presets::TUM_FR1,
            presets::BONN,
            LensDistortion {
                k1: -0.28,
                k2: 0.07,
                k3: 0.0,
                k4: 0.05,
                k5: 0.01,
                k6: 0.0,
                p1: 0.001,
                p2: -0.002,
            },
            LensDistortion::plumb_bob(0.12, 0.03, 0.0, 0.0, 0.0),
        ];
        assert!(v.len() >= 3, "the laws must be checked on several lenses");
        v
    }

    /// Normalised points covering a 640×480, 525 px image out to its corners.
    fn image_points() -> Vec<(f64, f64)> {
        let mut v = Vec::new();
        for iy in 0..=12 {
            for ix in 0..=16 {
                v.push((-0.61 + 1.22 * ix as f64 / 16.0, -0.46 + 0.92 * iy as f64 / 12.0));
            }
        }
        v.push((0.0, 0.0));
        v.push((1e-4, -1e-4));
        v
    }

    #[test]
    fn undistort_inverts_distort_over_the_image() {
        for lens in lenses() {
            for (x, y) in image_points() {
                let (xd, yd) = lens.distort(x, y);
                let (ux, uy) = lens
                    .undistort(xd, yd)
                    .unwrap_or_else(|| panic!("{lens:?} at ({x}, {y})"));
                assert!(
                    (ux - x).abs() < 1e-10 && (uy - y).abs() < 1e-10,
                    "{lens:?}: ({x}, {y}) -> ({ux}, {uy})"
                );
            }
        }
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        const STEP: f64 = 1e-6;
        for lens in lenses() {
            for (x, y) in image_points() {
                let (_, j) = lens.distort_with_jacobian(x, y);
                let dx = |dx: f64, dy: f64| lens.distort(x + dx, y + dy);
                let (px, py) = (dx(STEP, 0.0), dx(-STEP, 0.0));
                let (qx, qy) = (dx(0.0, STEP), dx(0.0, -STEP));
                let numeric = [
                    [(px.0 - py.0) / (2.0 * STEP), (qx.0 - qy.0) / (2.0 * STEP)],
                    [(px.1 - py.1) / (2.0 * STEP), (qx.1 - qy.1) / (2.0 * STEP)],
                ];
                for r in 0..2 {
                    for c in 0..2 {
                        assert!((j[r][c] - numeric[r][c]).abs() < 1e-6, "{lens:?} ({x},{y})");
                    }
                }
            }
        }
    }

    #[test]
    fn zero_coefficients_are_a_pinhole_and_models_are_checked() {
        assert_eq!(LensDistortion::from_ros("plumb_bob", &[0.0; 5]), Ok(None));
        assert_eq!(LensDistortion::from_ros("equidistant", &[]), Ok(None));
        let bonn = LensDistortion::from_ros("plumb_bob", &[0.039903, -0.099343, -0.000730, -0.000144, 0.0]);
        assert_eq!(bonn, Ok(Some(presets::BONN)));
        // Trimmed trailing zeros are accepted.
        assert_eq!(
            LensDistortion::from_ros("plumb_bob", &[0.1, 0.2]),
            Ok(Some(LensDistortion::plumb_bob(0.1, 0.2, 0.0, 0.0, 0.0)))
        );
        let rational = [0.1, 0.2, 0.001, 0.002, 0.3, 0.4, 0.5, 0.6];
        let lens = LensDistortion::from_ros("rational_polynomial", &rational)
            .unwrap()
            .unwrap();
        assert_eq!(lens.to_ros(), ("rational_polynomial", rational.to_vec()));
        assert_eq!(
            presets::BONN.to_ros(),
            ("plumb_bob", vec![0.039903, -0.099343, -0.000730, -0.000144, 0.0])
        );
        let err = LensDistortion::from_ros("equidistant", &[0.1, 0.0, 0.0, 0.0]).unwrap_err();
        assert!(
            err.0.contains("equidistant") && err.0.contains("plumb_bob"),
            "{err:?}"
        );
        assert!(LensDistortion::from_ros("plumb_bob", &[0.1; 6]).is_err());
        assert!(LensDistortion::from_ros("plumb_bob", &[f64::NAN, 0.0]).is_err());
    }

    #[test]
    fn camera_ray_and_pixel_are_inverse() {
        let camera = CameraModel {
            size: ImageSize::new(640, 480),
            intrinsics: k_presets::TUM_FR1,
            distortion: Some(presets::TUM_FR1),
        };
        for &(u, v) in &[(0.0, 0.0), (639.0, 479.0), (320.5, 240.25), (10.0, 400.0)] {
            let (x, y) = camera.ray(u, v).unwrap();
            let (pu, pv) = camera.pixel(x, y);
            assert!(
                (pu - u).abs() < 1e-7 && (pv - v).abs() < 1e-7,
                "({u},{v}) -> ({pu},{pv})"
            );
        }
        let pinhole = camera.undistorted();
        let (x, y) = pinhole.ray(100.0, 50.0).unwrap();
        let p = pinhole.intrinsics.back_project(100.0, 50.0, 1.0);
        assert!((x - p.x).abs() < 1e-15 && (y - p.y).abs() < 1e-15);
    }

    #[test]
    fn undistortion_refuses_points_beyond_the_fold() {
        // Barrel k1 = -0.3: r_d = r - 0.3 r³ grows only up to r = 1.054 (r_d = 0.702), so no
        // ray distorts to r_d = 0.8, while r_d = 0.5 has one.
        let lens = LensDistortion::plumb_bob(-0.3, 0.0, 0.0, 0.0, 0.0);
        assert!(lens.undistort(0.8, 0.0).is_none());
        let (x, y) = lens.undistort(0.5, 0.0).unwrap();
        assert!(x > 0.5 && x < 1.054 && y == 0.0);
    }
}
