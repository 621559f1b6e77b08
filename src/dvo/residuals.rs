//! Residuals, Jacobians and the row-parallel accumulation of the 6×6 normal equations.
//!
//! For a reference point p (reference camera, metres) and the current estimate
//! T = current_from_reference, let p′ = T·p = (x, y, z) and w = π(p′) its pixel in the current
//! image. Both residuals read the current level with **bilinear** interpolation at w, for the
//! values and for their gradients alike (docs/method.md, "Dense visual odometry"):
//! - photometric r_I = I_cur(w) − I_ref(p);
//! - geometric r_Z = Z_cur(w) − z, against the *transformed* depth z (dvo_slam / Open3D form).
//!
//! With the left perturbation T ← exp(δ)·T, δ = (v, ω), ∂p′/∂δ = [I₃ | −[p′]×], and for an image
//! gradient g = (g_x, g_y) at w: a = J_πᵀ g = (f_x g_x / z, f_y g_y / z, −(f_x g_x x + f_y g_y y)/z²),
//! so ∂(value at w)/∂δ = [a, p′ × a]. The photometric Jacobian is that with g = ∇I; the geometric
//! one uses g = ∇Z and subtracts ∂z/∂δ = (0, 0, 1, y, −x, 0) (the third row of ∂p′/∂δ), i.e.
//! J_Z = [b, p′ × b] with b = a_Z − e₃.
//!
//! The robust cost is Σ ρ_{k_I}(r_I) + γ Σ ρ_{k_Z}(r_Z) (bi-square, [`super::weights`]), summed
//! over *all* reference points: a point that projects outside the image or onto missing depth
//! pays the saturated loss, so the cost of two candidate poses is always comparable.

use nalgebra::{Isometry3, Matrix6, Point3, Vector6};
use rayon::prelude::*;

use super::weights::{bisquare, bisquare_saturated};
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::ImageSize;
use crate::pyramid::TargetSample;

/// Reference points processed per rayon task, in rows' worth of the level they come from
/// (a task takes `ROWS_PER_TASK × width` consecutive points): at the default finest level
/// (320 px wide) that is 2560 points, ≈ 0.1 ms of work, so the ≈ 22 k points selected on a
/// fr2_desk frame split into ≈ 9 tasks (balance on 2–8 cores) while the per-task reduction of a
/// 6×6 system stays negligible.
pub const ROWS_PER_TASK: usize = 8;

/// Points accumulated in f32 before the partial sums are flushed into the f64 totals: short
/// enough that f32 rounding stays below 1e-5 relative, long enough to keep the flush cheap.
const F32_FLUSH_POINTS: usize = 128;

/// A transformed depth below this (metres) cannot be projected meaningfully.
pub const MIN_TRANSFORMED_DEPTH_M: f32 = 1e-3;

/// A reference pixel back-projected into its camera, with its intensity.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ReferencePoint {
    /// Point in the reference camera frame, metres.
    pub point_m: [f32; 3],
    /// Reference intensity in [0, 1].
    pub intensity: f32,
}

/// Robust-cost constants of one level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CostParams {
    /// Bi-square threshold of the photometric residual (intensity units, [0, 1] scale).
    pub k_intensity: f32,
    /// Bi-square threshold of the depth residual, metres.
    pub k_depth_m: f32,
    /// Weight γ of the depth term.
    pub depth_weight: f32,
}

impl CostParams {
    /// Loss of a reference point that cannot be evaluated at all (or matches nowhere): the
    /// saturated bi-square loss of both channels.
    #[inline]
    pub fn saturated_point(&self) -> f32 {
        bisquare_saturated(self.k_intensity) + self.depth_weight * bisquare_saturated(self.k_depth_m)
    }
}

/// The current (target) level as the kernel reads it.
#[derive(Debug, Clone, Copy)]
pub struct TargetView<'a> {
    /// Packed samples, row-major.
    pub samples: &'a [TargetSample],
    /// Level size.
    pub size: ImageSize,
    /// Level intrinsics.
    pub intrinsics: PinholeIntrinsics,
}

/// Weighted normal equations H δ = −g of the robust cost, plus the cost itself.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormalEquations {
    /// Upper triangle of H = Σ w JᵀJ, row-major (H₀₀, H₀₁, …, H₀₅, H₁₁, …, H₅₅).
    pub hessian_upper: [f64; 21],
    /// g = Σ w Jᵀ r.
    pub gradient: [f64; 6],
    /// Σ ρ over all reference points (saturated loss for unusable ones).
    pub cost: f64,
    /// Reference points that project inside the current image.
    pub valid: usize,
    /// Of those, points with a non-zero robust weight in either channel.
    pub inliers: usize,
    /// Reference points evaluated.
    pub total: usize,
}

impl Default for NormalEquations {
    fn default() -> Self {
        Self {
            hessian_upper: [0.0; 21],
            gradient: [0.0; 6],
            cost: 0.0,
            valid: 0,
            inliers: 0,
            total: 0,
        }
    }
}

impl NormalEquations {
    /// Sum of two partial systems.
    pub fn merged(mut self, other: &Self) -> Self {
        for (a, b) in self.hessian_upper.iter_mut().zip(&other.hessian_upper) {
            *a += b;
        }
        for (a, b) in self.gradient.iter_mut().zip(&other.gradient) {
            *a += b;
        }
        self.cost += other.cost;
        self.valid += other.valid;
        self.inliers += other.inliers;
        self.total += other.total;
        self
    }

    /// H as a full symmetric matrix.
    pub fn hessian(&self) -> Matrix6<f64> {
        let mut h = Matrix6::zeros();
        let mut k = 0;
        for i in 0..6 {
            for j in i..6 {
                h[(i, j)] = self.hessian_upper[k];
                h[(j, i)] = self.hessian_upper[k];
                k += 1;
            }
        }
        h
    }

    /// g as a vector.
    pub fn gradient_vector(&self) -> Vector6<f64> {
        Vector6::from_column_slice(&self.gradient)
    }

    /// Cost per reference point (comparable across levels and frames); 0 without points.
    pub fn mean_cost(&self) -> f64 {
        if self.total == 0 {
            0.0
        } else {
            self.cost / self.total as f64
        }
    }
}

/// Residuals and Jacobians of one reference point (reference implementation, f64).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointLinearization {
    /// Photometric residual r_I.
    pub residual_intensity: f64,
    /// ∂r_I/∂δ.
    pub jacobian_intensity: Vector6<f64>,
    /// Depth residual r_Z (metres) and its Jacobian, when the current depth is usable at w.
    pub depth: Option<(f64, Vector6<f64>)>,
}

/// Bilinear interpolation of the packed samples at (u, v) (reference version, f64). `None`
/// outside [0, W−1) × [0, H−1), the domain where all four corners exist.
pub fn sample_bilinear(target: &TargetView<'_>, u: f64, v: f64) -> Option<[f64; 6]> {
    let (w, h) = (target.size.width, target.size.height);
    if !(u >= 0.0 && v >= 0.0 && u < (w as f64 - 1.0) && v < (h as f64 - 1.0)) {
        return None;
    }
    let (x0, y0) = (u.floor() as usize, v.floor() as usize);
    let (a, b) = (u - x0 as f64, v - y0 as f64);
    let corners = [
        (y0 * w + x0, (1.0 - a) * (1.0 - b)),
        (y0 * w + x0 + 1, a * (1.0 - b)),
        ((y0 + 1) * w + x0, (1.0 - a) * b),
        ((y0 + 1) * w + x0 + 1, a * b),
    ];
    let mut out = [0.0; 6];
    for (idx, wt) in corners {
        for (o, &s) in out.iter_mut().zip(&target.samples[idx].0[..6]) {
            *o += wt * f64::from(s);
        }
    }
    Some(out)
}

/// Residuals and Jacobians of one point at `current_from_reference` (reference
/// implementation in f64 with nalgebra; the fast kernel must agree with it). `None` when the
/// point does not project inside the bilinear domain of the current level.
pub fn linearize_point(
    point: &ReferencePoint,
    target: &TargetView<'_>,
    current_from_reference: &Isometry3<f64>,
) -> Option<PointLinearization> {
    let p = Point3::new(
        f64::from(point.point_m[0]),
        f64::from(point.point_m[1]),
        f64::from(point.point_m[2]),
    );
    let q = current_from_reference * p;
    if q.z <= f64::from(MIN_TRANSFORMED_DEPTH_M) {
        return None;
    }
    let k = &target.intrinsics;
    let uv = k.project(&q)?;
    let s = sample_bilinear(target, uv.x, uv.y)?;
    // J_π (2×3) and ∂p′/∂δ = [I | −[p′]×] (3×6).
    let j_pi = nalgebra::Matrix2x3::new(
        k.fx / q.z,
        0.0,
        -k.fx * q.x / (q.z * q.z),
        0.0,
        k.fy / q.z,
        -k.fy * q.y / (q.z * q.z),
    );
    let mut d_point = nalgebra::Matrix3x6::zeros();
    d_point
        .fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&nalgebra::Matrix3::identity());
    d_point
        .fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(-q.coords.cross_matrix()));
    let j_warp = j_pi * d_point; // 2×6: ∂w/∂δ
    let grad_i = nalgebra::RowVector2::new(s[1], s[2]);
    let jacobian_intensity = (grad_i * j_warp).transpose();
    let depth = if s[3].is_finite() && s[4].is_finite() && s[5].is_finite() {
        let grad_z = nalgebra::RowVector2::new(s[4], s[5]);
        let dz = d_point.row(2);
        Some((s[3] - q.z, (grad_z * j_warp - dz).transpose()))
    } else {
        None
    };
    Some(PointLinearization {
        residual_intensity: s[0] - f64::from(point.intensity),
        jacobian_intensity,
        depth,
    })
}

/// Scalar reference of the normal-equation accumulation: one thread, f64, nalgebra, built on
/// `linearize_point`. Slow; kept to test [`accumulate_normal_equations`] against.
pub fn accumulate_normal_equations_scalar(
    points: &[ReferencePoint],
    target: &TargetView<'_>,
    current_from_reference: &Isometry3<f64>,
    cost: &CostParams,
) -> NormalEquations {
    let mut h = Matrix6::<f64>::zeros();
    let mut g = Vector6::<f64>::zeros();
    let mut ne = NormalEquations {
        total: points.len(),
        ..Default::default()
    };
    let (k_i, k_z, gamma) = (cost.k_intensity, cost.k_depth_m, cost.depth_weight);
    for p in points {
        let Some(lin) = linearize_point(p, target, current_from_reference) else {
            ne.cost += f64::from(cost.saturated_point());
            continue;
        };
        ne.valid += 1;
        let (rho_i, w_i) = bisquare(lin.residual_intensity as f32, k_i);
        ne.cost += f64::from(rho_i);
        let w_i = f64::from(w_i);
        h += w_i * lin.jacobian_intensity * lin.jacobian_intensity.transpose();
        g += w_i * lin.residual_intensity * lin.jacobian_intensity;
        let mut w_z_pos = false;
        match lin.depth {
            Some((r_z, j_z)) => {
                let (rho_z, w_z) = bisquare(r_z as f32, k_z);
                ne.cost += f64::from(gamma * rho_z);
                let w_z = f64::from(gamma * w_z);
                w_z_pos = w_z > 0.0;
                h += w_z * j_z * j_z.transpose();
                g += w_z * r_z * j_z;
            }
            None => ne.cost += f64::from(gamma * bisquare_saturated(k_z)),
        }
        if w_i > 0.0 || w_z_pos {
            ne.inliers += 1;
        }
    }
    let mut k = 0;
    for i in 0..6 {
        for j in i..6 {
            ne.hessian_upper[k] = h[(i, j)];
            k += 1;
        }
    }
    ne.gradient.copy_from_slice(g.as_slice());
    ne
}

/// The fast kernel: [`accumulate_normal_equations_scalar`] in f32 per point with f64 totals,
/// row-parallel with rayon (fold per task, then reduce). `row_width` is the width of the level
/// the points came from (it only sets the task size, see `ROWS_PER_TASK`).
pub fn accumulate_normal_equations(
    points: &[ReferencePoint],
    row_width: usize,
    target: &TargetView<'_>,
    current_from_reference: &Isometry3<f64>,
    cost: &CostParams,
) -> NormalEquations {
    let kernel = KernelConstants::new(target, current_from_reference, cost);
    let chunk = (ROWS_PER_TASK * row_width).max(1);
    let run = |c: &[ReferencePoint]| accumulate_chunk_dispatch(c, target.samples, &kernel);
    if points.len() < MIN_POINTS_FOR_PARALLEL {
        return points
            .chunks(chunk)
            .fold(NormalEquations::default(), |acc, c| acc.merged(&run(c)));
    }
    // The partial systems are summed in point order, as on the calling thread above, not in
    // whatever grouping work stealing produced (`fold` + `reduce`): the f64 totals then do not
    // depend on the pool size, so neither do the estimate and `occmask process`'s output
    // bytes. (Sums of the f32 block totals are usually exact in f64 anyway; this makes it a
    // guarantee.) The partials are a few dozen 248-byte values per call.
    let partials: Vec<NormalEquations> = points.par_chunks(chunk).map(run).collect();
    partials
        .iter()
        .fold(NormalEquations::default(), |acc, p| acc.merged(p))
}

/// Below this many points a call runs on the calling thread: the coarse levels (≈ 1–5 k points,
/// 0.05–0.2 ms of work) cost less than waking the pool's other threads, which under load
/// measured more than the work itself (level 4, 1.1 k points: 0.38 ms per iteration through
/// rayon against 0.06 ms for the pass on a busy 2-core machine).
pub const MIN_POINTS_FOR_PARALLEL: usize = 8192;

/// [`accumulate_chunk`] compiled for AVX2 + FMA when the CPU has them (the same code: the
/// compiler then evaluates the 8-lane loops in one 256-bit register instead of two 128-bit
/// ones; without explicit `mul_add` the arithmetic and so the results are bit-identical).
/// Unlike the `simd_kernel!` kernels it has no AVX-512 build: on an AVX-512 Xeon that build
/// took 18 % more of the CPU than this one (`perf`, the Bonn window).
fn accumulate_chunk_dispatch(
    points: &[ReferencePoint],
    samples: &[TargetSample],
    kc: &KernelConstants,
) -> NormalEquations {
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU supports AVX2 and FMA (checked just above).
            return unsafe { accumulate_chunk_avx2(points, samples, kc) };
        }
    }
    accumulate_chunk(points, samples, kc)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn accumulate_chunk_avx2(
    points: &[ReferencePoint],
    samples: &[TargetSample],
    kc: &KernelConstants,
) -> NormalEquations {
    accumulate_chunk(points, samples, kc)
}

/// Everything the kernel needs, converted to f32 once per call.
struct KernelConstants {
    rotation: [f32; 9],
    translation: [f32; 3],
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    width: usize,
    u_max: f32,
    v_max: f32,
    cost: CostParams,
    saturated_point: f32,
}

impl KernelConstants {
    fn new(target: &TargetView<'_>, t: &Isometry3<f64>, cost: &CostParams) -> Self {
        let r = t.rotation.to_rotation_matrix();
        let m = r.matrix();
        let k = &target.intrinsics;
        Self {
            rotation: [
                m[(0, 0)] as f32,
                m[(0, 1)] as f32,
                m[(0, 2)] as f32,
                m[(1, 0)] as f32,
                m[(1, 1)] as f32,
                m[(1, 2)] as f32,
                m[(2, 0)] as f32,
                m[(2, 1)] as f32,
                m[(2, 2)] as f32,
            ],
            translation: [
                t.translation.vector.x as f32,
                t.translation.vector.y as f32,
                t.translation.vector.z as f32,
            ],
            fx: k.fx as f32,
            fy: k.fy as f32,
            cx: k.cx as f32,
            cy: k.cy as f32,
            width: target.size.width,
            u_max: target.size.width as f32 - 1.0,
            v_max: target.size.height as f32 - 1.0,
            cost: *cost,
            saturated_point: cost.saturated_point(),
        }
    }
}

/// Points evaluated together: the per-point arithmetic after the bilinear gather runs as
/// loops over this many lanes, which the compiler turns into SIMD (two SSE registers on the
/// x86-64 baseline, one AVX register where available).
const LANES: usize = 8;

/// Lane-wise f32 partial sums of a run of points (one column per lane).
struct LaneSums {
    h: [[f32; LANES]; 21],
    g: [[f32; LANES]; 6],
    cost: [f32; LANES],
}

impl LaneSums {
    fn new() -> Self {
        Self {
            h: [[0.0; LANES]; 21],
            g: [[0.0; LANES]; 6],
            cost: [0.0; LANES],
        }
    }

    /// H += w·J·Jᵀ (upper triangle), g += w·r·J for every lane.
    #[inline(always)]
    fn add(&mut self, j: &[[f32; LANES]; 6], weight: &[f32; LANES], residual: &[f32; LANES]) {
        let mut k = 0;
        for a in 0..6 {
            let mut wa = [0.0f32; LANES];
            for l in 0..LANES {
                wa[l] = weight[l] * j[a][l];
            }
            for jb in &j[a..] {
                let h = &mut self.h[k];
                for l in 0..LANES {
                    h[l] += wa[l] * jb[l];
                }
                k += 1;
            }
            let g = &mut self.g[a];
            for l in 0..LANES {
                g[l] += wa[l] * residual[l];
            }
        }
    }

    fn flush_into(&mut self, ne: &mut NormalEquations) {
        for (t, s) in ne.hessian_upper.iter_mut().zip(&self.h) {
            *t += s.iter().map(|&v| f64::from(v)).sum::<f64>();
        }
        for (t, s) in ne.gradient.iter_mut().zip(&self.g) {
            *t += s.iter().map(|&v| f64::from(v)).sum::<f64>();
        }
        ne.cost += self.cost.iter().map(|&v| f64::from(v)).sum::<f64>();
        *self = Self::new();
    }
}

/// Branch-free bi-square (ρ, w) for a lane; `inv_k` = 1/k, `rho_sat` = k²/6.
#[inline(always)]
fn bisquare_lane(residual: f32, inv_k: f32, rho_sat: f32) -> (f32, f32) {
    let s = residual * inv_k;
    let one_minus = (1.0 - s * s).max(0.0);
    let w = one_minus * one_minus;
    (rho_sat * (1.0 - w * one_minus), w)
}

/// The Jacobian [a, p′ × a] of a value whose image gradient, pre-scaled by f/z, is (gu, gv),
/// minus `dz` times ∂z/∂δ (dz = 1 for the depth residual, 0 for intensity).
#[inline(always)]
fn jacobian_lane(gu: f32, gv: f32, x: f32, y: f32, z: f32, iz: f32, dz: f32) -> [f32; 6] {
    let a2 = -(gu * x + gv * y) * iz - dz;
    [gu, gv, a2, y * a2 - z * gv, z * gu - x * a2, x * gv - y * gu]
}

// `!(a > b)` is deliberate: a NaN must take the reject branch.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
#[inline(always)]
fn accumulate_chunk(
    points: &[ReferencePoint],
    samples: &[TargetSample],
    kc: &KernelConstants,
) -> NormalEquations {
    let mut ne = NormalEquations {
        total: points.len(),
        ..Default::default()
    };
    let r = &kc.rotation;
    let t = &kc.translation;
    let w = kc.width;
    let (inv_ki, inv_kz) = (1.0 / kc.cost.k_intensity, 1.0 / kc.cost.k_depth_m);
    let (sat_i, sat_z) = (
        bisquare_saturated(kc.cost.k_intensity),
        bisquare_saturated(kc.cost.k_depth_m),
    );
    let gamma = kc.cost.depth_weight;
    let mut sums = LaneSums::new();
    for run in points.chunks(F32_FLUSH_POINTS) {
        for block in run.chunks(LANES) {
            // Stage 1a (lane-parallel): transform and project. Lanes that cannot be evaluated
            // (absent, behind the camera, outside the bilinear domain) pay the saturated loss
            // and keep valid = 0 and harmless finite values (x = y = 0, z = 1, samples 0).
            let mut valid = [0.0f32; LANES];
            let mut px = [0.0f32; LANES];
            let mut py = [0.0f32; LANES];
            let mut pz = [1.0f32; LANES];
            let mut ref_i = [0.0f32; LANES];
            let mut corner = [0u32; LANES];
            let mut frac_u = [0.0f32; LANES];
            let mut frac_v = [0.0f32; LANES];
            let mut present = [false; LANES];
            let (mut qx, mut qy, mut qz) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
            for (l, p) in block.iter().enumerate() {
                [qx[l], qy[l], qz[l]] = p.point_m;
                ref_i[l] = p.intensity;
                present[l] = true;
            }
            for l in 0..LANES {
                let (qx, qy, qz) = (qx[l], qy[l], qz[l]);
                let x = r[0] * qx + r[1] * qy + r[2] * qz + t[0];
                let y = r[3] * qx + r[4] * qy + r[5] * qz + t[1];
                let z = r[6] * qx + r[7] * qy + r[8] * qz + t[2];
                let iz = 1.0 / z;
                let u = kc.fx * x * iz + kc.cx;
                let v = kc.fy * y * iz + kc.cy;
                let inside = present[l]
                    & (z > MIN_TRANSFORMED_DEPTH_M)
                    & (u >= 0.0)
                    & (v >= 0.0)
                    & (u < kc.u_max)
                    & (v < kc.v_max);
                sums.cost[l] += if present[l] & !inside {
                    kc.saturated_point
                } else {
                    0.0
                };
                let (u, v) = if inside { (u, v) } else { (0.0, 0.0) };
                // u, v ≥ 0 here, so truncation is the floor.
                let (x0, y0) = (u as u32, v as u32);
                frac_u[l] = u - x0 as f32;
                frac_v[l] = v - y0 as f32;
                corner[l] = y0 * w as u32 + x0;
                valid[l] = if inside { 1.0 } else { 0.0 };
                px[l] = if inside { x } else { 0.0 };
                py[l] = if inside { y } else { 0.0 };
                pz[l] = if inside { z } else { 1.0 };
                ref_i[l] = if inside { ref_i[l] } else { 0.0 };
            }
            // Stage 1b (per lane, 8 channels wide): bilinear mix of the four packed corners.
            let mut mixed = [[0.0f32; 8]; LANES];
            for l in 0..LANES {
                if valid[l] == 0.0 {
                    continue;
                }
                let i = corner[l] as usize;
                let (a, b) = (frac_u[l], frac_v[l]);
                let (s00, s01, s10, s11) = (
                    &samples[i].0,
                    &samples[i + 1].0,
                    &samples[i + w].0,
                    &samples[i + w + 1].0,
                );
                let (w00, w01, w10, w11) = ((1.0 - a) * (1.0 - b), a * (1.0 - b), (1.0 - a) * b, a * b);
                for (k, m) in mixed[l].iter_mut().enumerate() {
                    *m = w00 * s00[k] + w01 * s01[k] + w10 * s10[k] + w11 * s11[k];
                }
            }
            // Stage 1c (lane-parallel): to one array per channel. NaN depth or depth gradient
            // at any corner drops the depth term (0 · NaN would poison the sums, so the values
            // are replaced too).
            let mut s = [[0.0f32; LANES]; 6];
            for (k, channel) in s.iter_mut().enumerate() {
                for l in 0..LANES {
                    channel[l] = mixed[l][k];
                }
            }
            let mut depth_ok = [0.0f32; LANES];
            for l in 0..LANES {
                let d_ok = s[3][l].is_finite() & s[4][l].is_finite() & s[5][l].is_finite();
                s[3][l] = if d_ok { s[3][l] } else { pz[l] };
                s[4][l] = if d_ok { s[4][l] } else { 0.0 };
                s[5][l] = if d_ok { s[5][l] } else { 0.0 };
                depth_ok[l] = if d_ok & (valid[l] > 0.0) { 1.0 } else { 0.0 };
            }
            // Stage 2 (lane-parallel): residuals, robust weights, Jacobians, accumulation.
            let mut jac_i = [[0.0f32; LANES]; 6];
            let mut jac_z = [[0.0f32; LANES]; 6];
            let (mut r_i, mut w_i, mut r_z, mut w_z) =
                ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
            for l in 0..LANES {
                let (x, y, z) = (px[l], py[l], pz[l]);
                let iz = 1.0 / z;
                r_i[l] = s[0][l] - ref_i[l];
                let (rho_i, wi) = bisquare_lane(r_i[l], inv_ki, sat_i);
                w_i[l] = wi * valid[l];
                r_z[l] = s[3][l] - z;
                let (rho_z, wz) = bisquare_lane(r_z[l], inv_kz, sat_z);
                w_z[l] = gamma * wz * depth_ok[l];
                sums.cost[l] +=
                    valid[l] * (rho_i + gamma * (depth_ok[l] * rho_z + (1.0 - depth_ok[l]) * sat_z));
                let ji = jacobian_lane(s[1][l] * kc.fx * iz, s[2][l] * kc.fy * iz, x, y, z, iz, 0.0);
                let jz = jacobian_lane(s[4][l] * kc.fx * iz, s[5][l] * kc.fy * iz, x, y, z, iz, 1.0);
                for k in 0..6 {
                    jac_i[k][l] = ji[k];
                    jac_z[k][l] = jz[k];
                }
            }
            sums.add(&jac_i, &w_i, &r_i);
            sums.add(&jac_z, &w_z, &r_z);
            for l in 0..LANES {
                ne.valid += usize::from(valid[l] > 0.0);
                ne.inliers += usize::from(w_i[l] > 0.0 || w_z[l] > 0.0);
            }
        }
        sums.flush_into(&mut ne);
    }
    ne
}

#[cfg(test)]
mod tests;
