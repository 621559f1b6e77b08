//! Slow-change evidence (not in the paper; docs/method.md, "Deviations", D16): a leaky
//! accumulation of every frame's ΔZ that catches what the per-frame truncation of Eq. 5 throws
//! away, plus the removal of the camera motion's error from it.
//!
//! The paper keeps A only where it exceeds τ_α (Eq. 5), so a surface whose depth drops by less
//! than τ_α per frame is cleared every frame: an object approaching head-on (a person walking
//! towards the camera: 2–3 cm per frame against τ_α ≈ 0.5 m at 3.5 m) or one that covers a
//! surface just behind it (a box sliding on a desk) is never found. W keeps a leaky sum of ΔZ
//! beside A: W ← retention · Ŵ + min(ΔZ, τ_α), carried by the same warp, reset where the
//! background reappears (ΔZ ≤ −τ_β), the warp is invalid, or an occlusion event (ΔZ > τ_α)
//! samples a depth edge of the previous frame (D22; without
//! [`SlowEvidenceConfig::occlusion_events`], at every occlusion event). For a static surface
//! ΔZ telescopes (the sum is the depth difference between the first and the last frame along
//! the warp chain), so W stays within the sensor noise; a steady approach adds up to its
//! speed / (1 − retention).
//!
//! What a leaky sum also adds up is any *systematic* error of ΔZ, and the camera motion's error
//! is one: the closed loop's DVO was measured to be off by 2–4 mm per frame in the same
//! direction for tens of frames (the synthetic desk), which W turned into whole surfaces of false
//! evidence. So before W is used, the ΔZ that a small motion error ξ would cause is fitted to the
//! frame's ΔZ over the static background and removed from W:
//! ΔZ(u) ≈ J(u)·ξ, with J(u) = [a, q × a], q the pixel's point in the previous camera, and
//! a = (g_u·f_x/q_z, g_v·f_y/q_z, −(g_u·f_x·x′ + g_v·f_y·y′)/q_z − 1) from the depth gradient
//! (g_u, g_v) per pixel and (x′, y′) = (q_x, q_y)/q_z: the linearised change of the previous
//! depth sampled at the moved projection minus the moved point's own depth. The fit is a Huber
//! IRLS over a sparse grid of background pixels (off the previous mask, off depth edges, |ΔZ|
//! below 10 % of Z); a fit that calls for more than a few millimetres or a fraction of a degree
//! is not a small error and is not applied.
//!
//! The evidence: pixels with W > α·Z, opened with a (2r+1)² square (bands along depth edges and
//! speckle go) and kept in 8-connected components of at least the object threshold, join the
//! mask (they do not enter A: the paper's accumulation, its prediction and pruning are
//! unchanged).

use nalgebra::{Isometry3, Matrix6, Vector6};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::transport::{PixelBounds, PixelRays, ROWS_PER_TASK};
use crate::error::{Error, Result};
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, Mask};
use crate::simd::{simd_kernel, Simd};

/// Parameters of the slow-change evidence ([`super::OcclusionConfig::slow_evidence`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SlowEvidenceConfig {
    /// Fraction of W kept from one frame to the next, in [0, 1): a steady depth decrease of v
    /// per frame adds up to v / (1 − retention).
    pub retention: f32,
    /// A pixel holds slow-change evidence when W > `alpha` · Z (unitless).
    pub alpha: f32,
    /// Radius r (px) of the (2r+1)² opening of the evidence before labelling.
    pub opening_radius_px: usize,
    /// Smallest evidence component that joins the mask, in pixels at 640 × 480 (scaled by the
    /// image area like the object threshold).
    pub min_object_pixels_vga: usize,
    /// Remove the ΔZ that the frame's camera-motion error causes (fitted over the background)
    /// from W before it is thresholded.
    pub motion_error_correction: bool,
    /// An occlusion event (ΔZ > τ_α, A's in the paper) also enters W, capped at τ_α, unless the
    /// warp's source lies at a depth edge of the previous frame (docs/method.md D22): an object
    /// whose leading edge uncovers less than the object size per frame then still adds up.
    /// `false`: W is reset there, as A alone handles the event.
    pub occlusion_events: bool,
}

impl Default for SlowEvidenceConfig {
    fn default() -> Self {
        Self {
            retention: 0.95,
            alpha: 0.04,
            opening_radius_px: 1,
            min_object_pixels_vga: 500,
            motion_error_correction: true,
            occlusion_events: true,
        }
    }
}

impl SlowEvidenceConfig {
    /// Checks every field.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the first bad field.
    pub fn validate(&self) -> Result<()> {
        if !(0.0..1.0).contains(&self.retention) {
            return Err(Error::InvalidParameter {
                name: "slow_evidence.retention",
                value: self.retention.to_string(),
                expected: "a fraction in [0, 1)".into(),
            });
        }
        Error::require_finite_positive("slow_evidence.alpha", self.alpha)
    }
}

/// Smallest short side (px) of an image that gets the evidence. W follows each pixel through a
/// nearest-pixel warp, and on a slanted surface every step's snapping adds the depth gradient
/// times up to half a pixel, which the leaky sum keeps. Measured on the synthetic static scenes
/// with an ideal sensor and the true poses: up to 6.4 % of the image flagged at 160 × 120,
/// ≤ 0.29 % at 320 × 240, none at 640 × 480.
pub(super) const MIN_SIDE_PX: usize = 240;

/// Largest motion error the fit may remove: 1 cm and 0.5° per frame. Measured errors of the
/// closed loop's DVO are 2–4 mm and ≤ 0.1° per frame; a larger fit is a moving object the fit
/// took for background.
const MAX_CORRECTION_M: f64 = 0.01;
const MAX_CORRECTION_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;
/// Background samples the fit aims for (a grid over the image).
const FIT_SAMPLES: usize = 2_000;
/// Fewer usable samples than this: no fit.
const MIN_FIT_SAMPLES: usize = 300;
/// A sample's |ΔZ| must be below this fraction of its depth (occlusions are not background).
const MAX_SAMPLE_DELTA: f32 = 0.1;
/// A sample's depth gradient step must be below this fraction of its depth (no depth edges).
const MAX_SAMPLE_STEP: f32 = 0.05;
/// IRLS iterations of the fit.
const FIT_ITERATIONS: usize = 2;
/// Huber threshold in robust standard deviations.
const HUBER_K: f64 = 1.345;

/// The motion error's ΔZ model: ΔZ(u) ≈ J(u)·ξ (see the module docs), from the frame's
/// motion and intrinsics.
#[derive(Debug, Clone, Copy)]
struct PixelModel {
    rotation: [[f32; 3]; 3],
    translation: [f32; 3],
    focal: [f32; 2],
}

impl PixelModel {
    fn new(previous_from_current: &Isometry3<f64>, intrinsics: &PinholeIntrinsics) -> Self {
        let r = previous_from_current
            .rotation
            .to_rotation_matrix()
            .into_inner()
            .cast::<f32>();
        let t = previous_from_current.translation.vector.cast::<f32>();
        Self {
            rotation: [
                [r[(0, 0)], r[(0, 1)], r[(0, 2)]],
                [r[(1, 0)], r[(1, 1)], r[(1, 2)]],
                [r[(2, 0)], r[(2, 1)], r[(2, 2)]],
            ],
            translation: [t.x, t.y, t.z],
            focal: [intrinsics.fx as f32, intrinsics.fy as f32],
        }
    }

    /// The pixel's point in the previous camera, from its ray (rx, ry, 1) and depth z.
    #[inline(always)]
    fn point(&self, rx: f32, ry: f32, z: f32) -> [f32; 3] {
        let r = &self.rotation;
        let t = &self.translation;
        [
            z * (r[0][0] * rx + r[0][1] * ry + r[0][2]) + t[0],
            z * (r[1][0] * rx + r[1][1] * ry + r[1][2]) + t[1],
            z * (r[2][0] * rx + r[2][1] * ry + r[2][2]) + t[2],
        ]
    }

    /// J at point q with depth gradient (gu, gv) per pixel.
    #[inline(always)]
    fn jacobian(&self, q: [f32; 3], gu: f32, gv: f32) -> [f32; 6] {
        let inverse_z = 1.0 / q[2];
        let (xp, yp) = (q[0] * inverse_z, q[1] * inverse_z);
        let (du, dv) = (gu * self.focal[0] * inverse_z, gv * self.focal[1] * inverse_z);
        let a = [du, dv, -(du * xp + dv * yp) - 1.0];
        [
            a[0],
            a[1],
            a[2],
            q[1] * a[2] - q[2] * a[1],
            q[2] * a[0] - q[0] * a[2],
            q[0] * a[1] - q[1] * a[0],
        ]
    }
}

/// Central-difference depth gradient (per pixel) at interior pixel i of a `width`-wide image,
/// or None at a depth edge or next to a missing depth.
#[inline(always)]
fn gradient(z: &[f32], i: usize, width: usize, max_step: f32) -> Option<(f32, f32)> {
    let (l, r, u, d, c) = (z[i - 1], z[i + 1], z[i - width], z[i + width], z[i]);
    let limit = max_step * c;
    let ok = l > 0.0
        && r > 0.0
        && u > 0.0
        && d > 0.0
        && (r - c).abs() < limit
        && (c - l).abs() < limit
        && (d - c).abs() < limit
        && (c - u).abs() < limit;
    ok.then_some((0.5 * (r - l), 0.5 * (d - u)))
}

/// Inputs of one frame's slow-change evidence.
pub(super) struct SlowFrame<'a> {
    pub config: &'a SlowEvidenceConfig,
    pub intrinsics: &'a PinholeIntrinsics,
    pub rays: &'a PixelRays,
    pub previous_from_current: &'a Isometry3<f64>,
    /// The frame's compensated depth.
    pub depth_m: &'a DepthMeters,
    /// W as the transport left it.
    pub w_m: &'a DepthMeters,
    /// The previous frame's mask (excluded from the fit).
    pub previous_mask: &'a Mask,
}

/// What one frame's pass found.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct SlowCounts {
    /// The motion error fitted and removed (v in m, ω in rad), None when none was applied.
    pub correction: Option<[f64; 6]>,
    /// Bounding box of the evidence set {W > α·Z}.
    pub bounds: Option<PixelBounds>,
    /// The share of W removed per pixel: ξ and its largest share over the fit's samples
    /// (relative to Z), when one was applied.
    pub applied: Option<([f32; 6], f32)>,
}

/// Scratch of the fit (allocated once).
#[derive(Debug, Clone)]
pub(super) struct SlowScratch {
    samples: Vec<([f32; 6], f32)>,
    /// |residual| per sample.
    magnitudes: Vec<f32>,
    /// A copy of `magnitudes` for the median (selection reorders it).
    order: Vec<f32>,
}

impl SlowScratch {
    /// Scratch for images of `area` pixels: the sample grid's stride is the rounded
    /// √(area / FIT_SAMPLES), so it holds at most 2.25 × FIT_SAMPLES samples (stride ≥ 2) or
    /// `area` (stride 1), and a fit never allocates.
    pub fn new(area: usize) -> Self {
        let capacity = area.min(3 * FIT_SAMPLES);
        Self {
            samples: Vec::with_capacity(capacity),
            magnitudes: Vec::with_capacity(capacity),
            order: Vec::with_capacity(capacity),
        }
    }
}

/// Fits the motion error over the background (see the module docs); None when there are too
/// few samples, the system is singular or the fit is not a small error.
fn fit_motion_error(
    frame: &SlowFrame<'_>,
    model: &PixelModel,
    scratch: &mut SlowScratch,
) -> Option<(Vector6<f64>, f32)> {
    let (width, height) = (frame.depth_m.width(), frame.depth_m.height());
    if width < 3 || height < 3 {
        return None;
    }
    let stride = ((width * height) as f64 / FIT_SAMPLES as f64)
        .sqrt()
        .round()
        .max(1.0) as usize;
    let (z, dz, mask) = (
        frame.depth_m.as_slice(),
        frame.w_m.as_slice(),
        frame.previous_mask.as_slice(),
    );
    scratch.samples.clear();
    for y in (1..height - 1).step_by(stride) {
        for x in (1..width - 1).step_by(stride) {
            let i = y * width + x;
            let (zi, di) = (z[i], dz[i]);
            if zi <= 0.0 || mask[i] != 0 || di == 0.0 || di.abs() > MAX_SAMPLE_DELTA * zi {
                continue;
            }
            let Some((gu, gv)) = gradient(z, i, width, MAX_SAMPLE_STEP) else {
                continue;
            };
            let j = model.jacobian(model.point(frame.rays.ray_x[x], frame.rays.ray_y[y], zi), gu, gv);
            // Relative to the depth: the evidence is thresholded relative to Z.
            let inverse = 1.0 / zi;
            scratch.samples.push((j.map(|v| v * inverse), di * inverse));
        }
    }
    if scratch.samples.len() < MIN_FIT_SAMPLES {
        return None;
    }
    let mut xi = Vector6::zeros();
    for _ in 0..FIT_ITERATIONS {
        // Robust scale: the median absolute residual.
        let current = xi.map(|v| v as f32);
        scratch.magnitudes.clear();
        scratch.magnitudes.extend(scratch.samples.iter().map(|(j, d)| {
            let predicted: f32 = j.iter().zip(current.iter()).map(|(a, b)| a * b).sum();
            (d - predicted).abs()
        }));
        scratch.order.clear();
        scratch.order.extend_from_slice(&scratch.magnitudes);
        let middle = scratch.order.len() / 2;
        let median = *scratch.order.select_nth_unstable_by(middle, f32::total_cmp).1;
        let k = (HUBER_K * 1.4826 * f64::from(median)).max(1e-5) as f32;
        // The upper triangle of H and b, in f64 over f32 terms.
        let mut h = [0.0f64; 21];
        let mut b = [0.0f64; 6];
        for ((j, d), &magnitude) in scratch.samples.iter().zip(&scratch.magnitudes) {
            let weight = if magnitude <= k { 1.0 } else { k / magnitude };
            let wj = j.map(|v| v * weight);
            let mut n = 0;
            for (r, &wr) in wj.iter().enumerate() {
                for &jc in &j[r..] {
                    h[n] += f64::from(wr * jc);
                    n += 1;
                }
                b[r] += f64::from(wr * d);
            }
        }
        let mut matrix = Matrix6::<f64>::zeros();
        let mut n = 0;
        for r in 0..6 {
            for c in r..6 {
                matrix[(r, c)] = h[n];
                matrix[(c, r)] = h[n];
                n += 1;
            }
        }
        // Directions the depth does not observe (a single plane) are damped to zero.
        let damping = 1e-6 * (matrix.trace() / 6.0).max(f64::MIN_POSITIVE);
        for k in 0..6 {
            matrix[(k, k)] += damping;
        }
        xi = matrix.cholesky()?.solve(&Vector6::from_column_slice(&b));
    }
    // W sums the per-frame errors with weights retention^k.
    let gain = 1.0 / (1.0 - f64::from(frame.config.retention));
    let small = xi.fixed_rows::<3>(0).norm() <= gain * MAX_CORRECTION_M
        && xi.fixed_rows::<3>(3).norm() <= gain * MAX_CORRECTION_RAD;
    if !(small && xi.iter().all(|v| v.is_finite())) {
        return None;
    }
    // The largest share J·Ξ over the samples, relative to Z.
    let current = [0, 1, 2, 3, 4, 5].map(|k| xi[k] as f32);
    let largest = scratch
        .samples
        .iter()
        .map(|(j, _)| j.iter().zip(&current).map(|(a, b)| a * b).sum::<f32>().abs())
        .fold(0.0f32, f32::max);
    Some((xi, largest))
}

/// One row of the evidence with the fitted motion error's share of W removed: e = 1 where
/// W − J·Ξ > α·Z (W ≠ 0), branch-free so that it vectorises. Pixels off a smooth surface (depth
/// edge, missing neighbour, the image border) lose the direct term only (no gradient).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn corrected_evidence_row_generic(
    model: &PixelModel,
    xi: &[f32; 6],
    ray_x: &[f32],
    ray_y: f32,
    (above, row, below): (&[f32], &[f32], &[f32]),
    alpha: f32,
    w_row: &[f32],
    e_row: &mut [u8],
) {
    let width = row.len();
    let (v, omega) = ([xi[0], xi[1], xi[2]], [xi[3], xi[4], xi[5]]);
    let [fx, fy] = model.focal;
    let r = &model.rotation;
    // q = z·(c·rx + row part) + t: the rotated ray's row part and its column coefficients.
    let row_part = [0, 1, 2].map(|k| r[k][1] * ray_y + r[k][2]);
    let column = [r[0][0], r[1][0], r[2][0]];
    let t = model.translation;
    let (ray_x, above, below, w_row, e_row) = (
        &ray_x[..width],
        &above[..width],
        &below[..width],
        &w_row[..width],
        &mut e_row[..width],
    );
    for x in 0..width {
        let zc = row[x];
        // Neighbours clamped at the border (a zero difference there).
        let (l, rr) = (row[x.saturating_sub(1)], row[(x + 1).min(width - 1)]);
        let (u, d) = (above[x], below[x]);
        let limit = MAX_SAMPLE_STEP * zc;
        let smooth = (l > 0.0)
            & (rr > 0.0)
            & (u > 0.0)
            & (d > 0.0)
            & ((rr - zc).abs() < limit)
            & ((zc - l).abs() < limit)
            & ((d - zc).abs() < limit)
            & ((zc - u).abs() < limit);
        let gu = if smooth { 0.5 * (rr - l) } else { 0.0 };
        let gv = if smooth { 0.5 * (d - u) } else { 0.0 };
        let rx = ray_x[x];
        let q = [
            zc * (column[0] * rx + row_part[0]) + t[0],
            zc * (column[1] * rx + row_part[1]) + t[1],
            zc * (column[2] * rx + row_part[2]) + t[2],
        ];
        // J·Ξ = a·(v + ω × q).
        let dq = [
            v[0] + omega[1] * q[2] - omega[2] * q[1],
            v[1] + omega[2] * q[0] - omega[0] * q[2],
            v[2] + omega[0] * q[1] - omega[1] * q[0],
        ];
        let inverse_z = if q[2] > 0.0 { 1.0 / q[2] } else { 0.0 };
        let (xp, yp) = (q[0] * inverse_z, q[1] * inverse_z);
        let (du, dv) = (gu * fx * inverse_z, gv * fy * inverse_z);
        let share = du * (dq[0] - xp * dq[2]) + dv * (dq[1] - yp * dq[2]) - dq[2];
        let share = if q[2] > 0.0 { share } else { 0.0 };
        let w = w_row[x];
        e_row[x] = u8::from((w != 0.0) & (w - share > alpha * zc));
    }
}

simd_kernel!(
    corrected_evidence_row,
    corrected_evidence_row_avx2,
    corrected_evidence_row_generic,
    (
        model: &PixelModel,
        xi: &[f32; 6],
        ray_x: &[f32],
        ray_y: f32,
        rows: (&[f32], &[f32], &[f32]),
        alpha: f32,
        w_row: &[f32],
        e_row: &mut [u8]
    )
);

/// Fitted shares below this fraction of α·Z are not worth a per-pixel correction.
const NEGLIGIBLE_SHARE: f32 = 0.05;
/// The per-pixel share may exceed the largest one over the fit's samples by this factor
/// (the samples are a sparse grid) before the pre-test would miss a pixel.
const SHARE_MARGIN: f32 = 1.5;

/// The frame's pass over W: fits the share of the camera motion's error in W (when
/// configured) and marks `evidence` (0 / 1) where W minus that share exceeds α·Z. Returns the
/// fitted share and the evidence's bounding box.
pub(super) fn update(frame: &SlowFrame<'_>, scratch: &mut SlowScratch, evidence: &mut [u8]) -> SlowCounts {
    let (width, height) = (frame.depth_m.width(), frame.depth_m.height());
    let model = PixelModel::new(frame.previous_from_current, frame.intrinsics);
    let xi = if frame.config.motion_error_correction {
        fit_motion_error(frame, &model, scratch)
    } else {
        None
    };
    // Pre-test W > (α − margin·largest share)·Z, then the exact test on the pixels it passes.
    let correction = xi
        .filter(|&(_, largest)| largest > NEGLIGIBLE_SHARE * frame.config.alpha)
        .map(|(x, largest)| ([0, 1, 2, 3, 4, 5].map(|k| x[k] as f32), largest));
    let pre_alpha = frame.config.alpha - correction.map_or(0.0, |(_, largest)| SHARE_MARGIN * largest);
    let simd = Simd::detect();
    let alpha = frame.config.alpha;
    let z = frame.depth_m.as_slice();
    let chunk = ROWS_PER_TASK * width;
    let bounds = frame
        .w_m
        .as_slice()
        .par_chunks(chunk)
        .zip(evidence[..width * height].par_chunks_mut(chunk))
        .enumerate()
        .map(|(task, (w_rows, e_rows))| {
            let mut bounds: Option<PixelBounds> = None;
            for (row, (w_row, e_row)) in w_rows
                .chunks_exact(width)
                .zip(e_rows.chunks_exact_mut(width))
                .enumerate()
            {
                let y = task * ROWS_PER_TASK + row;
                let z_row = &z[y * width..(y + 1) * width];
                for ((e, &w), &z) in e_row.iter_mut().zip(w_row).zip(z_row) {
                    *e = u8::from(w > pre_alpha * z);
                }
                // Rows the pre-test leaves empty hold no evidence; the others are evaluated whole.
                // Only the span of the candidates is evaluated (with a pixel on each side for
                // the gradient); the rest of the row holds no evidence.
                if let Some((c, _)) = &correction {
                    if let Some(first) = super::components::position_nonzero_u8(e_row) {
                        let last = e_row.iter().rposition(|&e| e != 0).unwrap_or(first);
                        let span = first.saturating_sub(1)..(last + 2).min(width);
                        let rows = |row: usize| &z[row * width..(row + 1) * width][span.clone()];
                        corrected_evidence_row(
                            simd,
                            &model,
                            c,
                            &frame.rays.ray_x[span.clone()],
                            frame.rays.ray_y[y],
                            (rows(y.saturating_sub(1)), rows(y), rows((y + 1).min(height - 1))),
                            alpha,
                            &w_row[span.clone()],
                            &mut e_row[span.clone()],
                        );
                        // The pixels beside the candidates were evaluated without their outer
                        // neighbour; they failed the pre-test.
                        if first > 0 {
                            e_row[first - 1] = 0;
                        }
                        if last + 1 < width {
                            e_row[last + 1] = 0;
                        }
                    }
                }
                let first = super::components::position_nonzero_u8(e_row).unwrap_or(usize::MAX);
                let last = e_row.iter().rposition(|&e| e != 0).unwrap_or(0);
                if first != usize::MAX {
                    bounds = PixelBounds::union(
                        bounds,
                        Some(PixelBounds {
                            x0: first,
                            x1: last,
                            y0: y,
                            y1: y,
                        }),
                    );
                }
            }
            bounds
        })
        .reduce(|| None, PixelBounds::union);
    SlowCounts {
        correction: xi.map(|(x, _)| [x[0], x[1], x[2], x[3], x[4], x[5]]),
        bounds,
        applied: correction,
    }
}

/// The pixels where W minus the applied share of the motion error exceeds `alpha`·Z (the
/// same test as the evidence's, at another α), appended to `out` with their depth Z (m), in
/// pixel order. `row` is scratch of the image's width.
pub(super) fn low_evidence(
    frame: &SlowFrame<'_>,
    applied: Option<([f32; 6], f32)>,
    alpha: f32,
    row: &mut Vec<u8>,
    out: &mut Vec<(u32, f32)>,
) {
    let (width, height) = (frame.depth_m.width(), frame.depth_m.height());
    let model = PixelModel::new(frame.previous_from_current, frame.intrinsics);
    let pre_alpha = alpha - applied.map_or(0.0, |(_, largest)| SHARE_MARGIN * largest);
    let simd = Simd::detect();
    let z = frame.depth_m.as_slice();
    row.clear();
    row.resize(width, 0);
    for (y, w_row) in frame.w_m.as_slice().chunks_exact(width).enumerate() {
        let z_row = &z[y * width..(y + 1) * width];
        for ((e, &w), &z) in row.iter_mut().zip(w_row).zip(z_row) {
            *e = u8::from(w > pre_alpha * z);
        }
        let Some(first) = super::components::position_nonzero_u8(row) else {
            continue;
        };
        let last = row.iter().rposition(|&e| e != 0).unwrap_or(first);
        if let Some((xi, _)) = &applied {
            let span = first.saturating_sub(1)..(last + 2).min(width);
            let rows = |r: usize| &z[r * width..(r + 1) * width][span.clone()];
            corrected_evidence_row(
                simd,
                &model,
                xi,
                &frame.rays.ray_x[span.clone()],
                frame.rays.ray_y[y],
                (rows(y.saturating_sub(1)), rows(y), rows((y + 1).min(height - 1))),
                alpha,
                &w_row[span.clone()],
                &mut row[span.clone()],
            );
        }
        for x in first..=last {
            if row[x] != 0 && z_row[x] > 0.0 && w_row[x] > pre_alpha * z_row[x] {
                out.push(((y * width + x) as u32, z_row[x]));
            }
        }
    }
}
