//! Levenberg–Marquardt on one pyramid level with accept/revert on the robust cost.
//!
//! Each iteration solves (H + λ·diag H) δ = −g at the current pose, evaluates the robust cost
//! *and* the normal equations at the candidate exp(δ)·T in one pass, and either accepts it
//! (λ ← λ / down-factor, the candidate's system becomes the current one) or reverts to the
//! current pose (λ ← λ · up-factor, the current system is reused, no extra pass). A level stops
//! on a small step (‖δ‖∞ below the tolerance), the iteration limit, or λ overflow
//! (docs/method.md, "Dense visual odometry": this fixes the authors' release, whose rejection
//! came one iteration late and was never reverted).

use nalgebra::{Isometry3, Matrix6, Vector6};

use super::residuals::{
    accumulate_normal_equations, CostParams, NormalEquations, ReferencePoint, TargetView,
};
use crate::geometry::{se3_exp, se3_log, Twist};

/// Smallest eigenvalue of the Jacobi-scaled H (unit diagonal, eigenvalues in [0, 6]) below
/// which the motion is not observable from the data (e.g. a textureless fronto-parallel
/// wall). Real scenes with weak but genuine constraints (the translation/rotation ambiguity of
/// a narrow field of view) stay above 1e-5 on our data; exactly missing constraints give
/// 0 up to rounding.
pub const DEGENERATE_MIN_SCALED_EIGENVALUE: f64 = 1e-7;

/// A diagonal entry of H below this fraction of the largest one means a direction with no
/// constraint at all (the Jacobi scaling would divide by ~0).
const DEGENERATE_DIAGONAL_RATIO: f64 = 1e-12;

/// A Gaussian prior on the motion: ½ Σᵢ informationᵢ · eᵢ² with e = log(T · T_prior⁻¹) (the
/// twist, translation first, that takes the prior to the estimate), added to the robust cost.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionPrior {
    /// The predicted motion.
    pub current_from_reference: Isometry3<f64>,
    /// Diagonal information per twist component (translation first), in the cost's units per
    /// m² or rad².
    pub information: [f64; 6],
}

impl MotionPrior {
    /// Adds the prior's cost, gradient and (diagonal) Hessian at `current_from_reference` to
    /// `ne`. With the left perturbation T ← exp(δ)·T, e(δ) ≈ e(0) + δ to first order.
    pub fn add_to(&self, ne: &mut NormalEquations, current_from_reference: &Isometry3<f64>) {
        let error = self.error(current_from_reference);
        let mut diagonal = 0;
        for i in 0..6 {
            let info = self.information[i];
            ne.cost += 0.5 * info * error[i] * error[i];
            ne.gradient[i] += info * error[i];
            ne.hessian_upper[diagonal] += info;
            diagonal += 6 - i;
        }
    }

    /// The prior's cost at `current_from_reference`.
    pub fn cost(&self, current_from_reference: &Isometry3<f64>) -> f64 {
        let error = self.error(current_from_reference);
        (0..6)
            .map(|i| 0.5 * self.information[i] * error[i] * error[i])
            .sum()
    }

    fn error(&self, current_from_reference: &Isometry3<f64>) -> Twist {
        se3_log(&(current_from_reference * self.current_from_reference.inverse()))
    }
}

/// The Levenberg–Marquardt schedule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmSchedule {
    /// λ at the start of every level.
    pub lambda_initial: f64,
    /// λ multiplier after a rejected step (> 1).
    pub lambda_up: f64,
    /// λ divisor after an accepted step (> 1).
    pub lambda_down: f64,
    /// The level ends when λ exceeds this.
    pub lambda_max: f64,
    /// Candidate evaluations per level at most.
    pub max_iterations: usize,
    /// The level ends after a step with ‖δ‖∞ below this (metres / radians).
    pub step_tolerance: f64,
}

/// Why a level stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LevelStop {
    /// The last step was below the step tolerance.
    SmallStep,
    /// The iteration limit was reached.
    MaxIterations,
    /// λ grew beyond its limit (no cost-decreasing step found).
    LambdaOverflow,
}

/// What went wrong on a level.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LevelError {
    /// H is rank deficient: some motion direction is not constrained.
    Degenerate,
    /// The step or the cost was not finite.
    NonFinite,
}

/// The result of one level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LevelResult {
    /// Candidate evaluations performed.
    pub iterations: usize,
    /// Normal equations (and cost) at the final pose.
    pub normal_equations: NormalEquations,
    /// Why the level ended.
    pub stop: LevelStop,
}

/// True when H does not constrain every motion direction (see
/// [`DEGENERATE_MIN_SCALED_EIGENVALUE`]).
// `!(a > b)` is deliberate: a NaN must count as degenerate.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
pub fn is_degenerate(h: &Matrix6<f64>) -> bool {
    let d = h.diagonal();
    let max = d.max();
    if !(max > 0.0) || !h.iter().all(|v| v.is_finite()) {
        return true;
    }
    if d.iter().any(|&v| !(v > max * DEGENERATE_DIAGONAL_RATIO)) {
        return true;
    }
    let s = d.map(|v| 1.0 / v.sqrt());
    let scaled = Matrix6::from_fn(|i, j| h[(i, j)] * s[i] * s[j]);
    let eig = scaled.symmetric_eigenvalues();
    !(eig.min() > DEGENERATE_MIN_SCALED_EIGENVALUE)
}

/// True when the cost, H and g are all finite (a NaN intensity in the input, for instance,
/// poisons them; that is reported as [`LevelError::NonFinite`], never passed on).
fn is_finite_system(ne: &NormalEquations) -> bool {
    ne.cost.is_finite() && ne.hessian_upper.iter().chain(&ne.gradient).all(|v| v.is_finite())
}

/// Solves (H + λ·diag H) δ = −g; `None` when the damped system is not positive definite or
/// the step is not finite.
pub fn damped_step(ne: &NormalEquations, lambda: f64) -> Option<Twist> {
    let mut h = ne.hessian();
    for i in 0..6 {
        h[(i, i)] *= 1.0 + lambda;
    }
    let chol = h.cholesky()?;
    let step: Vector6<f64> = -chol.solve(&ne.gradient_vector());
    step.iter().all(|v| v.is_finite()).then_some(step)
}

/// Runs LM on one level from `current_from_reference` (updated in place).
///
/// # Errors
/// [`LevelError`] when H is degenerate at the start or a step is not finite.
pub fn optimize_level(
    points: &[ReferencePoint],
    row_width: usize,
    target: &TargetView<'_>,
    cost: &CostParams,
    schedule: &LmSchedule,
    prior: Option<&MotionPrior>,
    current_from_reference: &mut Isometry3<f64>,
) -> Result<LevelResult, LevelError> {
    let data = accumulate_normal_equations(points, row_width, target, current_from_reference, cost);
    if !is_finite_system(&data) {
        return Err(LevelError::NonFinite);
    }
    // Degeneracy is a property of the data: a prior must not hide an unobservable direction.
    if is_degenerate(&data.hessian()) {
        return Err(LevelError::Degenerate);
    }
    let evaluate = |pose: &Isometry3<f64>| {
        let mut ne = accumulate_normal_equations(points, row_width, target, pose, cost);
        if let Some(prior) = prior {
            prior.add_to(&mut ne, pose);
        }
        ne
    };
    let mut ne = data;
    if let Some(prior) = prior {
        prior.add_to(&mut ne, current_from_reference);
    }
    let mut lambda = schedule.lambda_initial;
    let mut iterations = 0;
    let mut stop = LevelStop::MaxIterations;
    while iterations < schedule.max_iterations {
        let Some(step) = damped_step(&ne, lambda) else {
            // Not positive definite even with damping: only a degenerate H does that.
            return Err(LevelError::Degenerate);
        };
        iterations += 1;
        let candidate = se3_exp(&step) * *current_from_reference;
        let cand_ne = evaluate(&candidate);
        if !is_finite_system(&cand_ne) {
            return Err(LevelError::NonFinite);
        }
        let small = step.amax() < schedule.step_tolerance;
        if cand_ne.cost < ne.cost {
            *current_from_reference = candidate;
            ne = cand_ne;
            lambda /= schedule.lambda_down;
        } else {
            lambda *= schedule.lambda_up;
            if lambda > schedule.lambda_max {
                stop = LevelStop::LambdaOverflow;
                break;
            }
        }
        if small {
            stop = LevelStop::SmallStep;
            break;
        }
    }
    // The result reports the data's cost (the final-cost checks judge how well the images
    // agree, not how far the motion is from its prediction).
    if let Some(prior) = prior {
        ne.cost -= prior.cost(current_from_reference);
    }
    Ok(LevelResult {
        iterations,
        normal_equations: ne,
        stop,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn degeneracy_detects_missing_and_dependent_directions() {
        let full = Matrix6::<f64>::identity() * 3.0 + Matrix6::from_element(0.1);
        assert!(!is_degenerate(&full));
        let mut missing = full;
        for i in 0..6 {
            missing[(0, i)] = 0.0;
            missing[(i, 0)] = 0.0;
        }
        assert!(is_degenerate(&missing));
        // Two identical directions: rank 5.
        let j = nalgebra::Matrix6x5::<f64>::from_fn(|i, k| {
            if i == 5 {
                (k + 1) as f64
            } else if i == k {
                1.0
            } else {
                0.0
            }
        });
        assert!(is_degenerate(&(j * j.transpose())));
        assert!(is_degenerate(&Matrix6::from_element(f64::NAN)));
    }

    #[test]
    fn damped_step_solves_the_system() {
        let h = Matrix6::<f64>::identity() * 2.0 + Matrix6::from_element(0.3);
        let g = Vector6::new(1.0, -2.0, 0.5, 0.1, 0.0, 3.0);
        let mut ne = NormalEquations::default();
        let mut k = 0;
        for i in 0..6 {
            for j in i..6 {
                ne.hessian_upper[k] = h[(i, j)];
                k += 1;
            }
        }
        ne.gradient.copy_from_slice(g.as_slice());
        let step = damped_step(&ne, 0.0).unwrap();
        approx::assert_relative_eq!(h * step, -g, epsilon = 1e-12);
        let damped = damped_step(&ne, 1.0).unwrap();
        assert!(damped.norm() < step.norm());
    }
}
