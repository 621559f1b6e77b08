//! What goes into a [`Processor`](super::Processor) per frame and what comes out: the frame,
//! the pose outcome and fallback, the statistics and the mask.

use nalgebra::Isometry3;

use crate::dvo::{DvoFailure, DvoStatus, MAX_DVO_LEVELS};
use crate::image_buf::{DepthMeters, GrayF32, Mask};
use crate::occlusion::OcclusionStats;

#[cfg(doc)]
use super::{offline, FailurePolicy, PoseSource};

/// One RGB-D frame to process.
#[derive(Debug, Clone, Copy)]
pub struct FrameInput<'a> {
    /// Capture time (ns).
    pub timestamp_ns: u64,
    /// Gray image in [0, 1] (used by DVO).
    pub gray: &'a GrayF32,
    /// Depth in metres, 0 = invalid, registered to `gray`.
    pub depth_m: &'a DepthMeters,
    /// External pose of this frame; required by [`PoseSource::External`], ignored otherwise.
    pub world_from_marker: Option<&'a Isometry3<f64>>,
    /// Moving pixels of the previous frame known from elsewhere (the offline mode's look-ahead
    /// masks, [`offline`]): the closed loop's DVO ignores them as well as the detector's own
    /// mask. Ignored by the other pose sources and when DVO's reference is not the previous
    /// frame (frames skipped in between).
    pub ignore_in_previous: Option<&'a Mask>,
}

/// DVO's report for one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DvoSummary {
    /// Converged or why it failed.
    pub status: DvoStatus,
    /// LM iterations per level (0 = full resolution).
    pub iterations_per_level: [u32; MAX_DVO_LEVELS],
    /// Final robust cost per reference point (0 when DVO failed before computing it).
    pub final_cost: f64,
    /// Reference points with non-zero weight at the final pose.
    pub pixels_used: usize,
    /// Reference points (valid depth, not ignored) on the finest level used.
    pub reference_pixels: usize,
}

/// Why a motion DVO reported as converged was not believed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Implausible {
    /// The estimate is not finite.
    NonFinite,
    /// Translation beyond [`FailurePolicy::max_speed_mps`] × the frame interval.
    TooFast {
        /// Estimated translation (m).
        translation_m: f64,
        /// The bound (m).
        limit_m: f64,
    },
    /// Rotation beyond [`FailurePolicy::max_angular_speed_radps`] × the frame interval.
    TooFastRotation {
        /// Estimated rotation angle (rad).
        angle_rad: f64,
        /// The bound (rad).
        limit_rad: f64,
    },
    /// Too few reference points still carry weight.
    FewInliers {
        /// Used / reference points.
        fraction: f64,
    },
    /// The final cost is far above the recent accepted ones.
    HighCost {
        /// Final cost / median of recent accepted costs.
        ratio: f64,
    },
}

/// What the pipeline made of a frame's motion.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub enum PoseOutcome {
    /// The first frame with depth (the start of the trajectory).
    #[default]
    FirstFrame,
    /// DVO converged and the motion passed the plausibility checks.
    Tracked,
    /// The pose came from [`PoseSource::External`].
    External,
    /// DVO reported failure.
    DvoFailed(DvoFailure),
    /// DVO converged on a motion the plausibility checks reject.
    Rejected(Implausible),
    /// Too little valid depth (blackout): neither DVO nor the detector saw the frame.
    NoDepth,
    /// Depth but a flat gray image (black, saturated, lens covered): DVO did not see the
    /// frame, the detector did (with the fallback motion).
    NoTexture,
}

impl PoseOutcome {
    /// True when the frame's motion came from a fallback.
    pub fn is_failure(&self) -> bool {
        matches!(
            self,
            PoseOutcome::DvoFailed(_)
                | PoseOutcome::Rejected(_)
                | PoseOutcome::NoDepth
                | PoseOutcome::NoTexture
        )
    }

    /// Whether the outcome says the frame does not match its reference view (a rejected
    /// motion, or DVO's [`DvoFailure::PoorFit`]): a jump, after which the detector's
    /// accumulation no longer describes the scene and is reset.
    pub fn views_disagree(&self) -> bool {
        matches!(
            self,
            PoseOutcome::Rejected(_) | PoseOutcome::DvoFailed(DvoFailure::PoorFit { .. })
        )
    }

    /// A short stable name for logs and `/occmask/stats` (`converged`, `first_frame`,
    /// `external`, `failed_degenerate`, `failed_too_few_pixels`, `failed_non_finite`, `failed_poor_fit`,
    /// `rejected_non_finite`, `rejected_too_fast`, `rejected_too_fast_rotation`,
    /// `rejected_few_inliers`, `rejected_high_cost`, `no_depth`, `no_texture`).
    pub fn as_str(&self) -> &'static str {
        match self {
            PoseOutcome::FirstFrame => "first_frame",
            PoseOutcome::Tracked => "converged",
            PoseOutcome::External => "external",
            PoseOutcome::DvoFailed(DvoFailure::Degenerate { .. }) => "failed_degenerate",
            PoseOutcome::DvoFailed(DvoFailure::TooFewPixels { .. }) => "failed_too_few_pixels",
            PoseOutcome::DvoFailed(DvoFailure::NonFinite { .. }) => "failed_non_finite",
            PoseOutcome::DvoFailed(DvoFailure::PoorFit { .. }) => "failed_poor_fit",
            PoseOutcome::Rejected(Implausible::NonFinite) => "rejected_non_finite",
            PoseOutcome::Rejected(Implausible::TooFast { .. }) => "rejected_too_fast",
            PoseOutcome::Rejected(Implausible::TooFastRotation { .. }) => "rejected_too_fast_rotation",
            PoseOutcome::Rejected(Implausible::FewInliers { .. }) => "rejected_few_inliers",
            PoseOutcome::Rejected(Implausible::HighCost { .. }) => "rejected_high_cost",
            PoseOutcome::NoDepth => "no_depth",
            PoseOutcome::NoTexture => "no_texture",
        }
    }
}

/// The motion used when the frame's own could not be trusted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum PoseFallback {
    /// No fallback: the motion is the frame's own (tracked, external or first frame).
    #[default]
    None,
    /// The last trusted inter-frame motion, repeated.
    ConstantVelocity,
    /// Identity: the camera is assumed to stand still.
    Hold,
}

impl PoseFallback {
    /// `none`, `constant_velocity` or `hold` (as in `/occmask/stats`).
    pub fn as_str(self) -> &'static str {
        match self {
            PoseFallback::None => "none",
            PoseFallback::ConstantVelocity => "constant_velocity",
            PoseFallback::Hold => "hold",
        }
    }
}

/// Per-frame statistics.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FrameStats {
    /// DVO's report (`None` when DVO did not run: external poses, the first frame, no depth).
    pub dvo: Option<DvoSummary>,
    /// What the pipeline made of the motion.
    pub outcome: PoseOutcome,
    /// The fallback used for the motion.
    pub pose_fallback: PoseFallback,
    /// Frames in a row (this one included) whose motion was a fallback.
    pub consecutive_failures: u32,
    /// The detector's state was discarded at this frame (the frame starts a new accumulation
    /// and its mask is empty).
    pub detector_reset: bool,
    /// Fraction of pixels with valid depth.
    pub valid_depth_fraction: f64,
    /// The detector's counts and per-stage times (all zero when the detector skipped the frame).
    pub detector: OcclusionStats,
    /// Time spent obtaining the motion (DVO: pyramid + estimation), µs.
    pub pose_us: u64,
    /// Time spent in the detector, µs.
    pub detector_us: u64,
    /// Total processing time of the frame, µs.
    pub total_us: u64,
    /// Fraction of pixels in the mask.
    pub moving_fraction: f64,
}

/// The result of processing one frame (borrows the processor's buffers).
#[derive(Debug, Clone, Copy)]
pub struct FrameOutput<'a> {
    /// Frame index (0-based, since construction or reset).
    pub index: u64,
    /// Capture time (ns).
    pub timestamp_ns: u64,
    /// Moving-object mask (empty on frames without depth).
    pub mask: &'a Mask,
    /// What a closed loop's odometry ignores: the detector's mask without its slow-change
    /// evidence ([`crate::occlusion::OcclusionDetector::odometry_mask`]) and without the body
    /// completion ([`super::ProcessorConfig::body_completion`]).
    pub odometry_mask: &'a Mask,
    /// Motion from the previous frame's pose (identity for the first frame).
    pub current_from_previous: Isometry3<f64>,
    /// Camera pose: chained DVO motions from identity at the first frame, or the external pose.
    pub world_from_camera: Isometry3<f64>,
    /// The detector's accumulation map A (m), for debugging views (zero on frames without depth).
    pub accumulation_m: &'a DepthMeters,
    /// Statistics.
    pub stats: FrameStats,
}

/// A [`FrameOutput`] that owns its images, for callers that keep results beyond the next frame
/// (a processor that looks ahead returns them a block at a time; `occmask process` hands them to
/// its writer thread).
#[derive(Debug, Clone, PartialEq)]
pub struct FrameResult {
    /// Moving-object mask (255 = moving; empty on frames without depth).
    pub mask: Mask,
    /// Camera pose ([`FrameOutput::world_from_camera`]).
    pub world_from_camera: Isometry3<f64>,
    /// The accumulation map A (m), when the caller asked to keep it.
    pub accumulation_m: Option<DepthMeters>,
    /// Statistics.
    pub stats: FrameStats,
}

impl FrameOutput<'_> {
    /// The owned result, with a copy of the accumulation map if `keep_accumulation`.
    pub fn to_result(&self, keep_accumulation: bool) -> FrameResult {
        FrameResult {
            mask: self.mask.clone(),
            world_from_camera: self.world_from_camera,
            accumulation_m: keep_accumulation.then(|| self.accumulation_m.clone()),
            stats: self.stats,
        }
    }
}
