//! Per-sequence processing: camera motion (DVO or an external pose) + occlusion-accumulation
//! moving-object masks, frame by frame (algorithm.md §1).
//!
//! A [`Processor`] owns the pose source's state (a [`DvoTracker`] or the last external pose), the
//! [`OcclusionDetector`] and every scratch buffer, so [`Processor::process`] allocates nothing
//! after the first frame. Frames must be given in time order.
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
//!     })?;
//!     assert_eq!(output.mask.size(), config.size);
//! }
//! # Ok::<(), occmask::Error>(())
//! ```

use std::time::Instant;

use nalgebra::Isometry3;

use crate::dvo::{DvoConfig, DvoStatus, DvoTracker, MAX_DVO_LEVELS};
use crate::error::{Error, Result};
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, GrayF32, ImageSize, Mask};
use crate::occlusion::{OcclusionConfig, OcclusionDetector, OcclusionStats};

/// Where the camera motion comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PoseSource {
    /// DVO with the previous mask as its ignore mask (the paper's closed loop).
    DvoClosedLoop(DvoConfig),
    /// DVO without mask feedback.
    DvoUnmasked(DvoConfig),
    /// An external `world_from_marker` pose given with every frame.
    External {
        /// Fixed pose of the marker in the camera frame (`None` = the marker is the camera).
        camera_from_marker: Option<Isometry3<f64>>,
    },
}

/// Configuration of a [`Processor`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProcessorConfig {
    /// Detector parameters.
    pub occlusion: OcclusionConfig,
    /// Pose source.
    pub pose_source: PoseSource,
}

impl Default for ProcessorConfig {
    /// The paper's closed loop with default DVO and detector parameters.
    fn default() -> Self {
        Self {
            occlusion: OcclusionConfig::default(),
            pose_source: PoseSource::DvoClosedLoop(DvoConfig::default()),
        }
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
}

/// DVO's report for one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DvoSummary {
    /// Converged or why it failed (on failure the previous frame's motion is used again).
    pub status: DvoStatus,
    /// LM iterations per level (0 = full resolution).
    pub iterations_per_level: [u32; MAX_DVO_LEVELS],
    /// Final robust cost per reference point.
    pub final_cost: f64,
    /// Reference points with non-zero weight at the final pose.
    pub pixels_used: usize,
}

/// Per-frame statistics.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FrameStats {
    /// DVO's report (`None` for external poses and the first frame).
    pub dvo: Option<DvoSummary>,
    /// The detector's counts and per-stage times.
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
    /// Moving-object mask.
    pub mask: &'a Mask,
    /// Motion from the previous frame (identity for the first frame).
    pub current_from_previous: Isometry3<f64>,
    /// Camera pose: chained DVO motions from identity at the first frame, or the external pose.
    pub world_from_camera: Isometry3<f64>,
    /// The detector's accumulation map A (m), for debugging views.
    pub accumulation_m: &'a DepthMeters,
    /// Statistics.
    pub stats: FrameStats,
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
    frames: u64,
    world_from_camera: Isometry3<f64>,
    last_motion: Isometry3<f64>,
}

impl Processor {
    /// A processor for `size` frames seen through `intrinsics`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for invalid detector or DVO parameters, intrinsics or size.
    pub fn new(size: ImageSize, intrinsics: PinholeIntrinsics, config: ProcessorConfig) -> Result<Self> {
        let detector = OcclusionDetector::new(size, intrinsics, config.occlusion)?;
        let source = match config.pose_source {
            PoseSource::DvoClosedLoop(dvo) | PoseSource::DvoUnmasked(dvo) => MotionSource::Dvo {
                tracker: Box::new(DvoTracker::new(size, intrinsics, dvo)?),
                closed_loop: matches!(config.pose_source, PoseSource::DvoClosedLoop(_)),
            },
            PoseSource::External { camera_from_marker } => MotionSource::External {
                marker_from_camera: camera_from_marker.map_or_else(Isometry3::identity, |c| c.inverse()),
            },
        };
        Ok(Self {
            source,
            detector,
            frames: 0,
            world_from_camera: Isometry3::identity(),
            last_motion: Isometry3::identity(),
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
        self.last_motion = Isometry3::identity();
    }

    /// The detector (for its maps and configuration).
    pub fn detector(&self) -> &OcclusionDetector {
        &self.detector
    }

    /// Processes the next frame.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when an image is not the processor's size;
    /// [`Error::InvalidParameter`] when an external pose is required but missing or not finite.
    pub fn process(&mut self, frame: &FrameInput<'_>) -> Result<FrameOutput<'_>> {
        let started = Instant::now();
        let mut stats = FrameStats::default();
        let first = self.frames == 0;
        let current_from_previous = match &mut self.source {
            MotionSource::Dvo { tracker, closed_loop } => {
                let ignore = (*closed_loop && !first).then(|| self.detector.mask());
                let estimate = tracker.track(frame.gray, frame.depth_m, ignore, None)?;
                match estimate {
                    None => Isometry3::identity(),
                    Some(estimate) => {
                        stats.dvo = Some(DvoSummary {
                            status: estimate.status,
                            iterations_per_level: estimate.iterations_per_level,
                            final_cost: estimate.final_cost,
                            pixels_used: estimate.pixels_used,
                        });
                        if estimate.is_converged() {
                            estimate.current_from_reference
                        } else {
                            // Constant-velocity fallback: at 30 Hz the previous motion is a far
                            // better guess than identity for a moving camera.
                            self.last_motion
                        }
                    }
                }
            }
            MotionSource::External { marker_from_camera } => {
                let world_from_marker = frame.world_from_marker.ok_or_else(|| Error::InvalidParameter {
                    name: "world_from_marker",
                    value: format!(
                        "missing for frame {} (t = {} ns)",
                        self.frames, frame.timestamp_ns
                    ),
                    expected: "an external pose for every frame with PoseSource::External".into(),
                })?;
                let finite = world_from_marker.translation.vector.iter().all(|v| v.is_finite())
                    && world_from_marker.rotation.coords.iter().all(|v| v.is_finite());
                if !finite {
                    return Err(Error::InvalidParameter {
                        name: "world_from_marker",
                        value: format!("{world_from_marker:?}"),
                        expected: "a finite pose".into(),
                    });
                }
                let world_from_camera = world_from_marker * *marker_from_camera;
                let motion = if first {
                    Isometry3::identity()
                } else {
                    world_from_camera.inverse() * self.world_from_camera
                };
                self.world_from_camera = world_from_camera;
                motion
            }
        };
        if matches!(self.source, MotionSource::Dvo { .. }) && !first {
            // C_{i+1} = C_i · (current_from_previous)⁻¹ (algorithm.md §0).
            self.world_from_camera *= current_from_previous.inverse();
        }
        self.last_motion = current_from_previous;
        stats.pose_us = started.elapsed().as_micros() as u64;

        let detect_started = Instant::now();
        self.detector.update(frame.depth_m, &current_from_previous)?;
        stats.detector_us = detect_started.elapsed().as_micros() as u64;
        stats.detector = *self.detector.stats();
        stats.moving_fraction = stats.detector.mask_pixels as f64 / self.detector.size().area() as f64;
        stats.total_us = started.elapsed().as_micros() as u64;
        let index = self.frames;
        self.frames += 1;
        Ok(FrameOutput {
            index,
            timestamp_ns: frame.timestamp_ns,
            mask: self.detector.mask(),
            current_from_previous,
            world_from_camera: self.world_from_camera,
            accumulation_m: self.detector.accumulation_m(),
            stats,
        })
    }
}
