//! Per-sequence processing: camera motion (DVO or an external pose) + occlusion-accumulation
//! moving-object masks, frame by frame (docs/method.md).
//!
//! A [`Processor`] owns the pose source's state (a [`DvoTracker`] or the last external pose), the
//! [`OcclusionDetector`] and every scratch buffer, so with external poses [`Processor::process`]
//! allocates nothing after the first frame (`tests/detector_alloc.rs`); with DVO poses the
//! tracker still allocates now and then. Frames must be given in time order.
//!
//! Pose sources ([`PoseSource`]):
//! * [`PoseSource::DvoClosedLoop`]: the paper's loop. DVO estimates `current_from_previous` with
//!   the previous frame's mask as its ignore mask (moving pixels of the reference frame are left
//!   out, dilated per [`DvoConfig::ignore_dilation_radius_px`]); the detector then uses that motion.
//! * [`PoseSource::DvoUnmasked`]: the same DVO without the mask ("robust DVO" baseline).
//! * [`PoseSource::External`]: a `world_from_marker` pose per frame (motion capture, ground truth);
//!   `world_from_camera = world_from_marker · marker_from_camera`, with the optional fixed
//!   `camera_from_marker` calibration for markers that are not at the optical centre.
//!
//! # Failure modes
//!
//! Every frame gets a [`PoseOutcome`] and the pipeline never outputs NaN (poses, masks, the A
//! map and statistics are finite whatever the input). Per frame, in order:
//!
//! 1. **No depth** (valid-depth fraction below [`FailurePolicy::min_valid_depth_fraction`],
//!    e.g. a sensor blackout): neither DVO nor the detector sees the frame; the mask is empty,
//!    A reads as zero, outcome [`PoseOutcome::NoDepth`]. Both keep their state, so the first
//!    frame after the blackout is tracked against the last one before it.
//! 2. **No texture** (gray max − min below [`FailurePolicy::min_gray_range`]: black, saturated,
//!    covered): DVO does not see it ([`PoseOutcome::NoTexture`]); the detector runs with the
//!    fallback motion.
//! 3. Otherwise DVO runs. A **failure** ([`DvoStatus::Failed`]: degenerate, too few pixels,
//!    non-finite) gives [`PoseOutcome::DvoFailed`]. A **converged** motion must also pass the
//!    plausibility checks ([`Implausible`]): finite; translation ≤ [`FailurePolicy::max_speed_mps`]
//!    and rotation ≤ [`FailurePolicy::max_angular_speed_radps`] times the time since DVO's
//!    reference (clamped to [1/30 s, 1 s]); ≥ [`FailurePolicy::min_inlier_fraction`] of the
//!    reference points still weighted; final cost ≤ [`FailurePolicy::max_cost_ratio`] × (1 +
//!    frames skipped since the reference) × the median of the last 15 accepted costs. Else
//!    [`PoseOutcome::Rejected`].
//!
//! **Pose fallback** for every untrusted frame (no depth, no texture, failed, rejected): the last
//! trusted inter-frame motion (constant velocity, [`PoseFallback::ConstantVelocity`]) for up to
//! [`FailurePolicy::max_constant_velocity_frames`] consecutive frames (5 = 1/6 s at 30 Hz), then
//! identity ([`PoseFallback::Hold`]: the camera is assumed still rather than extrapolated). When
//! DVO tracks again after skipped frames, the new pose is its reference's pose composed with
//! the motion bridged over the gap (the held pose catches up in one step).
//!
//! **Detector state**: kept through no-texture and failed frames while on constant velocity
//! (the geometry is intact, only the pose is uncertain; measured: masks stay at F1 ≥ 0.98
//! through 4 black colour frames) and across a blackout that DVO bridges (F1 0.99 on the first
//! frame after a 4- or 10-frame blackout, against 0.17 rising to 0.89 over 8 frames after a
//! reset). It is **reset** (the frame starts a new accumulation; its mask is empty;
//! `detector_reset` in the stats) after a rejected motion or DVO's `PoorFit` failure (a jump:
//! keeping A would flag the whole new view), when the fallback reaches `Hold`, and when DVO cannot bridge a blackout.
//! [`FailurePolicy::reset_detector_after_gap`] also resets it after every blackout.
//! With [`PoseSource::External`] only the no-depth rule applies.
//!
//! # Example
//! ```
//! use occmask::image_buf::ImageSize;
//! use occmask::pipeline::{FrameInput, PoseSource, Processor, ProcessorConfig};
//! use occmask::synthetic::{Scenario, SequenceConfig, SyntheticSequence};
//! let config = SequenceConfig { size: ImageSize::new(160, 120), ..SequenceConfig::default() };
//! let sequence = SyntheticSequence::new(Scenario::SmallObjectCrossing, config);
//! let processor_config = ProcessorConfig {
//!     pose_source: PoseSource::External { camera_from_marker: None },
//!     ..ProcessorConfig::default()
//! };
//! let mut processor = Processor::new(config.size, config.intrinsics(), processor_config)?;
//! for i in 0..5 {
//!     let frame = sequence.frame(i);
//!     let output = processor.process(&FrameInput {
//!         timestamp_ns: frame.timestamp_ns,
//!         gray: &frame.gray,
//!         depth_m: &frame.depth_m,
//!         world_from_marker: Some(&frame.world_from_camera),
//!         ignore_in_previous: None,
//!     })?;
//!     assert_eq!(output.mask.size(), config.size);
//! }
//! # Ok::<(), occmask::Error>(())
//! ```

pub mod offline;

use std::time::Instant;

use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

use crate::dvo::completion::{IgnoreCompletion, IgnoreCompletionConfig};
use crate::dvo::{DvoConfig, DvoFailure, DvoStatus, DvoTracker, MAX_DVO_LEVELS};
use crate::error::{Error, Result};
use crate::geometry::se3::{is_finite_pose, rotation_angle_rad};
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, GrayF32, ImageSize, Mask};
use crate::occlusion::{OcclusionConfig, OcclusionDetector, OcclusionStats};
use offline::OfflineConfig;

/// Where the camera motion comes from.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum PoseSource {
    /// DVO ([`ProcessorConfig::dvo`]) with the previous mask as its ignore mask (the paper's
    /// closed loop).
    #[default]
    DvoClosedLoop,
    /// DVO without mask feedback.
    DvoUnmasked,
    /// An external `world_from_marker` pose given with every frame.
    External {
        /// Fixed pose of the marker in the camera frame (`None` = the marker is the camera).
        camera_from_marker: Option<Isometry3<f64>>,
    },
}

impl PoseSource {
    /// The name on the command line (`--pose`), in `/occmask/stats` and in the `occmask.process`
    /// metadata: `dvo`, `dvo-unmasked` or `external`.
    pub fn as_str(&self) -> &'static str {
        match self {
            PoseSource::DvoClosedLoop => "dvo",
            PoseSource::DvoUnmasked => "dvo-unmasked",
            PoseSource::External { .. } => "external",
        }
    }

    /// Whether the poses come with the frames (no DVO runs).
    pub fn is_external(&self) -> bool {
        matches!(self, PoseSource::External { .. })
    }
}

/// Below this fraction of pixels with valid depth a frame is treated as a sensor blackout:
/// neither DVO nor the detector sees it. 2 % of 640×480 is 6 100 pixels, six times DVO's
/// default `min_usable_pixels` (1 000 at the finest level), so a frame that passes can still
/// be tracked; a covered lens or a saturated depth sensor leaves well under 1 %.
pub const DEFAULT_MIN_VALID_DEPTH_FRACTION: f64 = 0.02;
/// Consecutive frames without a trusted motion that are bridged with the last trusted
/// motion (constant velocity); after that the camera is held still (identity). 5 frames is
/// 1/6 s at 30 Hz: long enough to bridge a dropped or textureless frame or two, short enough
/// that a stale velocity cannot carry the trajectory far (a 1 m/s camera drifts ≤ 17 cm).
pub const DEFAULT_MAX_CONSTANT_VELOCITY_FRAMES: u32 = 5;
/// Fastest plausible camera translation: 3 m/s (a brisk walk with a hand-held camera; TUM
/// RGB-D's fastest hand-held sequences stay under 1 m/s). At 30 Hz: 10 cm per frame.
pub const DEFAULT_MAX_SPEED_MPS: f64 = 3.0;
/// Fastest plausible camera rotation: 270 °/s (TUM fr1/360 peaks near 100 °/s; a quick
/// head turn is ~200 °/s). At 30 Hz: 9° per frame, about DVO's basin with 4 pyramid levels.
pub const DEFAULT_MAX_ANGULAR_SPEED_RADPS: f64 = 270.0 * std::f64::consts::PI / 180.0;
/// Smallest fraction of DVO's reference points that must still carry weight at the final pose.
pub const DEFAULT_MIN_INLIER_FRACTION: f64 = 0.25;
/// A converged cost this many times the median of the recent accepted costs is rejected.
/// Measured on the synthetic scenarios at 640×480: legitimate frames reach 4.3 (the dominant
/// object growing to cover 92 % of the view raises the cost smoothly, 1.8e-4 → 9.5e-4 in 12
/// frames); a teleport gives ≈ 70, structureless noisy gray ≈ 80. 10 sits between them (a
/// false rejection is expensive: it resets the detector).
pub const DEFAULT_MAX_COST_RATIO: f64 = 10.0;
/// A gray image with less contrast than 4 gray levels (of 255) has no texture DVO could use
/// (its default gradient threshold is 4/255 per pixel): black, saturated or covered.
pub const DEFAULT_MIN_GRAY_RANGE: f32 = 4.0 / 255.0;
/// The frame interval assumed when stamps repeat or go backwards (for the plausibility
/// bounds): 1/30 s.
const MIN_PLAUSIBILITY_INTERVAL_S: f64 = 1.0 / 30.0;
/// The frame interval the plausibility bounds stop growing at (a gap in the recording of more
/// than 1 s is checked as if it were 1 s).
const MAX_PLAUSIBILITY_INTERVAL_S: f64 = 1.0;
/// Accepted costs remembered for the cost-ratio check (half a second at 30 Hz).
const COST_HISTORY: usize = 15;
/// Accepted costs needed before the cost-ratio check applies.
const MIN_COST_HISTORY: usize = 5;

/// What the pipeline does when a frame's motion cannot be trusted (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FailurePolicy {
    /// Frames with less valid depth than this fraction are skipped as a blackout.
    pub min_valid_depth_fraction: f64,
    /// Consecutive untrusted frames bridged with constant velocity before holding still.
    pub max_constant_velocity_frames: u32,
    /// Fastest plausible camera translation (m/s).
    pub max_speed_mps: f64,
    /// Fastest plausible camera rotation (rad/s).
    pub max_angular_speed_radps: f64,
    /// Smallest plausible fraction of DVO reference points used at the final pose.
    pub min_inlier_fraction: f64,
    /// Largest plausible ratio of the final cost to the median recent accepted cost.
    pub max_cost_ratio: f64,
    /// Gray images whose max − min is below this are flat (black, saturated, covered lens):
    /// DVO skips them.
    pub min_gray_range: f32,
    /// Reset the detector when tracking resumes after skipped (blackout) frames, even when
    /// DVO bridges the gap.
    pub reset_detector_after_gap: bool,
}

impl Default for FailurePolicy {
    fn default() -> Self {
        Self {
            min_valid_depth_fraction: DEFAULT_MIN_VALID_DEPTH_FRACTION,
            max_constant_velocity_frames: DEFAULT_MAX_CONSTANT_VELOCITY_FRAMES,
            max_speed_mps: DEFAULT_MAX_SPEED_MPS,
            max_angular_speed_radps: DEFAULT_MAX_ANGULAR_SPEED_RADPS,
            min_inlier_fraction: DEFAULT_MIN_INLIER_FRACTION,
            max_cost_ratio: DEFAULT_MAX_COST_RATIO,
            min_gray_range: DEFAULT_MIN_GRAY_RANGE,
            reset_detector_after_gap: false,
        }
    }
}

impl FailurePolicy {
    /// Checks every field.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the first bad field.
    pub fn validate(&self) -> Result<()> {
        let checks: [(&'static str, f64, bool, &str); 5] = [
            (
                "min_valid_depth_fraction",
                self.min_valid_depth_fraction,
                (0.0..=1.0).contains(&self.min_valid_depth_fraction),
                "a fraction in [0, 1]",
            ),
            (
                "max_speed_mps",
                self.max_speed_mps,
                self.max_speed_mps > 0.0,
                "a positive speed",
            ),
            (
                "max_angular_speed_radps",
                self.max_angular_speed_radps,
                self.max_angular_speed_radps > 0.0,
                "a positive angular speed",
            ),
            (
                "min_inlier_fraction",
                self.min_inlier_fraction,
                (0.0..=1.0).contains(&self.min_inlier_fraction),
                "a fraction in [0, 1]",
            ),
            (
                "max_cost_ratio",
                self.max_cost_ratio,
                self.max_cost_ratio >= 1.0,
                "a ratio ≥ 1",
            ),
        ];
        for (name, value, ok, expected) in checks {
            if !ok {
                return Err(Error::InvalidParameter {
                    name,
                    value: value.to_string(),
                    expected: expected.into(),
                });
            }
        }
        Ok(())
    }
}

/// Configuration of a [`Processor`].
///
/// Serialised (the `--config` JSON file of `occmask process`) as `{"dvo": …, "occlusion": …,
/// "failure": …}`, each field by field; missing fields take the default, unknown ones are an
/// error. The pose source is not part of the file: it comes from the caller (`--pose`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ProcessorConfig {
    /// Pose source (not serialised).
    #[serde(skip)]
    pub pose_source: PoseSource,
    /// DVO parameters (used by the DVO pose sources).
    pub dvo: DvoConfig,
    /// Detector parameters.
    pub occlusion: OcclusionConfig,
    /// Failure handling.
    pub failure: FailurePolicy,
    /// Depth-connected completion of DVO's ignore mask (the closed loop's previous mask grown
    /// over the rest of each object's depth-continuous surface, see
    /// [`crate::dvo::completion`]); `None` = the detector's mask as it is (the paper).
    pub ignore_completion: Option<IgnoreCompletionConfig>,
    /// Causal or offline processing (chooses between [`Processor`] and
    /// [`offline::OfflineProcessor`] where a caller offers both, as `occmask process` does).
    pub mode: ProcessingMode,
    /// The offline mode's parameters ([`offline::OfflineProcessor`]; unused by [`Processor`]).
    pub offline: OfflineConfig,
}

/// How a recording is processed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ProcessingMode {
    /// Forward, backward and refinement passes with a bounded look-ahead
    /// ([`offline::OfflineProcessor`]): the default for recordings.
    #[default]
    Offline,
    /// One forward pass, each frame's result from it and the frames before ([`Processor`]):
    /// what an online user gets.
    Causal,
}

impl ProcessingMode {
    /// `offline` or `causal`.
    pub fn as_str(self) -> &'static str {
        match self {
            ProcessingMode::Offline => "offline",
            ProcessingMode::Causal => "causal",
        }
    }
}

impl Default for ProcessorConfig {
    /// The closed loop with [`DvoConfig::closed_loop`], the default detector, failure policy and
    /// ignore-mask completion.
    fn default() -> Self {
        Self {
            pose_source: PoseSource::default(),
            dvo: DvoConfig::closed_loop(),
            occlusion: OcclusionConfig::default(),
            failure: FailurePolicy::default(),
            ignore_completion: Some(IgnoreCompletionConfig::default()),
            mode: ProcessingMode::default(),
            offline: OfflineConfig::default(),
        }
    }
}

impl ProcessorConfig {
    /// Checks the DVO, detector, failure-policy and completion parameters.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the first bad field.
    pub fn validate(&self) -> Result<()> {
        self.dvo.validate()?;
        self.occlusion.validate()?;
        if let Some(completion) = &self.ignore_completion {
            completion.validate()?;
        }
        self.offline.validate()?;
        self.failure.validate()
    }
}

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

enum MotionSource {
    Dvo {
        tracker: Box<DvoTracker>,
        closed_loop: bool,
    },
    External {
        marker_from_camera: Isometry3<f64>,
    },
}

/// Per-sequence processor (see the module docs).
pub struct Processor {
    source: MotionSource,
    detector: OcclusionDetector,
    policy: FailurePolicy,
    frames: u64,
    /// Pose of the latest output frame.
    world_from_camera: Isometry3<f64>,
    /// Pose and stamp of DVO's reference (the latest frame it tracked).
    world_from_dvo_reference: Isometry3<f64>,
    dvo_reference_ns: Option<u64>,
    /// Frames DVO skipped (no depth, no texture) since its reference.
    dvo_skipped: u32,
    /// Pose of the detector's previous frame.
    world_from_detector_reference: Isometry3<f64>,
    /// The last trusted motion between consecutive frames (constant-velocity fallback).
    last_good_motion: Isometry3<f64>,
    consecutive_failures: u32,
    /// Frames the detector skipped (no depth) since its previous frame.
    detector_skipped: u32,
    recent_costs: [f64; COST_HISTORY],
    recent_cost_count: usize,
    empty_mask: Mask,
    zero_accumulation_m: DepthMeters,
    /// DVO's ignore mask: the detector's mask (and the caller's) and their completion.
    ignore: IgnoreMask,
}

/// The closed loop's ignore mask and its completion state.
struct IgnoreMask {
    completion: Option<IgnoreCompletion>,
    /// The union of the detector's and the caller's masks.
    union: Mask,
    /// Its completion.
    completed: Mask,
}

impl IgnoreMask {
    /// The ignore mask for DVO from the detector's mask, the caller's extra mask and the
    /// reference frame's depth.
    fn build<'a>(
        &'a mut self,
        detector_mask: &'a Mask,
        extra: Option<&Mask>,
        depth_m: &DepthMeters,
    ) -> Result<&'a Mask> {
        let base = match extra {
            Some(extra) => {
                for ((u, &d), &e) in self
                    .union
                    .as_mut_slice()
                    .iter_mut()
                    .zip(detector_mask.as_slice())
                    .zip(extra.as_slice())
                {
                    *u = d | e;
                }
                &self.union
            }
            None => detector_mask,
        };
        match &mut self.completion {
            Some(completion) => {
                completion.complete(base, depth_m, &mut self.completed)?;
                Ok(&self.completed)
            }
            None if extra.is_some() => Ok(&self.union),
            None => Ok(detector_mask),
        }
    }
}

/// [`Error::SizeMismatch`] unless `found` is `expected`.
pub(crate) fn check_size(what: &str, found: ImageSize, expected: ImageSize) -> Result<()> {
    if found == expected {
        Ok(())
    } else {
        Err(Error::SizeMismatch {
            what: format!("pipeline {what}"),
            expected,
            found,
        })
    }
}

/// Fraction of pixels with finite positive depth.
pub(crate) fn valid_depth_fraction(depth_m: &DepthMeters) -> f64 {
    let valid = depth_m
        .as_slice()
        .iter()
        .filter(|d| d.is_finite() && **d > 0.0)
        .count();
    valid as f64 / depth_m.size().area().max(1) as f64
}

/// max − min of the gray image (0 for a flat image; NaN pixels are ignored).
fn gray_range(gray: &GrayF32) -> f32 {
    let (lo, hi) = gray
        .as_slice()
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &g| {
            (lo.min(g), hi.max(g))
        });
    (hi - lo).max(0.0)
}

impl Processor {
    /// A processor for `size` frames seen through `intrinsics`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for invalid detector, DVO or failure-policy parameters,
    /// intrinsics or size.
    pub fn new(size: ImageSize, intrinsics: PinholeIntrinsics, config: ProcessorConfig) -> Result<Self> {
        config.failure.validate()?;
        let detector = OcclusionDetector::new(size, intrinsics, config.occlusion)?;
        let source = match config.pose_source {
            PoseSource::DvoClosedLoop | PoseSource::DvoUnmasked => MotionSource::Dvo {
                tracker: Box::new(DvoTracker::new(size, intrinsics, config.dvo)?),
                closed_loop: config.pose_source == PoseSource::DvoClosedLoop,
            },
            PoseSource::External { camera_from_marker } => MotionSource::External {
                marker_from_camera: camera_from_marker.map_or_else(Isometry3::identity, |c| c.inverse()),
            },
        };
        Ok(Self {
            source,
            detector,
            policy: config.failure,
            frames: 0,
            world_from_camera: Isometry3::identity(),
            world_from_dvo_reference: Isometry3::identity(),
            dvo_reference_ns: None,
            dvo_skipped: 0,
            world_from_detector_reference: Isometry3::identity(),
            last_good_motion: Isometry3::identity(),
            consecutive_failures: 0,
            detector_skipped: 0,
            recent_costs: [0.0; COST_HISTORY],
            recent_cost_count: 0,
            empty_mask: Mask::filled(size, 0),
            zero_accumulation_m: DepthMeters::filled(size, 0.0),
            ignore: IgnoreMask {
                completion: config
                    .ignore_completion
                    .map(|c| IgnoreCompletion::new(size, c))
                    .transpose()?,
                union: Mask::filled(size, 0),
                completed: Mask::filled(size, 0),
            },
        })
    }

    /// Forgets the sequence (the next frame starts a new one).
    pub fn reset(&mut self) {
        self.detector.reset();
        if let MotionSource::Dvo { tracker, .. } = &mut self.source {
            tracker.reset();
        }
        self.frames = 0;
        self.world_from_camera = Isometry3::identity();
        self.world_from_dvo_reference = Isometry3::identity();
        self.dvo_reference_ns = None;
        self.dvo_skipped = 0;
        self.world_from_detector_reference = Isometry3::identity();
        self.last_good_motion = Isometry3::identity();
        self.consecutive_failures = 0;
        self.detector_skipped = 0;
        self.recent_cost_count = 0;
    }

    /// The detector (for its maps and configuration).
    pub fn detector(&self) -> &OcclusionDetector {
        &self.detector
    }

    /// The failure policy in use.
    pub fn failure_policy(&self) -> &FailurePolicy {
        &self.policy
    }

    fn median_recent_cost(&self) -> Option<f64> {
        let n = self.recent_cost_count.min(COST_HISTORY);
        if n < MIN_COST_HISTORY {
            return None;
        }
        let mut costs = self.recent_costs;
        let costs = &mut costs[..n];
        costs.sort_by(f64::total_cmp);
        Some(costs[n / 2])
    }

    /// The plausibility checks on a converged DVO motion over `interval_s` (see the module docs).
    ///
    /// The cost bound grows with the frames DVO skipped before this one (`skipped`): a motion
    /// bridged over a gap sees more occlusion and noise than one between consecutive frames.
    fn check_plausible(
        &self,
        summary: &DvoSummary,
        motion: &Isometry3<f64>,
        interval_s: f64,
        skipped: u32,
    ) -> Result<(), Implausible> {
        if !is_finite_pose(motion) || !summary.final_cost.is_finite() {
            return Err(Implausible::NonFinite);
        }
        let interval_s = interval_s.clamp(MIN_PLAUSIBILITY_INTERVAL_S, MAX_PLAUSIBILITY_INTERVAL_S);
        let translation_m = motion.translation.vector.norm();
        let limit_m = self.policy.max_speed_mps * interval_s;
        if translation_m > limit_m {
            return Err(Implausible::TooFast {
                translation_m,
                limit_m,
            });
        }
        let angle_rad = rotation_angle_rad(motion);
        let limit_rad = self.policy.max_angular_speed_radps * interval_s;
        if angle_rad > limit_rad {
            return Err(Implausible::TooFastRotation { angle_rad, limit_rad });
        }
        let fraction = summary.pixels_used as f64 / summary.reference_pixels.max(1) as f64;
        if fraction < self.policy.min_inlier_fraction {
            return Err(Implausible::FewInliers { fraction });
        }
        if let Some(median) = self.median_recent_cost() {
            let ratio = summary.final_cost / median.max(f64::MIN_POSITIVE);
            if ratio > self.policy.max_cost_ratio * (1.0 + f64::from(skipped)) {
                return Err(Implausible::HighCost { ratio });
            }
        }
        Ok(())
    }

    fn remember_cost(&mut self, cost: f64) {
        self.recent_costs[self.recent_cost_count % COST_HISTORY] = cost;
        self.recent_cost_count += 1;
    }

    /// The fallback motion for one more untrusted frame (counts it).
    fn fallback_motion(&mut self) -> (PoseFallback, Isometry3<f64>) {
        self.consecutive_failures = self.consecutive_failures.saturating_add(1);
        if self.consecutive_failures <= self.policy.max_constant_velocity_frames {
            (PoseFallback::ConstantVelocity, self.last_good_motion)
        } else {
            (PoseFallback::Hold, Isometry3::identity())
        }
    }

    /// Processes the next frame.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when an image is not the processor's size;
    /// [`Error::InvalidParameter`] when an external pose is required but missing or not finite.
    pub fn process(&mut self, frame: &FrameInput<'_>) -> Result<FrameOutput<'_>> {
        let started = Instant::now();
        let size = self.detector.size();
        check_size("gray image", frame.gray.size(), size)?;
        check_size("depth image", frame.depth_m.size(), size)?;
        let mut stats = FrameStats {
            valid_depth_fraction: valid_depth_fraction(frame.depth_m),
            ..FrameStats::default()
        };
        let no_depth = stats.valid_depth_fraction < self.policy.min_valid_depth_fraction;
        let no_texture = !no_depth && gray_range(frame.gray) < self.policy.min_gray_range;
        let previous_output_pose = self.world_from_camera;
        let interval_s = self
            .dvo_reference_ns
            .map_or(0.0, |t| frame.timestamp_ns.saturating_sub(t) as f64 * 1e-9);
        let detector_after_gap = self.detector_skipped > 0;

        // The new pose, and whether the detector keeps its state (false = reset).
        let world_from_camera;
        let mut keep_detector = true;
        match &mut self.source {
            MotionSource::External { marker_from_camera } => {
                let world_from_marker = frame.world_from_marker.ok_or_else(|| Error::InvalidParameter {
                    name: "world_from_marker",
                    value: format!(
                        "missing for frame {} (t = {} ns)",
                        self.frames, frame.timestamp_ns
                    ),
                    expected: "an external pose for every frame with PoseSource::External".into(),
                })?;
                if !is_finite_pose(world_from_marker) {
                    return Err(Error::InvalidParameter {
                        name: "world_from_marker",
                        value: format!("{world_from_marker:?}"),
                        expected: "a finite pose".into(),
                    });
                }
                world_from_camera = world_from_marker * *marker_from_camera;
                stats.outcome = if no_depth {
                    PoseOutcome::NoDepth
                } else {
                    PoseOutcome::External
                };
                keep_detector = !(detector_after_gap && self.policy.reset_detector_after_gap);
            }
            MotionSource::Dvo { .. } if no_depth || no_texture => {
                stats.outcome = if no_depth {
                    PoseOutcome::NoDepth
                } else {
                    PoseOutcome::NoTexture
                };
                let (fallback, motion) = self.fallback_motion();
                stats.pose_fallback = fallback;
                world_from_camera = previous_output_pose * motion.inverse();
                keep_detector = fallback != PoseFallback::Hold && !detector_after_gap;
            }
            MotionSource::Dvo { tracker, closed_loop } => {
                // DVO's ignore mask must live on its reference frame: the detector's latest
                // mask is that frame's only when the detector saw the same frame last.
                let mask_on_reference = self.detector.frames_processed() > 0 && self.dvo_skipped == 0;
                let ignore = if *closed_loop && mask_on_reference {
                    if let Some(extra) = frame.ignore_in_previous {
                        check_size("ignore_in_previous", extra.size(), size)?;
                    }
                    Some(self.ignore.build(
                        self.detector.mask(),
                        frame.ignore_in_previous,
                        self.detector.compensated_depth_m(),
                    )?)
                } else {
                    None
                };
                let estimate = tracker.track(frame.gray, frame.depth_m, ignore, None)?;
                match estimate {
                    None => {
                        stats.outcome = PoseOutcome::FirstFrame;
                        world_from_camera = previous_output_pose;
                    }
                    Some(estimate) => {
                        let summary = DvoSummary {
                            status: estimate.status,
                            iterations_per_level: estimate.iterations_per_level,
                            final_cost: if estimate.final_cost.is_finite() {
                                estimate.final_cost
                            } else {
                                0.0
                            },
                            pixels_used: estimate.pixels_used,
                            reference_pixels: estimate.reference_pixels,
                        };
                        stats.dvo = Some(summary);
                        let motion = estimate.current_from_reference;
                        stats.outcome = match estimate.status {
                            DvoStatus::Failed(reason) => PoseOutcome::DvoFailed(reason),
                            DvoStatus::Converged => {
                                match self.check_plausible(&summary, &motion, interval_s, self.dvo_skipped) {
                                    Ok(()) => PoseOutcome::Tracked,
                                    Err(why) => PoseOutcome::Rejected(why),
                                }
                            }
                        };
                        if stats.outcome == PoseOutcome::Tracked {
                            self.consecutive_failures = 0;
                            if self.dvo_skipped == 0 {
                                self.remember_cost(summary.final_cost);
                                self.last_good_motion = motion;
                            }
                            world_from_camera = self.world_from_dvo_reference * motion.inverse();
                            keep_detector = !(detector_after_gap && self.policy.reset_detector_after_gap);
                        } else {
                            let (fallback, fallback_motion) = self.fallback_motion();
                            stats.pose_fallback = fallback;
                            world_from_camera = previous_output_pose * fallback_motion.inverse();
                            // A failed DVO (no texture, too few pixels) leaves the geometry
                            // intact: the detector goes on with the fallback motion. A
                            // rejected estimate or a poor fit (the views do not match: a
                            // jump), a failure after a blackout, or a failure run long
                            // enough to hold the pose discards it.
                            keep_detector = !stats.outcome.views_disagree()
                                && !detector_after_gap
                                && fallback != PoseFallback::Hold;
                        }
                    }
                }
            }
        }
        if let MotionSource::Dvo { tracker, .. } = &mut self.source {
            // The tracker's constant-velocity prediction holds only for an accepted estimate
            // over one frame interval.
            if no_depth || no_texture || stats.outcome != PoseOutcome::Tracked || self.dvo_skipped > 0 {
                tracker.forget_motion();
            }
            if no_depth || no_texture {
                self.dvo_skipped = self.dvo_skipped.saturating_add(1);
            } else {
                self.world_from_dvo_reference = world_from_camera;
                self.dvo_reference_ns = Some(frame.timestamp_ns);
                self.dvo_skipped = 0;
            }
        }
        stats.consecutive_failures = self.consecutive_failures;
        stats.pose_us = started.elapsed().as_micros() as u64;

        let detect_started = Instant::now();
        let (mask, accumulation_m) = if no_depth {
            self.detector_skipped = self.detector_skipped.saturating_add(1);
            (&self.empty_mask, &self.zero_accumulation_m)
        } else {
            // The motion since the detector's previous frame.
            let current_from_reference = world_from_camera.inverse() * self.world_from_detector_reference;
            if !keep_detector && self.detector.frames_processed() > 0 {
                self.detector.reset();
                stats.detector_reset = true;
            }
            self.detector
                .update_with_gray(frame.depth_m, Some(frame.gray), &current_from_reference)?;
            stats.detector = *self.detector.stats();
            // The detector's motion check restarted it (a motion far worse than none).
            stats.detector_reset |= stats.detector.motion_rejected;
            self.world_from_detector_reference = world_from_camera;
            self.detector_skipped = 0;
            (self.detector.mask(), self.detector.accumulation_m())
        };
        stats.detector_us = detect_started.elapsed().as_micros() as u64;
        stats.moving_fraction = stats.detector.mask_pixels as f64 / size.area().max(1) as f64;
        self.world_from_camera = world_from_camera;
        let current_from_previous = if self.frames == 0 {
            Isometry3::identity()
        } else {
            world_from_camera.inverse() * previous_output_pose
        };
        stats.total_us = started.elapsed().as_micros() as u64;
        let index = self.frames;
        self.frames += 1;
        Ok(FrameOutput {
            index,
            timestamp_ns: frame.timestamp_ns,
            mask,
            current_from_previous,
            world_from_camera,
            accumulation_m,
            stats,
        })
    }
}
