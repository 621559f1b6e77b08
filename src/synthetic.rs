//! Deterministic synthetic RGB-D sequences with exact ground truth (pure: no files).
//!
//! A box-shaped room with procedurally textured walls, floor and ceiling is seen by a moving
//! pinhole camera; textured rigid boxes move through it. Every pixel is ray-cast analytically
//! (ray/axis-aligned-box slabs), so depth, the ground-truth moving-object mask and all poses are
//! exact before the sensor model is applied. Colour integrates the texture over the pixel's
//! area, as a camera pixel integrates light ([`SequenceConfig::colour_samples_per_axis`]
//! stratified, jittered samples per axis): point-sampling the texture at pixel centres aliases
//! its fine detail on the grazing floor and ceiling into patterns that do not move with the
//! scene, which biased DVO by 1–2 mm (docs/accuracy.md, "DVO"). The sensor model imitates a Kinect-style
//! structured-light camera: Gaussian depth noise whose σ grows with Z², disparity quantisation,
//! the 1/5000 m storage quantisation of TUM-style PNGs, invalid depth along depth edges, on an
//! image border ring and outside the sensing range.
//!
//! Everything is a pure function of the [`SequenceConfig`] (including its seed) and the frame
//! index: per-pixel noise comes from a counter-based hash, so rendering is deterministic however
//! rayon schedules the rows.
//!
//! # Frames
//! The world frame is "optical-like": +x right, +y **down** (the floor is at +y), +z forward
//! from the initial camera. `world_from_camera` is the usual camera-to-world pose
//! (docs/method.md "Conventions", [`crate::geometry`]).
//!
//! # Ground-truth mask
//! A pixel is set in [`SyntheticFrame::gt_mask`] when the first surface hit is a box that moved
//! between the previous frame and this one (a box that stands still is background, as for the
//! detector). Frame 0 has an empty mask unless a box moves during its first inter-frame
//! interval (measured from `t = −1/fps`).
//!
//! # Example
//! ```
//! use occmask::image_buf::ImageSize;
//! use occmask::synthetic::{Scenario, SequenceConfig, SyntheticSequence};
//! let config = SequenceConfig { size: ImageSize::new(160, 120), ..SequenceConfig::default() };
//! let sequence = SyntheticSequence::new(Scenario::SmallObjectCrossing, config);
//! let frame = sequence.frame(10);
//! assert_eq!(frame.depth_m.size(), ImageSize::new(160, 120));
//! ```

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use crate::geometry::camera::presets::KINECT_DEFAULT;
use crate::geometry::distortion::{presets as lens_presets, CameraModel, LensDistortion};
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{gray_from_rgb8_into, DepthMeters, GrayF32, Image, ImageSize, Mask, Rgb8, MASK_SET};

mod raycast;
mod scenarios;
#[cfg(test)]
mod tests;

use raycast::{apply_sensor_model, gaussian, hash3, shade, BoxInCamera, Rays, Surface, ViewSetup};
use scenarios::{box_at, leg};

/// Raw depth units per metre of the `depth_raw` images (TUM convention).
pub const DEPTH_UNITS_PER_M: f32 = 5000.0;

/// Rows rendered per rayon task: a 640-px row costs ≈ 20 µs, so 8 rows amortise task overhead
/// while leaving 60 tasks per VGA frame for load balance.
const ROWS_PER_TASK: usize = 8;

/// Default [`SequenceConfig::colour_samples_per_axis`]. Measured on the 144-case DVO test
/// (`tests/integration/dvo_synthetic.rs`): regular (unjittered) n × n grids leave a y/pitch bias whose sign
/// flips with n (n = 1…10: −1.4, +1.3, −0.1, −1.1, +0.5, −0.4, +0.3 (n = 8), −0.2 mm on 3° pitch),
/// the texture's lattice beating against the sample grid on the grazing floor and ceiling;
/// jittered 2 × 2 removes it (0.1–0.4 mm for n = 2, 3 and 4 alike) at 4× the shading cost.
pub const DEFAULT_COLOUR_SAMPLES_PER_AXIS: usize = 2;

/// Kinect-like depth sensor model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthSensorModel {
    /// σ of the depth noise is `noise_coeff_per_m · Z²` (metres). 1.425e-3 /m is the Kinect v1
    /// axial-noise fit of Nguyen, Izadi & Lovell (3DIMPVT 2012) at mid range.
    pub noise_coeff_per_m: f32,
    /// Disparity quantisation step in pixels (Kinect v1: 1/8 px); 0 disables it.
    pub disparity_step_px: f32,
    /// Stereo baseline in metres used for disparity quantisation (Kinect v1: 0.075 m).
    pub baseline_m: f32,
    /// A pixel is invalid when a 4-neighbour's true depth is nearer by more than this (metres),
    /// imitating the missing depth on the background side of occlusion edges of
    /// structured-light sensors (the projector's shadow).
    pub edge_jump_m: f32,
    /// Width in pixels of the image border ring with no depth.
    pub border_px: usize,
    /// Nearest measurable depth (m); closer surfaces read as invalid.
    pub min_depth_m: f32,
    /// Farthest measurable depth (m); farther surfaces read as invalid.
    pub max_depth_m: f32,
    /// Additional per-pixel random dropout probability in [0, 1].
    pub dropout_probability: f32,
}

impl Default for DepthSensorModel {
    fn default() -> Self {
        Self {
            noise_coeff_per_m: 1.425e-3,
            disparity_step_px: 0.125,
            baseline_m: 0.075,
            edge_jump_m: 0.1,
            border_px: 4,
            min_depth_m: 0.4,
            max_depth_m: 8.0,
            dropout_probability: 0.002,
        }
    }
}

impl DepthSensorModel {
    /// A perfect sensor: no noise, no quantisation, no invalid pixels (range 0..∞).
    pub fn ideal() -> Self {
        Self {
            noise_coeff_per_m: 0.0,
            disparity_step_px: 0.0,
            baseline_m: 0.075,
            edge_jump_m: f32::INFINITY,
            border_px: 0,
            min_depth_m: 0.0,
            max_depth_m: f32::INFINITY,
            dropout_probability: 0.0,
        }
    }
}

/// Everything that defines a synthetic sequence besides its [`Scenario`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SequenceConfig {
    /// Image size; intrinsics scale with the width from the Kinect default (525 px at 640).
    pub size: ImageSize,
    /// Seed of every random choice (texture, noise).
    pub seed: u64,
    /// Frames per second (timestamps and motion per frame).
    pub fps: f64,
    /// Depth sensor model.
    pub sensor: DepthSensorModel,
    /// σ of the per-channel colour noise, in 8-bit levels (0 disables it).
    pub rgb_noise_levels: f32,
    /// Colour samples per pixel along each image axis: a pixel's colour is the mean of
    /// n × n samples, one at a random (per frame and pixel, deterministic) position in each cell
    /// of an n × n grid over the pixel, each cast as its own ray (silhouette pixels mix both
    /// surfaces, as a real pixel does). 1 samples the pixel centre only (the point-sampling
    /// renderer this replaced). Depth and the ground-truth mask always come from the centre ray.
    pub colour_samples_per_axis: usize,
    /// Number of frames; `None` uses the scenario's default length.
    pub frame_count: Option<usize>,
}

impl Default for SequenceConfig {
    fn default() -> Self {
        Self {
            size: ImageSize::new(640, 480),
            seed: 1,
            fps: 30.0,
            sensor: DepthSensorModel::default(),
            rgb_noise_levels: 1.0,
            colour_samples_per_axis: DEFAULT_COLOUR_SAMPLES_PER_AXIS,
            frame_count: None,
        }
    }
}

impl SequenceConfig {
    /// The Kinect default intrinsics (525 px, principal point at the centre) scaled to `size.width`.
    pub fn intrinsics(&self) -> PinholeIntrinsics {
        let scale = self.size.width as f64 / 640.0;
        PinholeIntrinsics::new(
            KINECT_DEFAULT.fx * scale,
            KINECT_DEFAULT.fy * scale,
            (self.size.width as f64 - 1.0) * 0.5,
            (self.size.height as f64 - 1.0) * 0.5,
        )
    }
}

/// The built-in scenarios (all in the same 6 m × 3 m × 6 m room).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Scenario {
    /// A 0.3 m box crosses the view at 2 m while the camera sways.
    SmallObjectCrossing,
    /// A 1.0 m × 1.6 m board passes 1.15 m in front of the camera and covers 50–75 % of the image
    /// for many frames (the case where unmasked DVO locks onto the object).
    DominantObject,
    /// The camera pans right while a box enters from the right image border.
    EnteringWhilePanning,
    /// Two boxes at different depths cross in opposite directions (one occludes the other).
    TwoObjectsCrossing,
    /// A box stands still for 1 s, then moves sideways and towards the camera.
    StillThenMoving,
    /// A box walks in from the side, then approaches the camera slowly (0.4 m/s).
    SlowApproach,
    /// Nothing moves but the camera (control for false positives).
    StaticScene,
    /// A 0.5 m box at 2.2 m is already moving sideways (0.6 m/s) at the first frame
    /// ([`FailureClass::LateOnset`]).
    InViewAtStart,
    /// A 0.5 m box at 1.8 m rests for 1.5 s, then slides sideways slowly (0.35 m/s, its own width
    /// in 43 frames) ([`FailureClass::LateOnset`]).
    RestsThenMovesSlowly,
    /// A box already moving at the first frame (0.8 m/s sideways) stops for 1 s, then moves off
    /// diagonally towards the camera ([`FailureClass::LateOnset`], twice).
    StopAndGo,
    /// A 0.6 m × 0.7 m box straight ahead on the optical axis rests for 0.5 s, then approaches
    /// the camera head-on at 0.7 m/s from 3.5 m to 1.4 m ([`FailureClass::HeadOnApproach`]).
    HeadOnApproach,
    /// The camera looks down (34°) at a desk; a 40 cm × 30 cm box slides across the desk top
    /// into the view at 0.6 m/s, seen against the desk just behind it except for its top,
    /// which passes in front of the far wall ([`FailureClass::NearBackground`]).
    SlidingOnDesk,
    /// A 1.2 m × 1.6 m board 1.3 m in front of the camera covers 76 % of the first frame and
    /// moves sideways (0.35 m/s) ([`FailureClass::DominantFromStart`]).
    DominantFromStart,
    /// The desk of [`Scenario::SlidingOnDesk`] with nothing on it (static control with a
    /// static box in view: [`FailureClass::StaticControl`]).
    StaticDesk,
    /// Held out: a 0.36 m box at 3 m already moving at the first frame (0.8 m/s sideways and
    /// slightly away), another camera path and textures ([`FailureClass::LateOnset`]).
    HeldOutInViewAtStart,
    /// Held out: a tall box at 2.5 m rests for 1.2 s, then moves sideways and closer
    /// (0.5 / 0.2 m/s) while the camera pans slowly ([`FailureClass::LateOnset`]).
    HeldOutRestsThenMoves,
    /// Held out: a 0.44 m × 0.6 m box off the optical axis is already approaching head-on at
    /// the first frame (0.6 m/s, from 3.85 m to 1.85 m) ([`FailureClass::HeadOnApproach`]).
    HeldOutHeadOnApproach,
    /// Held out: the camera looks down (26°) at the floor; a 24 cm tall box slides along it into
    /// the view (0.5 m/s) ([`FailureClass::NearBackground`]).
    HeldOutSlidingOnFloor,
    /// Held out: a 1.5 m × 1.8 m board 1.5 m away covers 82 % of the first frame and moves
    /// sideways while turning (0.3 m/s, 2.3 °/s) ([`FailureClass::DominantFromStart`]).
    HeldOutDominantFromStart,
    /// Held out: a panning, tilted camera in a room with a static shelf and a static cabinet
    /// ([`FailureClass::StaticControl`]).
    HeldOutStatic,
    /// Held out: a 1.1 m × 1.7 m block standing on the floor 1.5 m away covers more than half of
    /// the first frame and slides sideways (0.4 m/s); the camera looks down 20°, so the floor it
    /// stands on is in view below it, as under a person walking past
    /// ([`FailureClass::DominantFromStart`]).
    HeldOutDominantOnFloor,
    /// Held out: a 0.9 m × 1.75 m block standing on the floor 1.05 m away covers more than half
    /// of the first frame and moves off diagonally while turning (0.35 m/s sideways, 0.1 m/s
    /// away, 6 °/s); the camera pans after it, looking down 15°
    /// ([`FailureClass::DominantFromStart`]).
    HeldOutCloseOnFloor,
    /// Held out: a low, wide block (1.6 m × 1.0 m × 0.6 m, a sofa or a cart) standing on the
    /// floor 1.4 m away covers more than half of the first frame, its front and its top in
    /// view, and moves slowly sideways while turning (0.25 m/s, 0.05 m/s away, −3 °/s); the
    /// camera looks down 30°, so the floor is in view below it ([`FailureClass::DominantFromStart`]).
    HeldOutWideOnFloor,
    /// Held out: a cart (0.9 m × 0.9 m × 0.5 m) standing on the floor 2.2 m away, in view and
    /// moving at the first frame, rolls slowly sideways (0.3 m/s: its edges advance about
    /// 1.2 px a frame at 320×240) while the camera drifts, looking down 15°
    /// ([`FailureClass::LateOnset`]).
    HeldOutSlowCart,
}

/// The failure classes the later scenarios exercise (objects the occlusion detector finds
/// late, or not at all).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FailureClass {
    /// An object in view at the first frame, or one that rests and then starts to move: only
    /// the parts leaving its own footprint occlude anything.
    LateOnset,
    /// An object approaching the camera head-on: its depth decreases by a few centimetres per
    /// frame, far below the accumulation threshold, and only its expanding outline occludes.
    HeadOnApproach,
    /// An object moving close to the surface behind it: only where it passes in front of
    /// farther background is the occlusion above the threshold.
    NearBackground,
    /// An object that dominates the view from the first frame (the odometry must not follow it).
    DominantFromStart,
    /// Nothing moves but the camera (false-positive control).
    StaticControl,
}

impl FailureClass {
    /// A short snake_case name.
    pub fn name(self) -> &'static str {
        match self {
            FailureClass::LateOnset => "late_onset",
            FailureClass::HeadOnApproach => "head_on_approach",
            FailureClass::NearBackground => "near_background",
            FailureClass::DominantFromStart => "dominant_from_start",
            FailureClass::StaticControl => "static_control",
        }
    }
}

impl Scenario {
    /// The original scenarios, in declaration order (those every older test and tool iterates;
    /// [`Scenario::FAILURE_CLASSES`] and [`Scenario::HELD_OUT`] list the others, [`Scenario::EVERY`] all).
    pub const ALL: [Scenario; 7] = [
        Scenario::SmallObjectCrossing,
        Scenario::DominantObject,
        Scenario::EnteringWhilePanning,
        Scenario::TwoObjectsCrossing,
        Scenario::StillThenMoving,
        Scenario::SlowApproach,
        Scenario::StaticScene,
    ];

    /// The failure-class scenarios that defaults may be developed on, one or more per
    /// [`FailureClass`].
    pub const FAILURE_CLASSES: [Scenario; 7] = [
        Scenario::InViewAtStart,
        Scenario::RestsThenMovesSlowly,
        Scenario::StopAndGo,
        Scenario::HeadOnApproach,
        Scenario::SlidingOnDesk,
        Scenario::DominantFromStart,
        Scenario::StaticDesk,
    ];

    /// Held-out scenarios: the same failure classes with other seeds, sizes, speeds, depths and
    /// camera paths. No default is tuned on them; report them apart.
    pub const HELD_OUT: [Scenario; 10] = [
        Scenario::HeldOutInViewAtStart,
        Scenario::HeldOutRestsThenMoves,
        Scenario::HeldOutHeadOnApproach,
        Scenario::HeldOutSlidingOnFloor,
        Scenario::HeldOutDominantFromStart,
        Scenario::HeldOutStatic,
        Scenario::HeldOutDominantOnFloor,
        Scenario::HeldOutCloseOnFloor,
        Scenario::HeldOutWideOnFloor,
        Scenario::HeldOutSlowCart,
    ];

    /// Every scenario: [`Scenario::ALL`], then [`Scenario::FAILURE_CLASSES`], then
    /// [`Scenario::HELD_OUT`].
    pub const EVERY: [Scenario; 24] = [
        Scenario::SmallObjectCrossing,
        Scenario::DominantObject,
        Scenario::EnteringWhilePanning,
        Scenario::TwoObjectsCrossing,
        Scenario::StillThenMoving,
        Scenario::SlowApproach,
        Scenario::StaticScene,
        Scenario::InViewAtStart,
        Scenario::RestsThenMovesSlowly,
        Scenario::StopAndGo,
        Scenario::HeadOnApproach,
        Scenario::SlidingOnDesk,
        Scenario::DominantFromStart,
        Scenario::StaticDesk,
        Scenario::HeldOutInViewAtStart,
        Scenario::HeldOutRestsThenMoves,
        Scenario::HeldOutHeadOnApproach,
        Scenario::HeldOutSlidingOnFloor,
        Scenario::HeldOutDominantFromStart,
        Scenario::HeldOutStatic,
        Scenario::HeldOutDominantOnFloor,
        Scenario::HeldOutCloseOnFloor,
        Scenario::HeldOutWideOnFloor,
        Scenario::HeldOutSlowCart,
    ];

    /// The scenario called `name` ([`Self::name`]).
    pub fn from_name(name: &str) -> Option<Scenario> {
        Scenario::EVERY.into_iter().find(|s| s.name() == name)
    }

    /// True for the [`Scenario::HELD_OUT`] scenarios.
    pub fn is_held_out(self) -> bool {
        Scenario::HELD_OUT.contains(&self)
    }

    /// The failure class a later scenario was built for (`None` for the original ones, whose
    /// static control is [`Scenario::StaticScene`]).
    pub fn failure_class(self) -> Option<FailureClass> {
        match self {
            Scenario::SmallObjectCrossing
            | Scenario::DominantObject
            | Scenario::EnteringWhilePanning
            | Scenario::TwoObjectsCrossing
            | Scenario::StillThenMoving
            | Scenario::SlowApproach
            | Scenario::StaticScene => None,
            Scenario::InViewAtStart
            | Scenario::RestsThenMovesSlowly
            | Scenario::StopAndGo
            | Scenario::HeldOutInViewAtStart
            | Scenario::HeldOutRestsThenMoves
            | Scenario::HeldOutSlowCart => Some(FailureClass::LateOnset),
            Scenario::HeadOnApproach | Scenario::HeldOutHeadOnApproach => Some(FailureClass::HeadOnApproach),
            Scenario::SlidingOnDesk | Scenario::HeldOutSlidingOnFloor => Some(FailureClass::NearBackground),
            Scenario::DominantFromStart
            | Scenario::HeldOutDominantFromStart
            | Scenario::HeldOutDominantOnFloor
            | Scenario::HeldOutCloseOnFloor
            | Scenario::HeldOutWideOnFloor => Some(FailureClass::DominantFromStart),
            Scenario::StaticDesk | Scenario::HeldOutStatic => Some(FailureClass::StaticControl),
        }
    }

    /// True when nothing but the camera moves (the ground truth is empty in every frame).
    pub fn is_static(self) -> bool {
        matches!(
            self,
            Scenario::StaticScene | Scenario::StaticDesk | Scenario::HeldOutStatic
        )
    }

    /// A short snake_case name (for tables and file names).
    pub fn name(self) -> &'static str {
        match self {
            Scenario::SmallObjectCrossing => "small_object_crossing",
            Scenario::DominantObject => "dominant_object",
            Scenario::EnteringWhilePanning => "entering_while_panning",
            Scenario::TwoObjectsCrossing => "two_objects_crossing",
            Scenario::StillThenMoving => "still_then_moving",
            Scenario::SlowApproach => "slow_approach",
            Scenario::StaticScene => "static_scene",
            Scenario::InViewAtStart => "in_view_at_start",
            Scenario::RestsThenMovesSlowly => "rests_then_moves_slowly",
            Scenario::StopAndGo => "stop_and_go",
            Scenario::HeadOnApproach => "head_on_approach",
            Scenario::SlidingOnDesk => "sliding_on_desk",
            Scenario::DominantFromStart => "dominant_from_start",
            Scenario::StaticDesk => "static_desk",
            Scenario::HeldOutInViewAtStart => "held_out_in_view_at_start",
            Scenario::HeldOutRestsThenMoves => "held_out_rests_then_moves",
            Scenario::HeldOutHeadOnApproach => "held_out_head_on_approach",
            Scenario::HeldOutSlidingOnFloor => "held_out_sliding_on_floor",
            Scenario::HeldOutDominantFromStart => "held_out_dominant_from_start",
            Scenario::HeldOutStatic => "held_out_static",
            Scenario::HeldOutDominantOnFloor => "held_out_dominant_on_floor",
            Scenario::HeldOutCloseOnFloor => "held_out_close_on_floor",
            Scenario::HeldOutWideOnFloor => "held_out_wide_on_floor",
            Scenario::HeldOutSlowCart => "held_out_slow_cart",
        }
    }
}

/// Smooth camera trajectory: position `p0 + v·t + a ⊙ sin(2πt/T + φ)`, yaw (about −y, i.e.
/// turning right for positive values) `yaw0 + yaw_rate·t + yaw_amp·sin(2πt/T)`, and a small
/// pitch oscillation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraPath {
    /// Position at t = 0 (m, world).
    pub start_m: Vector3<f64>,
    /// Constant velocity (m/s, world).
    pub velocity_mps: Vector3<f64>,
    /// Sway amplitude per axis (m).
    pub sway_amplitude_m: Vector3<f64>,
    /// Sway period (s).
    pub sway_period_s: f64,
    /// Constant yaw rate (rad/s; positive turns the view to the right).
    pub yaw_rate_radps: f64,
    /// Yaw oscillation amplitude (rad).
    pub yaw_amplitude_rad: f64,
    /// Pitch oscillation amplitude (rad).
    pub pitch_amplitude_rad: f64,
    /// Constant pitch (rad) the oscillation is added to: positive tilts the view up (towards
    /// −y), negative down towards the floor (a camera looking down at a desk).
    pub pitch_offset_rad: f64,
}

impl CameraPath {
    /// A camera that never moves, at the room's standard viewpoint.
    pub fn fixed() -> Self {
        Self {
            start_m: Vector3::zeros(),
            velocity_mps: Vector3::zeros(),
            sway_amplitude_m: Vector3::zeros(),
            sway_period_s: 1.0,
            yaw_rate_radps: 0.0,
            yaw_amplitude_rad: 0.0,
            pitch_amplitude_rad: 0.0,
            pitch_offset_rad: 0.0,
        }
    }

    /// A hand-held-like camera: slow drift plus a few centimetres and degrees of sway.
    pub fn handheld() -> Self {
        Self {
            start_m: Vector3::zeros(),
            velocity_mps: Vector3::new(0.05, 0.0, 0.08),
            sway_amplitude_m: Vector3::new(0.06, 0.03, 0.04),
            sway_period_s: 2.7,
            yaw_rate_radps: 0.0,
            yaw_amplitude_rad: 0.06,
            pitch_amplitude_rad: 0.03,
            pitch_offset_rad: 0.0,
        }
    }

    /// `world_from_camera` at time `t_s`.
    pub fn world_from_camera(&self, t_s: f64) -> Isometry3<f64> {
        let phase = std::f64::consts::TAU * t_s / self.sway_period_s;
        let sway = Vector3::new(
            self.sway_amplitude_m.x * phase.sin(),
            self.sway_amplitude_m.y * (2.0 * phase + 0.7).sin(),
            self.sway_amplitude_m.z * (phase + 1.3).sin(),
        );
        let position = self.start_m + self.velocity_mps * t_s + sway;
        let yaw = self.yaw_rate_radps * t_s + self.yaw_amplitude_rad * (phase + 0.4).sin();
        let pitch = self.pitch_offset_rad + self.pitch_amplitude_rad * (1.5 * phase).sin();
        // +yaw turns the optical axis (+z) towards +x: rotation about +y by +yaw (y points down,
        // so this is a right turn as seen from above).
        let rotation = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), yaw)
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), pitch);
        Isometry3::from_parts(Translation3::from(position), rotation)
    }
}

/// One leg of a box's motion: constant linear and yaw velocity for t in [start_s, stop_s].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionLeg {
    /// Start of the leg (s).
    pub start_s: f64,
    /// End of the leg (s); may be infinite.
    pub stop_s: f64,
    /// Linear velocity of the box centre (m/s, world).
    pub velocity_mps: Vector3<f64>,
    /// Angular velocity about the world y axis (rad/s).
    pub yaw_rate_radps: f64,
}

/// A textured rigid box moving piecewise with constant velocities (legs may overlap: their
/// displacements add up).
#[derive(Debug, Clone, PartialEq)]
pub struct MovingBox {
    /// Half extents along the box's own axes (m).
    pub half_extents_m: Vector3<f64>,
    /// Pose of the box centre at t = 0 (world_from_object).
    pub world_from_object_start: Isometry3<f64>,
    /// Motion legs; outside every leg the box stands still.
    pub legs: Vec<MotionLeg>,
    /// Seed of the box's texture.
    pub texture_seed: u64,
}

impl MovingBox {
    /// `world_from_object` at time `t_s`.
    pub fn world_from_object(&self, t_s: f64) -> Isometry3<f64> {
        let mut displacement = Vector3::zeros();
        let mut yaw = 0.0;
        for leg in &self.legs {
            let moving_s = t_s.clamp(leg.start_s, leg.stop_s) - leg.start_s;
            displacement += leg.velocity_mps * moving_s;
            yaw += leg.yaw_rate_radps * moving_s;
        }
        let start = self.world_from_object_start;
        let rotation = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), yaw);
        Isometry3::from_parts(
            Translation3::from(start.translation.vector + displacement),
            rotation * start.rotation,
        )
    }

    /// True when the box moves at some time in (t0_s, t1_s].
    pub fn moves_between(&self, t0_s: f64, t1_s: f64) -> bool {
        self.legs.iter().any(|leg| {
            let moving = leg.velocity_mps.norm() > 0.0 || leg.yaw_rate_radps != 0.0;
            moving && t1_s > leg.start_s && t0_s < leg.stop_s
        })
    }
}

/// The static room: an axis-aligned box seen from inside (m, world frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Room {
    /// Minimum corner (m).
    pub min_m: Vector3<f64>,
    /// Maximum corner (m).
    pub max_m: Vector3<f64>,
    /// Seed of the wall textures.
    pub texture_seed: u64,
}

impl Room {
    /// The standard room: 6 m wide, 3 m high (floor 1.4 m below the camera), 6 m deep
    /// (far wall 4.5 m ahead, back wall 1.5 m behind the start position).
    pub fn standard(seed: u64) -> Self {
        Self {
            min_m: Vector3::new(-3.0, -1.6, -1.5),
            max_m: Vector3::new(3.0, 1.4, 4.5),
            texture_seed: seed,
        }
    }
}

/// A complete synthetic world: room, camera path, boxes and sensor.
#[derive(Debug, Clone, PartialEq)]
pub struct SyntheticSequence {
    /// Scenario the sequence was built from (`None` for hand-built scenes).
    pub scenario: Option<Scenario>,
    /// Configuration (size, seed, fps, sensor).
    pub config: SequenceConfig,
    /// The room.
    pub room: Room,
    /// The camera path.
    pub camera: CameraPath,
    /// The boxes.
    pub boxes: Vec<MovingBox>,
    /// Number of frames.
    pub frame_count: usize,
}

/// One rendered RGB-D frame with its ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct SyntheticFrame {
    /// Frame index in the sequence.
    pub index: usize,
    /// Timestamp (ns): index / fps.
    pub timestamp_ns: u64,
    /// Colour image.
    pub rgb: Rgb8,
    /// Gray image in [0, 1] (BT.601 luma of `rgb`).
    pub gray: GrayF32,
    /// Measured depth (m, 0 = invalid), equal to `depth_raw / 5000`.
    pub depth_m: DepthMeters,
    /// Raw 16-bit depth, [`DEPTH_UNITS_PER_M`] units per metre (0 = invalid).
    pub depth_raw: Image<u16>,
    /// Exact depth of the first surface hit (m), before the sensor model.
    pub depth_true_m: DepthMeters,
    /// Ground-truth moving-object mask (boxes that moved since the previous frame).
    pub gt_mask: Mask,
    /// Which surface the centre ray hits first: 1 + the index of the box in
    /// [`SyntheticSequence::boxes`], 0 for the room (moving or not: [`Self::gt_mask`] says
    /// whether it moved; boxes beyond the 254th all read 255): splits the ground truth per object.
    pub object_index: Image<u8>,
    /// Ground-truth camera pose.
    pub world_from_camera: Isometry3<f64>,
    /// Ground-truth pose of every box (same order as [`SyntheticSequence::boxes`]).
    pub world_from_objects: Vec<Isometry3<f64>>,
    /// Camera intrinsics.
    pub intrinsics: PinholeIntrinsics,
}

impl SyntheticFrame {
    /// An all-zero frame of `size` (buffers for [`SyntheticSequence::render_into`]).
    pub fn empty(size: ImageSize) -> Self {
        Self {
            index: 0,
            timestamp_ns: 0,
            rgb: Image::filled(size, [0; 3]),
            gray: Image::filled(size, 0.0),
            depth_m: Image::filled(size, 0.0),
            depth_raw: Image::filled(size, 0),
            depth_true_m: Image::filled(size, 0.0),
            gt_mask: Image::filled(size, 0),
            object_index: Image::filled(size, 0),
            world_from_camera: Isometry3::identity(),
            world_from_objects: Vec::new(),
            intrinsics: PinholeIntrinsics::new(1.0, 1.0, 0.0, 0.0),
        }
    }

    /// Fraction of pixels set in the ground-truth mask.
    pub fn gt_fraction(&self) -> f64 {
        let set = self.gt_mask.as_slice().iter().filter(|&&m| m != 0).count();
        set as f64 / self.gt_mask.size().area() as f64
    }
}

impl SyntheticSequence {
    /// A sequence with a custom camera path and boxes in the standard room.
    pub fn custom(
        config: SequenceConfig,
        camera: CameraPath,
        boxes: Vec<MovingBox>,
        frame_count: usize,
    ) -> Self {
        Self {
            scenario: None,
            config,
            room: Room::standard(config.seed),
            camera,
            boxes,
            frame_count,
        }
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.frame_count
    }

    /// True when the sequence has no frames.
    pub fn is_empty(&self) -> bool {
        self.frame_count == 0
    }

    /// Time of frame `index` (s).
    pub fn time_s(&self, index: usize) -> f64 {
        index as f64 / self.config.fps
    }

    /// Timestamp of frame `index` (ns).
    pub fn timestamp_ns(&self, index: usize) -> u64 {
        (index as f64 * 1e9 / self.config.fps).round() as u64
    }

    /// Ground-truth `world_from_camera` of frame `index`.
    pub fn world_from_camera(&self, index: usize) -> Isometry3<f64> {
        self.camera.world_from_camera(self.time_s(index))
    }

    /// Ground-truth inter-frame motion `current_from_previous` = C_i⁻¹·C_{i−1} for frame
    /// `index ≥ 1` (identity for frame 0).
    pub fn current_from_previous(&self, index: usize) -> Isometry3<f64> {
        if index == 0 {
            return Isometry3::identity();
        }
        self.world_from_camera(index).inverse() * self.world_from_camera(index - 1)
    }

    /// Renders frame `index` into a new frame.
    pub fn frame(&self, index: usize) -> SyntheticFrame {
        let mut frame = SyntheticFrame::empty(self.config.size);
        self.render_into(index, &mut frame);
        frame
    }

    /// Renders frame `index` into `frame`, reusing its buffers when the size matches.
    pub fn render_into(&self, index: usize, frame: &mut SyntheticFrame) {
        let pose = self.world_from_camera(index);
        self.render_view_into(index, self.time_s(index), &pose, frame);
    }

    /// Renders the world at time `t_s` from an arbitrary `world_from_camera`; `index` only seeds
    /// the per-frame noise and is stored in the frame. The mask marks boxes moving in
    /// (t_s − 1/fps, t_s].
    pub fn render_view_into(
        &self,
        index: usize,
        t_s: f64,
        world_from_camera: &Isometry3<f64>,
        frame: &mut SyntheticFrame,
    ) {
        let camera = CameraModel::pinhole(self.config.size, self.config.intrinsics());
        self.render_camera_into(index, t_s, world_from_camera, &camera, true, frame);
    }

    /// [`Self::render_view_into`] through any camera: its size, intrinsics and lens distortion
    /// (each pixel's rays are undistorted, so a distorted camera's image bends straight
    /// lines as a real lens does). Without `shade`, colour is not computed (left black): a
    /// depth camera's view. The depth sensor model uses the camera's fx for its disparity.
    pub fn render_camera_into(
        &self,
        index: usize,
        t_s: f64,
        world_from_camera: &Isometry3<f64>,
        camera: &CameraModel,
        shade_colour: bool,
        frame: &mut SyntheticFrame,
    ) {
        let size = camera.size;
        if frame.depth_m.size() != size {
            *frame = SyntheticFrame::empty(size);
        }
        let intrinsics = camera.intrinsics;
        frame.index = index;
        frame.timestamp_ns = (t_s * 1e9).round().max(0.0) as u64;
        frame.world_from_camera = *world_from_camera;
        frame.intrinsics = intrinsics;
        frame.world_from_objects.clear();
        frame
            .world_from_objects
            .extend(self.boxes.iter().map(|b| b.world_from_object(t_s)));

        let boxes: Vec<BoxInCamera> = self
            .boxes
            .iter()
            .zip(&frame.world_from_objects)
            .map(|(b, world_from_object)| {
                let object_from_camera = world_from_object.inverse() * world_from_camera;
                BoxInCamera {
                    rotation: object_from_camera.rotation.to_rotation_matrix().into_inner(),
                    origin: object_from_camera.translation.vector,
                    half: b.half_extents_m,
                    moving: b.moves_between(t_s - 1.0 / self.config.fps, t_s),
                    faces: std::array::from_fn(|face| {
                        Surface::new(b.texture_seed ^ (face as u64).wrapping_mul(0x9e37))
                    }),
                }
            })
            .collect();
        let view = ViewSetup {
            rays: Rays::new(camera),
            world_rotation: world_from_camera.rotation.to_rotation_matrix().into_inner(),
            world_origin: world_from_camera.translation.vector,
            room: self.room,
            room_faces: std::array::from_fn(|face| {
                Surface::new(self.room.texture_seed ^ (face as u64 + 1).wrapping_mul(0x51_7cc1_b727))
            }),
            boxes,
        };
        let width = size.width;
        let noise_seed = hash3(self.config.seed, index as u64, 0x5eed);
        let rgb_noise = self.config.rgb_noise_levels;
        let samples_per_axis = self.config.colour_samples_per_axis;

        frame
            .depth_true_m
            .as_mut_slice()
            .par_chunks_mut(ROWS_PER_TASK * width)
            .zip(frame.rgb.as_mut_slice().par_chunks_mut(ROWS_PER_TASK * width))
            .zip(frame.gt_mask.as_mut_slice().par_chunks_mut(ROWS_PER_TASK * width))
            .zip(
                frame
                    .object_index
                    .as_mut_slice()
                    .par_chunks_mut(ROWS_PER_TASK * width),
            )
            .enumerate()
            .for_each(|(chunk, (((depth_rows, rgb_rows), mask_rows), object_rows))| {
                let rows = depth_rows
                    .chunks_exact_mut(width)
                    .zip(rgb_rows.chunks_exact_mut(width))
                    .zip(mask_rows.chunks_exact_mut(width))
                    .zip(object_rows.chunks_exact_mut(width));
                for (row, (((depth_row, rgb_row), mask_row), object_row)) in rows.enumerate() {
                    let y = chunk * ROWS_PER_TASK + row;
                    for x in 0..width {
                        let Some((ray_x, ray_y)) = view.rays.centre(x, y) else {
                            // No ray (beyond a lens model's fold): nothing is seen there.
                            depth_row[x] = 0.0;
                            mask_row[x] = 0;
                            object_row[x] = 0;
                            rgb_row[x] = [0; 3];
                            continue;
                        };
                        let hit = view.cast(ray_x, ray_y);
                        depth_row[x] = hit.depth_m as f32;
                        mask_row[x] = if hit.moving { MASK_SET } else { 0 };
                        object_row[x] = hit.object;
                        if !shade_colour {
                            continue;
                        }
                        let pixel_key = (y * width + x) as u64;
                        let rgb = if samples_per_axis <= 1 {
                            shade(hit.surface, hit.u_m, hit.v_m)
                        } else {
                            view.pixel_colour(x, y, samples_per_axis, hash3(noise_seed, pixel_key, 0x717))
                        };
                        for (c, value) in rgb_row[x].iter_mut().enumerate() {
                            let noise = if rgb_noise > 0.0 {
                                rgb_noise * gaussian(noise_seed, pixel_key * 4 + c as u64)
                            } else {
                                0.0
                            };
                            // `as u8` saturates; +0.5 rounds (values are ≥ 0 after the clamp).
                            *value = ((rgb[c] * 255.0 + noise).max(0.0) + 0.5) as u8;
                        }
                    }
                }
            });
        gray_from_rgb8_into(&frame.rgb, &mut frame.gray).expect("same size by construction");
        apply_sensor_model(
            &self.config.sensor,
            intrinsics.fx as f32,
            noise_seed,
            &frame.depth_true_m,
            &mut frame.depth_raw,
            &mut frame.depth_m,
        );
    }
}

/// Kinect-class lens distortion for synthetic colour cameras: TUM's published freiburg1
/// calibration (a Kinect v1), whose image corners move by ≈ 9 px at 640×480.
pub const KINECT_LIKE_DISTORTION: LensDistortion = lens_presets::TUM_FR1;

/// A colour and a depth camera on one rig, for rendering recordings as a driver publishes
/// them: colour through its lens (distortion), depth from its own camera and pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RgbdRig {
    /// The colour camera (the ground-truth poses and masks are this camera's).
    pub color: CameraModel,
    /// The depth camera.
    pub depth: CameraModel,
    /// The depth camera's pose in the colour camera's optical frame.
    pub color_from_depth: Isometry3<f64>,
}

impl RgbdRig {
    /// One pinhole camera for both (what [`SyntheticSequence::render_into`] renders).
    pub fn registered(config: &SequenceConfig) -> Self {
        let camera = CameraModel::pinhole(config.size, config.intrinsics());
        Self {
            color: camera,
            depth: camera,
            color_from_depth: Isometry3::identity(),
        }
    }

    /// A RealSense D435-like rig at `config.size` (numbers for 640 columns, scaled with the
    /// width): colour = the config's camera with [`KINECT_LIKE_DISTORTION`]; depth 848×480
    /// with fx = fy = 427, (cx, cy) = (425.1, 238.6) and no distortion (the D435's depth is
    /// rectified), 15 mm to the colour camera's right with a 0.2° rotation, as its factory
    /// extrinsics are.
    pub fn realsense_like(config: &SequenceConfig) -> Self {
        let s = config.size.width as f64 / 640.0;
        let depth_size = ImageSize::new((848.0 * s).round() as usize, (480.0 * s).round() as usize);
        Self {
            color: CameraModel {
                size: config.size,
                intrinsics: config.intrinsics(),
                distortion: Some(KINECT_LIKE_DISTORTION),
            },
            depth: CameraModel::pinhole(
                depth_size,
                PinholeIntrinsics::new(427.0 * s, 427.0 * s, 425.1 * s, 238.6 * s),
            ),
            color_from_depth: Isometry3::new(
                Vector3::new(0.015, 0.0001, 0.0003),
                Vector3::new(0.002, -0.003, 0.001),
            ),
        }
    }
}

impl SyntheticSequence {
    /// Renders frame `index` through `rig`: `color` gets the colour camera's view (colour,
    /// grey, ground-truth mask, and the depth along its own rays, which no sensor of the rig
    /// measures), `depth` the depth camera's (`depth_raw`/`depth_m` with the sensor model; no
    /// colour). Both at the colour camera's ground-truth pose and time.
    pub fn render_rig_into(
        &self,
        index: usize,
        rig: &RgbdRig,
        color: &mut SyntheticFrame,
        depth: &mut SyntheticFrame,
    ) {
        let t_s = self.time_s(index);
        let world_from_color = self.world_from_camera(index);
        self.render_camera_into(index, t_s, &world_from_color, &rig.color, true, color);
        let world_from_depth = world_from_color * rig.color_from_depth;
        self.render_camera_into(index, t_s, &world_from_depth, &rig.depth, false, depth);
    }
}

/// Two frames of the standard room seen from a fixed viewpoint, the second one moved by
/// `current_from_reference` (so DVO should recover exactly that motion), for DVO accuracy tests.
///
/// With `with_moving_box`, a textured box covering ≈ 30 % of the reference view stands 1.5 m in
/// front of the camera and moves 5 cm to the right between the two frames (its pixels are set in
/// both frames' `gt_mask`). Timestamps are 0 and 1/fps.
pub fn motion_pair(
    config: SequenceConfig,
    current_from_reference: &Isometry3<f64>,
    with_moving_box: bool,
) -> (SyntheticFrame, SyntheticFrame) {
    let dt_s = 1.0 / config.fps;
    let mut boxes = Vec::new();
    if with_moving_box {
        // Front face at z = 1.5 m; 1.0 m × 0.75 m covers ≈ 350 × 263 px of 640 × 480 (30 %).
        // The leg starts at −dt, so the centre is at x = −0.25 m in the reference frame (t = 0).
        boxes.push(box_at(
            Vector3::new(-0.25 - 0.05, 0.0, 1.7),
            Vector3::new(0.5, 0.375, 0.2),
            leg(-dt_s, dt_s, Vector3::new(0.05 / dt_s, 0.0, 0.0), 0.0),
            config.seed ^ 0x99,
        ));
    }
    let sequence = SyntheticSequence::custom(config, CameraPath::fixed(), boxes, 2);
    let world_from_reference = Isometry3::identity();
    let world_from_current = world_from_reference * current_from_reference.inverse();
    let mut reference = SyntheticFrame::empty(config.size);
    let mut current = SyntheticFrame::empty(config.size);
    // The box moves during (−dt, dt], so both frames see it as moving.
    sequence.render_view_into(0, 0.0, &world_from_reference, &mut reference);
    sequence.render_view_into(1, dt_s, &world_from_current, &mut current);
    (reference, current)
}
