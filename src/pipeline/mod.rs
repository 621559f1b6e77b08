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

mod config;
mod frame;
pub mod offline;
mod reduce;
mod sequence;

use std::time::Instant;

use nalgebra::Isometry3;

use crate::dvo::completion::IgnoreCompletion;
use crate::dvo::{DvoConfig, DvoStatus, DvoTracker};
use crate::error::{Error, Result};
use crate::geometry::se3::{is_finite_pose, rotation_angle_rad};
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, GrayF32, ImageSize, Mask};
use crate::occlusion::bodies::BodyCompletion;
use crate::occlusion::OcclusionDetector;
use crate::simd::{simd_kernel, Simd};
pub use config::{
    FailurePolicy, PoseSource, ProcessingMode, ProcessorConfig, DEFAULT_MAX_ANGULAR_SPEED_RADPS,
    DEFAULT_MAX_CONSTANT_VELOCITY_FRAMES, DEFAULT_MAX_COST_RATIO, DEFAULT_MAX_SPEED_MPS,
    DEFAULT_MIN_GRAY_RANGE, DEFAULT_MIN_INLIER_FRACTION, DEFAULT_MIN_VALID_DEPTH_FRACTION,
};
pub use frame::{
    DvoSummary, FrameInput, FrameOutput, FrameResult, FrameStats, Implausible, PoseFallback, PoseOutcome,
};
pub use sequence::SequenceProcessor;

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
    /// The published mask's completion to bodies and its output (None when it is off).
    bodies: Option<(BodyCompletion, Mask)>,
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
    let valid = count_valid_depth(Simd::detect(), depth_m.as_slice());
    valid as f64 / depth_m.size().area().max(1) as f64
}

#[inline(always)]
fn count_valid_depth_generic(depth_m: &[f32]) -> usize {
    depth_m.iter().filter(|d| d.is_finite() && **d > 0.0).count()
}

simd_kernel!(
    count_valid_depth,
    count_valid_depth_avx2,
    count_valid_depth_generic,
    (depth_m: &[f32]) -> usize
);

/// max − min of the gray image (0 for a flat image; NaN pixels are ignored).
fn gray_range(gray: &GrayF32) -> f32 {
    let (lo, hi) = gray_bounds(Simd::detect(), gray.as_slice());
    (hi - lo).max(0.0)
}

#[inline(always)]
fn gray_bounds_generic(gray: &[f32]) -> (f32, f32) {
    gray.iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &g| {
            (lo.min(g), hi.max(g))
        })
}

simd_kernel!(
    gray_bounds,
    gray_bounds_avx2,
    gray_bounds_generic,
    (gray: &[f32]) -> (f32, f32)
);

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
            PoseSource::DvoClosedLoop => MotionSource::Dvo {
                tracker: Box::new(DvoTracker::new(size, intrinsics, config.dvo)?),
                closed_loop: true,
            },
            // The paper's baseline tracks frame to frame.
            PoseSource::DvoUnmasked => MotionSource::Dvo {
                tracker: Box::new(DvoTracker::new(
                    size,
                    intrinsics,
                    DvoConfig {
                        keyframe: None,
                        ..config.dvo
                    },
                )?),
                closed_loop: false,
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
            bodies: config
                .body_completion
                .map(|c| BodyCompletion::new(size, c).map(|b| (b, Mask::filled(size, 0))))
                .transpose()?,
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
                let use_mask = *closed_loop && mask_on_reference;
                let (ignore, detector) = (&mut self.ignore, &self.detector);
                // The completion runs beside the new frame's pyramid.
                let estimate = tracker.track_with(
                    frame.gray,
                    frame.depth_m,
                    move || {
                        if !use_mask {
                            return Ok(None);
                        }
                        if let Some(extra) = frame.ignore_in_previous {
                            check_size("ignore_in_previous", extra.size(), size)?;
                        }
                        ignore
                            .build(
                                detector.odometry_mask(),
                                frame.ignore_in_previous,
                                detector.compensated_depth_m(),
                            )
                            .map(Some)
                    },
                    None,
                )?;
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
        // Pixels the body completion added to the published mask.
        let mut completed_pixels = 0;
        let (mask, odometry_mask, accumulation_m) = if no_depth {
            self.detector_skipped = self.detector_skipped.saturating_add(1);
            (&self.empty_mask, &self.empty_mask, &self.zero_accumulation_m)
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
            let mask = match &mut self.bodies {
                Some((bodies, completed)) => {
                    completed.copy_from(self.detector.mask())?;
                    completed_pixels = bodies.complete(completed, frame.depth_m)?.added_pixels;
                    &*completed
                }
                None => self.detector.mask(),
            };
            (
                mask,
                self.detector.odometry_mask(),
                self.detector.accumulation_m(),
            )
        };
        stats.detector_us = detect_started.elapsed().as_micros() as u64;
        if let MotionSource::Dvo { tracker, .. } = &mut self.source {
            // The keyframe follows the detector's own mask: the body completion changes what is
            // published, never the odometry.
            let detector_moving_fraction = stats.detector.mask_pixels as f64 / size.area().max(1) as f64;
            let detector_frames = self.detector.frames_processed();
            if tracker.config().keyframe.is_some_and(|k| {
                detector_moving_fraction > k.max_moving_fraction || detector_frames < k.min_detector_frames
            }) {
                tracker.end_keyframe();
            }
        }
        stats.detector.mask_pixels += completed_pixels;
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
            odometry_mask,
            current_from_previous,
            world_from_camera,
            accumulation_m,
            stats,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every build of the frame checks' two scans against a per-pixel loop, over invalid depths
    /// (NaN, ±∞, 0, negative) and NaN gray, on a length that is no multiple of a vector.
    #[test]
    fn every_build_of_the_frame_scans_agrees_with_a_per_pixel_loop() {
        let depth_m: Vec<f32> = (0..1001)
            .map(|i| match i % 7 {
                0 => f32::NAN,
                1 => -1.0,
                2 => 0.0,
                3 => f32::INFINITY,
                k => k as f32 * 0.5,
            })
            .collect();
        let gray: Vec<f32> = (0..1001)
            .map(|i| {
                if i % 11 == 0 {
                    f32::NAN
                } else {
                    ((i * 37) % 101) as f32 / 100.0 + 0.005
                }
            })
            .collect();
        let mut valid = 0;
        for &z in &depth_m {
            if z.is_finite() && z > 0.0 {
                valid += 1;
            }
        }
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for &g in gray.iter().filter(|g| !g.is_nan()) {
            lo = if g < lo { g } else { lo };
            hi = if g > hi { g } else { hi };
        }
        assert!(valid > 400 && lo > 0.0 && hi > 0.9, "{valid} {lo} {hi}");
        for simd in Simd::available() {
            assert_eq!(count_valid_depth(simd, &depth_m), valid, "{simd:?}");
            assert_eq!(gray_bounds(simd, &gray), (lo, hi), "{simd:?}");
        }
    }
}
