//! Pinhole camera model, lens distortion and SE(3) Lie-group helpers (pure math, no I/O).
//!
//! # Conventions (docs/method.md), stated once for the whole crate
//! - Pixels are 0-based: x = column (right), y = row (down); (cx, cy) use the same convention.
//! - Camera frames are optical frames: +x right, +y down, +z forward.
//! - Transforms are named `target_from_source` and compose right to left:
//!   `point_in_world = world_from_camera * point_in_camera`.
//! - A twist ξ ∈ ℝ⁶ is ordered **(v, ω)**: translation part first, rotation second.
//! - The camera motion between frames i (reference) and i+1 (current) is
//!   `current_from_reference = exp(ξ)`: it maps a point in camera-i coordinates into
//!   camera-(i+1) coordinates. With camera-to-world poses C it equals C_{i+1}⁻¹·C_i, and a
//!   trajectory is chained as C_{i+1} = C_i · current_from_reference⁻¹.

pub mod camera;
pub mod distortion;
pub mod se3;

pub use camera::PinholeIntrinsics;
pub use distortion::{CameraModel, LensDistortion};
pub use se3::{se3_exp, se3_log, Twist};
