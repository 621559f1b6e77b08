//! The fused transport over the frame: its inputs, outputs, scratch and counts, and the
//! row-parallel loop that runs the per-row kernels of [`super`] band by band.

use nalgebra::Isometry3;
use rayon::prelude::*;

use super::{
    finish_row, warp_row, FinishParameters, FinishRow, PixelBounds, PixelRays, Simd, SlowRow, WarpParameters,
    NO_SOURCE, ROWS_PER_TASK,
};
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, Image};
use crate::occlusion::{OcclusionConfig, ThresholdForm, WarpDepth};

/// Per-sequence scratch of the fast kernel (allocated once).
#[derive(Debug, Clone)]
pub struct TransportScratch {
    /// R·ray_x per column, one vector per component of the rotated ray (per frame).
    column_terms: [Vec<f32>; 3],
    /// Warp sources (pixel index into the previous frame, or `NO_SOURCE`) of one row per
    /// parallel task: each task reuses its row, which stays in L1 (a whole-image buffer would
    /// cost 8 bytes of memory traffic per pixel).
    source_rows: Vec<u32>,
    /// One row per parallel task holding z′, then ΔZ, when ΔZ is not recorded
    /// ([`TransportOutputs::delta_z_m`] is None).
    staging_rows: Vec<f32>,
    /// One unused value per parallel task: the slow-evidence rows when W is not kept.
    no_slow_rows: Vec<f32>,
    /// The geometric warp's sources and z′ of one row per parallel task, for W when the
    /// detector's own warp is the release's ([`crate::occlusion::WarpDepth::PreviousCompensated`]).
    slow_source_rows: Vec<u32>,
    slow_qz_rows: Vec<f32>,
}

impl TransportScratch {
    /// Scratch for a `width` × `height` image.
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            column_terms: [vec![0.0; width], vec![0.0; width], vec![0.0; width]],
            source_rows: vec![NO_SOURCE; height.div_ceil(ROWS_PER_TASK) * width],
            staging_rows: vec![0.0; height.div_ceil(ROWS_PER_TASK) * width],
            no_slow_rows: vec![0.0; height.div_ceil(ROWS_PER_TASK)],
            slow_source_rows: vec![NO_SOURCE; height.div_ceil(ROWS_PER_TASK) * width],
            slow_qz_rows: vec![0.0; height.div_ceil(ROWS_PER_TASK) * width],
        }
    }
}

/// Read-only inputs of the transport step.
pub struct TransportInputs<'a> {
    /// Normalised pixel rays (fast kernel only).
    pub rays: &'a PixelRays,
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
    /// Slow-change evidence W of the previous frame (m) and its retention, when it is kept
    /// ([`crate::occlusion::SlowEvidenceConfig`]).
    pub slow_previous: Option<(&'a DepthMeters, f32)>,
}

/// Outputs of the transport step (all the detector's size).
pub struct TransportOutputs<'a> {
    /// Zc_{i+1} (m).
    pub compensated_m: &'a mut DepthMeters,
    /// A after accumulation and both truncations (m).
    pub accumulation_m: &'a mut DepthMeters,
    /// P̂: P_i sampled through the warp (0 / 1).
    pub predicted_carried: &'a mut Image<u8>,
    /// ΔZ (m), when it is recorded (it is no input to any later step: only for inspection).
    pub delta_z_m: Option<&'a mut DepthMeters>,
    /// Ñ (0 / 1).
    pub newly_discovered: &'a mut Image<u8>,
    /// 1 where A > τ_α (the object set O₀), else 0; one entry per pixel.
    pub object_set: &'a mut [u8],
    /// W = retention · Ŵ + min(ΔZ, τ_α) where the warp is valid, the background did not
    /// reappear (ΔZ > −τ_β) and ΔZ ≤ τ_α or, with
    /// [`crate::occlusion::SlowEvidenceConfig::occlusion_events`], the warp's source is off a
    /// depth edge; else 0 (m), when [`TransportInputs::slow_previous`] is given.
    pub slow_m: Option<&'a mut DepthMeters>,
}

/// Pixel counts of one transport.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TransportCounts {
    /// Pixels with a valid warp.
    pub warped: usize,
    /// Pixels in Ñ.
    pub newly_discovered: usize,
    /// Pixels in the object set O₀.
    pub object: usize,
    /// Bounding box of O₀ (None when empty).
    pub object_bounds: Option<PixelBounds>,
}

impl TransportCounts {
    fn merge(a: Self, b: Self) -> Self {
        Self {
            warped: a.warped + b.warped,
            newly_discovered: a.newly_discovered + b.newly_discovered,
            object: a.object + b.object,
            object_bounds: PixelBounds::union(a.object_bounds, b.object_bounds),
        }
    }
}

/// The fused row-parallel transport kernel (f32 warp). Also writes the object labels O₀.
/// Runs the widest build the CPU supports ([`Simd::detect`]).
pub fn transport(
    inputs: &TransportInputs<'_>,
    scratch: &mut TransportScratch,
    outputs: TransportOutputs<'_>,
) -> TransportCounts {
    transport_with(Simd::detect(), inputs, scratch, outputs)
}

/// [`transport`] with an explicit kernel build (a build the CPU lacks runs as the widest it has,
/// [`Simd::cpu`]).
pub fn transport_with(
    simd: Simd,
    inputs: &TransportInputs<'_>,
    scratch: &mut TransportScratch,
    outputs: TransportOutputs<'_>,
) -> TransportCounts {
    let simd = simd.min(Simd::cpu());
    let width = inputs.depth_m.width();
    let height = inputs.depth_m.height();
    let area = width * height;
    let rotation = inputs
        .previous_from_current
        .rotation
        .to_rotation_matrix()
        .into_inner()
        .cast::<f32>();
    let translation = inputs.previous_from_current.translation.vector.cast::<f32>();
    // Per frame: R[:,0]·ray_x per column.
    for (axis, terms) in scratch.column_terms.iter_mut().enumerate() {
        for (term, &ray_x) in terms.iter_mut().zip(&inputs.rays.ray_x) {
            *term = rotation[(axis, 0)] * ray_x;
        }
    }
    let k = inputs.intrinsics;
    let warp = WarpParameters {
        translation: [translation.x, translation.y, translation.z],
        focal: [k.fx as f32, k.fy as f32],
        centre: [k.cx as f32, k.cy as f32],
        max: [(width - 1) as f32, (height - 1) as f32],
        width: width as u32,
        geometric: inputs.config.warp_depth == WarpDepth::Current,
    };
    let geometric = warp.geometric;
    let finish = FinishParameters {
        geometric,
        quadratic: inputs.config.threshold_form == ThresholdForm::Quadratic,
        alpha: inputs.config.alpha,
        beta: inputs.config.beta,
        retention: inputs.config.sub_threshold_retention,
    };
    let [terms_x, terms_y, terms_z] = &scratch.column_terms;
    let (terms_x, terms_y, terms_z) = (&terms_x[..width], &terms_y[..width], &terms_z[..width]);
    // Gathers read these at warp sources (< area by construction; sliced so the bound is known).
    let previous_zc = &inputs.compensated_previous_m.as_slice()[..area];
    let previous_a = &inputs.accumulation_previous_m.as_slice()[..area];
    let previous_p = &inputs.predicted_previous.as_slice()[..area];
    let chunk = ROWS_PER_TASK * width;
    // ΔZ into the output image (a task's rows), or into one staging row per task.
    let recording = outputs.delta_z_m.is_some();
    let (dz_buffer, dz_chunk) = match outputs.delta_z_m {
        Some(delta_z_m) => (delta_z_m.as_mut_slice(), chunk),
        None => (&mut scratch.staging_rows[..], width),
    };
    // W's rows (or one unused value per task), and Ŵ's source with the retention.
    let slow_previous = inputs
        .slow_previous
        .filter(|_| outputs.slow_m.is_some())
        .map(|(w, retention)| (&w.as_slice()[..area], retention));
    let slow_events = inputs.config.slow_evidence.is_some_and(|c| c.occlusion_events);
    let (slow_buffer, slow_chunk) = match outputs.slow_m {
        Some(slow_m) if slow_previous.is_some() => (slow_m.as_mut_slice(), chunk),
        _ => (&mut scratch.no_slow_rows[..], 1),
    };
    // W always compares depths through the geometric warp (a static surface's ΔZ then sums to
    // zero along the warp chain); when A uses the release's warp, W gets a warp of its own.
    let slow_warp = (slow_previous.is_some() && !geometric).then_some(WarpParameters {
        translation: warp.translation,
        focal: warp.focal,
        centre: warp.centre,
        max: warp.max,
        width: warp.width,
        geometric: true,
    });
    outputs
        .compensated_m
        .as_mut_slice()
        .par_chunks_mut(chunk)
        .zip(outputs.accumulation_m.as_mut_slice().par_chunks_mut(chunk))
        .zip(outputs.predicted_carried.as_mut_slice().par_chunks_mut(chunk))
        .zip(dz_buffer.par_chunks_mut(dz_chunk))
        .zip(outputs.newly_discovered.as_mut_slice().par_chunks_mut(chunk))
        .zip(outputs.object_set[..area].par_chunks_mut(chunk))
        .zip(scratch.source_rows.par_chunks_mut(width))
        .zip(slow_buffer.par_chunks_mut(slow_chunk))
        .zip(scratch.slow_source_rows.par_chunks_mut(width))
        .zip(scratch.slow_qz_rows.par_chunks_mut(width))
        .enumerate()
        .map(
            |(
                task,
                (
                    (
                        (
                            ((((((zc_rows, a_rows), p_rows), dz_rows), n_rows), set_rows), source_row),
                            slow_rows,
                        ),
                        slow_source_row,
                    ),
                    slow_qz_row,
                ),
            )| {
                let mut counts = TransportCounts::default();
                let rows = zc_rows
                    .chunks_exact_mut(width)
                    .zip(a_rows.chunks_exact_mut(width))
                    .zip(p_rows.chunks_exact_mut(width))
                    .zip(n_rows.chunks_exact_mut(width))
                    .zip(set_rows.chunks_exact_mut(width));
                for (row, ((((zc_row, a_row), p_row), n_row), set_row)) in rows.enumerate() {
                    let dz_row = if recording {
                        &mut dz_rows[row * width..(row + 1) * width]
                    } else {
                        &mut dz_rows[..width]
                    };
                    let y = task * ROWS_PER_TASK + row;
                    let measured_row = inputs.depth_m.row(y);
                    let previous_row = inputs.compensated_previous_m.row(y);
                    // Rotated ray = column term + row term, row term = R[:,1]·ray_y + R[:,2].
                    let ray_y = inputs.rays.ray_y[y];
                    let row_term = [0, 1, 2].map(|axis| rotation[(axis, 1)] * ray_y + rotation[(axis, 2)]);
                    if let Some(slow_warp) = &slow_warp {
                        warp_row(
                            simd,
                            slow_warp,
                            row_term,
                            [terms_x, terms_y, terms_z],
                            (measured_row, previous_row),
                            slow_qz_row,
                            slow_source_row,
                        );
                    }
                    let slow = slow_previous.map(|(previous, retention)| SlowRow {
                        previous,
                        retention,
                        row: &mut slow_rows[row * width..(row + 1) * width],
                        own_warp: slow_warp.is_some().then_some((&*slow_source_row, &*slow_qz_row)),
                        events: slow_events,
                        width,
                    });
                    // Pass 1: the warp source of every pixel; the ΔZ row holds z′ until pass 2
                    // reads it.
                    warp_row(
                        simd,
                        &warp,
                        row_term,
                        [terms_x, terms_y, terms_z],
                        (measured_row, previous_row),
                        dz_row,
                        source_row,
                    );
                    // Pass 2: gather and finish (steps 3–9) and the object labels.
                    let row_counts = finish_row(
                        simd,
                        &finish,
                        measured_row,
                        source_row,
                        (previous_zc, previous_a, previous_p),
                        FinishRow {
                            compensated_m: zc_row,
                            accumulation_m: a_row,
                            predicted_carried: p_row,
                            delta_z_m: dz_row,
                            newly_discovered: n_row,
                            object_set: set_row,
                        },
                        slow,
                    );
                    counts.warped += row_counts.warped;
                    counts.newly_discovered += row_counts.newly_discovered;
                    counts.object += row_counts.object;
                    let (first, last) = row_counts.object_columns;
                    if first != usize::MAX {
                        let bounds = PixelBounds {
                            x0: first,
                            x1: last,
                            y0: y,
                            y1: y,
                        };
                        counts.object_bounds = PixelBounds::union(counts.object_bounds, Some(bounds));
                    }
                }
                counts
            },
        )
        .reduce(TransportCounts::default, TransportCounts::merge)
}
