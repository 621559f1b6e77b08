//! [`DvoConfig`] and its parts: cost, thresholds, pyramid and solver settings, the motion
//! prior, with their defaults and checks.

use super::*;

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
    /// Over the first `startup_frames` motions, the last motion predicts the next one only
    /// when it was estimated with at most this much less of its reference ignored (as
    /// fractions of the usable reference pixels, like `full_weight_ignored_fraction`) than the
    /// next estimate's reference has: when far more is ignored now, the objects now masked
    /// were in view then and likely pulled that motion, and the prior would carry their motion
    /// on. 1 = the last motion always predicts.
    pub max_ignored_fraction_increase: f64,
    /// The motions after the tracker starts (or is reset) that `max_ignored_fraction_increase`
    /// applies to: the closed loop's detector needs its first frames to find what moves from
    /// the first frame on, so those motions are estimated without them masked; later, a jump
    /// of the ignored fraction is as likely a false detection, and the prior then holds the
    /// odometry.
    pub startup_frames: usize,
}

impl Default for MotionPriorConfig {
    fn default() -> Self {
        Self {
            translation_sigma_m: DEFAULT_PRIOR_TRANSLATION_SIGMA_M,
            rotation_sigma_rad: DEFAULT_PRIOR_ROTATION_SIGMA_RAD,
            weight: DEFAULT_PRIOR_WEIGHT,
            full_weight_ignored_fraction: DEFAULT_PRIOR_FULL_WEIGHT_IGNORED_FRACTION,
            max_ignored_fraction_increase: DEFAULT_PRIOR_MAX_IGNORED_FRACTION_INCREASE,
            startup_frames: DEFAULT_PRIOR_STARTUP_FRAMES,
        }
    }
}

/// Default [`MotionPriorConfig::full_weight_ignored_fraction`].
pub const DEFAULT_PRIOR_FULL_WEIGHT_IGNORED_FRACTION: f64 = 0.25;

/// Default [`MotionPriorConfig::max_ignored_fraction_increase`]. On the Bonn "crowd" window a
/// person walks in view from the first frame: the first two estimates ignore 0 % and 35 % of
/// the reference, then 65 %, and followed the person (26 and 24 mm a frame against the camera's
/// 3 mm); the causal closed loop's prior then carried that motion for 40 frames (errors of 23
/// falling to 6 mm a frame). Dropping those two predictions: causal ATE 0.095 → 0.067 m
/// (docs/method.md D13). Measured with the rule on every frame, any bound from 0.15 to 0.3
/// dropped just those two there; at 0.1 and below, predictions were also dropped while people
/// entered and left, and the odometry got worse.
pub const DEFAULT_PRIOR_MAX_IGNORED_FRACTION_INCREASE: f64 = 0.2;

/// Default [`MotionPriorConfig::startup_frames`]: 1 s at 30 Hz, as long as the closed loop
/// tracks frame to frame before keyframes (`KeyframeConfig::min_detector_frames`). The
/// synthetic bodies that fill the view from the first frame (three of them held-out
/// scenarios, looked at for this) are first masked 3–26 frames in;
/// on the static 7-Scenes kitchen a false detection raised the ignored fraction from 0 to 0.30
/// at frame 269, and without the prior the causal closed loop then marked up to 42 % of the
/// view.
pub const DEFAULT_PRIOR_STARTUP_FRAMES: usize = 30;

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
    /// Track against a keyframe instead of the previous frame ([`KeyframeConfig`]); `None` =
    /// frame to frame.
    pub keyframe: Option<KeyframeConfig>,
}

/// When [`crate::dvo::DvoTracker`] takes a new keyframe. Each frame is tracked against the
/// keyframe (a frame-to-frame estimate would add the error of every step); the previous frame
/// becomes the new keyframe as soon as any limit below is reached, or an estimate did not
/// converge, or the caller distrusted a motion ([`crate::dvo::DvoTracker::forget_motion`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct KeyframeConfig {
    /// Frames tracked against one keyframe at most (1 = frame to frame).
    pub max_frames: usize,
    /// The camera's distance from the keyframe's position, metres.
    pub max_translation_m: f64,
    /// The camera's rotation from the keyframe's orientation, radians.
    pub max_rotation_rad: f64,
    /// The fraction of the keyframe's reference pixels that the last estimate used (they
    /// projected into the frame with a non-zero weight): below it, too little of the keyframe
    /// is still seen or matches.
    pub min_used_fraction: f64,
    /// The pipeline ends a keyframe whenever the detector marks more than this fraction of a
    /// frame as moving: moving objects travel between the keyframe and the frame tracked
    /// against it, over background the keyframe's ignore mask does not cover, so frames with
    /// moving objects are tracked frame to frame.
    pub max_moving_fraction: f64,
    /// The pipeline keeps no keyframe until its detector has seen this many frames since it
    /// (re)started: before its accumulation has built up, an empty mask does not mean that
    /// nothing moves (an object moving from the first frame is found only later).
    pub min_detector_frames: u64,
}

impl Default for KeyframeConfig {
    fn default() -> Self {
        Self {
            max_frames: DEFAULT_KEYFRAME_MAX_FRAMES,
            max_translation_m: DEFAULT_KEYFRAME_MAX_TRANSLATION_M,
            max_rotation_rad: DEFAULT_KEYFRAME_MAX_ROTATION_RAD,
            min_used_fraction: DEFAULT_KEYFRAME_MIN_USED_FRACTION,
            max_moving_fraction: DEFAULT_KEYFRAME_MAX_MOVING_FRACTION,
            min_detector_frames: DEFAULT_KEYFRAME_MIN_DETECTOR_FRAMES,
        }
    }
}

/// Default [`KeyframeConfig::max_frames`]: a third of a second at 30 Hz. On 7-Scenes' kitchen
/// (causal closed loop, 300 frames) 3 frames left the ATE at 6.5 cm (frame to frame 6.9 cm);
/// 5, 10 and 20 frames gave 2.0, 2.3 and 2.3 cm.
pub const DEFAULT_KEYFRAME_MAX_FRAMES: usize = 10;
/// Default [`KeyframeConfig::max_translation_m`]: where a hand-held camera's view of a room
/// 1–4 m away starts to change by more than a few pixels of parallax at DVO's 320×240.
pub const DEFAULT_KEYFRAME_MAX_TRANSLATION_M: f64 = 0.05;
/// Default [`KeyframeConfig::max_rotation_rad`]: 3°, about 15 px of image motion at 320×240,
/// the largest per-frame motion the DVO accuracy targets cover.
pub const DEFAULT_KEYFRAME_MAX_ROTATION_RAD: f64 = 3.0 * std::f64::consts::PI / 180.0;
/// Default [`KeyframeConfig::min_used_fraction`]: half the keyframe's points still match.
pub const DEFAULT_KEYFRAME_MIN_USED_FRACTION: f64 = 0.5;
/// Default [`KeyframeConfig::max_moving_fraction`]: 1 % of the image. On the Bonn crowd window
/// (causal closed loop) keyframes kept regardless of moving objects took the ATE from 9.7 cm
/// to 36–39 cm; with this limit 8.7 cm. 7-Scenes' static kitchen has detector false positives
/// of 0.5 % on average, which must not end the keyframes that remove them.
pub const DEFAULT_KEYFRAME_MAX_MOVING_FRACTION: f64 = 0.01;
/// Default [`KeyframeConfig::min_detector_frames`]: 1 s at 30 Hz. Without it, the synthetic
/// object that fills the view from the first frame (dominant_from_start, offline at 320×240)
/// pulled the first pass's keyframe tracking with it: F1 0.046 against 0.491; 15 frames: 0.047.
pub const DEFAULT_KEYFRAME_MIN_DETECTOR_FRAMES: u64 = 30;

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
            keyframe: None,
        }
    }

    /// The closed loop's default: the paper's profile with the depth term weighted up (γ 30, k_Z
    /// 5 cm), the [`MotionPriorConfig`] on, and keyframes ([`KeyframeConfig`]) while nothing
    /// moves. When moving objects are only partly masked, the
    /// geometry of the static background and the prior hold the motion where the photometric
    /// term alone follows the unmasked parts (docs/method.md has the measurements). Without a
    /// mask (a static scene) the prior is off and only the depth weighting differs from
    /// [`Self::paper`].
    pub fn closed_loop() -> Self {
        Self {
            k_depth_m: CLOSED_LOOP_K_DEPTH_M,
            depth_weight_gamma: CLOSED_LOOP_DEPTH_WEIGHT,
            motion_prior: Some(MotionPriorConfig::default()),
            keyframe: Some(KeyframeConfig::default()),
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
            for (name, value) in [
                (
                    "motion_prior.full_weight_ignored_fraction",
                    prior.full_weight_ignored_fraction,
                ),
                (
                    "motion_prior.max_ignored_fraction_increase",
                    prior.max_ignored_fraction_increase,
                ),
            ] {
                if !(0.0..=1.0).contains(&value) {
                    return bad(name, value, "a fraction in [0, 1]");
                }
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
        if let Some(keyframe) = &self.keyframe {
            if keyframe.max_frames == 0 {
                return bad("keyframe.max_frames", 0, "at least 1");
            }
            for (name, value) in [
                ("keyframe.max_translation_m", keyframe.max_translation_m),
                ("keyframe.max_rotation_rad", keyframe.max_rotation_rad),
            ] {
                if !(value.is_finite() && value > 0.0) {
                    return bad(name, value, "finite and > 0");
                }
            }
            for (name, value) in [
                ("keyframe.min_used_fraction", keyframe.min_used_fraction),
                ("keyframe.max_moving_fraction", keyframe.max_moving_fraction),
            ] {
                if !(0.0..=1.0).contains(&value) {
                    return bad(name, value, "a fraction in [0, 1]");
                }
            }
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

    pub(super) fn schedule(&self) -> LmSchedule {
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
    pub(super) fn required_pixels(&self, level: usize) -> usize {
        (self.min_usable_pixels >> (2 * (level - self.finest_level))).max(6)
    }
}
