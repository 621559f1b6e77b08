//! The detector's parameters: [`OcclusionConfig`] with its defaults and checks, and the
//! choices its fields name ([`ThresholdForm`], [`WarpDepth`], [`Adjacency`]).

use serde::{Deserialize, Serialize};

use super::{scaled_pixels, AppearanceGrowthConfig, SlowEvidenceConfig};
use crate::error::{Error, Result};
use crate::image_buf::ImageSize;

/// Functional form of the truncation thresholds τ_α and τ_β (paper Eq. 4–6; docs/method.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ThresholdForm {
    /// τ = coefficient · Z (the authors' release; coefficients in m/m, i.e. unitless).
    #[default]
    Linear,
    /// τ = coefficient · Z² (the paper's Eq. 4; coefficients in 1/m).
    Quadratic,
}

/// Which depth back-projects a current pixel for the warp, and what ΔZ compares (paper Eq. 1–2;
/// docs/method.md step 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WarpDepth {
    /// The release: back-project pixel u with the previous compensated depth Zc_i(u) and compare
    /// raw depths, ΔZ = Zc_i(n(u)) − Zc_{i+1}(u).
    #[default]
    PreviousCompensated,
    /// A true backward warp where the current depth is measured: back-project with Z_{i+1}(u),
    /// and compare with the warped point's depth z′ in the previous camera,
    /// ΔZ = Zc_i(n(u)) − z′; unmeasured pixels fall back to the release rule.
    Current,
}

/// Adjacency used by the pruning test of predicted areas (docs/method.md step 12).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Adjacency {
    /// Left, right, up, down (the release's stencil intent).
    #[default]
    Four,
    /// The 8 surrounding pixels.
    Eight,
}

/// Every parameter of the detector, with the release defaults (docs/method.md, "Parameters").
///
/// Serialised (JSON config files) field by field with these names; missing fields take the
/// default, unknown ones are an error; `null` switches an optional stage off.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OcclusionConfig {
    /// α of τ_α: accumulation below τ_α is not an object (unitless for linear, 1/m for quadratic).
    pub alpha: f32,
    /// β of τ_β: a depth increase ΔZ ≤ −τ_β (background reappears) resets the accumulation.
    pub beta: f32,
    /// Linear (release) or quadratic (paper) thresholds.
    pub threshold_form: ThresholdForm,
    /// Fraction of an accumulation at or below τ_α kept for the next frame (0 = the paper's
    /// truncation, Eq. 5, which clears it). Above 0 the accumulation is leaky: a slow, steady
    /// depth decrease (an object approaching head-on) adds up over frames instead of being
    /// cleared every frame, while noise decays. Values in [0, 1).
    pub sub_threshold_retention: f32,
    /// Minimum object component size at 640 × 480 in pixels; scaled by image area.
    pub min_object_pixels_vga: usize,
    /// Prediction only crosses 4-neighbour edges whose depth step is below this (m).
    pub prediction_depth_gate_m: f32,
    /// Prediction stops after a ring that contributed at most this many neighbour terms.
    pub prediction_stop_terms: usize,
    /// Grow accumulation into the newly discovered area (Eq. 10); off = skip prediction and pruning.
    pub predict_newly_discovered: bool,
    /// Adjacency of the pruning test.
    pub prune_adjacency: Adjacency,
    /// Warp depth and ΔZ comparison.
    pub warp_depth: WarpDepth,
    /// Radius r (px) of a square (2r+1)² morphological opening of {A > τ_α} before labelling:
    /// object structures thinner than 2r+1 px are erased from A like small components (except
    /// near the border, see `thin_structure_border_margin_px`). 0 = off (the release). Not in the paper: it
    /// removes the 1–3 px strips that flickering Kinect depth edges leave along long edges of
    /// static scenes (see docs/method.md, "Deviations").
    pub thin_structure_radius_px: usize,
    /// Thin structures within this many pixels of the image border are kept: objects entering
    /// the view start as thin slivers there.
    pub thin_structure_border_margin_px: usize,
    /// Thin pixels within this many pixels of the opening's result, along 8-connected paths
    /// inside the object set, are kept (a bounded reconstruction by geodesic dilation): the thin
    /// rim a slowly moving body leaves along its edges, and the base of a limb, stay with the
    /// body, while strips with no thick part nearby are erased as before. 0 = the plain opening.
    pub thin_structure_reconnect_px: usize,
    /// Pixels the thin-structure filter erased in the previous frame (carried by the warp)
    /// count as object pixels in this frame's opening, without joining the set: a leading edge
    /// that advances by 1–2 px a frame leaves a new thin strip each frame beside the one erased
    /// before, and the two together are thick enough to stay, while a flickering band returns
    /// to the same pixels and stays thin. false = each frame's opening alone.
    pub thin_structure_advance: bool,
    /// A predicted component that is not attached to a non-predicted object pixel is still kept
    /// when it holds pixels that were predicted object in the previous frame and it reaches
    /// within this many pixels of the image border: an object leaving the view loses its
    /// non-predicted part through the border first. 0 = prune it (the release).
    pub prune_exit_margin_px: usize,
    /// A component of A smaller than the minimum object size is still kept, down to this
    /// fraction of that size, when it is a leaving object's remainder: it reaches within
    /// `prune_exit_margin_px` of the image border and holds a pixel of the previous frame's
    /// mask. An object leaving the view shrinks through the border and keeps its mask to the
    /// end; run backwards in time (the offline mode's backward pass), that is an object
    /// entering the view, found while it is still a sliver. In (0, 1]; 1 (or an exit margin
    /// of 0) = every component needs the full size (the paper).
    pub exit_min_object_fraction: f32,
    /// Runs of pixels without depth (after the hole filling from the previous frame) along a
    /// row or column, bounded by the mask on both sides or by the mask and the image border,
    /// join the mask when at most this long (pixels at 640 px image width, scaled with the
    /// width): the sensor's invalid border band beside an object entering the view, holes on
    /// its dark parts (see [`super::gaps`]). Not in the paper; 0 = off (the paper).
    pub invalid_depth_gap_px_vga: usize,
    /// Motion check (not in the paper): when the given motion explains the depth worse than no
    /// motion at all by more than this margin (a fraction of the sampled pixels, see
    /// [`consistency::depth_consistency`]), the motion is taken to be wrong and the detector
    /// restarts from this frame instead of accumulating misregistered depth edges (which would
    /// stay in A as static false positives). `None` = trust every motion (the release).
    ///
    /// [`consistency::depth_consistency`]: super::consistency::depth_consistency
    pub motion_check_margin: Option<f32>,
    /// Appearance-gated object completion (not in the paper, see [`AppearanceGrowthConfig`]):
    /// after the mask is final, objects grow into neighbouring pixels with continuous depth
    /// whose intensity changed against the previous image warped with the camera motion. Needs
    /// the gray image ([`OcclusionDetector::update_with_gray`]); `None` = off (the paper, and
    /// the default: on real people the changing shadows at their feet let it grow over the
    /// floor, which then misleads the closed loop's odometry; docs/method.md has the figures).
    ///
    /// [`OcclusionDetector::update_with_gray`]: super::OcclusionDetector::update_with_gray
    pub appearance_growth: Option<AppearanceGrowthConfig>,
    /// Slow-change evidence (not in the paper, see [`SlowEvidenceConfig`]): a leaky sum of ΔZ
    /// beside A, cleared of the camera motion's error, whose large components join the mask: an
    /// object approaching head-on or covering a surface just behind it, whose ΔZ per frame stays
    /// below τ_α. On by default (measured on the synthetic failure classes and on real people,
    /// docs/method.md D16), for images of at least 240 px on the short side; `None` = off (the
    /// paper's accumulation alone).
    pub slow_evidence: Option<SlowEvidenceConfig>,
}

impl Default for OcclusionConfig {
    fn default() -> Self {
        Self {
            alpha: 0.15,
            beta: 0.225,
            threshold_form: ThresholdForm::Linear,
            sub_threshold_retention: 0.0,
            min_object_pixels_vga: 500,
            prediction_depth_gate_m: 0.05,
            prediction_stop_terms: 10,
            predict_newly_discovered: true,
            prune_adjacency: Adjacency::Four,
            warp_depth: WarpDepth::PreviousCompensated,
            thin_structure_radius_px: 1,
            thin_structure_border_margin_px: 16,
            thin_structure_reconnect_px: THIN_STRUCTURE_RECONNECT_PX,
            thin_structure_advance: true,
            prune_exit_margin_px: EXIT_MARGIN_PX,
            exit_min_object_fraction: EXIT_MIN_OBJECT_FRACTION,
            invalid_depth_gap_px_vga: INVALID_DEPTH_GAP_PX_VGA,
            motion_check_margin: Some(MOTION_CHECK_MARGIN),
            appearance_growth: None,
            slow_evidence: Some(SlowEvidenceConfig::default()),
        }
    }
}

/// Default `motion_check_margin`. Measured (docs/accuracy.md): with correct motions
/// the motion's consistency minus identity's is ≥ −0.02 on every synthetic frame and ≥ −0.07 on
/// the real TUM / 7-Scenes frames; the two ground-truth glitches found there score −0.18 and
/// −0.23. 0.1 lies between.
const MOTION_CHECK_MARGIN: f32 = 0.1;

/// Default `prune_exit_margin_px`: the Kinect leaves a few invalid pixels along the border and
/// the prediction never writes the outermost ring, so a leaving object's remainder ends a few
/// pixels inside the image; 8 px covers that with room for the warp's rounding.
const EXIT_MARGIN_PX: usize = 8;

/// Default `exit_min_object_fraction`: a quarter of the minimum object size (125 px at VGA).
/// Measured on the synthetic failure classes at 320×240 (offline, DVO; docs/method.md D23): the
/// box entering the view at the desk's corner is half found at frame 9 instead of 11 with 0.25
/// or 0.1, at frame 10 with 0.5; no other class moves by more than 0.001 in F1.
const EXIT_MIN_OBJECT_FRACTION: f32 = 0.25;

/// Default `thin_structure_reconnect_px`. Measured (docs/method.md D25): on people walking past
/// the camera (Bonn "crowd", offline at 320×240) the masks' F1 went 0.858 → 0.929 with 2 px and
/// 0.940 with 4 px, the closed loop's ATE 0.041 → 0.041 m and 0.044 m; the opening off entirely
/// scored 0.944 but drifted (0.264 m). Static recordings: 7-Scenes offline unchanged (mean
/// 0.049 %, max 0.574 %), TUM with DVO 0 %, TUM with ground-truth poses max 0.678 → 0.917 %.
const THIN_STRUCTURE_RECONNECT_PX: usize = 2;

/// Default `invalid_depth_gap_px_vga`: the invalid band structured-light sensors leave along
/// the image border is 10–29 px wide at VGA on the TUM and Bonn recordings (the median run from
/// each border); 32 px spans it.
const INVALID_DEPTH_GAP_PX_VGA: usize = 32;

impl OcclusionConfig {
    /// Checks every parameter.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the first bad parameter.
    pub fn validate(&self) -> Result<()> {
        let positive = Error::require_finite_positive;
        positive("alpha", self.alpha)?;
        positive("beta", self.beta)?;
        positive("prediction_depth_gate_m", self.prediction_depth_gate_m)?;
        if !(0.0..1.0).contains(&self.sub_threshold_retention) {
            return Err(Error::InvalidParameter {
                name: "sub_threshold_retention",
                value: self.sub_threshold_retention.to_string(),
                expected: "a fraction in [0, 1)".into(),
            });
        }
        if !(self.exit_min_object_fraction > 0.0 && self.exit_min_object_fraction <= 1.0) {
            return Err(Error::InvalidParameter {
                name: "exit_min_object_fraction",
                value: self.exit_min_object_fraction.to_string(),
                expected: "a fraction in (0, 1]".into(),
            });
        }
        if let Some(margin) = self.motion_check_margin {
            positive("motion_check_margin", margin)?;
        }
        if let Some(growth) = &self.appearance_growth {
            growth.validate()?;
        }
        if let Some(slow) = &self.slow_evidence {
            slow.validate()?;
        }
        Ok(())
    }

    /// Minimum object component size for an image of `size` (500 px × area / VGA area, ≥ 1).
    pub fn min_object_pixels(&self, size: ImageSize) -> usize {
        scaled_pixels(self.min_object_pixels_vga, size)
    }

    /// [`Self::invalid_depth_gap_px_vga`] for an image of `size` (scaled with its width; 0 stays
    /// 0, otherwise at least 1).
    pub fn invalid_depth_gap_px(&self, size: ImageSize) -> usize {
        if self.invalid_depth_gap_px_vga == 0 {
            return 0;
        }
        ((self.invalid_depth_gap_px_vga * size.width) as f64 / 640.0)
            .round()
            .max(1.0) as usize
    }

    /// τ for depth `z_m` with coefficient `coefficient` in this config's form.
    #[inline]
    pub fn threshold(&self, coefficient: f32, z_m: f32) -> f32 {
        match self.threshold_form {
            ThresholdForm::Linear => coefficient * z_m,
            ThresholdForm::Quadratic => coefficient * z_m * z_m,
        }
    }
}
