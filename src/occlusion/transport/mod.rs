//! Per-pixel state transport (docs/method.md steps 2–9): warp field, depth compensation,
//! occlusion map ΔZ, carried A and P, accumulation, truncations and the newly discovered area,
//! plus the initial labels of the object set {A > τ_α} (step 10's input) and its bounding box.
//!
//! [`transport`] is the fused, row-parallel kernel used by the detector; [`transport_scalar`]
//! is a literal step-by-step reference (one full-image pass per step, f64 nalgebra projection)
//! kept for the agreement test.
//!
//! The fast kernel warps in f32: per frame it precomputes R·(x−cx)/fx per column, so the
//! rotated ray of pixel (x, y) is that column term plus a per-row term, a point is ray·Z + t, and
//! the projection takes one reciprocal. Per row it first computes every pixel's warp source in a
//! branch-free loop the compiler vectorises, then gathers and finishes the pixels. f32 changes
//! the nearest-pixel rounding only for warps within ≈ 1e-4 px of a half-pixel boundary (the
//! agreement test bounds how many pixels that may affect).

use crate::geometry::PinholeIntrinsics;

/// Rows per rayon task: one VGA row costs ≈ 1 µs, so 16 rows (≈ 15 µs) amortise the task
/// overhead while 30 tasks per frame still balance two to eight cores.
pub const ROWS_PER_TASK: usize = 16;

mod orchestration;
mod scalar;

pub use orchestration::{
    transport, transport_with, TransportCounts, TransportInputs, TransportOutputs, TransportScratch,
};
pub use scalar::transport_scalar;

/// 2^23: the smallest f32 whose ulp is 1 (see `warp_row`'s rounding).
const ROUND_MAGIC: f32 = 8_388_608.0;

/// Warp source of a pixel whose warp is invalid.
const NO_SOURCE: u32 = u32::MAX;

pub(super) use crate::simd::simd_kernel;
pub use crate::simd::Simd;

/// Inclusive bounding box of a pixel set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelBounds {
    /// First column.
    pub x0: usize,
    /// Last column.
    pub x1: usize,
    /// First row.
    pub y0: usize,
    /// Last row.
    pub y1: usize,
}

impl PixelBounds {
    /// The box of both (either may be absent).
    pub fn union(a: Option<Self>, b: Option<Self>) -> Option<Self> {
        match (a, b) {
            (Some(a), Some(b)) => Some(Self {
                x0: a.x0.min(b.x0),
                x1: a.x1.max(b.x1),
                y0: a.y0.min(b.y0),
                y1: a.y1.max(b.y1),
            }),
            (a, None) => a,
            (None, b) => b,
        }
    }
}

/// Per-sequence normalised rays of the pixel grid (f32; the f64 reference uses the intrinsics).
#[derive(Debug, Clone)]
pub struct PixelRays {
    /// (x − cx)/fx per column.
    pub ray_x: Vec<f32>,
    /// (y − cy)/fy per row.
    pub ray_y: Vec<f32>,
}

impl PixelRays {
    /// The rays of a `width` × `height` grid.
    pub fn new(intrinsics: &PinholeIntrinsics, width: usize, height: usize) -> Self {
        Self {
            ray_x: (0..width)
                .map(|x| ((x as f64 - intrinsics.cx) / intrinsics.fx) as f32)
                .collect(),
            ray_y: (0..height)
                .map(|y| ((y as f64 - intrinsics.cy) / intrinsics.fy) as f32)
                .collect(),
        }
    }
}

/// Per-frame constants of the f32 warp.
struct WarpParameters {
    /// t of previous_from_current (m).
    translation: [f32; 3],
    /// fx, fy.
    focal: [f32; 2],
    /// cx, cy.
    centre: [f32; 2],
    /// W − 1, H − 1: the last valid coordinates.
    max: [f32; 2],
    width: u32,
    /// Back-project at the measured depth where valid (`WarpDepth::Current`).
    geometric: bool,
}

/// One row of the warp (docs/method.md step 2): back-projects each pixel at the previous
/// compensated depth, or (`geometric`) at its measured depth where that is valid; `sources` gets
/// the nearest previous pixel or `NO_SOURCE`, `qz` the warped point's depth z′. Branch-free, on
/// equal-length slices, so it vectorises.
#[inline(always)]
fn warp_row_generic(
    warp: &WarpParameters,
    row_term: [f32; 3],
    [terms_x, terms_y, terms_z]: [&[f32]; 3],
    (measured, previous): (&[f32], &[f32]),
    qz_row: &mut [f32],
    sources: &mut [u32],
) {
    let n = qz_row.len();
    let (terms_x, terms_y, terms_z, sources) =
        (&terms_x[..n], &terms_y[..n], &terms_z[..n], &mut sources[..n]);
    let (measured, previous) = (&measured[..n], &previous[..n]);
    let [tx, ty, tz] = warp.translation;
    let [fx, fy] = warp.focal;
    let [cx, cy] = warp.centre;
    let [max_x, max_y] = warp.max;
    let geometric = warp.geometric;
    for i in 0..n {
        let z = if geometric & (measured[i] > 0.0) {
            measured[i]
        } else {
            previous[i]
        };
        let qx = z * (terms_x[i] + row_term[0]) + tx;
        let qy = z * (terms_y[i] + row_term[1]) + ty;
        let qz = z * (terms_z[i] + row_term[2]) + tz;
        let inverse_z = 1.0 / qz;
        let u = fx * qx * inverse_z + cx;
        let v = fy * qy * inverse_z + cy;
        let valid = (z > 0.0) & (qz > 0.0) & (u >= 0.0) & (u <= max_x) & (v >= 0.0) & (v <= max_y);
        // Nearest pixel of the coordinates clamped into the image (so invalid pixels convert
        // too): adding 2^23 rounds a float in [0, 2^23) to an integer (ties
        // to even), whose bits minus those of 2^23 are that integer. Unlike `as`, this
        // vectorises on SSE2.
        let column = (clamp_coordinate(u, max_x) + ROUND_MAGIC).to_bits() - ROUND_MAGIC.to_bits();
        let line = (clamp_coordinate(v, max_y) + ROUND_MAGIC).to_bits() - ROUND_MAGIC.to_bits();
        let source = line * warp.width + column;
        sources[i] = if valid { source } else { NO_SOURCE };
        qz_row[i] = qz;
    }
}

simd_kernel!(
    warp_row,
    warp_row_avx2,
    warp_row_generic,
    (
        warp: &WarpParameters,
        row_term: [f32; 3],
        terms: [&[f32]; 3],
        measured_and_previous: (&[f32], &[f32]),
        qz_row: &mut [f32],
        sources: &mut [u32]
    )
);

/// `value` clamped into [0, max], NaN → 0. Written as two selects (one SSE `maxps`/`minps`
/// each) rather than `f32::max`/`min`, whose NaN rules cost extra instructions per lane.
#[inline(always)]
fn clamp_coordinate(value: f32, max: f32) -> f32 {
    let at_least_zero = if value > 0.0 { value } else { 0.0 };
    if at_least_zero < max {
        at_least_zero
    } else {
        max
    }
}

/// Per-frame constants of steps 3–9.
struct FinishParameters {
    geometric: bool,
    quadratic: bool,
    alpha: f32,
    beta: f32,
    /// `OcclusionConfig::sub_threshold_retention`.
    retention: f32,
}

/// Output rows of [`finish_row`].
struct FinishRow<'a> {
    compensated_m: &'a mut [f32],
    accumulation_m: &'a mut [f32],
    predicted_carried: &'a mut [u8],
    /// z′ on entry (geometric mode), ΔZ on return.
    delta_z_m: &'a mut [f32],
    newly_discovered: &'a mut [u8],
    object_set: &'a mut [u8],
}

/// Slow-change evidence of one row ([`finish_row`]): Ŵ's source image, the retention, and the
/// row of W to write.
struct SlowRow<'a> {
    previous: &'a [f32],
    retention: f32,
    row: &'a mut [f32],
    /// W's own (geometric) warp of the row: sources and z′; None = the row's warp is it.
    own_warp: Option<(&'a [u32], &'a [f32])>,
    /// Occlusion events (ΔZ > τ_α) enter W ([`crate::occlusion::SlowEvidenceConfig::occlusion_events`]).
    events: bool,
    /// Image width (px), for the neighbours of a source pixel.
    width: usize,
}

/// Counts of one row.
struct RowCounts {
    warped: usize,
    newly_discovered: usize,
    object: usize,
    /// First and last object column (usize::MAX, 0 when none).
    object_columns: (usize, usize),
}

/// Pixels per block of [`finish_row`]: the gathered values live in stack arrays this long
/// (1.1 KB, in L1) between the gather loop and the vectorised finishing loop.
const FINISH_BLOCK: usize = 128;

/// One row of steps 3–9 plus the object labels: per block of pixels, gathers the previous Zc,
/// A, P at the warp sources (scalar loads), then finishes every pixel in a branch-free loop the
/// compiler vectorises.
#[allow(clippy::too_many_arguments)]
fn finish_row(
    simd: Simd,
    finish: &FinishParameters,
    measured_row: &[f32],
    sources: &[u32],
    (previous_zc, previous_a, previous_p): (&[f32], &[f32], &[u8]),
    out: FinishRow<'_>,
    mut slow: Option<SlowRow<'_>>,
) -> RowCounts {
    let n = measured_row.len();
    let last_pixel = previous_zc.len() - 1;
    let (previous_a, previous_p) = (&previous_a[..=last_pixel], &previous_p[..=last_pixel]);
    let mut counts = RowCounts {
        warped: 0,
        newly_discovered: 0,
        object: 0,
        object_columns: (usize::MAX, 0),
    };
    // The gathered values of one block (every block's gather overwrites its part).
    let mut sampled = [0.0f32; FINISH_BLOCK];
    let mut carried_a = [0.0f32; FINISH_BLOCK];
    let mut carried_p = [0u8; FINISH_BLOCK];
    let mut start = 0;
    while start < n {
        let len = FINISH_BLOCK.min(n - start);
        let end = start + len;
        let sources = &sources[start..end];
        gather_block(
            simd,
            sources,
            previous_zc,
            previous_a,
            previous_p,
            &mut sampled[..len],
            &mut carried_a[..len],
            &mut carried_p[..len],
        );
        let measured = &measured_row[start..end];
        let zc_row = &mut out.compensated_m[start..end];
        let a_row = &mut out.accumulation_m[start..end];
        let p_row = &mut out.predicted_carried[start..end];
        let dz_row = &mut out.delta_z_m[start..end];
        let n_row = &mut out.newly_discovered[start..end];
        let set_row = &mut out.object_set[start..end];
        // Three single-width loops (f32; f32 → u8; to u8) so each one vectorises.
        let warped_count = finish_block(
            simd,
            finish,
            sources,
            measured,
            (&mut sampled[..len], &carried_a[..len]),
            zc_row,
            a_row,
            dz_row,
        );
        let object_count = object_set_block(simd, finish, zc_row, a_row, set_row);
        if let Some(slow) = slow.as_mut() {
            slow_update(
                simd,
                finish,
                sources,
                measured,
                previous_zc,
                zc_row,
                dz_row,
                slow,
                start..end,
            );
        }
        let newly_count = flags_block(
            simd,
            sources,
            &sampled[..len],
            zc_row,
            &carried_p[..len],
            n_row,
            p_row,
        );
        counts.warped += warped_count as usize;
        counts.newly_discovered += newly_count as usize;
        counts.object += object_count as usize;
        if object_count > 0 {
            let first = set_row.iter().position(|&l| l != 0).unwrap_or(0);
            let last = set_row.iter().rposition(|&l| l != 0).unwrap_or(0);
            counts.object_columns.0 = counts.object_columns.0.min(start + first);
            counts.object_columns.1 = start + last;
        }
        start = end;
    }
    counts
}

/// W on the block `range` of a row (its sources, measured depth, Zc and ΔZ slices are the
/// block's): through the row's own warp or, when W has one ([`SlowRow::own_warp`]), through that.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
fn slow_update(
    simd: Simd,
    finish: &FinishParameters,
    sources: &[u32],
    measured: &[f32],
    previous_zc: &[f32],
    zc_row: &[f32],
    dz_row: &[f32],
    slow: &mut SlowRow<'_>,
    range: std::ops::Range<usize>,
) {
    let len = range.len();
    let mut carried_w = [0.0f32; FINISH_BLOCK];
    let mut own_delta = [0.0f32; FINISH_BLOCK];
    let (slow_sources, slow_dz): (&[u32], &[f32]) = match slow.own_warp {
        None => (sources, dz_row),
        Some((own_sources, own_qz)) => {
            let own_sources = &own_sources[range.clone()];
            geometric_delta_block(
                simd,
                own_sources,
                previous_zc,
                measured,
                &own_qz[range.clone()],
                &mut own_delta[..len],
            );
            (own_sources, &own_delta[..len])
        }
    };
    gather_slow_block(simd, slow_sources, slow.previous, &mut carried_w[..len]);
    let kept_events = slow_block(
        simd,
        slow_sources,
        finish.alpha,
        finish.beta,
        finish.quadratic,
        slow.retention,
        zc_row,
        slow_dz,
        &carried_w[..len],
        slow.events,
        &mut slow.row[range.clone()],
    );
    if kept_events > 0 {
        // Rare pixels (an occlusion event): those whose source lies at a depth edge leave W.
        let w_row = &mut slow.row[range];
        for (i, w) in w_row.iter_mut().enumerate() {
            let zc = zc_row[i];
            let z_or_one = if finish.quadratic { zc } else { 1.0 };
            let event = slow_dz[i] > finish.alpha * zc * z_or_one;
            if event && *w != 0.0 && source_at_depth_edge(previous_zc, slow.width, slow_sources[i]) {
                *w = 0.0;
            }
        }
    }
}

/// A 4-neighbour of a source pixel whose depth differs from the source's by more than this
/// fraction of it (or that has no depth, or lies outside the image) puts the source at a depth
/// edge, where sampling one pixel off turns a static surface into an occlusion event.
pub(super) const EVENT_EDGE_STEP: f32 = 0.1;

/// Whether the previous frame's pixel `source` ([`NO_SOURCE`]: no warp) lies at a depth edge of
/// `previous_zc` (see [`EVENT_EDGE_STEP`]).
pub(super) fn source_at_depth_edge(previous_zc: &[f32], width: usize, source: u32) -> bool {
    if source == NO_SOURCE {
        return true;
    }
    let s = source as usize;
    let (x, z) = (s % width, previous_zc[s]);
    let limit = EVENT_EDGE_STEP * z;
    let neighbours = [
        (x > 0).then(|| s - 1),
        (x + 1 < width).then_some(s + 1),
        s.checked_sub(width),
        Some(s + width).filter(|&n| n < previous_zc.len()),
    ];
    !neighbours
        .iter()
        .all(|n| n.is_some_and(|n| previous_zc[n] > 0.0 && (previous_zc[n] - z).abs() < limit))
}

/// Steps 3–8 on one block (f32 only; every slice a separate argument so the compiler knows
/// they do not alias and vectorises): `sampled` gets the validity-masked previous depth, ΔZ
/// holds z′ on entry (geometric mode). Returns the warped pixels.
#[inline(always)]
fn finish_block_generic(
    finish: &FinishParameters,
    sources: &[u32],
    measured: &[f32],
    (sampled, carried_a): (&mut [f32], &[f32]),
    zc_row: &mut [f32],
    a_row: &mut [f32],
    dz_row: &mut [f32],
) -> u32 {
    let len = sources.len();
    let (measured, sampled, carried_a) = (&measured[..len], &mut sampled[..len], &carried_a[..len]);
    let (zc_row, a_row, dz_row) = (&mut zc_row[..len], &mut a_row[..len], &mut dz_row[..len]);
    let (alpha, beta, quadratic, geometric) = (finish.alpha, finish.beta, finish.quadratic, finish.geometric);
    let retention = finish.retention;
    let mut warped_count = 0u32;
    for i in 0..len {
        let warped = sources[i] != NO_SOURCE;
        let sampled_m = if warped { sampled[i] } else { 0.0 };
        sampled[i] = sampled_m;
        let measured_m = measured[i];
        let compensated_m = if measured_m > 0.0 { measured_m } else { sampled_m };
        let use_z_prime = geometric & (measured_m > 0.0) & warped;
        let compared_m = if use_z_prime { dz_row[i] } else { compensated_m };
        let delta_z_m = if warped { sampled_m - compared_m } else { 0.0 };
        // τ = (coefficient·Z)·Z or (coefficient·Z)·1, exactly `OcclusionConfig::threshold`.
        let z_or_one = if quadratic { compensated_m } else { 1.0 };
        let tau_alpha = alpha * compensated_m * z_or_one;
        let tau_beta = beta * compensated_m * z_or_one;
        let accumulation = (if warped { carried_a[i] } else { 0.0 }) + delta_z_m;
        // Below τ_α the accumulation is kept at `retention` times its value (0 = the
        // release's truncation); a reappearing background (ΔZ ≤ −τ_β) clears it.
        let kept = if accumulation > tau_alpha {
            accumulation
        } else {
            retention * (if accumulation > 0.0 { accumulation } else { 0.0 })
        };
        zc_row[i] = compensated_m;
        a_row[i] = if delta_z_m <= -tau_beta { 0.0 } else { kept };
        dz_row[i] = delta_z_m;
        warped_count += u32::from(warped);
    }
    warped_count
}

simd_kernel!(
    finish_block,
    finish_block_avx2,
    finish_block_generic,
    (
        finish: &FinishParameters,
        sources: &[u32],
        measured: &[f32],
        sampled_and_carried_a: (&mut [f32], &[f32]),
        zc_row: &mut [f32],
        a_row: &mut [f32],
        dz_row: &mut [f32]
    ) -> u32
);

/// Gathers the previous Zc, A, P at the warp sources of one block (an invalid source reads
/// pixel `last_pixel`, discarded by the finishing loops).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn gather_block_generic(
    sources: &[u32],
    previous_zc: &[f32],
    previous_a: &[f32],
    previous_p: &[u8],
    sampled: &mut [f32],
    carried_a: &mut [f32],
    carried_p: &mut [u8],
) {
    let len = sources.len();
    let last_pixel = previous_zc.len() - 1;
    let (previous_a, previous_p) = (&previous_a[..=last_pixel], &previous_p[..=last_pixel]);
    let (sampled, carried_a, carried_p) = (&mut sampled[..len], &mut carried_a[..len], &mut carried_p[..len]);
    for i in 0..len {
        let at = (sources[i] as usize).min(last_pixel);
        sampled[i] = previous_zc[at];
        carried_a[i] = previous_a[at];
        carried_p[i] = previous_p[at];
    }
}

simd_kernel!(
    gather_block,
    gather_block_avx2,
    gather_block_generic,
    (
        sources: &[u32],
        previous_zc: &[f32],
        previous_a: &[f32],
        previous_p: &[u8],
        sampled: &mut [f32],
        carried_a: &mut [f32],
        carried_p: &mut [u8]
    ),
    widest = Avx2
);

/// Gathers the previous slow-change evidence at the warp sources of one block (an invalid source
/// reads the last pixel; [`slow_block`] discards it, as ΔZ is 0 there).
#[inline(always)]
fn gather_slow_block_generic(sources: &[u32], previous_w: &[f32], carried_w: &mut [f32]) {
    let len = sources.len();
    let last_pixel = previous_w.len() - 1;
    let carried_w = &mut carried_w[..len];
    for i in 0..len {
        carried_w[i] = previous_w[(sources[i] as usize).min(last_pixel)];
    }
}

simd_kernel!(
    gather_slow_block,
    gather_slow_block_avx2,
    gather_slow_block_generic,
    (sources: &[u32], previous_w: &[f32], carried_w: &mut [f32]),
    widest = Avx2
);

/// ΔZ of the geometric warp on one block (W's own warp): the previous compensated depth at the
/// warp source minus the warped point's depth z′, where the pixel is measured and warped (0
/// elsewhere; [`slow_block`] then resets W for want of a source).
#[inline(always)]
fn geometric_delta_block_generic(
    sources: &[u32],
    previous_zc: &[f32],
    measured: &[f32],
    qz: &[f32],
    delta: &mut [f32],
) {
    let len = sources.len();
    let last_pixel = previous_zc.len() - 1;
    let (measured, qz, delta) = (&measured[..len], &qz[..len], &mut delta[..len]);
    for i in 0..len {
        let sampled = previous_zc[(sources[i] as usize).min(last_pixel)];
        let valid = (sources[i] != NO_SOURCE) & (measured[i] > 0.0);
        delta[i] = if valid { sampled - qz[i] } else { 0.0 };
    }
}

simd_kernel!(
    geometric_delta_block,
    geometric_delta_block_avx2,
    geometric_delta_block_generic,
    (sources: &[u32], previous_zc: &[f32], measured: &[f32], qz: &[f32], delta: &mut [f32])
);

/// W of one block: retention · Ŵ + min(ΔZ, τ_α) where the pixel was warped, the background
/// did not reappear (ΔZ > −τ_β) and, unless `events`, nothing moved in front of it at once
/// (ΔZ ≤ τ_α: the paper leaves an occlusion event to A), else 0. Returns the occlusion events
/// kept in W.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn slow_block_generic(
    sources: &[u32],
    alpha: f32,
    beta: f32,
    quadratic: bool,
    retention: f32,
    zc_row: &[f32],
    dz_row: &[f32],
    carried_w: &[f32],
    events: bool,
    w_row: &mut [f32],
) -> u32 {
    let len = w_row.len();
    let (sources, zc_row, dz_row, carried_w) =
        (&sources[..len], &zc_row[..len], &dz_row[..len], &carried_w[..len]);
    let mut kept_events = 0;
    for i in 0..len {
        let z_or_one = if quadratic { zc_row[i] } else { 1.0 };
        let tau_alpha = alpha * zc_row[i] * z_or_one;
        let tau_beta = beta * zc_row[i] * z_or_one;
        let keep = (sources[i] != NO_SOURCE) & (dz_row[i] > -tau_beta) & (events | (dz_row[i] <= tau_alpha));
        w_row[i] = if keep {
            retention * carried_w[i] + dz_row[i].min(tau_alpha)
        } else {
            0.0
        };
        kept_events += u32::from(keep & (dz_row[i] > tau_alpha));
    }
    kept_events
}

simd_kernel!(
    slow_block,
    slow_block_avx2,
    slow_block_generic,
    (
        sources: &[u32],
        alpha: f32,
        beta: f32,
        quadratic: bool,
        retention: f32,
        zc_row: &[f32],
        dz_row: &[f32],
        carried_w: &[f32],
        events: bool,
        w_row: &mut [f32]
    ) -> u32
);

/// O₀ of one block: 1 where A > τ_α, else 0. Returns the object pixels.
#[inline(always)]
fn object_set_block_generic(
    finish: &FinishParameters,
    zc_row: &[f32],
    a_row: &[f32],
    labels: &mut [u8],
) -> u32 {
    let len = labels.len();
    let (zc_row, a_row) = (&zc_row[..len], &a_row[..len]);
    let mut object_count = 0u32;
    for i in 0..len {
        let z_or_one = if finish.quadratic { zc_row[i] } else { 1.0 };
        let object = a_row[i] > finish.alpha * zc_row[i] * z_or_one;
        labels[i] = u8::from(object);
        object_count += u32::from(object);
    }
    object_count
}

simd_kernel!(
    object_set_block,
    object_set_block_avx2,
    object_set_block_generic,
    (finish: &FinishParameters, zc_row: &[f32], a_row: &[f32], labels: &mut [u8]) -> u32
);

/// Ñ and P̂ of one block (`sampled` already masked by validity). Returns |Ñ|.
#[inline(always)]
fn flags_block_generic(
    sources: &[u32],
    sampled: &[f32],
    zc_row: &[f32],
    carried_p: &[u8],
    newly_row: &mut [u8],
    p_row: &mut [u8],
) -> u32 {
    let len = sources.len();
    let (sampled, zc_row, carried_p) = (&sampled[..len], &zc_row[..len], &carried_p[..len]);
    let (newly_row, p_row) = (&mut newly_row[..len], &mut p_row[..len]);
    let mut newly_count = 0u32;
    for i in 0..len {
        let newly = (zc_row[i] > 0.0) & (sampled[i] == 0.0);
        newly_row[i] = u8::from(newly);
        // An unconditional load masked by a select (a conditional load keeps the loop scalar).
        let keep = if sources[i] != NO_SOURCE { u8::MAX } else { 0 };
        p_row[i] = carried_p[i] & keep;
        newly_count += u32::from(newly);
    }
    newly_count
}

simd_kernel!(
    flags_block,
    flags_block_avx2,
    flags_block_generic,
    (
        sources: &[u32],
        sampled: &[f32],
        zc_row: &[f32],
        carried_p: &[u8],
        newly_row: &mut [u8],
        p_row: &mut [u8]
    ) -> u32
);

/// Thresholds of the object-mask pass (steps 11–12).
pub(super) struct ObjectMaskParameters {
    /// τ = α·Z² instead of α·Z.
    pub quadratic: bool,
    /// α of τ_α.
    pub alpha: f32,
    /// Prediction on: P = (P̂ ∨ Ñ) ∧ O; off: P = ∅.
    pub predicting: bool,
}

/// Steps 11–12 input on a run of pixels: O = {A > τ_α} into `mask` (0 / `MASK_SET`) and P = (P̂ ∨ Ñ)
/// ∧ O into `predicted` (0 / 1, the pruning labels its runs directly). Returns (|O|, |P|). Single-width loops so each vectorises.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn object_mask_block_generic(
    parameters: &ObjectMaskParameters,
    accumulation_m: &[f32],
    compensated_m: &[f32],
    carried: &[u8],
    newly: &[u8],
    mask: &mut [u8],
    predicted: &mut [u8],
) -> (u32, u32) {
    let len = mask.len();
    let (a, z, carried, newly) = (
        &accumulation_m[..len],
        &compensated_m[..len],
        &carried[..len],
        &newly[..len],
    );
    let predicted = &mut predicted[..len];
    let (quadratic, alpha) = (parameters.quadratic, parameters.alpha);
    let mut object_count = 0u32;
    for i in 0..len {
        // (α·Z)·Z or (α·Z)·1: exactly `OcclusionConfig::threshold`.
        let z_or_one = if quadratic { z[i] } else { 1.0 };
        let object = a[i] > alpha * z[i] * z_or_one;
        mask[i] = if object { crate::image_buf::MASK_SET } else { 0 };
        object_count += u32::from(object);
    }
    let keep = if parameters.predicting { u8::MAX } else { 0 };
    let mut predicted_count = 0u32;
    for i in 0..len {
        let is_predicted = mask[i] & ((carried[i] & super::PREDICTED) | newly[i]) & keep != 0;
        predicted[i] = u8::from(is_predicted);
        predicted_count += u32::from(is_predicted);
    }
    (object_count, predicted_count)
}

simd_kernel!(
    object_mask_block,
    object_mask_block_avx2,
    object_mask_block_generic,
    (
        parameters: &ObjectMaskParameters,
        accumulation_m: &[f32],
        compensated_m: &[f32],
        carried: &[u8],
        newly: &[u8],
        mask: &mut [u8],
        predicted: &mut [u8]
    ) -> (u32, u32)
);

/// [`object_mask_block_generic`] in the given build, or in the widest the CPU runs
/// ([`Simd::cpu`]) where that is narrower.
#[allow(clippy::too_many_arguments)]
pub(super) fn object_mask_block_with(
    simd: Simd,
    parameters: &ObjectMaskParameters,
    accumulation_m: &[f32],
    compensated_m: &[f32],
    carried: &[u8],
    newly: &[u8],
    mask: &mut [u8],
    predicted: &mut [u8],
) -> (u32, u32) {
    let simd = simd.min(Simd::cpu());
    object_mask_block(
        simd,
        parameters,
        accumulation_m,
        compensated_m,
        carried,
        newly,
        mask,
        predicted,
    )
}
