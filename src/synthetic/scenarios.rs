//! The built-in scenarios: each one's room, camera path and moving boxes.

use super::*;

pub(super) fn box_at(center: Vector3<f64>, half: Vector3<f64>, legs: Vec<MotionLeg>, seed: u64) -> MovingBox {
    MovingBox {
        half_extents_m: half,
        world_from_object_start: Isometry3::translation(center.x, center.y, center.z),
        legs,
        texture_seed: seed,
    }
}

/// A box that never moves (furniture): part of the background, never in the ground truth.
pub(super) fn static_box(center: Vector3<f64>, half: Vector3<f64>, seed: u64) -> MovingBox {
    box_at(center, half, Vec::new(), seed)
}

/// A box that has moved with `velocity_mps` since `since_s` (< 0, so it moves during frame 0's
/// interval and frame 0's ground truth holds it) and is centred at `center_at_zero` at t = 0.
pub(super) fn box_moving_since(
    center_at_zero: Vector3<f64>,
    half: Vector3<f64>,
    since_s: f64,
    velocity_mps: Vector3<f64>,
    yaw_rate_radps: f64,
    seed: u64,
) -> MovingBox {
    box_at(
        center_at_zero + velocity_mps * since_s,
        half,
        leg(since_s, f64::INFINITY, velocity_mps, yaw_rate_radps),
        seed,
    )
}

/// XOR-ed into the sequence seed for the room texture of the held-out scenarios, so that they
/// are not seen through the walls the other scenarios were developed on.
pub(super) const HELD_OUT_ROOM_SALT: u64 = 0x0e1d_4e1d_5a17;

/// Seconds the boxes of the "already moving" scenarios have moved before frame 0.
pub(super) const MOVING_SINCE_S: f64 = -1.0;

/// Pitch of the camera looking down at the desk (34°): the desk top fills the middle of the
/// image, its front below, a band of the far wall above.
pub(super) const DESK_CAMERA_PITCH_RAD: f64 = -0.6;

/// The desk of [`Scenario::SlidingOnDesk`] and [`Scenario::StaticDesk`]: a block 2.6 m wide and
/// 1.8 m deep standing on the floor, its top 0.7 m above the floor (y = 0.7, 0.7 m below the
/// camera), from 0.9 m to 2.7 m ahead.
pub(super) fn desk(seed: u64) -> MovingBox {
    static_box(
        Vector3::new(0.0, 1.05, 1.8),
        Vector3::new(1.3, 0.35, 0.9),
        seed ^ 0x8d,
    )
}

/// The camera of the desk scenarios: hand-held, looking down at the desk, drifting slowly.
pub(super) fn desk_camera() -> CameraPath {
    CameraPath {
        velocity_mps: Vector3::new(0.02, 0.0, 0.03),
        pitch_offset_rad: DESK_CAMERA_PITCH_RAD,
        ..CameraPath::handheld()
    }
}

pub(super) fn leg(
    start_s: f64,
    stop_s: f64,
    velocity_mps: Vector3<f64>,
    yaw_rate_radps: f64,
) -> Vec<MotionLeg> {
    vec![MotionLeg {
        start_s,
        stop_s,
        velocity_mps,
        yaw_rate_radps,
    }]
}

impl SyntheticSequence {
    /// Builds one of the built-in scenarios.
    pub fn new(scenario: Scenario, config: SequenceConfig) -> Self {
        let seed = config.seed;
        let room = if scenario.is_held_out() {
            Room::standard(seed ^ HELD_OUT_ROOM_SALT)
        } else {
            Room::standard(seed)
        };
        let forever = f64::INFINITY;
        let (camera, boxes, default_frames) = match scenario {
            Scenario::SmallObjectCrossing => {
                let b = box_at(
                    Vector3::new(-1.6, 0.2, 2.0),
                    Vector3::new(0.15, 0.15, 0.15),
                    leg(0.0, forever, Vector3::new(1.0, 0.0, 0.0), 0.0),
                    seed ^ 0x11,
                );
                (CameraPath::handheld(), vec![b], 90)
            }
            Scenario::DominantObject => {
                // Front face 1.15 m away: 1.0 m covers ≈ 460 of 640 columns and the full height,
                // so the box covers up to ≈ 75 % of the view but never all of it (no visual
                // odometry can work when nothing static is visible).
                let b = box_at(
                    Vector3::new(-1.45, 0.1, 1.35),
                    Vector3::new(0.5, 0.8, 0.2),
                    leg(0.0, forever, Vector3::new(0.45, 0.0, 0.0), 0.05),
                    seed ^ 0x22,
                );
                (CameraPath::handheld(), vec![b], 150)
            }
            Scenario::EnteringWhilePanning => {
                let camera = CameraPath {
                    yaw_rate_radps: 0.2,
                    yaw_amplitude_rad: 0.0,
                    velocity_mps: Vector3::new(0.0, 0.0, 0.05),
                    ..CameraPath::handheld()
                };
                let b = box_at(
                    Vector3::new(2.3, 0.0, 2.4),
                    Vector3::new(0.3, 0.4, 0.25),
                    leg(0.0, forever, Vector3::new(-0.8, 0.0, 0.0), 0.0),
                    seed ^ 0x33,
                );
                (camera, vec![b], 90)
            }
            Scenario::TwoObjectsCrossing => {
                let near = box_at(
                    Vector3::new(-1.3, 0.25, 1.8),
                    Vector3::new(0.25, 0.3, 0.2),
                    leg(0.0, forever, Vector3::new(0.9, 0.0, 0.0), 0.0),
                    seed ^ 0x44,
                );
                let far = box_at(
                    Vector3::new(1.6, -0.1, 3.0),
                    Vector3::new(0.3, 0.35, 0.25),
                    leg(0.0, forever, Vector3::new(-1.0, 0.0, 0.0), 0.0),
                    seed ^ 0x55,
                );
                (CameraPath::handheld(), vec![near, far], 90)
            }
            Scenario::StillThenMoving => {
                let b = box_at(
                    Vector3::new(-0.4, 0.2, 2.2),
                    Vector3::new(0.25, 0.3, 0.2),
                    leg(1.0, forever, Vector3::new(0.9, 0.0, -0.4), 0.0),
                    seed ^ 0x66,
                );
                (CameraPath::handheld(), vec![b], 90)
            }
            Scenario::SlowApproach => {
                let walk_in = MotionLeg {
                    start_s: 0.0,
                    stop_s: 1.4,
                    velocity_mps: Vector3::new(0.9, 0.0, 0.0),
                    yaw_rate_radps: 0.0,
                };
                let approach = MotionLeg {
                    start_s: 1.4,
                    stop_s: forever,
                    velocity_mps: Vector3::new(0.0, 0.0, -0.4),
                    yaw_rate_radps: 0.0,
                };
                let b = box_at(
                    Vector3::new(-1.4, 0.1, 3.2),
                    Vector3::new(0.25, 0.35, 0.2),
                    vec![walk_in, approach],
                    seed ^ 0x77,
                );
                (CameraPath::handheld(), vec![b], 120)
            }
            Scenario::StaticScene => (CameraPath::handheld(), Vec::new(), 90),
            Scenario::InViewAtStart => {
                let b = box_moving_since(
                    Vector3::new(-0.7, 0.15, 2.4),
                    Vector3::new(0.25, 0.3, 0.2),
                    MOVING_SINCE_S,
                    Vector3::new(0.6, 0.0, 0.0),
                    0.0,
                    seed ^ 0x81,
                );
                (CameraPath::handheld(), vec![b], 90)
            }
            Scenario::RestsThenMovesSlowly => {
                let b = box_at(
                    Vector3::new(0.5, 0.05, 2.0),
                    Vector3::new(0.25, 0.35, 0.2),
                    leg(1.5, forever, Vector3::new(-0.35, 0.0, 0.0), 0.0),
                    seed ^ 0x82,
                );
                (CameraPath::handheld(), vec![b], 120)
            }
            Scenario::StopAndGo => {
                let sideways = MotionLeg {
                    start_s: -0.5,
                    stop_s: 1.0,
                    velocity_mps: Vector3::new(0.8, 0.0, 0.0),
                    yaw_rate_radps: 0.0,
                };
                let off_and_closer = MotionLeg {
                    start_s: 2.0,
                    stop_s: forever,
                    velocity_mps: Vector3::new(-0.3, 0.0, -0.5),
                    yaw_rate_radps: 0.0,
                };
                // At x = −0.9 + 0.8 · 0.5 = −0.5 m at t = 0, −0.1 m while it rests.
                let b = box_at(
                    Vector3::new(-0.9, 0.2, 2.5),
                    Vector3::new(0.2, 0.3, 0.2),
                    vec![sideways, off_and_closer],
                    seed ^ 0x83,
                );
                (CameraPath::handheld(), vec![b], 120)
            }
            Scenario::HeadOnApproach => {
                // Front face from 3.5 m (t ≤ 0.5 s) to 1.4 m (t = 3.5 s, frame 105).
                let b = box_at(
                    Vector3::new(0.0, 0.1, 3.7),
                    Vector3::new(0.3, 0.35, 0.2),
                    leg(0.5, forever, Vector3::new(0.0, 0.0, -0.7), 0.0),
                    seed ^ 0x84,
                );
                // Hand-held sway, but no forward drift: the box alone closes the distance.
                let camera = CameraPath {
                    velocity_mps: Vector3::new(0.02, 0.0, 0.0),
                    ..CameraPath::handheld()
                };
                (camera, vec![b], 105)
            }
            Scenario::SlidingOnDesk => {
                // Resting on the desk top (y = 0.7), 1.5 m ahead; enters the view from the left.
                let b = box_at(
                    Vector3::new(-1.2, 0.55, 1.5),
                    Vector3::new(0.2, 0.15, 0.15),
                    leg(0.0, forever, Vector3::new(0.6, 0.0, 0.0), 0.0),
                    seed ^ 0x85,
                );
                (desk_camera(), vec![desk(seed), b], 100)
            }
            Scenario::DominantFromStart => {
                let b = box_moving_since(
                    Vector3::new(-0.15, 0.1, 1.4),
                    Vector3::new(0.6, 0.8, 0.1),
                    MOVING_SINCE_S,
                    Vector3::new(0.35, 0.0, 0.0),
                    0.0,
                    seed ^ 0x86,
                );
                (CameraPath::handheld(), vec![b], 120)
            }
            Scenario::StaticDesk => (desk_camera(), vec![desk(seed)], 90),
            Scenario::HeldOutInViewAtStart => {
                let b = box_moving_since(
                    Vector3::new(0.6, -0.05, 3.1),
                    Vector3::new(0.18, 0.25, 0.15),
                    2.0 * MOVING_SINCE_S,
                    Vector3::new(-0.8, 0.0, 0.1),
                    0.0,
                    seed ^ 0x91,
                );
                let camera = CameraPath {
                    start_m: Vector3::new(0.1, -0.05, 0.0),
                    velocity_mps: Vector3::new(-0.04, 0.0, 0.05),
                    sway_amplitude_m: Vector3::new(0.04, 0.02, 0.05),
                    sway_period_s: 3.3,
                    yaw_rate_radps: 0.04,
                    yaw_amplitude_rad: 0.05,
                    pitch_amplitude_rad: 0.02,
                    pitch_offset_rad: 0.0,
                };
                (camera, vec![b], 90)
            }
            Scenario::HeldOutRestsThenMoves => {
                let b = box_at(
                    Vector3::new(0.7, 0.0, 2.7),
                    Vector3::new(0.2, 0.45, 0.18),
                    leg(1.2, forever, Vector3::new(-0.5, 0.0, -0.2), 0.0),
                    seed ^ 0x92,
                );
                let camera = CameraPath {
                    velocity_mps: Vector3::new(0.03, 0.0, 0.04),
                    sway_amplitude_m: Vector3::new(0.05, 0.03, 0.03),
                    sway_period_s: 2.2,
                    yaw_rate_radps: -0.06,
                    ..CameraPath::handheld()
                };
                (camera, vec![b], 100)
            }
            Scenario::HeldOutHeadOnApproach => {
                // Front face from 3.85 m (frame 0) to 1.85 m (frame 100).
                let b = box_moving_since(
                    Vector3::new(0.25, -0.05, 4.0),
                    Vector3::new(0.22, 0.3, 0.15),
                    MOVING_SINCE_S,
                    Vector3::new(0.0, 0.0, -0.6),
                    0.0,
                    seed ^ 0x93,
                );
                let camera = CameraPath {
                    start_m: Vector3::zeros(),
                    velocity_mps: Vector3::new(-0.02, 0.0, 0.0),
                    sway_amplitude_m: Vector3::new(0.05, 0.03, 0.03),
                    sway_period_s: 2.3,
                    yaw_rate_radps: 0.0,
                    yaw_amplitude_rad: 0.04,
                    pitch_amplitude_rad: 0.025,
                    pitch_offset_rad: 0.0,
                };
                (camera, vec![b], 100)
            }
            Scenario::HeldOutSlidingOnFloor => {
                // Resting on the floor (y = 1.4), 2.2 m ahead; enters the view from the right.
                let b = box_at(
                    Vector3::new(1.8, 1.28, 2.2),
                    Vector3::new(0.2, 0.12, 0.2),
                    leg(0.0, forever, Vector3::new(-0.5, 0.0, -0.05), 0.0),
                    seed ^ 0x94,
                );
                let camera = CameraPath {
                    start_m: Vector3::new(0.0, -0.1, 0.0),
                    velocity_mps: Vector3::new(0.0, 0.0, 0.04),
                    sway_amplitude_m: Vector3::new(0.05, 0.02, 0.03),
                    sway_period_s: 2.9,
                    yaw_rate_radps: 0.0,
                    yaw_amplitude_rad: 0.05,
                    pitch_amplitude_rad: 0.02,
                    pitch_offset_rad: -0.45,
                };
                (camera, vec![b], 100)
            }
            Scenario::HeldOutDominantFromStart => {
                let b = box_moving_since(
                    Vector3::new(0.15, 0.0, 1.62),
                    Vector3::new(0.75, 0.9, 0.12),
                    MOVING_SINCE_S,
                    Vector3::new(-0.3, 0.0, 0.0),
                    0.04,
                    seed ^ 0x95,
                );
                let camera = CameraPath {
                    start_m: Vector3::zeros(),
                    velocity_mps: Vector3::new(-0.03, 0.0, 0.05),
                    sway_amplitude_m: Vector3::new(0.05, 0.03, 0.03),
                    sway_period_s: 3.1,
                    yaw_rate_radps: 0.0,
                    yaw_amplitude_rad: 0.05,
                    pitch_amplitude_rad: 0.025,
                    pitch_offset_rad: 0.0,
                };
                (camera, vec![b], 120)
            }
            Scenario::HeldOutStatic => {
                let shelf = static_box(
                    Vector3::new(-1.6, 0.5, 2.6),
                    Vector3::new(0.25, 0.9, 0.6),
                    seed ^ 0x96,
                );
                let cabinet = static_box(
                    Vector3::new(0.8, 1.1, 2.8),
                    Vector3::new(0.6, 0.3, 0.3),
                    seed ^ 0x97,
                );
                let camera = CameraPath {
                    start_m: Vector3::zeros(),
                    velocity_mps: Vector3::new(0.03, 0.0, 0.06),
                    sway_amplitude_m: Vector3::new(0.05, 0.03, 0.04),
                    sway_period_s: 2.5,
                    yaw_rate_radps: 0.1,
                    yaw_amplitude_rad: 0.03,
                    pitch_amplitude_rad: 0.03,
                    pitch_offset_rad: -0.15,
                };
                (camera, vec![shelf, cabinet], 90)
            }
            Scenario::HeldOutDominantOnFloor => {
                // Standing on the floor (y = 1.4): centre 0.85 m above it.
                let b = box_moving_since(
                    Vector3::new(-0.1, 0.55, 1.55),
                    Vector3::new(0.55, 0.85, 0.2),
                    MOVING_SINCE_S,
                    Vector3::new(0.4, 0.0, 0.0),
                    -0.03,
                    seed ^ 0x98,
                );
                let camera = CameraPath {
                    start_m: Vector3::new(0.0, 0.05, 0.0),
                    velocity_mps: Vector3::new(0.02, 0.0, -0.03),
                    sway_amplitude_m: Vector3::new(0.04, 0.03, 0.03),
                    sway_period_s: 2.3,
                    yaw_rate_radps: 0.0,
                    yaw_amplitude_rad: 0.04,
                    pitch_amplitude_rad: 0.02,
                    pitch_offset_rad: -0.35,
                };
                (camera, vec![b], 90)
            }
            Scenario::HeldOutCloseOnFloor => {
                // Standing on the floor (y = 1.4): centre 0.875 m above it, front face at 1.05 m.
                let b = box_moving_since(
                    Vector3::new(-0.1, 0.525, 1.25),
                    Vector3::new(0.45, 0.875, 0.2),
                    MOVING_SINCE_S,
                    Vector3::new(0.35, 0.0, 0.1),
                    0.1,
                    seed ^ 0x99,
                );
                let camera = CameraPath {
                    start_m: Vector3::new(0.0, 0.1, 0.0),
                    velocity_mps: Vector3::new(0.03, 0.0, 0.02),
                    sway_amplitude_m: Vector3::new(0.03, 0.02, 0.03),
                    sway_period_s: 1.9,
                    yaw_rate_radps: 0.05,
                    yaw_amplitude_rad: 0.03,
                    pitch_amplitude_rad: 0.02,
                    pitch_offset_rad: -0.26,
                };
                (camera, vec![b], 90)
            }
            Scenario::HeldOutWideOnFloor => {
                // Standing on the floor (y = 1.4): centre 0.5 m above it, front face at 1.4 m.
                let b = box_moving_since(
                    Vector3::new(0.1, 0.9, 1.7),
                    Vector3::new(0.8, 0.5, 0.3),
                    MOVING_SINCE_S,
                    Vector3::new(-0.25, 0.0, 0.05),
                    -0.05,
                    seed ^ 0x9a,
                );
                let camera = CameraPath {
                    start_m: Vector3::zeros(),
                    velocity_mps: Vector3::new(-0.02, 0.0, 0.03),
                    sway_amplitude_m: Vector3::new(0.04, 0.02, 0.03),
                    sway_period_s: 2.6,
                    yaw_rate_radps: 0.0,
                    yaw_amplitude_rad: 0.04,
                    pitch_amplitude_rad: 0.02,
                    pitch_offset_rad: -0.52,
                };
                (camera, vec![b], 90)
            }
            Scenario::HeldOutSlowCart => {
                // Standing on the floor (y = 1.4): centre 0.45 m above it, front face at 2.2 m.
                let b = box_moving_since(
                    Vector3::new(0.3, 0.95, 2.45),
                    Vector3::new(0.45, 0.45, 0.25),
                    MOVING_SINCE_S,
                    Vector3::new(-0.3, 0.0, 0.0),
                    0.0,
                    seed ^ 0x9b,
                );
                let camera = CameraPath {
                    start_m: Vector3::zeros(),
                    velocity_mps: Vector3::new(0.02, 0.0, 0.03),
                    sway_amplitude_m: Vector3::new(0.04, 0.02, 0.03),
                    sway_period_s: 2.7,
                    yaw_rate_radps: 0.0,
                    yaw_amplitude_rad: 0.04,
                    pitch_amplitude_rad: 0.02,
                    pitch_offset_rad: -0.26,
                };
                (camera, vec![b], 90)
            }
        };
        Self {
            scenario: Some(scenario),
            config,
            room,
            camera,
            boxes,
            frame_count: config.frame_count.unwrap_or(default_frames),
        }
    }
}
