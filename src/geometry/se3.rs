//! SE(3) exponential and logarithm on nalgebra's `Isometry3`.
//!
//! Twists are ordered (v, ω) (see the module docs of [`crate::geometry`]). SO(3) exp/log come
//! from nalgebra (`UnitQuaternion::from_scaled_axis`, `scaled_axis`); only the coupling
//! matrix V of SE(3) is written here.

use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3, Vector6};

/// A twist (v, ω) ∈ se(3): translation part first (metres), rotation part second (radians).
pub type Twist = Vector6<f64>;

/// Below this rotation angle (radians) the closed-form coefficients of V lose precision
/// (they divide by θ² and θ³), so their Taylor series are used instead. At 1e-4 the
/// series' first omitted term is ~θ⁴/720 ≈ 1e-19, far below f64 resolution.
const SMALL_ANGLE_RAD: f64 = 1e-4;

/// Hat operator: the skew-symmetric matrix of ω (ω^ v = ω × v).
#[inline]
pub fn hat(omega: &Vector3<f64>) -> Matrix3<f64> {
    omega.cross_matrix()
}

/// The left Jacobian V(ω) of SO(3), with t = V v in the exponential map.
fn left_jacobian(omega: &Vector3<f64>) -> Matrix3<f64> {
    let theta_sq = omega.norm_squared();
    let theta = theta_sq.sqrt();
    let w = hat(omega);
    let (a, b) = if theta < SMALL_ANGLE_RAD {
        (0.5 - theta_sq / 24.0, 1.0 / 6.0 - theta_sq / 120.0)
    } else {
        (
            (1.0 - theta.cos()) / theta_sq,
            (theta - theta.sin()) / (theta_sq * theta),
        )
    };
    Matrix3::identity() + a * w + b * w * w
}

/// The inverse of [`left_jacobian`].
fn left_jacobian_inverse(omega: &Vector3<f64>) -> Matrix3<f64> {
    let theta_sq = omega.norm_squared();
    let theta = theta_sq.sqrt();
    let w = hat(omega);
    let c = if theta < SMALL_ANGLE_RAD {
        1.0 / 12.0 + theta_sq / 720.0
    } else {
        (1.0 - theta * theta.sin() / (2.0 * (1.0 - theta.cos()))) / theta_sq
    };
    Matrix3::identity() - 0.5 * w + c * w * w
}

/// The exponential map se(3) → SE(3).
pub fn se3_exp(xi: &Twist) -> Isometry3<f64> {
    let v = Vector3::new(xi[0], xi[1], xi[2]);
    let omega = Vector3::new(xi[3], xi[4], xi[5]);
    let rotation = UnitQuaternion::from_scaled_axis(omega);
    let translation = left_jacobian(&omega) * v;
    Isometry3::from_parts(Translation3::from(translation), rotation)
}

/// The logarithm SE(3) → se(3), the inverse of [`se3_exp`] for rotation angles below π.
pub fn se3_log(transform: &Isometry3<f64>) -> Twist {
    let omega = transform.rotation.scaled_axis();
    let v = left_jacobian_inverse(&omega) * transform.translation.vector;
    Twist::new(v.x, v.y, v.z, omega.x, omega.y, omega.z)
}

/// Whether every translation and quaternion component of `transform` is finite.
pub fn is_finite_pose(transform: &Isometry3<f64>) -> bool {
    transform.translation.vector.iter().all(|v| v.is_finite())
        && transform.rotation.coords.iter().all(|v| v.is_finite())
}

/// Rotation angle of a transform in radians, in [0, π].
pub fn rotation_angle_rad(transform: &Isometry3<f64>) -> f64 {
    transform.rotation.angle()
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// Curated twists: zero, tiny (small-angle branch), moderate, large angles near π.
    fn examples() -> Vec<Twist> {
        vec![
            Twist::zeros(),
            Twist::new(1e-3, -2e-3, 5e-4, 1e-9, -1e-9, 2e-9),
            Twist::new(0.01, 0.02, -0.03, 5e-5, -3e-5, 1e-5),
            Twist::new(0.05, -0.01, 0.02, 0.01, 0.03, -0.02),
            Twist::new(-0.4, 0.3, 1.2, 0.7, -0.2, 0.4),
            Twist::new(1.0, 2.0, 3.0, 2.5, 0.0, 0.0),
            Twist::new(0.2, -0.1, 0.3, 0.0, 1.5, -2.0),
        ]
    }

    #[test]
    fn at_least_three_examples() {
        assert!(examples().len() >= 3);
    }

    #[test]
    fn log_of_exp_is_identity() {
        for xi in examples() {
            let back = se3_log(&se3_exp(&xi));
            assert_relative_eq!(back, xi, epsilon = 1e-10, max_relative = 1e-9);
        }
    }

    #[test]
    fn exp_of_log_is_identity() {
        for xi in examples() {
            let t = se3_exp(&xi);
            let t2 = se3_exp(&se3_log(&t));
            assert_relative_eq!(t.to_homogeneous(), t2.to_homogeneous(), epsilon = 1e-10);
        }
    }

    #[test]
    fn exp_of_negative_is_inverse() {
        for xi in examples() {
            let a = se3_exp(&(-xi));
            let b = se3_exp(&xi).inverse();
            assert_relative_eq!(a.to_homogeneous(), b.to_homogeneous(), epsilon = 1e-10);
        }
    }

    #[test]
    fn exp_matches_series_matrix_exponential() {
        // exp of the 4x4 twist matrix by its power series, independent of the closed form.
        for xi in examples() {
            let mut m = nalgebra::Matrix4::<f64>::zeros();
            let w = hat(&Vector3::new(xi[3], xi[4], xi[5]));
            m.fixed_view_mut::<3, 3>(0, 0).copy_from(&w);
            m[(0, 3)] = xi[0];
            m[(1, 3)] = xi[1];
            m[(2, 3)] = xi[2];
            let mut term = nalgebra::Matrix4::<f64>::identity();
            let mut sum = term;
            for k in 1..60 {
                term = term * m / k as f64;
                sum += term;
            }
            assert_relative_eq!(se3_exp(&xi).to_homogeneous(), sum, epsilon = 1e-9);
        }
    }

    #[test]
    fn exp_is_a_one_parameter_subgroup() {
        // exp(sξ)·exp(tξ) = exp((s + t)ξ): checks the coupling matrix V against itself at
        // three scales (both branches of its coefficients), not only nalgebra's products.
        for xi in examples() {
            for (s, t) in [(0.3, 0.7), (-0.4, 1.1), (1e-5, 2e-5)] {
                let product = se3_exp(&(xi * s)) * se3_exp(&(xi * t));
                let sum = se3_exp(&(xi * (s + t)));
                assert_relative_eq!(product.to_homogeneous(), sum.to_homogeneous(), epsilon = 1e-10);
            }
        }
    }

    #[test]
    fn pure_translation_and_pure_rotation() {
        let t = se3_exp(&Twist::new(0.1, 0.2, 0.3, 0.0, 0.0, 0.0));
        assert_relative_eq!(t.translation.vector, Vector3::new(0.1, 0.2, 0.3));
        assert_relative_eq!(rotation_angle_rad(&t), 0.0);
        let r = se3_exp(&Twist::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.3));
        assert_relative_eq!(rotation_angle_rad(&r), 0.3, epsilon = 1e-12);
        assert_relative_eq!(r.translation.vector.norm(), 0.0);
    }
}
