//! Per-pixel state transport (algorithm.md §1 steps 2–9): warp field, depth compensation,
//! occlusion map ΔZ, carried A and P, accumulation, truncations and the newly discovered area.
//!
//! [`transport`] is the fused, row-parallel kernel used by the detector; [`transport_scalar`]
//! is a literal step-by-step reference (one full-image pass per step, nalgebra projection) kept
//! for the agreement test.

use nalgebra::{Isometry3, Point3};
use rayon::prelude::*;

use super::{OcclusionConfig, WarpDepth};
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, Image};

/// Rows per rayon task: one VGA row costs ≈ 2 µs, so 16 rows (≈ 30 µs) amortise the task
/// overhead while 30 tasks per frame still balance two to eight cores.
const ROWS_PER_TASK: usize = 16;

/// Read-only inputs of the transport step.
pub struct TransportInputs<'a> {
    /// Normalised ray x per column, (x − cx)/fx.
    pub ray_x: &'a [f64],
    /// Normalised ray y per row, (y − cy)/fy.
    pub ray_y: &'a [f64],
    /// Camera intrinsics.
    pub intrinsics: &'a PinholeIntrinsics,
    /// exp(−ξ): maps current-camera points into the previous camera.
    pub previous_from_current: &'a Isometry3<f64>,
    /// Thresholds.
    pub config: &'a OcclusionConfig,
    /// Measured depth of the current frame (m, 0 = invalid).
    pub depth_m: &'a DepthMeters,
    /// Compensated depth of the previous frame (m).
    pub compensated_previous_m: &'a DepthMeters,
    /// Accumulation map of the previous frame (m).
    pub accumulation_previous_m: &'a DepthMeters,
    /// Predicted-area map of the previous frame (0 / 1).
    pub predicted_previous: &'a Image<u8>,
}

/// Outputs of the transport step (all the detector's size).
pub struct TransportOutputs<'a> {
    /// Zc_{i+1} (m).
    pub compensated_m: &'a mut DepthMeters,
    /// A after accumulation and both truncations (m).
    pub accumulation_m: &'a mut DepthMeters,
    /// P̂: P_i sampled through the warp (0 / 1).
    pub predicted_carried: &'a mut Image<u8>,
    /// ΔZ (m).
    pub delta_z_m: &'a mut DepthMeters,
    /// Ñ (0 / 1).
    pub newly_discovered: &'a mut Image<u8>,
}

/// Pixel counts of one transport.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TransportCounts {
    /// Pixels with a valid warp.
    pub warped: usize,
    /// Pixels in Ñ.
    pub newly_discovered: usize,
}

/// The fused row-parallel transport kernel.
pub fn transport(inputs: &TransportInputs<'_>, outputs: TransportOutputs<'_>) -> TransportCounts {
    let width = inputs.depth_m.width();
    let height = inputs.depth_m.height();
    let (max_x, max_y) = ((width - 1) as f64, (height - 1) as f64);
    let rotation = inputs
        .previous_from_current
        .rotation
        .to_rotation_matrix()
        .into_inner();
    let translation = inputs.previous_from_current.translation.vector;
    let k = inputs.intrinsics;
    let geometric = inputs.config.warp_depth == WarpDepth::Current;
    let column0 = rotation.column(0);
    let chunk = ROWS_PER_TASK * width;
    let config = inputs.config;
    let previous_zc = inputs.compensated_previous_m.as_slice();
    let previous_a = inputs.accumulation_previous_m.as_slice();
    let previous_p = inputs.predicted_previous.as_slice();
    outputs
        .compensated_m
        .as_mut_slice()
        .par_chunks_mut(chunk)
        .zip(outputs.accumulation_m.as_mut_slice().par_chunks_mut(chunk))
        .zip(outputs.predicted_carried.as_mut_slice().par_chunks_mut(chunk))
        .zip(outputs.delta_z_m.as_mut_slice().par_chunks_mut(chunk))
        .zip(outputs.newly_discovered.as_mut_slice().par_chunks_mut(chunk))
        .enumerate()
        .map(|(task, ((((zc_rows, a_rows), p_rows), dz_rows), n_rows))| {
            let mut counts = TransportCounts::default();
            for (row, ((((zc_row, a_row), p_row), dz_row), n_row)) in zc_rows
                .chunks_exact_mut(width)
                .zip(a_rows.chunks_exact_mut(width))
                .zip(p_rows.chunks_exact_mut(width))
                .zip(dz_rows.chunks_exact_mut(width))
                .zip(n_rows.chunks_exact_mut(width))
                .enumerate()
            {
                let y = task * ROWS_PER_TASK + row;
                let ray_y = inputs.ray_y[y];
                // R·(rx, ry, 1) = rx·R[:,0] + (ry·R[:,1] + R[:,2]); the bracket is constant per row.
                let row_term = rotation.column(1) * ray_y + rotation.column(2);
                let previous_row = inputs.compensated_previous_m.row(y);
                let measured_row = inputs.depth_m.row(y);
                for (x, ((((((zc, a), p), dz), n), &measured), &previous)) in zc_row
                    .iter_mut()
                    .zip(a_row.iter_mut())
                    .zip(p_row.iter_mut())
                    .zip(dz_row.iter_mut())
                    .zip(n_row.iter_mut())
                    .zip(measured_row)
                    .zip(previous_row)
                    .enumerate()
                {
                    let use_current = geometric && measured > 0.0;
                    let z_back_projected = if use_current { measured } else { previous } as f64;
                    let mut source = usize::MAX;
                    let mut warped_depth_m = 0.0f32;
                    if z_back_projected > 0.0 {
                        let z = z_back_projected;
                        let ray_x = inputs.ray_x[x];
                        let qx = z * (column0.x * ray_x + row_term.x) + translation.x;
                        let qy = z * (column0.y * ray_x + row_term.y) + translation.y;
                        let qz = z * (column0.z * ray_x + row_term.z) + translation.z;
                        if qz > 0.0 {
                            let u = k.fx * qx / qz + k.cx;
                            let v = k.fy * qy / qz + k.cy;
                            if (0.0..=max_x).contains(&u) && (0.0..=max_y).contains(&v) {
                                // Nearest pixel: both coordinates are ≥ 0, so +0.5 and truncation round.
                                source = (v + 0.5) as usize * width + (u + 0.5) as usize;
                                warped_depth_m = qz as f32;
                            }
                        }
                    }
                    // Steps 3–9 (as `finish_pixel`, inlined on hoisted slices).
                    let warped = source != usize::MAX;
                    let (sampled_m, accumulation_carried, predicted_carried) = if warped {
                        (previous_zc[source], previous_a[source], previous_p[source])
                    } else {
                        (0.0, 0.0, 0)
                    };
                    let compensated_m = if measured > 0.0 { measured } else { sampled_m };
                    let compared_m = if use_current && warped {
                        warped_depth_m
                    } else {
                        compensated_m
                    };
                    let delta_z_m = if warped { sampled_m - compared_m } else { 0.0 };
                    let mut accumulation_m = accumulation_carried + delta_z_m;
                    if accumulation_m <= config.threshold(config.alpha, compensated_m) {
                        accumulation_m = 0.0;
                    }
                    if delta_z_m <= -config.threshold(config.beta, compensated_m) {
                        accumulation_m = 0.0;
                    }
                    let newly = compensated_m > 0.0 && sampled_m == 0.0;
                    *zc = compensated_m;
                    *a = accumulation_m;
                    *p = predicted_carried;
                    *dz = delta_z_m;
                    *n = u8::from(newly);
                    counts.warped += usize::from(warped);
                    counts.newly_discovered += usize::from(newly);
                }
            }
            counts
        })
        .reduce(TransportCounts::default, |a, b| TransportCounts {
            warped: a.warped + b.warped,
            newly_discovered: a.newly_discovered + b.newly_discovered,
        })
}

/// Reference implementation: the algorithm.md §1 steps as separate full-image passes, with
/// nalgebra transforms and [`PinholeIntrinsics::project`]. Slow; for tests.
pub fn transport_scalar(inputs: &TransportInputs<'_>, outputs: TransportOutputs<'_>) -> TransportCounts {
    let size = inputs.depth_m.size();
    let (width, height) = (size.width, size.height);
    // Step 2: warp field.
    let mut warp: Vec<Option<usize>> = vec![None; size.area()];
    let mut warped_depth: Vec<Option<f32>> = vec![None; size.area()];
    let geometric = inputs.config.warp_depth == WarpDepth::Current;
    for y in 0..height {
        for x in 0..width {
            let measured = inputs.depth_m.get(x, y);
            let use_current = geometric && measured > 0.0;
            let z = if use_current {
                measured
            } else {
                inputs.compensated_previous_m.get(x, y)
            };
            if z <= 0.0 {
                continue;
            }
            let point_in_current = inputs.intrinsics.back_project(x as f64, y as f64, z as f64);
            let point_in_previous: Point3<f64> = inputs.previous_from_current * point_in_current;
            if let Some(pixel) = inputs.intrinsics.project(&point_in_previous) {
                if pixel.x >= 0.0
                    && pixel.y >= 0.0
                    && pixel.x <= (width - 1) as f64
                    && pixel.y <= (height - 1) as f64
                {
                    warp[y * width + x] = Some(pixel.y.round() as usize * width + pixel.x.round() as usize);
                    warped_depth[y * width + x] = use_current.then_some(point_in_previous.z as f32);
                }
            }
        }
    }
    // Steps 3–9, pixel by pixel in the documented order.
    let mut counts = TransportCounts::default();
    for (i, source) in warp.iter().enumerate() {
        let (x, y) = (i % width, i / width);
        let measured = inputs.depth_m.get(x, y);
        let sampled = source.map_or(0.0, |n| inputs.compensated_previous_m.as_slice()[n]);
        let compensated = if measured > 0.0 { measured } else { sampled };
        let delta_z = if source.is_some() {
            sampled - compensated
        } else {
            0.0
        };
        let carried_a = source.map_or(0.0, |n| inputs.accumulation_previous_m.as_slice()[n]);
        let carried_p = source.map_or(0, |n| inputs.predicted_previous.as_slice()[n]);
        let mut a = carried_a + delta_z;
        let config = inputs.config;
        if a <= config.threshold(config.alpha, compensated) {
            a = 0.0;
        }
        if delta_z <= -config.threshold(config.beta, compensated) {
            a = 0.0;
        }
        let newly = (sampled == 0.0) != (compensated == 0.0);
        outputs.compensated_m.set(x, y, compensated);
        outputs.delta_z_m.set(x, y, delta_z);
        outputs.accumulation_m.set(x, y, a);
        outputs.predicted_carried.set(x, y, carried_p);
        outputs.newly_discovered.set(x, y, u8::from(newly));
        counts.warped += usize::from(source.is_some());
        counts.newly_discovered += usize::from(newly);
    }
    counts
}
