//! Offline processing of a recorded sequence: the causal pipeline ([`Processor`]) runs once
//! forward, the detector then runs backward in time over the same poses, and a second forward
//! pass refines the motion with both passes' masks.
//!
//! Occlusion accumulation only sees an object where it moves in front of something farther
//! away, so a causal detector finds an object late (an object in view from the first frame,
//! one that rests and then starts to move) and only at its leading edge. Run backward in time,
//! the same detector sees every object's *trailing* edge and its past: what it marks is where
//! the object will have been. For a recording both directions are available, and their union
//! covers objects from the first frame on and over more of their surface. With those masks the
//! closed loop's DVO ignores most of every moving object, which is what keeps the odometry
//! from following people who fill half the view (docs/method.md has the measurements).
//!
//! Passes, per block of [`OfflineConfig::block_frames`] frames with
//! [`OfflineConfig::lookahead_frames`] more frames buffered beyond it:
//! 1. **first pass** (as frames arrive): the causal pipeline, for the closed loop with DVO on a
//!    coarser finest level ([`OfflineConfig::first_pass_finest_level`]: its poses only seed the
//!    masks); the DVO baseline runs as it is; external poses need no first pass;
//! 2. **backward pass** (once the look-ahead is buffered): a fresh detector from the last
//!    buffered frame back to the block's first, with the first pass's poses;
//! 3. **refinement pass** (the block's frames in order): the pipeline again, for the closed loop
//!    with [`OfflineConfig::refinement_dvo`] ignoring the first pass's forward and backward masks
//!    of each frame's predecessor as well as its own; otherwise with the first pass's (or the
//!    external) poses. A frame's mask is the refinement pass's ∪ the backward pass's.
//!
//! Pass 1 of a new frame runs beside passes 2 and 3 of earlier ones, and the refinement of a
//! block's last half beside the backward pass of the next block (see [`OfflineProcessor`]).
//! Frames are emitted in order, a block's worth spread over the pushes until the next backward
//! pass has finished, so results lag the input by up to `block_frames + lookahead_frames` and
//! half a block more frames, and that many frames are buffered (gray as u16, depth as f32, two
//! masks: 2.4 MB per 640×480 frame).
//! Buffers are recycled: after the first block nothing is allocated per frame.

use std::collections::VecDeque;

use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

use super::{
    check_size, valid_depth_fraction, FrameInput, FrameOutput, PoseSource, Processor, ProcessorConfig,
};
use crate::dvo::{DvoConfig, MotionPriorConfig};
use crate::error::{Error, Result};
use crate::geometry::se3::is_finite_pose;
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, GrayF32, Image, ImageSize, Mask};
use crate::occlusion::{OcclusionConfig, OcclusionDetector};
use crate::pyramid::{downsample_depth_into, downsample_gray_into, level_size};

/// Parameters of the offline mode ([`OfflineProcessor`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OfflineConfig {
    /// Frames finished together (≥ 1).
    pub block_frames: usize,
    /// Frames beyond a block that the backward pass starts from: how far ahead it looks (an
    /// object resting at the block's end is found if it moves within this many frames).
    pub lookahead_frames: usize,
    /// The closed loop's first pass runs DVO down to this pyramid level only (0 = full
    /// resolution; never finer than the configured DVO's own finest level, never coarser than
    /// its coarsest).
    pub first_pass_finest_level: usize,
    /// The closed loop's first pass sees the frames halved this many times by 2×2 reduction
    /// (gray: box mean, depth: edge-aware), detector included; its masks are enlarged back
    /// (nearest pixel) to seed the refinement pass's ignore masks. 0 = full resolution. The
    /// first pass's poses and masks only seed the later passes, which run at full resolution.
    pub first_pass_halvings: usize,
    /// DVO of the closed loop's refinement pass.
    pub refinement_dvo: DvoConfig,
}

/// Default [`OfflineConfig::block_frames`]: 2 s at 30 Hz.
pub const DEFAULT_BLOCK_FRAMES: usize = 60;
/// Default [`OfflineConfig::lookahead_frames`]: 1 s at 30 Hz.
pub const DEFAULT_LOOKAHEAD_FRAMES: usize = 30;
/// Default [`OfflineConfig::first_pass_finest_level`]: 160×120 for VGA, a quarter of the
/// closed loop's finest level's pixels.
pub const DEFAULT_FIRST_PASS_FINEST_LEVEL: usize = 2;
/// Default [`OfflineConfig::first_pass_halvings`]: 320×240 for VGA. The first pass's DVO runs
/// at 160×120 either way; its detector costs a quarter, and the seeds it gives the refinement
/// pass are pooled to DVO's resolution and dilated there anyway (docs/method.md has the figures).
pub const DEFAULT_FIRST_PASS_HALVINGS: usize = 1;
/// The first pass is never reduced below this many pixels on its short side: VGA runs at
/// 320×240, smaller images at full resolution. At 160×120 the detector lost an object resting
/// and then moving slowly (the synthetic late-onset class at 320×240: F1 0.728 and onset 31
/// frames against 0.778 and 24 at full resolution).
const MIN_REDUCED_SIDE_PX: usize = 240;

impl Default for OfflineConfig {
    /// The refinement pass uses the paper's DVO weights with the motion prior: once the moving
    /// objects are masked, the photometric term is the more accurate one.
    fn default() -> Self {
        Self {
            block_frames: DEFAULT_BLOCK_FRAMES,
            lookahead_frames: DEFAULT_LOOKAHEAD_FRAMES,
            first_pass_finest_level: DEFAULT_FIRST_PASS_FINEST_LEVEL,
            first_pass_halvings: DEFAULT_FIRST_PASS_HALVINGS,
            refinement_dvo: DvoConfig {
                motion_prior: Some(MotionPriorConfig::default()),
                ..DvoConfig::paper()
            },
        }
    }
}

impl OfflineConfig {
    /// Checks every field.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the first bad field.
    pub fn validate(&self) -> Result<()> {
        if self.block_frames == 0 {
            return Err(Error::InvalidParameter {
                name: "offline.block_frames",
                value: "0".into(),
                expected: "at least 1".into(),
            });
        }
        self.refinement_dvo.validate()
    }
}

/// A frame waiting for its backward and refinement passes.
#[derive(Debug, Clone)]
struct Buffered {
    timestamp_ns: u64,
    /// Gray in units of 1/65535 (the refinement pass's input, to within 1e-5).
    gray: Image<u16>,
    depth_m: DepthMeters,
    world_from_marker: Option<Isometry3<f64>>,
    /// The first pass's camera pose (or the external camera pose).
    world_from_camera: Isometry3<f64>,
    /// The first pass's mask (closed loop only; empty otherwise).
    first_mask: Mask,
    /// The first pass discarded its detector's state at this frame (a jump from the previous).
    first_reset: bool,
    /// Enough valid depth for the detector (not a blackout).
    has_depth: bool,
    /// The backward pass's mask.
    backward_mask: Mask,
}

/// Where a frame's result goes: called in frame order, from whichever of the pool's threads
/// runs the refinement pass (hence `Send`).
pub type Emit<'e> = dyn FnMut(FrameOutput<'_>) -> Result<()> + Send + 'e;

/// Sequence processor of the offline mode (see the module docs).
///
/// Pass 1 is a chain over the frames as they arrive; the backward pass is a second chain over
/// the frames that pass 1 has finished, and the refinement a third over the frames that the
/// backward pass has finished. [`Self::push`] runs them side by side (`rayon::join`): the new
/// frame's pass 1, a share of the running backward pass and the refinement of a share of the
/// frames waiting for it. Every chain keeps its order, so the results are those of running the
/// passes one after the other; only the time differs (on one thread, `join` runs them in turn).
pub struct OfflineProcessor {
    config: OfflineConfig,
    first: FirstPass,
    later: LaterPasses,
}

/// Pass 1.
struct FirstPass {
    /// `None` with external poses.
    processor: Option<Processor>,
    /// The reduced frames when the pass runs at lower resolution.
    reduced: Option<Reduced>,
    source: PoseSource,
    /// External poses: the marker's pose in the camera.
    marker_from_camera: Isometry3<f64>,
    min_valid_depth_fraction: f64,
}

/// Passes 2 and 3, and the frames they work on. The two are separate chains (the backward
/// pass writes the backward masks of frames that the refinement has not reached yet), so they
/// run side by side: the refinement of the previous block's last frames beside the backward
/// pass of the next block.
struct LaterPasses {
    backward: BackwardPass,
    refinement: Refinement,
}

/// Pass 2 and the frames waiting for it.
struct BackwardPass {
    appearance_growth: bool,
    detector: OcclusionDetector,
    /// Frames after pass 1 whose backward pass has not run: the next block and its look-ahead
    /// (and the frames pushed while the pass runs).
    buffer: VecDeque<Buffered>,
    /// The pass in progress, if any.
    running: Option<BackwardRun>,
    /// Scratch: a buffered frame's gray as f32 (appearance growth).
    gray: GrayF32,
}

/// Where a backward pass has got to: it runs over `buffer[..end]` from the last frame back,
/// a few frames at a time ([`BackwardPass::step`]).
struct BackwardRun {
    /// Frames of `buffer[..end]` still to run: the next is `left - 1`.
    left: usize,
    /// The frames the pass covers.
    end: usize,
    /// The first `keep` frames keep their backward masks and go to the refinement.
    keep: usize,
    /// The pose of the detector's previous frame (the later one in time).
    reference: Option<Isometry3<f64>>,
}

/// Pass 3 and the frames waiting for it.
struct Refinement {
    source: PoseSource,
    refine: Processor,
    /// Frames after the backward pass, waiting for refinement (in order).
    ready: VecDeque<Buffered>,
    /// Recycled frame buffers.
    spare: Vec<Buffered>,
    size: ImageSize,
    /// Scratch: a buffered frame's gray as f32.
    gray: GrayF32,
    /// The emitted mask (refinement ∪ backward).
    mask: Mask,
    /// The first pass's forward ∪ backward mask of the last emitted frame (the next frame's
    /// `ignore_in_previous` in the closed loop's refinement pass).
    previous_seed_mask: Mask,
    has_previous_seed_mask: bool,
}

impl OfflineProcessor {
    /// An offline processor for `size` frames seen through `intrinsics`, with `config`'s pose
    /// source, DVO, detector, failure policy and [`ProcessorConfig::offline`] parameters.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for invalid parameters, intrinsics or size.
    pub fn new(size: ImageSize, intrinsics: PinholeIntrinsics, config: ProcessorConfig) -> Result<Self> {
        config.validate()?;
        let offline = config.offline;
        let mut reduced = None;
        let first = match config.pose_source {
            PoseSource::DvoClosedLoop => {
                let coarsest = config.dvo.levels_for(size).saturating_sub(1);
                let finest = offline
                    .first_pass_finest_level
                    .min(coarsest)
                    .max(config.dvo.finest_level);
                let halvings = usable_halvings(size, offline.first_pass_halvings);
                // The same pyramid levels in full-resolution terms, counted from the reduced
                // image.
                let dvo = DvoConfig {
                    levels: config.dvo.levels.saturating_sub(halvings).max(1),
                    finest_level: finest.saturating_sub(halvings),
                    ..config.dvo
                };
                reduced = Reduced::new(size, halvings);
                Some(Processor::new(
                    level_size(size, halvings),
                    intrinsics.at_level(halvings as u32),
                    ProcessorConfig {
                        dvo,
                        occlusion: reduced_occlusion_config(&config.occlusion, halvings),
                        ..config
                    },
                )?)
            }
            PoseSource::DvoUnmasked => Some(Processor::new(size, intrinsics, config)?),
            PoseSource::External { .. } => None,
        };
        let refine = match config.pose_source {
            PoseSource::DvoClosedLoop => ProcessorConfig {
                dvo: offline.refinement_dvo,
                ..config
            },
            // The DVO baseline's poses (camera poses) and external poses are replayed.
            PoseSource::DvoUnmasked => ProcessorConfig {
                pose_source: PoseSource::External {
                    camera_from_marker: None,
                },
                ..config
            },
            PoseSource::External { .. } => config,
        };
        let marker_from_camera = match config.pose_source {
            PoseSource::External {
                camera_from_marker: Some(c),
            } => c.inverse(),
            _ => Isometry3::identity(),
        };
        Ok(Self {
            config: offline,
            first: FirstPass {
                processor: first,
                reduced,
                source: config.pose_source,
                marker_from_camera,
                min_valid_depth_fraction: config.failure.min_valid_depth_fraction,
            },
            later: LaterPasses {
                backward: BackwardPass {
                    appearance_growth: config.occlusion.appearance_growth.is_some(),
                    detector: OcclusionDetector::new(size, intrinsics, config.occlusion)?,
                    buffer: VecDeque::new(),
                    running: None,
                    gray: GrayF32::filled(size, 0.0),
                },
                refinement: Refinement {
                    source: config.pose_source,
                    refine: Processor::new(size, intrinsics, refine)?,
                    ready: VecDeque::new(),
                    spare: Vec::new(),
                    size,
                    gray: GrayF32::filled(size, 0.0),
                    mask: Mask::filled(size, 0),
                    previous_seed_mask: Mask::filled(size, 0),
                    has_previous_seed_mask: false,
                },
            },
        })
    }

    /// Frames pushed but not yet emitted.
    pub fn pending_frames(&self) -> usize {
        self.later.backward.buffer.len() + self.later.refinement.ready.len()
    }

    /// Adds the next frame (frames in time order). Calls `emit` for every frame whose result
    /// is final now, in order: none until a block and its look-ahead are buffered, then a share
    /// of a block's frames at every push, so that a block is emitted by the time the next one's
    /// look-ahead is buffered.
    ///
    /// # Errors
    /// As [`Processor::process`], and whatever `emit` returns.
    pub fn push(&mut self, frame: &FrameInput<'_>, emit: &mut Emit<'_>) -> Result<()> {
        let size = self.later.refinement.size;
        check_size("gray image", frame.gray.size(), size)?;
        check_size("depth image", frame.depth_m.size(), size)?;
        let mut buffered = self
            .later
            .refinement
            .spare
            .pop()
            .unwrap_or_else(|| Buffered::new(size));
        let (first, later, config) = (&mut self.first, &mut self.later, &self.config);
        let (first_done, later_done) = rayon::join(
            || first.run(frame, &mut buffered),
            || later.work_beside_first_pass(config, emit),
        );
        later_done?;
        first_done?;
        self.later.backward.buffer.push_back(buffered);
        Ok(())
    }

    /// Finishes every buffered frame (the end of the sequence), calling `emit` for each.
    ///
    /// # Errors
    /// As [`Self::push`].
    pub fn finish(&mut self, emit: &mut Emit<'_>) -> Result<()> {
        while !self.finish_step(emit)? {}
        Ok(())
    }

    /// A step of [`Self::finish`]: calls `emit` for the next few frames (none while a backward
    /// pass has nothing to run beside it) and returns whether every frame has been emitted. A
    /// caller that writes each step's results before the next step writes while the remaining
    /// frames are processed.
    ///
    /// # Errors
    /// As [`Self::push`].
    pub fn finish_step(&mut self, emit: &mut Emit<'_>) -> Result<bool> {
        let later = &mut self.later;
        if later.backward.running.is_none() && !later.backward.buffer.is_empty() {
            later.backward.start(&self.config);
        }
        let refined = FINISH_STEP_FRAMES.min(later.refinement.ready.len());
        later.step(refined, emit)?;
        Ok(later.backward.buffer.is_empty() && later.refinement.ready.is_empty())
    }
}

impl Buffered {
    fn new(size: ImageSize) -> Self {
        Self {
            timestamp_ns: 0,
            gray: Image::filled(size, 0),
            depth_m: DepthMeters::filled(size, 0.0),
            world_from_marker: None,
            world_from_camera: Isometry3::identity(),
            first_mask: Mask::filled(size, 0),
            first_reset: false,
            has_depth: false,
            backward_mask: Mask::filled(size, 0),
        }
    }
}

impl FirstPass {
    /// Pass 1 for `frame`, into `buffered`.
    fn run(&mut self, frame: &FrameInput<'_>, buffered: &mut Buffered) -> Result<()> {
        buffered.timestamp_ns = frame.timestamp_ns;
        for (q, &g) in buffered.gray.as_mut_slice().iter_mut().zip(frame.gray.as_slice()) {
            *q = quantize_gray(g);
        }
        buffered
            .depth_m
            .as_mut_slice()
            .copy_from_slice(frame.depth_m.as_slice());
        buffered.world_from_marker = frame.world_from_marker.copied();
        buffered.has_depth = valid_depth_fraction(frame.depth_m) >= self.min_valid_depth_fraction;
        match &mut self.processor {
            Some(first) => {
                let (gray, depth_m) = match &mut self.reduced {
                    Some(reduced) => reduced.reduce(frame.gray, frame.depth_m)?,
                    None => (frame.gray, frame.depth_m),
                };
                let out = first.process(&FrameInput {
                    gray,
                    depth_m,
                    ignore_in_previous: None,
                    ..*frame
                })?;
                buffered.world_from_camera = out.world_from_camera;
                buffered.first_reset = out.stats.detector_reset;
                if self.source == PoseSource::DvoClosedLoop {
                    copy_or_enlarge_mask(out.mask, &mut buffered.first_mask);
                }
            }
            None => {
                let marker = frame.world_from_marker.ok_or_else(|| Error::InvalidParameter {
                    name: "world_from_marker",
                    value: format!("missing at t = {} ns", frame.timestamp_ns),
                    expected: "an external pose for every frame with PoseSource::External".into(),
                })?;
                if !is_finite_pose(marker) {
                    return Err(Error::InvalidParameter {
                        name: "world_from_marker",
                        value: format!("{marker:?}"),
                        expected: "a finite pose".into(),
                    });
                }
                buffered.world_from_camera = marker * self.marker_from_camera;
                buffered.first_reset = false;
            }
        }
        Ok(())
    }
}

impl LaterPasses {
    /// The work that runs beside one new frame's pass 1. The refinement of the waiting frames
    /// is spread evenly over the pushes, except for [`held_frames`] of them: those are refined
    /// beside the next backward pass, which starts once a block and its look-ahead are
    /// buffered and runs in steps over the pushes that refine them.
    fn work_beside_first_pass(&mut self, config: &OfflineConfig, emit: &mut Emit<'_>) -> Result<()> {
        let window = config.block_frames + config.lookahead_frames;
        if self.backward.running.is_none() && self.backward.buffer.len() >= window {
            self.backward.start(config);
        }
        let waiting = self.refinement.ready.len();
        let count = if self.backward.running.is_some() {
            waiting.min(1)
        } else {
            // This push and the ones after it until the next backward pass starts.
            let pushes_left = window.saturating_sub(self.backward.buffer.len()).max(1);
            let spread = waiting.saturating_sub(held_frames(config));
            // spread / pushes_left, rounded: an even share per push, all of it at the last.
            (2 * spread + pushes_left) / (2 * pushes_left)
        };
        self.step(count, emit)
    }

    /// Refines and emits `count` waiting frames beside a step of the running backward pass
    /// (if any): the pass's remaining frames spread over the steps that the waiting frames
    /// last, all of them when none are waiting.
    fn step(&mut self, count: usize, emit: &mut Emit<'_>) -> Result<()> {
        let (backward, refinement) = (&mut self.backward, &mut self.refinement);
        let Some(run) = &backward.running else {
            return refinement.refine_ready(count, emit);
        };
        let steps_left = refinement.ready.len().div_ceil(count.max(1)).max(1);
        let frames = run.left.div_ceil(steps_left);
        let (backward_done, refined) =
            rayon::join(|| backward.step(frames), || refinement.refine_ready(count, emit));
        backward_done?;
        refined?;
        if let Some(keep) = backward.take_finished() {
            refinement.ready.extend(backward.buffer.drain(..keep));
        }
        Ok(())
    }
}

/// The waiting frames refined beside a backward pass instead of before it: half a block. The
/// backward pass runs the detector over a block and its look-ahead, the refinement DVO and
/// the detector per frame, so at 60 + 30 frames the pass takes about as long as refining 30
/// frames. Holding them costs their memory (see the module docs).
fn held_frames(config: &OfflineConfig) -> usize {
    config.block_frames / 2
}

/// Frames a step of [`OfflineProcessor::finish_step`] refines: few, so that the results reach
/// the caller (and its writer) while the others are processed.
const FINISH_STEP_FRAMES: usize = 2;

impl BackwardPass {
    /// Starts pass 2 over the buffered block and its look-ahead (all buffered frames at the
    /// end of the sequence), from the last frame back, with a fresh detector.
    fn start(&mut self, config: &OfflineConfig) {
        let end = self
            .buffer
            .len()
            .min(config.block_frames + config.lookahead_frames);
        self.detector.reset();
        self.running = Some(BackwardRun {
            left: end,
            end,
            keep: config.block_frames.min(end),
            reference: None,
        });
    }

    /// The next `frames` frames of the running pass (no-op when none runs).
    fn step(&mut self, frames: usize) -> Result<()> {
        let Some(run) = &mut self.running else {
            return Ok(());
        };
        for _ in 0..frames {
            let Some(j) = run.left.checked_sub(1) else {
                break;
            };
            run.left = j;
            // A jump between frames j and j + 1 (the first pass reset its detector at j + 1)
            // is the same jump backwards.
            if j + 1 < run.end && self.buffer[j + 1].first_reset {
                self.detector.reset();
                run.reference = None;
            }
            let frame = &mut self.buffer[j];
            if !frame.has_depth {
                frame.backward_mask.fill(0);
                continue;
            }
            let current_from_previous = run.reference.map_or_else(Isometry3::identity, |previous| {
                frame.world_from_camera.inverse() * previous
            });
            let gray = if self.appearance_growth {
                dequantize_gray_into(&frame.gray, &mut self.gray);
                Some(&self.gray)
            } else {
                None
            };
            let mask = self
                .detector
                .update_with_gray(&frame.depth_m, gray, &current_from_previous)?;
            if j < run.keep {
                frame
                    .backward_mask
                    .as_mut_slice()
                    .copy_from_slice(mask.as_slice());
            }
            run.reference = Some(frame.world_from_camera);
        }
        Ok(())
    }

    /// Ends a pass that has run over all its frames: how many of the buffer's first frames
    /// are done (`None` while it runs or when none does).
    fn take_finished(&mut self) -> Option<usize> {
        let keep = self.running.as_ref().filter(|run| run.left == 0)?.keep;
        self.running = None;
        Some(keep)
    }
}

impl Refinement {
    /// Pass 3 and `emit` for the first `count` waiting frames, which are then recycled.
    fn refine_ready(&mut self, count: usize, emit: &mut Emit<'_>) -> Result<()> {
        for _ in 0..count {
            let Some(frame) = self.ready.pop_front() else {
                break;
            };
            let result = self.refine_and_emit(&frame, emit);
            self.spare.push(frame);
            result?;
        }
        Ok(())
    }

    /// Pass 3 for one frame, then `emit` with the refinement ∪ backward mask.
    fn refine_and_emit(&mut self, frame: &Buffered, emit: &mut Emit<'_>) -> Result<()> {
        dequantize_gray_into(&frame.gray, &mut self.gray);
        let closed_loop = self.source == PoseSource::DvoClosedLoop;
        let replayed_pose = match self.source {
            PoseSource::DvoClosedLoop => None,
            PoseSource::DvoUnmasked => Some(frame.world_from_camera),
            PoseSource::External { .. } => frame.world_from_marker,
        };
        let ignore = (closed_loop && self.has_previous_seed_mask).then_some(&self.previous_seed_mask);
        let out = self.refine.process(&FrameInput {
            timestamp_ns: frame.timestamp_ns,
            gray: &self.gray,
            depth_m: &frame.depth_m,
            world_from_marker: replayed_pose.as_ref(),
            ignore_in_previous: ignore,
        })?;
        let mut moving = 0usize;
        for ((m, &r), &b) in self
            .mask
            .as_mut_slice()
            .iter_mut()
            .zip(out.mask.as_slice())
            .zip(frame.backward_mask.as_slice())
        {
            *m = r | b;
            moving += usize::from(*m != 0);
        }
        let mut stats = out.stats;
        stats.detector.mask_pixels = moving;
        stats.moving_fraction = moving as f64 / self.size.area().max(1) as f64;
        let output = FrameOutput {
            mask: &self.mask,
            stats,
            ..out
        };
        emit(output)?;
        if closed_loop {
            for ((s, &f), &b) in self
                .previous_seed_mask
                .as_mut_slice()
                .iter_mut()
                .zip(frame.first_mask.as_slice())
                .zip(frame.backward_mask.as_slice())
            {
                *s = f | b;
            }
            self.has_previous_seed_mask = true;
        }
        Ok(())
    }
}

/// `requested` halvings of `size`, fewer where the image would get smaller than
/// [`MIN_REDUCED_SIDE_PX`] on its short side.
fn usable_halvings(size: ImageSize, requested: usize) -> usize {
    (0..requested)
        .take_while(|&k| {
            let next = level_size(size, k + 1);
            next.width.min(next.height) >= MIN_REDUCED_SIDE_PX
        })
        .count()
}

/// The detector's parameters for the image halved `halvings` times: the border margins (in
/// pixels) shrink with it; the object size is given at VGA and scales by itself.
fn reduced_occlusion_config(config: &OcclusionConfig, halvings: usize) -> OcclusionConfig {
    OcclusionConfig {
        thin_structure_border_margin_px: config.thin_structure_border_margin_px >> halvings,
        prune_exit_margin_px: config.prune_exit_margin_px >> halvings,
        ..*config
    }
}

/// Scratch of the first pass at reduced resolution: each halving's gray and depth.
struct Reduced {
    gray: Vec<GrayF32>,
    depth_m: Vec<DepthMeters>,
}

impl Reduced {
    /// `None` for 0 halvings.
    fn new(size: ImageSize, halvings: usize) -> Option<Self> {
        let sizes = || (1..=halvings).map(|k| level_size(size, k));
        (halvings > 0).then(|| Self {
            gray: sizes().map(|s| GrayF32::filled(s, 0.0)).collect(),
            depth_m: sizes().map(|s| DepthMeters::filled(s, 0.0)).collect(),
        })
    }

    /// `gray` halved by 2×2 box means and `depth_m` by edge-aware 2×2 reductions.
    fn reduce<'a>(
        &'a mut self,
        gray: &'a GrayF32,
        depth_m: &'a DepthMeters,
    ) -> Result<(&'a GrayF32, &'a DepthMeters)> {
        for k in 0..self.depth_m.len() {
            let (done, rest) = self.gray.split_at_mut(k);
            downsample_gray_into(done.last().unwrap_or(gray), &mut rest[0])?;
            let (done, rest) = self.depth_m.split_at_mut(k);
            downsample_depth_into(done.last().unwrap_or(depth_m), &mut rest[0])?;
        }
        Ok((
            self.gray.last().unwrap_or(gray),
            self.depth_m.last().unwrap_or(depth_m),
        ))
    }
}

/// `mask` into `full`: copied at the same size, else enlarged by the nearest pixel from the
/// image halved some number of times; rows and columns beyond the reduced image's cover (odd
/// sides) take its last ones.
fn copy_or_enlarge_mask(mask: &Mask, full: &mut Mask) {
    if mask.size() == full.size() {
        full.as_mut_slice().copy_from_slice(mask.as_slice());
        return;
    }
    let (rw, rh) = (mask.width(), mask.height());
    let fw = full.width();
    if rw == 0 || rh == 0 {
        full.fill(0);
        return;
    }
    let halvings = (full.width() / rw).max(1).ilog2();
    let src = mask.as_slice();
    for (y, row) in full.as_mut_slice().chunks_exact_mut(fw).enumerate() {
        let ry = (y >> halvings).min(rh - 1);
        let src_row = &src[ry * rw..(ry + 1) * rw];
        for (x, m) in row.iter_mut().enumerate() {
            *m = src_row[(x >> halvings).min(rw - 1)];
        }
    }
}

/// Gray in [0, 1] as u16 units of 1/65535 (clamped, rounded half up; NaN → 0).
///
/// `+ 0.5` and truncation instead of `f32::round`, which is a library call per pixel on the
/// baseline x86-64 target. From 0.5 up the sum is exact or rounds within the same integer; below
/// 0.5 it can round up to 1.0, hence the guard. Checked against `round` for every f32 in [0, 1]
/// (outside the tests, with numpy); `quantize_gray_agrees_with_round` keeps the boundaries.
#[inline]
fn quantize_gray(g: f32) -> u16 {
    let x = g.clamp(0.0, 1.0) * 65535.0;
    if x < 0.5 {
        0
    } else {
        (x + 0.5) as u16
    }
}

fn dequantize_gray_into(q: &Image<u16>, gray: &mut GrayF32) {
    for (g, &v) in gray.as_mut_slice().iter_mut().zip(q.as_slice()) {
        *g = f32::from(v) / 65535.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::SegmentationTally;
    use crate::synthetic::{Scenario, SequenceConfig, SyntheticSequence};

    /// What a run emits: per frame its index, stamp, pose and mask.
    type Emitted = Vec<(u64, u64, Isometry3<f64>, Mask)>;

    const SIZE: ImageSize = ImageSize::new(160, 120);

    /// Short blocks, so that several backward passes and a partial last block occur.
    fn short_blocks() -> OfflineConfig {
        OfflineConfig {
            block_frames: 7,
            lookahead_frames: 4,
            ..OfflineConfig::default()
        }
    }

    /// `frames` frames of `scenario` at 160×120 and a closed-loop offline processor for them.
    fn setup(scenario: Scenario, frames: usize) -> (SyntheticSequence, OfflineProcessor) {
        let sequence = SyntheticSequence::new(
            scenario,
            SequenceConfig {
                size: SIZE,
                frame_count: Some(frames),
                ..SequenceConfig::default()
            },
        );
        let config = ProcessorConfig {
            offline: short_blocks(),
            ..ProcessorConfig::default()
        };
        let processor =
            OfflineProcessor::new(SIZE, sequence.config.intrinsics(), config).expect("valid config");
        (sequence, processor)
    }

    /// Pushes frame `i` of `sequence`.
    fn push(processor: &mut OfflineProcessor, sequence: &SyntheticSequence, i: usize, emit: &mut Emit<'_>) {
        let frame = sequence.frame(i);
        let input = FrameInput {
            timestamp_ns: frame.timestamp_ns,
            gray: &frame.gray,
            depth_m: &frame.depth_m,
            world_from_marker: None,
            ignore_in_previous: None,
        };
        processor.push(&input, emit).expect("push");
    }

    /// Two crossing boxes, offline, on a pool of `threads` threads.
    fn run(threads: usize, frames: usize) -> Emitted {
        run_noting_the_end(threads, frames).0
    }

    /// [`run`], and whether a backward pass was running when the stream ended.
    fn run_noting_the_end(threads: usize, frames: usize) -> (Emitted, bool) {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a test pool");
        pool.install(|| {
            let (sequence, mut processor) = setup(Scenario::TwoObjectsCrossing, frames);
            let mut emitted = Emitted::new();
            let mut keep = |out: FrameOutput<'_>| {
                emitted.push((
                    out.index,
                    out.timestamp_ns,
                    out.world_from_camera,
                    out.mask.clone(),
                ));
                Ok(())
            };
            for i in 0..frames {
                push(&mut processor, &sequence, i, &mut keep);
            }
            let mid_pass = processor.later.backward.running.is_some();
            processor.finish(&mut keep).expect("finish");
            assert_eq!(processor.pending_frames(), 0);
            (emitted, mid_pass)
        })
    }

    #[test]
    fn passes_side_by_side_give_the_results_of_one_thread() {
        let frames = 40;
        let one = run(1, frames);
        let two = run(2, frames);
        // Every frame once, in order.
        let indices: Vec<u64> = one.iter().map(|e| e.0).collect();
        assert_eq!(indices, (0..frames as u64).collect::<Vec<_>>());
        assert_eq!(one.len(), two.len());
        for (a, b) in one.iter().zip(&two) {
            assert_eq!((a.0, a.1), (b.0, b.1));
            assert_eq!(a.2, b.2, "pose of frame {}", a.0);
            assert!(a.3 == b.3, "mask of frame {}", a.0);
        }
        // The detector found the boxes (the comparison is not between empty masks).
        assert!(one.iter().any(|e| e.3.as_slice().iter().any(|&m| m != 0)));
    }

    /// The passes one after the other: pass 1 over every frame, then each backward pass over
    /// its block and look-ahead, each followed by the refinement of its block.
    fn run_passes_in_turn(frames: usize) -> Emitted {
        let (sequence, mut processor) = setup(Scenario::TwoObjectsCrossing, frames);
        let config = processor.config;
        let size = processor.later.refinement.size;
        for i in 0..frames {
            let frame = sequence.frame(i);
            let mut buffered = Buffered::new(size);
            let input = FrameInput {
                timestamp_ns: frame.timestamp_ns,
                gray: &frame.gray,
                depth_m: &frame.depth_m,
                world_from_marker: None,
                ignore_in_previous: None,
            };
            processor.first.run(&input, &mut buffered).expect("pass 1");
            processor.later.backward.buffer.push_back(buffered);
        }
        let mut emitted = Emitted::new();
        let mut keep = |out: FrameOutput<'_>| {
            emitted.push((
                out.index,
                out.timestamp_ns,
                out.world_from_camera,
                out.mask.clone(),
            ));
            Ok(())
        };
        let LaterPasses { backward, refinement } = &mut processor.later;
        while !backward.buffer.is_empty() {
            backward.start(&config);
            backward.step(usize::MAX).expect("pass 2");
            let keep_frames = backward.take_finished().expect("a finished pass");
            refinement.ready.extend(backward.buffer.drain(..keep_frames));
            refinement
                .refine_ready(refinement.ready.len(), &mut keep)
                .expect("pass 3");
        }
        emitted
    }

    #[test]
    fn scheduled_passes_give_the_results_of_the_passes_in_turn() {
        // Several blocks, ending between backward passes and while one runs.
        for (frames, ends_mid_pass) in [(30, false), (34, true)] {
            let in_turn = run_passes_in_turn(frames);
            let (scheduled, mid_pass) = run_noting_the_end(2, frames);
            assert_eq!(mid_pass, ends_mid_pass, "{frames} frames");
            assert_eq!(in_turn.len(), frames);
            assert_eq!(in_turn.len(), scheduled.len());
            for (a, b) in in_turn.iter().zip(&scheduled) {
                assert_eq!((a.0, a.1), (b.0, b.1));
                assert_eq!(a.2, b.2, "pose of frame {}", a.0);
                assert!(a.3 == b.3, "mask of frame {}", a.0);
            }
        }
    }

    #[test]
    fn quantize_gray_agrees_with_round() {
        let reference = |g: f32| (g.clamp(0.0, 1.0) * 65535.0).round() as u16;
        // Every half-step boundary and its float neighbours, plus the edge cases (the largest
        // values below one half step, whose `+ 0.5` rounds up to 1.0, among them).
        for g in [0.499_999_97 / 65535.0, 0.499_999_9 / 65535.0, 1e-30] {
            assert_eq!(quantize_gray(g), reference(g), "g = {g:e}");
        }
        for k in 0..=65535u32 {
            let x = (k as f32 + 0.5) / 65535.0;
            for g in [x, x.next_down(), x.next_up(), k as f32 / 65535.0] {
                assert_eq!(quantize_gray(g), reference(g), "g = {g:e}");
            }
        }
        for g in [-1.0, 0.0, 1.0, 2.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            assert_eq!(quantize_gray(g), reference(g), "g = {g}");
        }
    }

    #[test]
    fn enlarged_masks_repeat_each_reduced_pixel_and_cover_odd_sides() {
        let mut reduced = Mask::filled(ImageSize::new(3, 2), 0);
        reduced.as_mut_slice().copy_from_slice(&[1, 0, 2, 0, 3, 0]);
        let mut full = Mask::filled(ImageSize::new(7, 5), 9);
        copy_or_enlarge_mask(&reduced, &mut full);
        let expected: [[u8; 7]; 5] = [
            [1, 1, 0, 0, 2, 2, 2],
            [1, 1, 0, 0, 2, 2, 2],
            [0, 0, 3, 3, 0, 0, 0],
            [0, 0, 3, 3, 0, 0, 0],
            [0, 0, 3, 3, 0, 0, 0],
        ];
        assert_eq!(full.as_slice(), expected.concat().as_slice());
    }

    /// Mean F1 of the emitted masks against the ground truth, closed loop, offline, over the
    /// frames with a moving object.
    fn offline_f1(scenario: Scenario, size: ImageSize, frames: usize, offline: OfflineConfig) -> f64 {
        let sequence = SyntheticSequence::new(
            scenario,
            SequenceConfig {
                size,
                frame_count: Some(frames),
                ..SequenceConfig::default()
            },
        );
        let config = ProcessorConfig {
            offline,
            ..ProcessorConfig::default()
        };
        let mut processor =
            OfflineProcessor::new(size, sequence.config.intrinsics(), config).expect("valid config");
        let mut tally = SegmentationTally::default();
        let mut index = 0usize;
        let mut score = |out: FrameOutput<'_>| {
            tally.add_masks(out.mask, &sequence.frame(index).gt_mask)?;
            index += 1;
            Ok(())
        };
        for i in 0..frames {
            push(&mut processor, &sequence, i, &mut score);
        }
        processor.finish(&mut score).expect("finish");
        tally.summary().mean_f1
    }

    #[test]
    fn a_first_pass_at_half_resolution_masks_as_well_as_a_full_one() {
        // VGA: the first pass runs at 320×240. Measured: F1 0.857 with a full-resolution first
        // pass and at half; the bound allows 0.03 less than full.
        let size = ImageSize::new(640, 480);
        let frames = 30;
        let full = offline_f1(
            Scenario::TwoObjectsCrossing,
            size,
            frames,
            OfflineConfig {
                first_pass_halvings: 0,
                ..short_blocks()
            },
        );
        let half = offline_f1(Scenario::TwoObjectsCrossing, size, frames, short_blocks());
        eprintln!("F1 full-resolution first pass {full:.3}, half {half:.3}");
        assert!(half >= full - 0.03, "half {half:.3} vs full {full:.3}");
    }

    #[test]
    fn emits_a_block_over_the_pushes_until_the_next_backward_pass() {
        // Results lag by at most a block, its look-ahead and the frames held for the next
        // backward pass, and nothing is emitted before the first backward pass.
        let config = short_blocks();
        let frames = 30;
        let (sequence, mut processor) = setup(Scenario::StaticScene, frames);
        let window = config.block_frames + config.lookahead_frames;
        let lag = window + held_frames(&config);
        let mut emitted = 0usize;
        for i in 0..frames {
            let mut count = |_: FrameOutput<'_>| {
                emitted += 1;
                Ok(())
            };
            push(&mut processor, &sequence, i, &mut count);
            let pushed = i + 1;
            if pushed <= window {
                assert_eq!(emitted, 0, "after {pushed} frames");
            }
            assert!(
                pushed - emitted <= lag,
                "after {pushed} frames, {emitted} emitted"
            );
            assert_eq!(processor.pending_frames(), pushed - emitted);
        }
        processor.finish(&mut |_| Ok(())).expect("finish");
        assert_eq!(processor.pending_frames(), 0);
    }
}
