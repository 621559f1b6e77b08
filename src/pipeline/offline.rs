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
//!    external) poses. A frame's mask is the refinement pass's ∪ the backward pass's, each
//!    large enough object in it completed to the depth-connected body it belongs to when that
//!    body is bounded by depth edges ([`ProcessorConfig::body_completion`], docs/method.md D26);
//! 4. **temporal hysteresis** ([`OfflineConfig::hysteresis_frames`], "confirm later, mark
//!    earlier"): refined frames are held back that many frames; where a frame's slow-change
//!    evidence confirms an object, the pixels of the frames before it whose evidence was above
//!    a low threshold, and that land on the confirmed pixels through the camera motion, join
//!    their masks, frame by frame backwards, before they are emitted.
//!
//! Pass 1 of a new frame runs beside passes 2 and 3 of earlier ones (see [`OfflineProcessor`]).
//! Frames are emitted in order, a block's worth spread over the pushes until the next backward
//! pass, so results lag the input by up to `block_frames + lookahead_frames` frames (plus
//! `hysteresis_frames`), and that many frames are buffered (gray as u16, depth as f32, two masks:
//! 2.4 MB per 640×480 frame; a held frame keeps four masks, A and its candidates: 2.4 MB and
//! 8 bytes per candidate).
//! Buffers are recycled: after the first block nothing is allocated per frame.

use std::collections::VecDeque;

use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

use super::reduce::{copy_or_enlarge, halvings_keeping_side, FrameReduction, Reduced};
use super::{
    check_size, valid_depth_fraction, FrameInput, FrameOutput, FrameStats, PoseSource, Processor,
    ProcessorConfig,
};
use crate::dvo::{DvoConfig, MotionPriorConfig};
use crate::error::{Error, Result};
use crate::geometry::se3::is_finite_pose;
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, GrayF32, Image, ImageSize, Mask};
use crate::occlusion::bodies::BodyCompletion;
use crate::occlusion::{OcclusionConfig, OcclusionDetector};
use crate::pyramid::level_size;

mod hysteresis;
pub mod registration;
use hysteresis::Hysteresis;
use registration::RegistrationProfile;

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
    /// its coarsest), or to a finer one where this level's short side would have fewer than
    /// [`Self::first_pass_min_side_px`] pixels.
    pub first_pass_finest_level: usize,
    /// The first pass's DVO runs on a pyramid level whose short side has at least this many
    /// pixels (down to the configured DVO's finest level at most). 0 =
    /// [`Self::first_pass_finest_level`] as given (a pyramid index, whatever the image size).
    pub first_pass_min_side_px: usize,
    /// The closed loop's first pass sees the frames halved this many times by 2×2 reduction
    /// (gray: box mean, depth: edge-aware), detector included; its masks are enlarged back
    /// (nearest pixel) to seed the refinement pass's ignore masks. 0 = full resolution. The
    /// first pass's poses and masks only seed the later passes, which run at full resolution.
    pub first_pass_halvings: usize,
    /// The closed loop's first pass tracks only the far background: its DVO ignores, on each
    /// reference frame, the pixels nearer than this fraction of that frame's
    /// [`FAR_LAYER_QUANTILE`] depth, so that an object filling the near view from the first
    /// frame cannot carry the camera with it. In (0, 1]; `None`: off (the default: on the real
    /// recordings it costs accuracy, docs/method.md D21). The refinement pass is unchanged.
    pub first_pass_ignore_nearer_than: Option<f32>,
    /// Working resolution of the offline mode (applied by [`super::SequenceProcessor`]; an
    /// [`OfflineProcessor`] processes frames at the size it is given): frames are halved as
    /// many times as their short side keeps at least this many pixels, processed at that size,
    /// and their masks enlarged back. 0 = full resolution; otherwise at least
    /// [`MIN_WORKING_SIDE_PX`]. The causal mode always runs at full resolution.
    pub min_working_side_px: usize,
    /// DVO of the closed loop's refinement pass.
    pub refinement_dvo: DvoConfig,
    /// The refinement pass's DVO runs on a pyramid level whose short side has at least this
    /// many pixels: [`Self::refinement_dvo`]'s finest level is lowered (to full resolution at
    /// most) until it does. 0 = that finest level as configured (a pyramid index, whatever the
    /// image size).
    pub refinement_min_side_px: usize,
    /// Temporal hysteresis (pass 4 in the module docs): the refinement pass's results are held back this
    /// many frames, and pixels of a held frame with slow-change evidence above the low threshold
    /// join its mask where they land on the mask of the frame after it. 0 = off. Needs the
    /// slow-change evidence (off on images under 240 px on their short side).
    pub hysteresis_frames: usize,
    /// The hysteresis's low threshold as a fraction of the slow-change evidence's α, in (0, 1].
    pub hysteresis_low_fraction: f32,
    /// The closed loop's refinement on a recording whose colour is not registered to its depth,
    /// found from its first frames ([`registration`]). `None`: not checked, every recording is
    /// refined with [`Self::refinement_dvo`] and [`Self::hysteresis_frames`].
    pub unregistered_colour: Option<UnregisteredColourConfig>,
}

/// What the closed loop's refinement pass uses instead on a recording whose colour is not
/// registered to its depth ([`OfflineConfig::unregistered_colour`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct UnregisteredColourConfig {
    /// Colour counts as not registered when the median [`registration::RegistrationProfile::score`]
    /// of the measured frames is below this.
    pub min_score: f32,
    /// The check looks at the first this many frames and measures every
    /// [`REGISTRATION_FRAME_STRIDE`]-th of them (those with enough depth edges,
    /// [`registration::MIN_EDGE_PIXELS`], give a score); the decision is taken earlier if the
    /// refinement pass is due first.
    pub frames: usize,
    /// The refinement pass's DVO on such a recording.
    pub refinement_dvo: DvoConfig,
    /// [`OfflineConfig::hysteresis_frames`] on such a recording.
    pub hysteresis_frames: usize,
}

/// Default [`UnregisteredColourConfig::min_score`]. Measured over the first 90 frames (every
/// third; medians): TUM fr2_desk 2.6 and the Bonn crowd 2.5 (registered; single frames
/// 1.6–3.5), 7-Scenes redkitchen 0.87 (not registered; single frames 0.69–1.78; the processor's
/// median over all 90: 0.90).
pub const DEFAULT_MIN_REGISTRATION_SCORE: f32 = 1.5;
/// Default [`UnregisteredColourConfig::frames`]: the frames buffered before the first
/// refinement at the default block and look-ahead, so the check delays nothing.
pub const DEFAULT_REGISTRATION_FRAMES: usize = DEFAULT_BLOCK_FRAMES + DEFAULT_LOOKAHEAD_FRAMES;
/// The registration check measures every this many frames: one scan of a VGA frame cost 2.7 % of
/// `process`'s CPU on the 200-frame Bonn window when every frame was measured, and a third of the
/// first 90 frames decides the same on the real recordings (medians: TUM fr2_desk 2.6, the Bonn
/// crowd 2.5, 7-Scenes 0.87 against 0.90 from all 90).
pub const REGISTRATION_FRAME_STRIDE: usize = 3;
impl Default for UnregisteredColourConfig {
    fn default() -> Self {
        Self {
            min_score: DEFAULT_MIN_REGISTRATION_SCORE,
            frames: DEFAULT_REGISTRATION_FRAMES,
            // The causal closed loop's own DVO: the depth term weighted and keyframes while nothing
            // moves (docs/method.md D18).
            refinement_dvo: DvoConfig::closed_loop(),
            hysteresis_frames: 0,
        }
    }
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
/// Default [`OfflineConfig::hysteresis_frames`]: about half a second at 30 Hz, twice the frames
/// the slow-change evidence took to confirm an object approaching head-on (8 at 320×240).
pub const DEFAULT_HYSTERESIS_FRAMES: usize = 16;
/// Default [`OfflineConfig::hysteresis_low_fraction`]. Measured on the synthetic failure classes
/// at 320×240 with an earlier variant (seeded by the whole published mask, 1 px radius): 0.3
/// marked enough of the static surroundings of the moving objects to cost the sliding box F1
/// 0.855 → 0.816; 0.6 left the late-onset box's onset at 21 frames (0.5: 16).
pub const DEFAULT_HYSTERESIS_LOW_FRACTION: f32 = 0.5;
/// Default [`OfflineConfig::first_pass_min_side_px`]: the 120 rows the first pass's DVO sees on
/// VGA are kept on smaller images (a 320×240 input would track at 80×60, where the board that
/// fills the synthetic view from the first frame outweighs the background around it). Measured
/// on that scenario at 320×240 (offline, DVO, seeds 1 / 2 / 3): F1 0.035 / 0.058 / 0.050 →
/// 0.497 / 0.608 / 0.567; seed 1 ATE 28.6 → 5.6 cm (docs/method.md, D11).
pub const DEFAULT_FIRST_PASS_MIN_SIDE_PX: usize = 120;
/// Default [`OfflineConfig::refinement_min_side_px`]: the 240 rows the refinement's DVO sees on
/// VGA (finest level 1) are kept on smaller images, which would otherwise track at 160×120 (a
/// 320×240 input) on a quarter of the pixels. Measured on the synthetic failure classes and
/// held-out scenarios at 320×240 (offline, DVO): ATE lower on all twelve, e.g. the static desk
/// 4.9 → 0.8 mm, the object in view at the start 8.5 → 4.5 cm (docs/method.md, D11); VGA input
/// is unchanged.
pub const DEFAULT_REFINEMENT_MIN_SIDE_PX: usize = 240;
/// [`OfflineConfig::first_pass_ignore_nearer_than`] is a fraction of this quantile of a frame's
/// valid depths: the far background's depth, unmoved by the few farthest pixels (a window, the
/// noisy rim of the depth image).
pub const FAR_LAYER_QUANTILE: f64 = 0.9;

/// Default [`OfflineConfig::min_working_side_px`]: VGA (and 1280×720) is processed at half
/// size, 320×240 as it is. On people walking past a hand-held VGA camera (Bonn "crowd") the
/// offline mode ran at 1.7× the frames/s of full resolution, its closed loop as accurate (ATE
/// 0.038 m against 0.046 m) and its masks a little less complete (F1 0.929 against 0.938;
/// docs/method.md D24, D25); 240 px is also the smallest short side at which the slow-change
/// evidence runs.
pub const DEFAULT_MIN_WORKING_SIDE_PX: usize = 240;

/// The smallest [`OfflineConfig::min_working_side_px`] other than 0: below it an object of the
/// minimum size is a few pixels across.
pub const MIN_WORKING_SIDE_PX: usize = 60;

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
            first_pass_min_side_px: DEFAULT_FIRST_PASS_MIN_SIDE_PX,
            first_pass_halvings: DEFAULT_FIRST_PASS_HALVINGS,
            first_pass_ignore_nearer_than: None,
            min_working_side_px: DEFAULT_MIN_WORKING_SIDE_PX,
            hysteresis_frames: DEFAULT_HYSTERESIS_FRAMES,
            hysteresis_low_fraction: DEFAULT_HYSTERESIS_LOW_FRACTION,
            refinement_min_side_px: DEFAULT_REFINEMENT_MIN_SIDE_PX,
            refinement_dvo: Self::paper_refinement_dvo(),
            unregistered_colour: Some(UnregisteredColourConfig::default()),
        }
    }
}

impl OfflineConfig {
    /// The default refinement DVO: the paper's weights with the motion prior, whose prediction
    /// is always the last motion: this pass ignores the masks of passes that looked ahead, so
    /// its motions are estimated with the objects masked from their first frames, and more
    /// ignored later means that objects came into view, not that they pulled the last motion
    /// ([`MotionPriorConfig::max_ignored_fraction_increase`]: docs/method.md D13).
    pub fn paper_refinement_dvo() -> DvoConfig {
        DvoConfig {
            motion_prior: Some(MotionPriorConfig {
                max_ignored_fraction_increase: 1.0,
                ..MotionPriorConfig::default()
            }),
            ..DvoConfig::paper()
        }
    }

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
        if !(self.hysteresis_low_fraction > 0.0 && self.hysteresis_low_fraction <= 1.0) {
            return Err(Error::InvalidParameter {
                name: "offline.hysteresis_low_fraction",
                value: self.hysteresis_low_fraction.to_string(),
                expected: "a fraction in (0, 1]".into(),
            });
        }
        if self.min_working_side_px != 0 && self.min_working_side_px < MIN_WORKING_SIDE_PX {
            return Err(Error::InvalidParameter {
                name: "offline.min_working_side_px",
                value: self.min_working_side_px.to_string(),
                expected: format!("0 (full resolution) or at least {MIN_WORKING_SIDE_PX} pixels"),
            });
        }
        if let Some(fraction) = self.first_pass_ignore_nearer_than {
            if !(fraction > 0.0 && fraction <= 1.0) {
                return Err(Error::InvalidParameter {
                    name: "offline.first_pass_ignore_nearer_than",
                    value: fraction.to_string(),
                    expected: "a fraction in (0, 1], or null".into(),
                });
            }
        }
        if let Some(unregistered) = &self.unregistered_colour {
            if !(unregistered.min_score.is_finite() && unregistered.min_score >= 0.0) {
                return Err(Error::InvalidParameter {
                    name: "offline.unregistered_colour.min_score",
                    value: unregistered.min_score.to_string(),
                    expected: "finite and >= 0".into(),
                });
            }
            unregistered.refinement_dvo.validate()?;
        }
        self.refinement_dvo.validate()
    }
}

/// What the registration check ([`OfflineConfig::unregistered_colour`]) decided.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColourRegistration {
    /// The colour was found registered to the depth (the paper's refinement and the hysteresis
    /// ran); false: the unregistered recording's refinement ran.
    pub registered: bool,
    /// The median score decided on (`None`: no frame had enough depth edges to be scored, which
    /// counts as registered).
    pub score: Option<f32>,
    /// The score below which colour counts as not registered.
    pub min_score: f32,
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
    /// The backward pass's mask without the slow-change evidence (the refinement's seed), when
    /// the detector has that evidence; else the seed is `backward_mask`.
    backward_odometry_mask: Option<Mask>,
}

/// Where a frame's result goes: called in frame order, from whichever of the pool's threads
/// runs the refinement pass (hence `Send`).
pub type Emit<'e> = dyn FnMut(FrameOutput<'_>) -> Result<()> + Send + 'e;

/// Where results go when nothing runs beside the caller (the end of the sequence, and the
/// passes that [`Emit`] reaches through): as [`Emit`], but only ever called on the caller's
/// thread, so it need not be `Send`.
pub type Sink<'e> = dyn FnMut(FrameOutput<'_>) -> Result<()> + 'e;

/// Sequence processor of the offline mode (see the module docs).
///
/// Pass 1 is a chain over the frames as they arrive; the backward and refinement passes are a
/// second chain over the frames that pass 1 has finished. [`Self::push`] runs the two side by
/// side (`rayon::join`): the new frame's pass 1 on one thread, and on another the backward pass
/// that the previous frame made due plus the refinement of a share of the frames waiting for it.
/// Within the refinement, a frame's completion (body completion, hysteresis, emit) runs beside
/// the next frame's pass; and once the colour registration check has decided, the reduction of
/// the new frame to the working resolution (`push_reducing`) runs in pass 1's half.
/// Both chains keep their order, so the results are those of running the passes one after the
/// other; only the time differs (on one thread, `join` runs them in turn).
pub struct OfflineProcessor {
    config: OfflineConfig,
    first: FirstPass,
    later: LaterPasses,
    /// The colour/depth registration check, until it has decided (closed loop only).
    registration: Option<RegistrationCheck>,
    /// Its decision, once taken.
    registration_decision: Option<ColourRegistration>,
}

/// The registration scores of the first frames and what replaces the refinement pass if they
/// find the colour not registered.
struct RegistrationCheck {
    config: UnregisteredColourConfig,
    /// Frames pushed so far, and the scores of those measured.
    frames_seen: usize,
    scores: Vec<f32>,
    /// The refinement pass's processor config on unregistered colour.
    refine: ProcessorConfig,
    intrinsics: PinholeIntrinsics,
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
    /// [`OfflineConfig::first_pass_ignore_nearer_than`] (closed loop only).
    near_layer: Option<NearLayer>,
}

/// The near layer that the first pass's DVO ignores on its reference frame.
struct NearLayer {
    fraction: f32,
    /// The previous frame's near pixels (nonzero = near), on the first pass's pixel grid.
    previous: Mask,
    /// The valid depths of a frame (the quantile's work buffer).
    depths_m: Vec<f32>,
}

/// Passes 2 and 3, and the frames they work on.
struct LaterPasses {
    /// Pass 2.
    backward: BackwardPass,
    /// Frames after pass 1 whose backward pass has not run: the next block and its look-ahead.
    buffer: VecDeque<Buffered>,
    /// Pass 3.
    refinement: Refinement,
}

/// Pass 2's detector and scratch.
struct BackwardPass {
    detector: OcclusionDetector,
    /// Scratch: a buffered frame's gray as f32 (0×0 unless the detector's appearance growth
    /// is on).
    gray: GrayF32,
}

/// Pass 3, the frames waiting for it, and what it emits.
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
    /// The first pass's forward ∪ backward mask of the last refined frame (the next frame's
    /// `ignore_in_previous` in the closed loop's refinement pass).
    previous_seed_mask: Mask,
    has_previous_seed_mask: bool,
    /// The temporal hysteresis's held frames (None when it is off).
    hysteresis: Option<Hysteresis>,
    /// Completes the emitted mask's objects to their bodies (None when it is off).
    bodies: Option<BodyCompletion>,
    /// Recycled [`Refined`] results.
    spare_refined: Vec<Refined>,
    /// Scratch of the hysteresis's candidates (one image row).
    candidate_row: Vec<u8>,
}

/// One frame's refinement-pass results, copied out of the processor: the frame's completion
/// ([`complete_refined`]: body completion, hysteresis, `emit`) runs while the processor goes on
/// to the next frame.
struct Refined {
    index: u64,
    timestamp_ns: u64,
    current_from_previous: Isometry3<f64>,
    world_from_camera: Isometry3<f64>,
    stats: FrameStats,
    /// The refinement pass's own mask.
    refinement_mask: Mask,
    odometry_mask: Mask,
    accumulation_m: DepthMeters,
    /// The detector's slow-change candidates of the frame for the hysteresis (none when it is
    /// off or the frame has no depth).
    candidates: Vec<(u32, f32)>,
    /// The published mask: refinement ∪ backward, completed to bodies.
    mask: Mask,
}

/// What the refinement pass of one frame reads and writes besides the frame
/// ([`Refinement::refine_ready`] lends it to the pool's other thread).
struct RefinementPass<'a> {
    source: PoseSource,
    refine: &'a mut Processor,
    gray: &'a mut GrayF32,
    previous_seed_mask: &'a mut Mask,
    has_previous_seed_mask: &'a mut bool,
    /// The hysteresis's low fraction, when it is on.
    low_fraction: Option<f32>,
    candidate_row: &'a mut Vec<u8>,
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
        // The passes' own masks stay as their detectors leave them; the emitted mask is completed.
        let body_completion = config.body_completion;
        let config = ProcessorConfig {
            body_completion: None,
            ..config
        };
        let mut reduced = None;
        let mut near_layer = None;
        let first = match config.pose_source {
            PoseSource::DvoClosedLoop => {
                let finest = first_pass_finest_level(&offline, &config.dvo, size);
                let halvings = usable_halvings(size, offline.first_pass_halvings);
                // The same pyramid levels in full-resolution terms, counted from the reduced
                // image.
                let dvo = DvoConfig {
                    levels: config.dvo.levels.saturating_sub(halvings).max(1),
                    finest_level: finest.saturating_sub(halvings),
                    ..config.dvo
                };
                reduced = Reduced::new(size, halvings);
                let first_size = level_size(size, halvings);
                near_layer = offline.first_pass_ignore_nearer_than.map(|fraction| NearLayer {
                    fraction,
                    previous: Mask::filled(first_size, 0),
                    depths_m: Vec::with_capacity(first_size.width * first_size.height),
                });
                Some(Processor::new(
                    first_size,
                    intrinsics.at_level(halvings as u32),
                    ProcessorConfig {
                        dvo,
                        occlusion: first_pass_occlusion_config(&config.occlusion, halvings),
                        ..config
                    },
                )?)
            }
            PoseSource::DvoUnmasked => Some(Processor::new(
                size,
                intrinsics,
                ProcessorConfig {
                    occlusion: first_pass_occlusion_config(&config.occlusion, 0),
                    ..config
                },
            )?),
            PoseSource::External { .. } => None,
        };
        let refine = match config.pose_source {
            PoseSource::DvoClosedLoop => ProcessorConfig {
                dvo: refinement_dvo(&offline, offline.refinement_dvo, size),
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
        let registration = match (config.pose_source, offline.unregistered_colour) {
            (PoseSource::DvoClosedLoop, Some(unregistered)) => Some(RegistrationCheck {
                config: unregistered,
                frames_seen: 0,
                scores: Vec::with_capacity(unregistered.frames.div_ceil(REGISTRATION_FRAME_STRIDE)),
                refine: ProcessorConfig {
                    dvo: refinement_dvo(&offline, unregistered.refinement_dvo, size),
                    ..refine
                },
                intrinsics,
            }),
            _ => None,
        };
        let refine = Processor::new(size, intrinsics, refine)?;
        // The candidates are the slow-change evidence's: none on images too small for it.
        let hysteresis = refine
            .detector()
            .config()
            .slow_evidence
            .and_then(|_| Hysteresis::new(&offline, size, intrinsics));
        Ok(Self {
            config: offline,
            first: FirstPass {
                processor: first,
                reduced,
                source: config.pose_source,
                marker_from_camera,
                min_valid_depth_fraction: config.failure.min_valid_depth_fraction,
                near_layer,
            },
            later: LaterPasses {
                backward: BackwardPass {
                    detector: OcclusionDetector::new(size, intrinsics, config.occlusion)?,
                    gray: GrayF32::filled(
                        match config.occlusion.appearance_growth {
                            Some(_) => size,
                            None => ImageSize::new(0, 0),
                        },
                        0.0,
                    ),
                },
                buffer: VecDeque::new(),
                refinement: Refinement {
                    source: config.pose_source,
                    refine,
                    ready: VecDeque::new(),
                    spare: Vec::new(),
                    size,
                    gray: GrayF32::filled(size, 0.0),
                    previous_seed_mask: Mask::filled(size, 0),
                    has_previous_seed_mask: false,
                    hysteresis,
                    bodies: body_completion
                        .map(|c| BodyCompletion::new(size, c))
                        .transpose()?,
                    spare_refined: Vec::new(),
                    candidate_row: Vec::with_capacity(size.width),
                },
            },
            registration,
            registration_decision: None,
        })
    }

    /// Whether the recording's colour was found registered to its depth (the refinement pass's
    /// DVO and hysteresis follow; [`OfflineConfig::unregistered_colour`]): `None` before the
    /// check has decided or where it is off.
    pub fn colour_registered(&self) -> Option<bool> {
        self.registration_decision.map(|d| d.registered)
    }

    /// The median [`registration::RegistrationProfile::score`] the check decided on (`None`
    /// before, where it is off, or without a frame with enough depth edges).
    pub fn registration_score(&self) -> Option<f32> {
        self.registration_decision.and_then(|d| d.score)
    }

    /// The registration check's decision, for reports (`None` before it has decided or where
    /// it is off).
    pub fn colour_registration(&self) -> Option<ColourRegistration> {
        self.registration_decision
    }

    /// Measures `frame` for the registration check, and decides once it has its frames or the
    /// refinement pass is due.
    fn check_registration(&mut self, frame: Option<&FrameInput<'_>>) -> Result<()> {
        let Some(check) = &mut self.registration else {
            return Ok(());
        };
        if let Some(frame) = frame {
            if check.frames_seen % REGISTRATION_FRAME_STRIDE == 0 && check.frames_seen < check.config.frames {
                // NaN gray (invalid input) gives no score.
                let score = RegistrationProfile::measure(frame.gray, frame.depth_m)
                    .map(|profile| profile.score())
                    .filter(|score| !score.is_nan());
                check.scores.extend(score);
            }
            check.frames_seen += 1;
        }
        let window = self.config.block_frames + self.config.lookahead_frames;
        let refinement_due =
            frame.is_none() || self.later.buffer.len() >= window || !self.later.refinement.ready.is_empty();
        if check.frames_seen < check.config.frames && !refinement_due {
            return Ok(());
        }
        let score = quantile(&mut check.scores, 0.5);
        let registered = score.is_none_or(|score| score >= check.config.min_score);
        if !registered {
            let refinement = &mut self.later.refinement;
            let size = refinement.size;
            refinement.refine = Processor::new(size, check.intrinsics, check.refine)?;
            let offline = OfflineConfig {
                hysteresis_frames: check.config.hysteresis_frames,
                ..self.config
            };
            refinement.hysteresis = refinement
                .refine
                .detector()
                .config()
                .slow_evidence
                .and_then(|_| Hysteresis::new(&offline, size, check.intrinsics));
        }
        self.registration_decision = Some(ColourRegistration {
            registered,
            score,
            min_score: check.config.min_score,
        });
        self.registration = None;
        Ok(())
    }

    /// Frames pushed but not yet emitted.
    pub fn pending_frames(&self) -> usize {
        let refinement = &self.later.refinement;
        self.later.buffer.len()
            + refinement.ready.len()
            + refinement.hysteresis.as_ref().map_or(0, Hysteresis::len)
    }

    /// Adds the next frame (frames in time order). Calls `emit` for every frame whose result
    /// is final now, in order: none until a block and its look-ahead are buffered, then a share
    /// of a block's frames at every push, so that a block is emitted by the time the next one's
    /// look-ahead is buffered.
    ///
    /// # Errors
    /// As [`Processor::process`], and whatever `emit` returns.
    pub fn push(&mut self, frame: &FrameInput<'_>, emit: &mut Emit<'_>) -> Result<()> {
        self.push_reducing(frame, None, emit)
    }

    /// [`Self::push`] of `frame` as `reduction` reduces it to this processor's size (`None`:
    /// `frame` is of that size). Once the registration check has decided, the reduction runs
    /// in the first pass's half of the join, beside the later passes (until then the check
    /// reads the reduced frame before the passes start): the same result, off the critical
    /// path when the later passes take longer.
    pub(crate) fn push_reducing(
        &mut self,
        frame: &FrameInput<'_>,
        mut reduction: Option<&mut FrameReduction>,
        emit: &mut Emit<'_>,
    ) -> Result<()> {
        let size = self.later.refinement.size;
        if reduction.is_none() {
            // A frame of another size fails before any pass runs.
            working_frame(frame, None, size)?;
        }
        let reduce_first = self.registration.is_some();
        if reduce_first {
            if let Some(r) = reduction.as_deref_mut() {
                r.reduce(frame)?;
            }
            self.check_registration(Some(&working_frame(frame, reduction.as_deref(), size)?))?;
        }
        let mut buffered = self.later.refinement.spare.pop().unwrap_or_else(|| {
            // The detector leaves the evidence out on small images (then the two masks agree).
            Buffered::new(
                size,
                self.later.backward.detector.config().slow_evidence.is_some(),
            )
        });
        let (first, later, config) = (&mut self.first, &mut self.later, &self.config);
        let (first_done, later_done) = rayon::join(
            || {
                if !reduce_first {
                    if let Some(r) = reduction.as_deref_mut() {
                        r.reduce(frame)?;
                    }
                }
                first.run(&working_frame(frame, reduction.as_deref(), size)?, &mut buffered)
            },
            || later.work_beside_first_pass(config, emit),
        );
        later_done?;
        first_done?;
        self.later.buffer.push_back(buffered);
        Ok(())
    }

    /// Finishes every buffered frame (the end of the sequence), calling `emit` for each.
    ///
    /// # Errors
    /// As [`Self::push`].
    pub fn finish(&mut self, emit: &mut Sink<'_>) -> Result<()> {
        self.check_registration(None)?;
        let LaterPasses {
            backward,
            buffer,
            refinement,
        } = &mut self.later;
        // One backward pass keeps every frame still buffered: block by block, each pass would
        // start a fresh detector at the same last frame and recompute the later blocks' masks.
        // It runs beside the refinement of the frames already past it (the two read different
        // frames); `emit` stays on the caller's thread.
        let mut backward_done = Ok(());
        let refined = rayon::in_place_scope(|scope| {
            scope.spawn(|_| backward_done = backward.run(buffer, buffer.len()));
            refinement.refine_ready(refinement.ready.len(), emit)
        });
        refined?;
        backward_done?;
        let later = &mut self.later;
        later.release_to_refinement(later.buffer.len());
        let refinement = &mut later.refinement;
        refinement.refine_ready(refinement.ready.len(), emit)?;
        if let Some(hysteresis) = &mut refinement.hysteresis {
            hysteresis.flush(emit)?;
        }
        Ok(())
    }
}

impl Buffered {
    fn new(size: ImageSize, slow_evidence: bool) -> Self {
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
            backward_odometry_mask: slow_evidence.then(|| Mask::filled(size, 0)),
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
                    ignore_in_previous: self.near_layer.as_ref().map(|layer| &layer.previous),
                    ..*frame
                })?;
                if let Some(layer) = &mut self.near_layer {
                    mark_near_layer(depth_m, layer.fraction, &mut layer.depths_m, &mut layer.previous);
                }
                buffered.world_from_camera = out.world_from_camera;
                buffered.first_reset = out.stats.detector_reset;
                if self.source == PoseSource::DvoClosedLoop {
                    copy_or_enlarge(out.odometry_mask, &mut buffered.first_mask);
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
    /// The work that runs beside one new frame's pass 1: the backward pass once a block and its
    /// look-ahead are buffered, and the refinement of the waiting frames spread evenly over the
    /// pushes until the next backward pass is due.
    fn work_beside_first_pass(&mut self, config: &OfflineConfig, emit: &mut Emit<'_>) -> Result<()> {
        let window = config.block_frames + config.lookahead_frames;
        if self.buffer.len() >= window {
            self.backward_pass(config.block_frames)?;
        }
        // This push and the ones after it until the buffer is full again.
        let pushes_left = window.saturating_sub(self.buffer.len()).max(1);
        let refinement = &mut self.refinement;
        refinement.refine_ready(refinement.ready.len().div_ceil(pushes_left), emit)
    }

    /// Pass 2 over every buffered frame; the first `n` then wait for refinement.
    fn backward_pass(&mut self, n: usize) -> Result<()> {
        self.backward.run(&mut self.buffer, n)?;
        self.release_to_refinement(n);
        Ok(())
    }

    /// The first `n` buffered frames, past the backward pass, go to wait for refinement.
    fn release_to_refinement(&mut self, n: usize) {
        let n = n.min(self.buffer.len());
        self.refinement.ready.extend(self.buffer.drain(..n));
    }
}

impl BackwardPass {
    /// A fresh detector from the last frame of `buffer` back to the first; the first `keep`
    /// frames keep their backward masks.
    fn run(&mut self, buffer: &mut VecDeque<Buffered>, keep: usize) -> Result<()> {
        self.detector.reset();
        // The pose of the detector's previous frame (the later one in time).
        let mut reference: Option<Isometry3<f64>> = None;
        for j in (0..buffer.len()).rev() {
            // A jump between frames j and j + 1 (the first pass reset its detector at j + 1)
            // is the same jump backwards.
            if buffer.get(j + 1).is_some_and(|later| later.first_reset) {
                self.detector.reset();
                reference = None;
            }
            let frame = &mut buffer[j];
            if !frame.has_depth {
                frame.backward_mask.fill(0);
                if let Some(seed) = &mut frame.backward_odometry_mask {
                    seed.fill(0);
                }
                continue;
            }
            let current_from_previous = reference.map_or_else(Isometry3::identity, |previous| {
                frame.world_from_camera.inverse() * previous
            });
            let gray = if self.detector.config().appearance_growth.is_some() {
                dequantize_gray_into(&frame.gray, &mut self.gray);
                Some(&self.gray)
            } else {
                None
            };
            let mask = self
                .detector
                .update_with_gray(&frame.depth_m, gray, &current_from_previous)?;
            if j < keep {
                frame
                    .backward_mask
                    .as_mut_slice()
                    .copy_from_slice(mask.as_slice());
                if let Some(seed) = &mut frame.backward_odometry_mask {
                    seed.as_mut_slice()
                        .copy_from_slice(self.detector.odometry_mask().as_slice());
                }
            }
            reference = Some(frame.world_from_camera);
        }
        Ok(())
    }
}

impl Refinement {
    /// Pass 3 and `emit` for the first `count` waiting frames, which are then recycled. Each
    /// frame's completion ([`complete_refined`]) runs on this thread beside the next frame's
    /// refinement pass, which the pool's other thread may take.
    fn refine_ready(&mut self, count: usize, emit: &mut Sink<'_>) -> Result<()> {
        let mut previous: Option<(Buffered, Refined)> = None;
        let mut result = Ok(());
        for _ in 0..count {
            let Some(frame) = self.ready.pop_front() else {
                break;
            };
            let size = self.size;
            let mut refined = self.spare_refined.pop().unwrap_or_else(|| Refined::new(size));
            let low_fraction = self.hysteresis.as_ref().map(Hysteresis::low_fraction);
            let Self {
                source,
                refine,
                gray,
                previous_seed_mask,
                has_previous_seed_mask,
                hysteresis,
                bodies,
                spare,
                spare_refined,
                candidate_row,
                ..
            } = self;
            let mut pass = RefinementPass {
                source: *source,
                refine,
                gray,
                previous_seed_mask,
                has_previous_seed_mask,
                low_fraction,
                candidate_row,
            };
            let mut refined_result = Ok(());
            let completed = rayon::in_place_scope(|scope| {
                scope.spawn(|_| refined_result = pass.run(&frame, &mut refined));
                previous.take().map_or(Ok(()), |(done, mut out)| {
                    let completed =
                        complete_refined(&done, &mut out, bodies.as_mut(), hysteresis.as_mut(), size, emit);
                    spare.push(done);
                    spare_refined.push(out);
                    completed
                })
            });
            result = completed.and(refined_result);
            if result.is_err() {
                self.spare.push(frame);
                self.spare_refined.push(refined);
                break;
            }
            previous = Some((frame, refined));
        }
        if let Some((frame, mut refined)) = previous {
            result = complete_refined(
                &frame,
                &mut refined,
                self.bodies.as_mut(),
                self.hysteresis.as_mut(),
                self.size,
                emit,
            );
            self.spare.push(frame);
            self.spare_refined.push(refined);
        }
        result
    }
}

impl RefinementPass<'_> {
    /// Pass 3 for `frame`, its results into `refined`.
    fn run(&mut self, frame: &Buffered, refined: &mut Refined) -> Result<()> {
        dequantize_gray_into(&frame.gray, self.gray);
        let closed_loop = self.source == PoseSource::DvoClosedLoop;
        let replayed_pose = match self.source {
            PoseSource::DvoClosedLoop => None,
            PoseSource::DvoUnmasked => Some(frame.world_from_camera),
            PoseSource::External { .. } => frame.world_from_marker,
        };
        let ignore = (closed_loop && *self.has_previous_seed_mask).then_some(&*self.previous_seed_mask);
        let out = self.refine.process(&FrameInput {
            timestamp_ns: frame.timestamp_ns,
            gray: self.gray,
            depth_m: &frame.depth_m,
            world_from_marker: replayed_pose.as_ref(),
            ignore_in_previous: ignore,
        })?;
        refined.index = out.index;
        refined.timestamp_ns = out.timestamp_ns;
        refined.current_from_previous = out.current_from_previous;
        refined.world_from_camera = out.world_from_camera;
        refined.stats = out.stats;
        refined
            .refinement_mask
            .as_mut_slice()
            .copy_from_slice(out.mask.as_slice());
        refined
            .odometry_mask
            .as_mut_slice()
            .copy_from_slice(out.odometry_mask.as_slice());
        refined
            .accumulation_m
            .as_mut_slice()
            .copy_from_slice(out.accumulation_m.as_slice());
        refined.candidates.clear();
        if let Some(fraction) = self.low_fraction.filter(|_| frame.has_depth) {
            self.refine
                .detector()
                .slow_candidates(fraction, self.candidate_row, &mut refined.candidates);
        }
        if closed_loop {
            for ((s, &f), &b) in self
                .previous_seed_mask
                .as_mut_slice()
                .iter_mut()
                .zip(frame.first_mask.as_slice())
                .zip(
                    frame
                        .backward_odometry_mask
                        .as_ref()
                        .unwrap_or(&frame.backward_mask)
                        .as_slice(),
                )
            {
                *s = f | b;
            }
            *self.has_previous_seed_mask = true;
        }
        Ok(())
    }
}

impl Refined {
    fn new(size: ImageSize) -> Self {
        Self {
            index: 0,
            timestamp_ns: 0,
            current_from_previous: Isometry3::identity(),
            world_from_camera: Isometry3::identity(),
            stats: FrameStats::default(),
            refinement_mask: Mask::filled(size, 0),
            odometry_mask: Mask::filled(size, 0),
            accumulation_m: DepthMeters::filled(size, 0.0),
            candidates: Vec::new(),
            mask: Mask::filled(size, 0),
        }
    }
}

/// The rest of pass 3 for a refined `frame`: `emit` (through the hysteresis, when it is on)
/// with the refinement ∪ backward mask, its objects completed to their bodies.
fn complete_refined(
    frame: &Buffered,
    refined: &mut Refined,
    bodies: Option<&mut BodyCompletion>,
    hysteresis: Option<&mut Hysteresis>,
    size: ImageSize,
    emit: &mut Sink<'_>,
) -> Result<()> {
    for ((m, &r), &b) in refined
        .mask
        .as_mut_slice()
        .iter_mut()
        .zip(refined.refinement_mask.as_slice())
        .zip(frame.backward_mask.as_slice())
    {
        *m = r | b;
    }
    if let Some(bodies) = bodies {
        bodies.complete(&mut refined.mask, &frame.depth_m)?;
    }
    let moving = refined.mask.as_slice().iter().filter(|&&m| m != 0).count();
    let mut stats = refined.stats;
    stats.detector.mask_pixels = moving;
    stats.moving_fraction = moving as f64 / size.area().max(1) as f64;
    let output = FrameOutput {
        index: refined.index,
        timestamp_ns: refined.timestamp_ns,
        mask: &refined.mask,
        odometry_mask: &refined.odometry_mask,
        current_from_previous: refined.current_from_previous,
        world_from_camera: refined.world_from_camera,
        accumulation_m: &refined.accumulation_m,
        stats,
    };
    match hysteresis {
        Some(hysteresis) => {
            hysteresis.hold(&output, &refined.refinement_mask);
            hysteresis.settle(&mut refined.candidates, emit)
        }
        None => emit(output),
    }
}

/// `frame` as `reduction` left it (`None`: as it is), checked to be of `size`.
fn working_frame<'a>(
    frame: &'a FrameInput<'a>,
    reduction: Option<&'a FrameReduction>,
    size: ImageSize,
) -> Result<FrameInput<'a>> {
    let frame = reduction.map_or(*frame, |r| r.view(frame));
    check_size("gray image", frame.gray.size(), size)?;
    check_size("depth image", frame.depth_m.size(), size)?;
    Ok(frame)
}

/// Marks in `near` (nonzero = near) the pixels of `depth_m` with valid depth nearer than
/// `fraction` × the [`FAR_LAYER_QUANTILE`] of its valid depths; nothing on a frame without
/// valid depth. `depths_m` is the work buffer.
fn mark_near_layer(depth_m: &DepthMeters, fraction: f32, depths_m: &mut Vec<f32>, near: &mut Mask) {
    let is_valid = |z: f32| z > 0.0 && z.is_finite();
    depths_m.clear();
    depths_m.extend(depth_m.as_slice().iter().copied().filter(|&z| is_valid(z)));
    let limit_m = quantile(depths_m, FAR_LAYER_QUANTILE).map_or(0.0, |far_m| far_m * fraction);
    for (n, &z) in near.as_mut_slice().iter_mut().zip(depth_m.as_slice()) {
        *n = u8::from(is_valid(z) && z < limit_m);
    }
}

/// The first pass's DVO finest level (in full-resolution terms) for images of `size`:
/// [`OfflineConfig::first_pass_finest_level`] within the configured DVO's levels, lowered until
/// its short side is at least [`OfflineConfig::first_pass_min_side_px`] (never below the DVO's
/// own finest level).
fn first_pass_finest_level(offline: &OfflineConfig, dvo: &DvoConfig, size: ImageSize) -> usize {
    let coarsest = dvo.levels_for(size).saturating_sub(1);
    let mut finest = offline.first_pass_finest_level.min(coarsest);
    while finest > dvo.finest_level && short_side(size, finest) < offline.first_pass_min_side_px {
        finest -= 1;
    }
    finest.max(dvo.finest_level)
}

/// The shorter side of pyramid `level` of `size`.
fn short_side(size: ImageSize, level: usize) -> usize {
    let s = level_size(size, level);
    s.width.min(s.height)
}

/// A refinement pass's DVO `dvo` for images of `size`: its finest level lowered until that
/// level's short side is at least [`OfflineConfig::refinement_min_side_px`] (or the level is
/// full resolution).
fn refinement_dvo(offline: &OfflineConfig, dvo: DvoConfig, size: ImageSize) -> DvoConfig {
    let mut finest_level = dvo.finest_level;
    while finest_level > 0 && short_side(size, finest_level) < offline.refinement_min_side_px {
        finest_level -= 1;
    }
    DvoConfig { finest_level, ..dvo }
}

/// The `q` quantile of `values` (reordered; the value of rank round((n − 1)·q), so 0.5 is the
/// upper median), `None` for none.
fn quantile(values: &mut [f32], q: f64) -> Option<f32> {
    let rank = ((values.len().checked_sub(1)?) as f64 * q).round() as usize;
    Some(*values.select_nth_unstable_by(rank, f32::total_cmp).1)
}

/// `requested` halvings of `size`, fewer where the image would get smaller than
/// [`MIN_REDUCED_SIDE_PX`] on its short side.
fn usable_halvings(size: ImageSize, requested: usize) -> usize {
    halvings_keeping_side(size, MIN_REDUCED_SIDE_PX, requested)
}

/// The first pass's detector parameters, for the image halved `halvings` times: the border
/// margins (in pixels) shrink with it (the object size is given at VGA and scales by itself),
/// and there is no slow-change evidence: the first pass's masks only seed the odometry of the
/// later passes, which ignores that evidence ([`crate::occlusion::OcclusionDetector::odometry_mask`]),
/// and the evidence does not enter the detector's state.
fn first_pass_occlusion_config(config: &OcclusionConfig, halvings: usize) -> OcclusionConfig {
    OcclusionConfig {
        thin_structure_border_margin_px: config.thin_structure_border_margin_px >> halvings,
        prune_exit_margin_px: config.prune_exit_margin_px >> halvings,
        slow_evidence: None,
        ..*config
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
mod tests;
