//! Robust dense visual odometry (DVO) between consecutive RGB-D frames that ignores masked
//! (moving) pixels of the reference frame: the "Robust DVO" of Kim, Kim & Kim (ICRA 2020)
//! without the authors' release's bugs (docs/method.md, "Dense visual odometry").
//!
//! - Cost: Σ ρ_{k_I}(r_I) + γ·Σ ρ_{k_Z}(r_Z) over reference pixels with valid depth that are not
//!   ignored; r_I photometric, r_Z = Z_cur(w) − z′ against the transformed depth; ρ bi-square
//!   (paper Eq. 11–13). See [`residuals`] for the residuals and Jacobians.
//! - Solver: IRLS inside a true Levenberg–Marquardt with accept/revert on the robust cost,
//!   coarse to fine over an image pyramid ([`crate::pyramid`]), see [`solver`].
//! - Motion convention (crate-wide, [`crate::geometry`]): the estimate is
//!   `current_from_reference`, mapping reference-camera points into the current camera;
//!   chain it into poses with [`crate::trajectory::chain`].
//!
//! Use [`DvoTracker`] per sequence (it keeps the previous frame as the reference and allocates
//! its pyramids and scratch once; `track` still allocates now and then, as
//! `tests/detector_alloc.rs` notes), or [`DvoEstimator`] on two explicitly built pyramids.
//!
//! # Example
//! ```
//! use occmask::dvo::{DvoConfig, DvoTracker};
//! use occmask::geometry::{se3_exp, Twist};
//! use occmask::image_buf::ImageSize;
//! use occmask::synthetic::{motion_pair, SequenceConfig};
//!
//! let config = SequenceConfig { size: ImageSize::new(320, 240), ..SequenceConfig::default() };
//! let truth = se3_exp(&Twist::new(0.01, 0.0, 0.0, 0.0, 0.0, 0.0)); // 1 cm to the right
//! let (reference, current) = motion_pair(config, &truth, false);
//! let mut tracker = DvoTracker::new(config.size, reference.intrinsics, DvoConfig::paper())?;
//! assert!(tracker.track(&reference.gray, &reference.depth_m, None, None)?.is_none()); // first frame
//! let estimate = tracker.track(&current.gray, &current.depth_m, None, None)?.expect("second frame");
//! assert!(estimate.is_converged());
//! let error = estimate.current_from_reference.inverse() * truth;
//! assert!(error.translation.vector.norm() < 0.003); // metres
//! # Ok::<(), occmask::Error>(())
//! ```

// Kernels are crate-private; `residuals` and `solver` stay public for the DVO benchmark and
// the profiling example, which time them on their own.
pub(crate) mod completion;
pub(crate) mod mask;
pub mod residuals;
pub mod solver;
pub(crate) mod weights;

pub use completion::{IgnoreCompletion, IgnoreCompletionConfig};

use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::geometry::se3::is_finite_pose;
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, GrayF32, ImageSize, Mask};
use crate::pyramid::{level_size, ImagePyramid, TargetSample};
use residuals::{CostParams, ReferencePoint, TargetView};
use solver::{LevelError, LevelStop, LmSchedule};

/// Most pyramid levels a [`DvoConfig`] may ask for (sizes the per-level arrays of
/// [`DvoEstimate`]; 640×480 has 7 levels of at least 8×8 pixels).
pub const MAX_DVO_LEVELS: usize = 8;

/// Default initial LM damping λ₀ (relative to diag H). The release uses 0.1 (docs/method.md),
/// but Marquardt damping λ·diag H shrinks the step along H's weakest eigen-direction by
/// ≈ μ_min / (λ·d): on a distant, nearly fronto-parallel scene the x-translation / yaw valley
/// has μ_min / d ≈ 1e-4, so with λ₀ = 0.1 (divided by only 1.5 per accepted step) the solver
/// stops several millimetres short along it. Measured on the synthetic pairs of
/// `tests/integration/dvo_synthetic.rs` (worst of six motions, finest level 1): λ₀ 0.1 → 7.2 mm, 0.01 →
/// 2.1 mm, 1e-3 → 1.45 mm, 1e-4 → 1.67 mm; on TUM fr2_desk identical RPE and 45 % fewer
/// finest-level iterations. Rejected steps still raise λ by ×3 as in the release.
pub const LM_LAMBDA_INITIAL: f64 = 1e-3;

/// Default step tolerance (‖δ‖∞, metres / radians). 1e-4 m = 0.1 mm and 1e-4 rad = 0.006°
/// are 10× below the accuracy targets; tightening to 1e-5 changed no synthetic or TUM error by
/// more than 0.01 mm but cost 2.5× more finest-level iterations.
pub const STEP_TOLERANCE: f64 = 1e-4;

/// Default [`DvoConfig::levels`]: 5, one more than the Matlab release's 4. The LM linearisation
/// only converges when the motion moves the coarsest level's image by about its texture's
/// correlation length (1–2 px); a 3° rotation moves a 640×480 image by 27 px, i.e. 3.4 px at
/// 80×60 (level 3) but 1.7 px at 40×30 (level 4). Measured on the synthetic pairs of
/// `tests/integration/dvo_synthetic.rs` with the 30 % box masked (12 seeds × 6 motions): with 4 levels the
/// 3° pitch case ended in a wrong minimum for 4 of 12 seeds (43–310 mm off, cost near the
/// saturated loss), with 5 levels none did. Images too small for 5 levels use as many as fit
/// (see [`DvoConfig::levels_for`]).
pub const DEFAULT_LEVELS: usize = 5;

/// Default [`DvoConfig::max_final_cost_fraction`]. The final robust cost per point, as a
/// fraction of the loss of a point that matches nowhere (the saturated bi-square loss), is
/// 0.05–0.13 for every correct synthetic estimate and 0.65–0.73 for the wrong minima of the
/// 4-level solver described at [`DEFAULT_LEVELS`] (which reported `Converged` then); on TUM
/// fr2_desk (49 pairs) the largest is 0.10. 0.5 sits between the two with room for blur and
/// noise.
pub const MAX_FINAL_COST_FRACTION: f64 = 0.5;

/// Default [`DvoConfig::min_gradient_per_px`]: 4 gray levels (of 255) per pixel. Measured on
/// TUM fr2_desk (49 pairs, finest level 1): threshold 0 → 2.55 mm / 0.264° RPE at 20.2 ms CPU
/// per pair, 2/255 → 2.57 mm at 15.1 ms, 4/255 → 2.60 mm / 0.265° at 11.4 ms, 8/255 → 2.64 mm
/// at 9.8 ms; on the synthetic pairs the worst error moved by < 0.06 mm. The paper selects no
/// pixels; set 0 to use every pixel with depth.
pub const MIN_GRADIENT_PER_PX: f32 = 4.0 / 255.0;

/// [`DvoConfig::closed_loop`]'s depth weight γ (the paper's is 0.001).
pub const CLOSED_LOOP_DEPTH_WEIGHT: f32 = 30.0;
/// [`DvoConfig::closed_loop`]'s bi-square threshold of the depth residual: 5 cm (the paper's is
/// 0.5 m), so a point whose depth moved with a person stops pulling.
pub const CLOSED_LOOP_K_DEPTH_M: f32 = 0.05;

/// The bi-square threshold k_I of the photometric residual (gray in [0, 1]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum IntensityThreshold {
    /// The same k_I on every level (paper: 48/255).
    Constant(f32),
    /// The Matlab release's schedule k_I(lvl) = (64 − 48·e^{lvl−4})/255 with lvl = level + 1
    /// (lvl 1 = full resolution): 61.6/255 at full resolution down to 16/255 at level 3 and
    /// on any coarser level.
    ReleaseSchedule,
}

impl IntensityThreshold {
    /// k_I on pyramid level `level` (0 = full resolution).
    pub fn at_level(&self, level: usize) -> f32 {
        match *self {
            Self::Constant(k) => k,
            // The release runs 4 levels (lvl 1..=4); a coarser level keeps lvl 4's 16/255
            // (the formula would turn negative there).
            Self::ReleaseSchedule => (64.0 - 48.0 * ((level as f32 + 1.0).min(4.0) - 4.0).exp()) / 255.0,
        }
    }
}

/// The constant-velocity motion prior of [`DvoConfig::motion_prior`]: ½ Σᵢ (eᵢ/σᵢ)² × `weight` ×
/// N × ρ_sat added to the cost, with e the twist from the predicted motion to the estimate, N
/// the level's reference points and ρ_sat the saturated loss of one point. So a deviation of
/// one sigma in one twist component costs as much as `weight` × N points turning into
/// outliers, whatever the number of points and the robust thresholds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MotionPriorConfig {
    /// Sigma of the change of the per-frame translation, metres.
    pub translation_sigma_m: f64,
    /// Sigma of the change of the per-frame rotation, radians.
    pub rotation_sigma_rad: f64,
    /// Relative weight (see the type's docs).
    pub weight: f64,
    /// The prior acts in proportion to the fraction of usable reference pixels the ignore mask
    /// removed, reaching full `weight` at this fraction: with nothing masked (a static scene)
    /// the images alone decide; the more of the view moving objects take, the less the rest
    /// can be trusted to be free of their unmasked parts. 0 = full weight always.
    pub full_weight_ignored_fraction: f64,
}

impl Default for MotionPriorConfig {
    fn default() -> Self {
        Self {
            translation_sigma_m: DEFAULT_PRIOR_TRANSLATION_SIGMA_M,
            rotation_sigma_rad: DEFAULT_PRIOR_ROTATION_SIGMA_RAD,
            weight: DEFAULT_PRIOR_WEIGHT,
            full_weight_ignored_fraction: DEFAULT_PRIOR_FULL_WEIGHT_IGNORED_FRACTION,
        }
    }
}

/// Default [`MotionPriorConfig::full_weight_ignored_fraction`].
pub const DEFAULT_PRIOR_FULL_WEIGHT_IGNORED_FRACTION: f64 = 0.25;

/// Default [`MotionPriorConfig::translation_sigma_m`]: 5 mm of change per frame, 0.15 m/s at
/// 30 Hz, several times a hand-held camera's frame-to-frame change (TUM fr2_desk: 1.1 mm mean,
/// 2.8 mm largest).
pub const DEFAULT_PRIOR_TRANSLATION_SIGMA_M: f64 = 0.005;
/// Default [`MotionPriorConfig::rotation_sigma_rad`]: 2° of change per frame (TUM fr2_desk:
/// 0.38° mean, 1.24° largest); rotations are well constrained by the images, so the prior
/// barely acts on them.
pub const DEFAULT_PRIOR_ROTATION_SIGMA_RAD: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// Default [`MotionPriorConfig::weight`].
pub const DEFAULT_PRIOR_WEIGHT: f64 = 0.03;

/// DVO parameters. Start from [`DvoConfig::paper`] (the default) or [`DvoConfig::release`]
/// and override fields; [`DvoConfig::validate`] checks them (the tracker calls it).
///
/// Serialised (JSON config files) field by field with these names; missing fields take the
/// default, unknown ones are an error.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DvoConfig {
    /// Pyramid levels at most (level 0 = input resolution, each next one half the size); an image
    /// too small for that many uses as many as keep the coarsest side ≥
    /// [`crate::pyramid::MIN_LEVEL_SIDE_PX`] ([`Self::levels_for`]). Default [`DEFAULT_LEVELS`].
    pub levels: usize,
    /// The finest level the solver runs on (0 = full resolution). Default 1 (320×240 for VGA):
    /// see docs/method.md ("Dense visual odometry") for what level 0 costs and buys.
    pub finest_level: usize,
    /// LM candidate evaluations per level at most.
    pub max_iterations_per_level: usize,
    /// LM damping λ at the start of each level (relative to diag H).
    pub lm_lambda_initial: f64,
    /// λ multiplier after a rejected step.
    pub lm_lambda_up: f64,
    /// λ divisor after an accepted step.
    pub lm_lambda_down: f64,
    /// A level ends when λ exceeds this.
    pub lm_lambda_max: f64,
    /// A level ends after a step whose largest twist component is below this (metres for
    /// translation, radians for rotation) on the finest level; coarser levels use
    /// 2^(level − finest_level) times this.
    pub step_tolerance: f64,
    /// Bi-square threshold of the photometric residual (gray units, [0, 1]).
    pub k_intensity: IntensityThreshold,
    /// Bi-square threshold of the depth residual, metres.
    pub k_depth_m: f32,
    /// Weight γ of the depth term in the cost (dimensionless).
    pub depth_weight_gamma: f32,
    /// An estimate whose final robust cost per point on the finest level exceeds this fraction
    /// of the saturated loss (a point that matches nowhere) is reported as
    /// [`DvoFailure::PoorFit`]: the solver ended in a wrong minimum. Default
    /// [`MAX_FINAL_COST_FRACTION`]; 1 disables the check.
    pub max_final_cost_fraction: f64,
    /// Reference pixels that must project into the current frame with a non-zero robust
    /// weight at the finest level (scaled by 1/4 per coarser level) for a `Converged` result.
    pub min_usable_pixels: usize,
    /// The ignore mask is dilated by at least this many full-resolution pixels (square).
    pub ignore_dilation_radius_px: usize,
    /// Start from the previous converged motion instead of identity when the caller gives no
    /// initial guess (constant-velocity prior).
    pub init_from_previous_motion: bool,
    /// A Gaussian prior pulling the estimate towards the previous converged motion (constant
    /// velocity): resolves what the images leave ambiguous (the sideways-translation / yaw
    /// valley of a distant, flat background) in favour of a smooth camera path. `None` = off.
    pub motion_prior: Option<MotionPriorConfig>,
    /// Reference pixels whose intensity gradient magnitude is below this (gray units per pixel
    /// of their level) are not used: they add almost nothing to the normal equations but cost
    /// as much as any other point. 0 uses every pixel with depth.
    pub min_gradient_per_px: f32,
    /// Reference depths below this are not used, metres.
    pub min_depth_m: f32,
    /// Reference depths above this are not used, metres (∞ = no limit; `null` in JSON).
    #[serde(with = "crate::serde_util::f32_infinite_as_null")]
    pub max_depth_m: f32,
}

impl Default for DvoConfig {
    fn default() -> Self {
        Self::paper()
    }
}

impl DvoConfig {
    /// The paper's weights (k_I 48/255, k_Z 0.5 m, γ 0.001) with the release's LM schedule
    /// (×3 on rejection, ÷1.5 on acceptance, stop > 200, ≤ 40 iterations; docs/method.md)
    /// except λ₀ = [`LM_LAMBDA_INITIAL`] instead of 0.1 and 5 levels instead of 4
    /// ([`DEFAULT_LEVELS`]; both measured, see there).
    pub fn paper() -> Self {
        Self {
            levels: DEFAULT_LEVELS,
            finest_level: 1,
            max_iterations_per_level: 40,
            lm_lambda_initial: LM_LAMBDA_INITIAL,
            lm_lambda_up: 3.0,
            lm_lambda_down: 1.5,
            lm_lambda_max: 200.0,
            step_tolerance: STEP_TOLERANCE,
            k_intensity: IntensityThreshold::Constant(48.0 / 255.0),
            k_depth_m: 0.5,
            depth_weight_gamma: 0.001,
            max_final_cost_fraction: MAX_FINAL_COST_FRACTION,
            min_usable_pixels: 1000,
            ignore_dilation_radius_px: 4,
            init_from_previous_motion: false,
            motion_prior: None,
            min_gradient_per_px: MIN_GRADIENT_PER_PX,
            min_depth_m: 0.0,
            max_depth_m: f32::INFINITY,
        }
    }

    /// The closed loop's default: the paper's profile with the depth term weighted up (γ 30, k_Z
    /// 5 cm) and the [`MotionPriorConfig`] on. When moving objects are only partly masked, the
    /// geometry of the static background and the prior hold the motion where the photometric
    /// term alone follows the unmasked parts (docs/method.md has the measurements). Without a
    /// mask (a static scene) the prior is off and only the depth weighting differs from
    /// [`Self::paper`].
    pub fn closed_loop() -> Self {
        Self {
            k_depth_m: CLOSED_LOOP_K_DEPTH_M,
            depth_weight_gamma: CLOSED_LOOP_DEPTH_WEIGHT,
            motion_prior: Some(MotionPriorConfig::default()),
            ..Self::paper()
        }
    }

    /// The Matlab release's weights: k_I level schedule, k_Z 0.25 m, γ 0.01 (docs/method.md).
    pub fn release() -> Self {
        Self {
            k_intensity: IntensityThreshold::ReleaseSchedule,
            k_depth_m: 0.25,
            depth_weight_gamma: 0.01,
            ..Self::paper()
        }
    }

    /// Checks every parameter.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the first bad field.
    // `!(a > b)` is deliberate: a NaN parameter must be rejected.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    pub fn validate(&self) -> Result<()> {
        fn bad(name: &'static str, value: impl ToString, expected: &str) -> Result<()> {
            Err(Error::InvalidParameter {
                name,
                value: value.to_string(),
                expected: expected.into(),
            })
        }
        if self.levels == 0 || self.levels > MAX_DVO_LEVELS {
            return bad("levels", self.levels, "1..=8");
        }
        if self.finest_level >= self.levels {
            return bad("finest_level", self.finest_level, "below `levels`");
        }
        if self.max_iterations_per_level == 0 {
            return bad("max_iterations_per_level", 0, "at least 1");
        }
        if !(self.lm_lambda_initial.is_finite() && self.lm_lambda_initial >= 0.0) {
            return bad("lm_lambda_initial", self.lm_lambda_initial, "finite and >= 0");
        }
        if !(self.lm_lambda_up.is_finite() && self.lm_lambda_up > 1.0) {
            return bad("lm_lambda_up", self.lm_lambda_up, "finite and > 1");
        }
        if !(self.lm_lambda_down.is_finite() && self.lm_lambda_down > 1.0) {
            return bad("lm_lambda_down", self.lm_lambda_down, "finite and > 1");
        }
        if !(self.lm_lambda_max.is_finite() && self.lm_lambda_max > self.lm_lambda_initial) {
            return bad(
                "lm_lambda_max",
                self.lm_lambda_max,
                "finite and > lm_lambda_initial",
            );
        }
        if !(self.step_tolerance.is_finite() && self.step_tolerance >= 0.0) {
            return bad(
                "step_tolerance",
                self.step_tolerance,
                "finite and >= 0 (metres / radians)",
            );
        }
        for l in self.finest_level..self.levels {
            let k = self.k_intensity.at_level(l);
            if !(k.is_finite() && k > 0.0) {
                return bad("k_intensity", k, "finite and > 0 on every level (gray units)");
            }
        }
        if !(self.k_depth_m.is_finite() && self.k_depth_m > 0.0) {
            return bad("k_depth_m", self.k_depth_m, "finite and > 0 (metres)");
        }
        if !(self.depth_weight_gamma.is_finite() && self.depth_weight_gamma >= 0.0) {
            return bad("depth_weight_gamma", self.depth_weight_gamma, "finite and >= 0");
        }
        if let Some(prior) = &self.motion_prior {
            for (name, value) in [
                ("motion_prior.translation_sigma_m", prior.translation_sigma_m),
                ("motion_prior.rotation_sigma_rad", prior.rotation_sigma_rad),
                ("motion_prior.weight", prior.weight),
            ] {
                if !(value.is_finite() && value > 0.0) {
                    return bad(name, value, "finite and > 0");
                }
            }
            if !(0.0..=1.0).contains(&prior.full_weight_ignored_fraction) {
                return bad(
                    "motion_prior.full_weight_ignored_fraction",
                    prior.full_weight_ignored_fraction,
                    "a fraction in [0, 1]",
                );
            }
        }
        if !(self.max_final_cost_fraction > 0.0 && self.max_final_cost_fraction <= 1.0) {
            return bad(
                "max_final_cost_fraction",
                self.max_final_cost_fraction,
                "in (0, 1] (fraction of the saturated robust loss)",
            );
        }
        if self.min_usable_pixels < 6 {
            return bad(
                "min_usable_pixels",
                self.min_usable_pixels,
                "at least 6 (six unknowns)",
            );
        }
        if !(self.min_gradient_per_px.is_finite() && self.min_gradient_per_px >= 0.0) {
            return bad(
                "min_gradient_per_px",
                self.min_gradient_per_px,
                "finite and >= 0 (gray units per pixel)",
            );
        }
        if !(self.min_depth_m.is_finite() && self.min_depth_m >= 0.0) {
            return bad("min_depth_m", self.min_depth_m, "finite and >= 0 (metres)");
        }
        if !(self.max_depth_m > self.min_depth_m) {
            return bad(
                "max_depth_m",
                self.max_depth_m,
                "> min_depth_m (metres; may be infinite)",
            );
        }
        Ok(())
    }

    /// The levels actually used for images of `size`: [`Self::levels`], reduced until the
    /// coarsest level's sides are at least [`crate::pyramid::MIN_LEVEL_SIDE_PX`] (never below 1).
    pub fn levels_for(&self, size: ImageSize) -> usize {
        let mut levels = self.levels.max(1);
        while levels > 1 {
            let coarsest = level_size(size, levels - 1);
            if coarsest.width >= crate::pyramid::MIN_LEVEL_SIDE_PX
                && coarsest.height >= crate::pyramid::MIN_LEVEL_SIDE_PX
            {
                break;
            }
            levels -= 1;
        }
        levels
    }

    fn schedule(&self) -> LmSchedule {
        LmSchedule {
            lambda_initial: self.lm_lambda_initial,
            lambda_up: self.lm_lambda_up,
            lambda_down: self.lm_lambda_down,
            lambda_max: self.lm_lambda_max,
            max_iterations: self.max_iterations_per_level,
            step_tolerance: self.step_tolerance,
        }
    }

    /// The robust-cost constants of pyramid `level` (at or above [`Self::finest_level`]).
    pub fn cost_at_level(&self, level: usize) -> CostParams {
        CostParams {
            k_intensity: self.k_intensity.at_level(level),
            k_depth_m: self.k_depth_m,
            depth_weight: self.depth_weight_gamma,
        }
    }

    /// Usable pixels required on `level`.
    fn required_pixels(&self, level: usize) -> usize {
        (self.min_usable_pixels >> (2 * (level - self.finest_level))).max(6)
    }
}

/// Why an estimate failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DvoFailure {
    /// Too few reference pixels were usable on the finest level (no depth, everything
    /// masked, out of view, or all residuals beyond the robust thresholds).
    TooFewPixels {
        /// Usable pixels found.
        found: usize,
        /// Pixels required ([`DvoConfig::min_usable_pixels`]).
        required: usize,
    },
    /// Some motion direction is unconstrained (textureless or planar scene) on `level`.
    Degenerate {
        /// The pyramid level.
        level: usize,
    },
    /// A step or the cost became non-finite on `level`.
    NonFinite {
        /// The pyramid level.
        level: usize,
    },
    /// The solver ended far from any pose that explains the images: the final robust cost per
    /// point is `cost_permille` ‰ of the saturated loss (a point that matches nowhere), above
    /// the limit [`DvoConfig::max_final_cost_fraction`] (`limit_permille` ‰). Typically a wrong
    /// local minimum (motion too large for the coarsest level, a moving object not masked).
    PoorFit {
        /// Final cost per point, ‰ of the saturated loss.
        cost_permille: u32,
        /// The configured limit, ‰.
        limit_permille: u32,
    },
}

/// Outcome of an estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DvoStatus {
    /// A usable motion estimate.
    Converged,
    /// No usable estimate: [`DvoEstimate::current_from_reference`] is the initial guess.
    Failed(DvoFailure),
}

/// The motion between a reference and a current frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DvoEstimate {
    /// Maps reference-camera points into the current camera (finite even on failure: then it
    /// is the initial guess).
    pub current_from_reference: Isometry3<f64>,
    /// Whether the estimate is usable.
    pub status: DvoStatus,
    /// LM candidate evaluations on each pyramid level (index = level, 0 = full resolution;
    /// 0 for levels not run).
    pub iterations_per_level: [u32; MAX_DVO_LEVELS],
    /// Why each level ended (`None` = not run or skipped for too few pixels).
    pub stop_per_level: [Option<LevelStop>; MAX_DVO_LEVELS],
    /// Robust cost per reference point at the final pose on the finest level.
    pub final_cost: f64,
    /// Reference points with a non-zero robust weight at the final pose on the finest level.
    pub pixels_used: usize,
    /// Reference points (valid depth, not ignored) on the finest level.
    pub reference_pixels: usize,
}

impl DvoEstimate {
    /// True for [`DvoStatus::Converged`].
    pub fn is_converged(&self) -> bool {
        self.status == DvoStatus::Converged
    }

    /// Total LM iterations over all levels.
    pub fn total_iterations(&self) -> u32 {
        self.iterations_per_level.iter().sum()
    }
}

/// Preallocated scratch for estimating the motion between two [`ImagePyramid`]s: reference
/// point lists and ignore masks per level.
#[derive(Debug, Clone)]
pub struct DvoEstimator {
    config: DvoConfig,
    size: ImageSize,
    /// Reference points per level (empty below the finest level).
    points: Vec<Vec<ReferencePoint>>,
    /// Ignore mask per level, 0/1 (level 0 only allocated when it is used).
    ignore: Vec<Vec<u8>>,
    column_scratch: Vec<u32>,
    /// Of the finest level's usable reference pixels, the fraction the ignore mask removed
    /// (set by [`Self::prepare_reference`]).
    ignored_fraction: f64,
}

impl DvoEstimator {
    /// Allocates scratch for images of `size`. The stored config ([`Self::config`]) has
    /// `levels` reduced to [`DvoConfig::levels_for`] `size`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for an invalid config or a size too small for its levels.
    pub fn new(size: ImageSize, config: DvoConfig) -> Result<Self> {
        config.validate()?;
        let config = DvoConfig {
            levels: config.levels_for(size).max(config.finest_level + 1),
            ..config
        };
        let coarsest = level_size(size, config.levels - 1);
        if coarsest.width < crate::pyramid::MIN_LEVEL_SIDE_PX
            || coarsest.height < crate::pyramid::MIN_LEVEL_SIDE_PX
        {
            return Err(Error::InvalidParameter {
                name: "levels",
                value: config.levels.to_string(),
                expected: format!("few enough levels for {size} (the coarsest would be {coarsest})"),
            });
        }
        let points = (0..config.levels)
            .map(|l| {
                if l >= config.finest_level {
                    Vec::with_capacity(level_size(size, l).area())
                } else {
                    Vec::new()
                }
            })
            .collect();
        let ignore = (0..config.levels)
            .map(|l| {
                if l == 0 && config.finest_level > 0 {
                    Vec::new()
                } else {
                    vec![0u8; level_size(size, l).area()]
                }
            })
            .collect();
        Ok(Self {
            config,
            size,
            points,
            ignore,
            column_scratch: Vec::with_capacity(size.width),
            ignored_fraction: 0.0,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &DvoConfig {
        &self.config
    }

    /// Reference points of `level` prepared by the last [`Self::prepare_reference`].
    pub fn reference_points(&self, level: usize) -> &[ReferencePoint] {
        self.points.get(level).map_or(&[], |p| p.as_slice())
    }

    /// Builds the per-level ignore masks and reference point lists of `reference`.
    ///
    /// The ignore mask (nonzero = ignore, reference pixel grid) is OR-pooled to the finest
    /// level, dilated there by ⌈radius / 2^finest⌉ pixels (≥ `ignore_dilation_radius_px` at
    /// full resolution), and OR-pooled to coarser levels. Pixels with invalid depth or depth
    /// outside [min_depth_m, max_depth_m] are excluded as well.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when the pyramid or mask size differs from the estimator's, or
    /// [`Error::InvalidParameter`] when the pyramid lacks a level the config uses.
    pub fn prepare_reference(
        &mut self,
        reference: &ImagePyramid,
        ignore_in_reference: Option<&Mask>,
    ) -> Result<()> {
        self.check_pyramid("reference pyramid", reference)?;
        let cfg = self.config;
        let finest = cfg.finest_level;
        let have_mask = match ignore_in_reference {
            Some(m) => {
                if m.size() != self.size {
                    return Err(Error::SizeMismatch {
                        what: "ignore mask vs frame".into(),
                        expected: self.size,
                        found: m.size(),
                    });
                }
                // Pool the full-resolution mask down to the finest level.
                let mut src_size = self.size;
                if finest == 0 {
                    for (d, &s) in self.ignore[0].iter_mut().zip(m.as_slice()) {
                        *d = u8::from(s != 0);
                    }
                } else {
                    for l in 1..=finest {
                        let dst_size = level_size(self.size, l);
                        let (before, after) = self.ignore.split_at_mut(l);
                        let src: &[u8] = if l == 1 { m.as_slice() } else { &before[l - 1] };
                        // Raw masks use 255; pooling only tests nonzero and writes 0/1.
                        mask::pool_or_into(src, src_size, &mut after[0], dst_size);
                        src_size = dst_size;
                    }
                }
                let radius = cfg.ignore_dilation_radius_px.div_ceil(1 << finest);
                mask::dilate_square(
                    &mut self.ignore[finest],
                    level_size(self.size, finest),
                    radius,
                    &mut self.column_scratch,
                );
                for l in finest + 1..cfg.levels {
                    let (before, after) = self.ignore.split_at_mut(l);
                    mask::pool_or_into(
                        &before[l - 1],
                        level_size(self.size, l - 1),
                        &mut after[0],
                        level_size(self.size, l),
                    );
                }
                true
            }
            None => false,
        };
        for l in finest..cfg.levels {
            let Some(level) = reference.level(l) else {
                return Err(missing_level(l));
            };
            let pts = &mut self.points[l];
            pts.clear();
            let mut ignored = 0usize;
            let k = level.intrinsics;
            let (fx_inv, fy_inv) = (1.0 / k.fx as f32, 1.0 / k.fy as f32);
            let (cx, cy) = (k.cx as f32, k.cy as f32);
            let w = level.size().width;
            let depth = level.depth_m.as_slice();
            let gray = level.gray.as_slice();
            let ignore = &self.ignore[l];
            let min_grad_sq = cfg.min_gradient_per_px * cfg.min_gradient_per_px;
            // Row by row (no division per pixel); the tests are the same for every pixel.
            for (y, ((depth_row, gray_row), sample_row)) in depth
                .chunks_exact(w)
                .zip(gray.chunks_exact(w))
                .zip(level.samples.chunks_exact(w))
                .enumerate()
            {
                let ignore_row = if have_mask {
                    &ignore[y * w..(y + 1) * w]
                } else {
                    &[][..]
                };
                let ray_y = (y as f32 - cy) * fy_inv;
                for (x, ((&z, &g), sample)) in depth_row.iter().zip(gray_row).zip(sample_row).enumerate() {
                    if !(z > 0.0 && z >= cfg.min_depth_m && z <= cfg.max_depth_m) {
                        continue;
                    }
                    if min_grad_sq > 0.0 {
                        let (gx, gy) = (sample.0[TargetSample::GRAD_X], sample.0[TargetSample::GRAD_Y]);
                        if gx * gx + gy * gy < min_grad_sq {
                            continue;
                        }
                    }
                    if have_mask && ignore_row[x] != 0 {
                        ignored += 1;
                        continue;
                    }
                    pts.push(ReferencePoint {
                        point_m: [(x as f32 - cx) * fx_inv * z, ray_y * z, z],
                        intensity: g,
                    });
                }
            }
            if l == finest {
                self.ignored_fraction = ignored as f64 / (ignored + pts.len()).max(1) as f64;
            }
        }
        Ok(())
    }

    fn check_pyramid(&self, what: &str, p: &ImagePyramid) -> Result<()> {
        if p.size() != self.size {
            return Err(Error::SizeMismatch {
                what: what.into(),
                expected: self.size,
                found: p.size(),
            });
        }
        if p.num_levels() < self.config.levels || p.finest_level() > self.config.finest_level {
            return Err(missing_level(self.config.finest_level));
        }
        Ok(())
    }

    /// Estimates `current_from_reference` between two built pyramids, coarse to fine.
    /// `initial_current_from_reference` defaults to identity.
    ///
    /// # Errors
    /// Size or level mismatches between the pyramids, mask and estimator. A motion that
    /// cannot be estimated is not an error: it is a [`DvoStatus::Failed`] estimate.
    pub fn estimate(
        &mut self,
        reference: &ImagePyramid,
        current: &ImagePyramid,
        ignore_in_reference: Option<&Mask>,
        initial_current_from_reference: Option<&Isometry3<f64>>,
    ) -> Result<DvoEstimate> {
        self.prepare_reference(reference, ignore_in_reference)?;
        self.estimate_prepared(current, initial_current_from_reference, None)
    }

    /// [`Self::estimate`] with the reference already prepared by [`Self::prepare_reference`],
    /// and the predicted motion for [`DvoConfig::motion_prior`] (ignored when the prior is off;
    /// no prediction, no prior).
    ///
    /// # Errors
    /// As [`Self::estimate`].
    // `!(a <= b)` is deliberate: a NaN cost fraction must fail the plausibility check.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    pub fn estimate_prepared(
        &mut self,
        current: &ImagePyramid,
        initial_current_from_reference: Option<&Isometry3<f64>>,
        prior: Option<&Isometry3<f64>>,
    ) -> Result<DvoEstimate> {
        self.check_pyramid("current pyramid", current)?;
        let cfg = self.config;
        let initial = initial_current_from_reference
            .copied()
            .unwrap_or_else(Isometry3::identity);
        if !is_finite_pose(&initial) {
            return Err(Error::InvalidParameter {
                name: "initial_current_from_reference",
                value: format!("{initial:?}"),
                expected: "a finite transform".into(),
            });
        }
        let mut estimate = DvoEstimate {
            current_from_reference: initial,
            status: DvoStatus::Converged,
            iterations_per_level: [0; MAX_DVO_LEVELS],
            stop_per_level: [None; MAX_DVO_LEVELS],
            final_cost: 0.0,
            pixels_used: 0,
            reference_pixels: self.points[cfg.finest_level].len(),
        };
        let schedule = cfg.schedule();
        let mut pose = initial;
        for l in (cfg.finest_level..cfg.levels).rev() {
            let Some(level) = current.level(l) else {
                return Err(missing_level(l));
            };
            let points = &self.points[l];
            let required = cfg.required_pixels(l);
            let is_finest = l == cfg.finest_level;
            if points.len() < required {
                if is_finest {
                    return Ok(failed(
                        estimate,
                        initial,
                        DvoFailure::TooFewPixels {
                            found: points.len(),
                            required,
                        },
                    ));
                }
                continue; // a coarse level without enough pixels is skipped
            }
            let target = TargetView {
                samples: &level.samples,
                size: level.size(),
                intrinsics: level.intrinsics,
            };
            let cost = cfg.cost_at_level(l);
            let mut level_pose = pose;
            // A coarse level only has to bring the pose into the next level's basin, and its
            // pixels are 2^(l − finest) times larger: its step tolerance is that much looser.
            let level_schedule = LmSchedule {
                step_tolerance: schedule.step_tolerance * f64::from(1u32 << (l - cfg.finest_level)),
                ..schedule
            };
            let level_prior = match (cfg.motion_prior, prior) {
                (Some(p), Some(motion)) => {
                    let ramp = if p.full_weight_ignored_fraction > 0.0 {
                        (self.ignored_fraction / p.full_weight_ignored_fraction).min(1.0)
                    } else {
                        1.0
                    };
                    let scale = ramp * p.weight * points.len() as f64 * f64::from(cost.saturated_point());
                    let t = scale / (p.translation_sigma_m * p.translation_sigma_m);
                    let r = scale / (p.rotation_sigma_rad * p.rotation_sigma_rad);
                    Some(solver::MotionPrior {
                        current_from_reference: *motion,
                        information: [t, t, t, r, r, r],
                    })
                }
                _ => None,
            };
            match solver::optimize_level(
                points,
                level.size().width,
                &target,
                &cost,
                &level_schedule,
                level_prior.as_ref(),
                &mut level_pose,
            ) {
                Ok(res) => {
                    estimate.iterations_per_level[l] = res.iterations as u32;
                    estimate.stop_per_level[l] = Some(res.stop);
                    let ne = res.normal_equations;
                    if ne.inliers < required {
                        if is_finest {
                            return Ok(failed(
                                estimate,
                                initial,
                                DvoFailure::TooFewPixels {
                                    found: ne.inliers,
                                    required,
                                },
                            ));
                        }
                        continue; // keep the pose from the coarser level
                    }
                    pose = level_pose;
                    if is_finest {
                        estimate.final_cost = ne.mean_cost();
                        estimate.pixels_used = ne.inliers;
                    }
                }
                // A coarse level can be degenerate when a moving object leaves only a few
                // background pixels there (4^l fewer than at full resolution): it is skipped
                // like a coarse level without enough pixels. Only the finest level decides.
                Err(LevelError::Degenerate) if !is_finest => continue,
                Err(LevelError::Degenerate) => {
                    return Ok(failed(estimate, initial, DvoFailure::Degenerate { level: l }));
                }
                Err(LevelError::NonFinite) => {
                    return Ok(failed(estimate, initial, DvoFailure::NonFinite { level: l }));
                }
            }
        }
        if !is_finite_pose(&pose) {
            return Ok(failed(
                estimate,
                initial,
                DvoFailure::NonFinite {
                    level: cfg.finest_level,
                },
            ));
        }
        // A wrong minimum looks converged to the solver (small steps, cost no longer
        // decreasing) but leaves most points near the saturated loss.
        let saturated = f64::from(cfg.cost_at_level(cfg.finest_level).saturated_point());
        let fraction = estimate.final_cost / saturated;
        if !(fraction <= cfg.max_final_cost_fraction) {
            let permille = |f: f64| (f * 1000.0).round().clamp(0.0, f64::from(u32::MAX)) as u32;
            return Ok(failed(
                estimate,
                initial,
                DvoFailure::PoorFit {
                    cost_permille: permille(fraction),
                    limit_permille: permille(cfg.max_final_cost_fraction),
                },
            ));
        }
        estimate.current_from_reference = pose;
        Ok(estimate)
    }
}

fn failed(mut estimate: DvoEstimate, initial: Isometry3<f64>, reason: DvoFailure) -> DvoEstimate {
    estimate.current_from_reference = initial;
    estimate.status = DvoStatus::Failed(reason);
    estimate
}

fn missing_level(level: usize) -> Error {
    Error::InvalidParameter {
        name: "pyramid",
        value: format!("without level {level}"),
        expected: "a pyramid built with the estimator's levels and finest level".into(),
    }
}

/// Frame-to-frame DVO over a sequence: keeps the previous frame's pyramid as the reference.
///
/// The pyramids and scratch are allocated in [`DvoTracker::new`]; [`DvoTracker::track`] builds
/// the new frame's pyramid once, estimates the motion from the previous frame, then swaps the
/// two pyramids (no copy). `track` is not free of allocations: it makes a few now and then
/// (counted in `tests/detector_alloc.rs`).
#[derive(Debug, Clone)]
pub struct DvoTracker {
    estimator: DvoEstimator,
    reference: ImagePyramid,
    current: ImagePyramid,
    has_reference: bool,
    previous_motion: Option<Isometry3<f64>>,
}

impl DvoTracker {
    /// A tracker for frames of `size` seen through `intrinsics` (level-0 values).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for an invalid config, invalid intrinsics, or a size too
    /// small for the requested levels.
    pub fn new(size: ImageSize, intrinsics: PinholeIntrinsics, config: DvoConfig) -> Result<Self> {
        let estimator = DvoEstimator::new(size, config)?;
        let config = *estimator.config();
        let reference = ImagePyramid::new(size, intrinsics, config.levels, config.finest_level)?;
        let current = reference.clone();
        Ok(Self {
            estimator,
            reference,
            current,
            has_reference: false,
            previous_motion: None,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &DvoConfig {
        self.estimator.config()
    }

    /// Forgets the last motion, so the next [`Self::track`] has no constant-velocity prediction
    /// (no [`DvoConfig::motion_prior`], no [`DvoConfig::init_from_previous_motion`]): for the
    /// caller to call when that motion was not trusted or the next estimate spans more than
    /// one frame interval (frames skipped in between).
    pub fn forget_motion(&mut self) {
        self.previous_motion = None;
    }

    /// Forgets the reference frame (the next [`Self::track`] returns `None`) and the motion prior.
    pub fn reset(&mut self) {
        self.has_reference = false;
        self.previous_motion = None;
    }

    /// Adds a frame: returns the motion from the previous frame to this one (`None` for the
    /// first frame after creation or [`Self::reset`]), then keeps this frame as the reference.
    ///
    /// `ignore_in_reference` (nonzero = ignore) lives on the *previous* frame's pixel grid
    /// (the moving objects detected there); it is dilated per the config. The initial guess
    /// is `initial_current_from_reference`, else the previous converged motion when
    /// [`DvoConfig::init_from_previous_motion`] is set, else identity.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when an image or the mask is not the tracker's size (the
    /// tracker's state is then unchanged), [`Error::InvalidParameter`] for a non-finite
    /// initial guess.
    pub fn track(
        &mut self,
        gray: &GrayF32,
        depth_m: &DepthMeters,
        ignore_in_reference: Option<&Mask>,
        initial_current_from_reference: Option<&Isometry3<f64>>,
    ) -> Result<Option<DvoEstimate>> {
        if let Some(m) = ignore_in_reference {
            if m.size() != self.reference.size() {
                return Err(Error::SizeMismatch {
                    what: "ignore mask vs frame".into(),
                    expected: self.reference.size(),
                    found: m.size(),
                });
            }
        }
        if !self.has_reference {
            self.current.build(gray, depth_m)?;
            std::mem::swap(&mut self.reference, &mut self.current);
            self.has_reference = true;
            return Ok(None);
        }
        // The new frame's pyramid and the reference's point lists are independent: build them
        // side by side (the point lists are a serial pass; the pyramid is row-parallel).
        let (current, estimator, reference) = (&mut self.current, &mut self.estimator, &self.reference);
        let (built, prepared) = rayon::join(
            || current.build(gray, depth_m),
            || estimator.prepare_reference(reference, ignore_in_reference),
        );
        built?;
        prepared?;
        let prior = if self.config().init_from_previous_motion {
            self.previous_motion
        } else {
            None
        };
        let initial = initial_current_from_reference.copied().or(prior);
        let estimate = self.estimator.estimate_prepared(
            &self.current,
            initial.as_ref(),
            self.previous_motion.as_ref(),
        )?;
        std::mem::swap(&mut self.reference, &mut self.current);
        self.previous_motion = estimate.is_converged().then_some(estimate.current_from_reference);
        Ok(Some(estimate))
    }

    /// Estimates the motion between two explicitly given frames with the tracker's buffers
    /// (for tests and benchmarks); afterwards `current` is the tracker's reference.
    ///
    /// # Errors
    /// As [`Self::track`].
    pub fn estimate_between(
        &mut self,
        reference: (&GrayF32, &DepthMeters),
        current: (&GrayF32, &DepthMeters),
        ignore_in_reference: Option<&Mask>,
        initial_current_from_reference: Option<&Isometry3<f64>>,
    ) -> Result<DvoEstimate> {
        self.reset();
        self.track(reference.0, reference.1, None, None)?;
        let est = self.track(
            current.0,
            current.1,
            ignore_in_reference,
            initial_current_from_reference,
        )?;
        est.ok_or_else(|| Error::InvalidParameter {
            name: "reference",
            value: "missing".into(),
            expected: "a reference frame (internal error)".into(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profiles_validate_and_differ_where_documented() {
        DvoConfig::paper().validate().unwrap();
        DvoConfig::release().validate().unwrap();
        assert_eq!(DvoConfig::default(), DvoConfig::paper());
        let r = DvoConfig::release();
        assert!((r.k_intensity.at_level(3) - 16.0 / 255.0).abs() < 1e-6);
        assert!((r.k_intensity.at_level(0) - 61.61 / 255.0).abs() < 1e-4);
        assert_eq!(r.k_intensity.at_level(4), r.k_intensity.at_level(3));
        // Too small for 5 levels: as many as fit (40×30 → 40, 20, 10 px wide).
        assert_eq!(DvoConfig::paper().levels_for(ImageSize::new(640, 480)), 5);
        assert_eq!(DvoConfig::paper().levels_for(ImageSize::new(40, 30)), 2);
    }

    #[test]
    fn ignored_pixels_are_dropped_with_at_least_the_dilation_radius() {
        use crate::geometry::camera::presets;
        let size = ImageSize::new(128, 96);
        let config = DvoConfig {
            levels: 3,
            finest_level: 1,
            min_gradient_per_px: 0.0,
            ..DvoConfig::paper()
        };
        let gray = GrayF32::from_fn(size, |x, y| ((x * 7 + y * 3) % 11) as f32 / 11.0);
        let mut depth = DepthMeters::filled(size, 2.0);
        depth.set(100, 80, 0.0); // one invalid pixel: its coarse pixel keeps the other children
        let mut pyr = ImagePyramid::new(size, presets::TUM_FR2, 3, 1).unwrap();
        pyr.build(&gray, &depth).unwrap();
        let mut est = DvoEstimator::new(size, config).unwrap();
        est.prepare_reference(&pyr, None).unwrap();
        assert_eq!(est.reference_points(1).len(), 64 * 48);
        assert_eq!(est.reference_points(2).len(), 32 * 24);
        // Ignore full-resolution columns 40..=59 (255 = set, as in a Mask).
        let mask = Mask::from_fn(size, |x, _| if (40..60).contains(&x) { 255 } else { 0 });
        est.prepare_reference(&pyr, Some(&mask)).unwrap();
        let k1 = presets::TUM_FR2.at_level(1);
        for p in est.reference_points(1) {
            // Back to the level-1 column, then to full-resolution coordinates of its children.
            let x1 = (f64::from(p.point_m[0]) / f64::from(p.point_m[2]) * k1.fx + k1.cx).round() as i64;
            let (c0, c1) = (2 * x1, 2 * x1 + 1);
            let gap = (40 - c1).max(c0 - 59);
            assert!(
                gap > 4,
                "level-1 column {x1} is within {gap} px of the ignored band"
            );
        }
        let kept = est.reference_points(1).len();
        assert!(kept < 64 * 48 - 10 * 48, "{kept}");
        assert!(est.reference_points(2).len() < 32 * 24 - 5 * 24);
    }

    #[test]
    fn validation_names_the_bad_field() {
        let cases: Vec<(DvoConfig, &str)> = vec![
            (
                DvoConfig {
                    levels: 0,
                    ..DvoConfig::paper()
                },
                "levels",
            ),
            (
                DvoConfig {
                    finest_level: DEFAULT_LEVELS,
                    ..DvoConfig::paper()
                },
                "finest_level",
            ),
            (
                DvoConfig {
                    lm_lambda_up: 1.0,
                    ..DvoConfig::paper()
                },
                "lm_lambda_up",
            ),
            (
                DvoConfig {
                    k_depth_m: f32::NAN,
                    ..DvoConfig::paper()
                },
                "k_depth_m",
            ),
            (
                DvoConfig {
                    k_intensity: IntensityThreshold::Constant(0.0),
                    ..DvoConfig::paper()
                },
                "k_intensity",
            ),
            (
                DvoConfig {
                    step_tolerance: -1.0,
                    ..DvoConfig::paper()
                },
                "step_tolerance",
            ),
            (
                DvoConfig {
                    max_depth_m: 0.0,
                    ..DvoConfig::paper()
                },
                "max_depth_m",
            ),
            (
                DvoConfig {
                    max_final_cost_fraction: 0.0,
                    ..DvoConfig::paper()
                },
                "max_final_cost_fraction",
            ),
            (
                DvoConfig {
                    min_usable_pixels: 2,
                    ..DvoConfig::paper()
                },
                "min_usable_pixels",
            ),
        ];
        for (cfg, name) in cases {
            match cfg.validate() {
                Err(Error::InvalidParameter { name: n, .. }) => assert_eq!(n, name),
                other => panic!("{name}: {other:?}"),
            }
        }
    }
}
