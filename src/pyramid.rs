//! Gray + depth image pyramids for dense visual odometry, preallocated once per sequence.
//!
//! Level 0 is the input resolution; level ℓ is 2^ℓ times smaller (odd sizes are cropped, as
//! the authors' Matlab release does). Per level the pyramid holds:
//! - `gray`: 2×2 box mean of the finer level (values in [0, 1]);
//! - `depth_m`: an *edge-aware* 2×2 mean (see [`downsample_depth_into`]); 0 = invalid;
//! - `samples`: one packed [`TargetSample`] per pixel (intensity, its gradient, depth, its
//!   gradient) so that the DVO kernel reads all six values of a bilinear corner with one
//!   cache line, the layout of Kerl et al.'s dvo_slam;
//! - the intrinsics of the level ([`PinholeIntrinsics::at_level`]: the 2×2 box mean puts coarse
//!   pixel j at fine coordinate 2j + 0.5).
//!
//! # Depth pyramid choice
//! A plain mean of the valid children blends foreground and background at depth edges and
//! creates depths where no surface exists (the authors' release does this); plain subsampling
//! (dvo_slam) avoids that but samples fine pixel 2j, half a pixel away from where the intensity
//! mean and the scaled intrinsics put coarse pixel j. Here a coarse depth is the mean of those
//! valid children that lie within [`DEPTH_EDGE_RELATIVE`] of the *nearest* valid child: on a
//! smooth surface it is the full 2×2 mean (centred at 2j + 0.5, noise averaged), across an edge
//! it keeps only the foreground side, never a blend.
//!
//! Levels finer than the pyramid's `finest_level` are not built (the DVO does not use them),
//! except for the intermediate ones needed to reach it; level 0 is then never copied.

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, GrayF32, ImageSize};
use crate::simd::{simd_kernel, Simd};

/// Two depths closer than this fraction of the nearer one are taken to lie on one surface.
/// Kinect-class sensors have ≈1 % depth noise at 1–4 m and a 2×2 block of a slanted surface
/// spans well under 5 % of its depth except at grazing angles, while real depth edges
/// (object against background) are usually ≥ 10 %.
pub const DEPTH_EDGE_RELATIVE: f32 = 0.05;

/// Rows processed per rayon task in the pyramid kernels. At 320 px per row, 16 rows are
/// ≈ 5 k pixels (a few µs of work): big enough to amortise task overhead, small enough to
/// balance two to eight cores on a 240-row level.
pub const ROWS_PER_TASK: usize = 16;

/// The smallest level side the pyramid accepts: the DVO's bilinear sampling and central
/// differences need a few interior pixels, and coarser levels carry no usable signal.
pub const MIN_LEVEL_SIDE_PX: usize = 8;

/// Values of one pixel packed for bilinear gathers by the DVO kernel.
///
/// Index: [`TargetSample::INTENSITY`], `GRAD_X`, `GRAD_Y` (intensity per pixel), `DEPTH`
/// (metres), `DEPTH_GRAD_X`, `DEPTH_GRAD_Y` (metres per pixel), then two pads so a sample is
/// exactly 32 bytes. Depth and its gradient are NaN where the depth is invalid or a depth edge
/// makes its gradient meaningless, so a bilinear mix touching such a pixel is NaN, which the
/// kernel tests once.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C, align(32))]
pub struct TargetSample(pub [f32; 8]);

impl TargetSample {
    /// Intensity in [0, 1].
    pub const INTENSITY: usize = 0;
    /// ∂I/∂x, per pixel (central difference, one-sided on the border).
    pub const GRAD_X: usize = 1;
    /// ∂I/∂y, per pixel.
    pub const GRAD_Y: usize = 2;
    /// Depth in metres (NaN = unusable).
    pub const DEPTH: usize = 3;
    /// ∂Z/∂x in metres per pixel (NaN = unusable).
    pub const DEPTH_GRAD_X: usize = 4;
    /// ∂Z/∂y in metres per pixel (NaN = unusable).
    pub const DEPTH_GRAD_Y: usize = 5;
}

/// One pyramid level.
#[derive(Debug, Clone)]
pub struct PyramidLevel {
    /// Intrinsics of this level.
    pub intrinsics: PinholeIntrinsics,
    /// Gray intensity, [0, 1].
    pub gray: GrayF32,
    /// Depth in metres, 0 = invalid.
    pub depth_m: DepthMeters,
    /// Packed intensity/depth/gradients per pixel, row-major (empty below the finest level).
    pub samples: Vec<TargetSample>,
}

impl PyramidLevel {
    /// The level's size.
    pub fn size(&self) -> ImageSize {
        self.gray.size()
    }
}

/// Size of level `level` of an image of `size` (each halving crops an odd side).
pub fn level_size(size: ImageSize, level: usize) -> ImageSize {
    ImageSize::new(size.width >> level, size.height >> level)
}

/// A gray + depth pyramid, allocated once by [`ImagePyramid::new`] and refilled per frame by
/// [`ImagePyramid::build`] without allocating.
#[derive(Debug, Clone)]
pub struct ImagePyramid {
    size: ImageSize,
    finest_level: usize,
    levels: Vec<PyramidLevel>,
}

impl ImagePyramid {
    /// Preallocates `num_levels` levels of an image of `size`, building levels
    /// `finest_level..num_levels`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] when the intrinsics are invalid, `num_levels` is 0,
    /// `finest_level ≥ num_levels`, or the coarsest level would be smaller than
    /// [`MIN_LEVEL_SIDE_PX`] on a side.
    pub fn new(
        size: ImageSize,
        intrinsics: PinholeIntrinsics,
        num_levels: usize,
        finest_level: usize,
    ) -> Result<Self> {
        if !intrinsics.is_valid() {
            return Err(Error::InvalidParameter {
                name: "intrinsics",
                value: format!("{intrinsics:?}"),
                expected: "finite values with fx, fy > 0".into(),
            });
        }
        if num_levels == 0 || num_levels > 16 {
            return Err(Error::InvalidParameter {
                name: "levels",
                value: num_levels.to_string(),
                expected: "1..=16 pyramid levels".into(),
            });
        }
        if finest_level >= num_levels {
            return Err(Error::InvalidParameter {
                name: "finest_level",
                value: finest_level.to_string(),
                expected: format!("a level below the number of levels ({num_levels})"),
            });
        }
        let coarsest = level_size(size, num_levels - 1);
        if coarsest.width < MIN_LEVEL_SIDE_PX || coarsest.height < MIN_LEVEL_SIDE_PX {
            return Err(Error::InvalidParameter {
                name: "levels",
                value: num_levels.to_string(),
                expected: format!(
                    "few enough levels that the coarsest of {size} is at least \
                     {MIN_LEVEL_SIDE_PX}x{MIN_LEVEL_SIDE_PX} (it would be {coarsest})"
                ),
            });
        }
        let levels = (0..num_levels)
            .map(|l| {
                // Level 0 is only stored when it is used; otherwise the input is read directly.
                let s = if l == 0 && finest_level > 0 {
                    ImageSize::new(0, 0)
                } else {
                    level_size(size, l)
                };
                PyramidLevel {
                    intrinsics: intrinsics.at_level(l as u32),
                    gray: GrayF32::filled(s, 0.0),
                    depth_m: DepthMeters::filled(s, 0.0),
                    samples: if l >= finest_level {
                        vec![TargetSample::default(); s.area()]
                    } else {
                        Vec::new()
                    },
                }
            })
            .collect();
        Ok(Self {
            size,
            finest_level,
            levels,
        })
    }

    /// Input image size (level 0).
    pub fn size(&self) -> ImageSize {
        self.size
    }

    /// Number of levels (including unbuilt ones below the finest).
    pub fn num_levels(&self) -> usize {
        self.levels.len()
    }

    /// The finest level that is built.
    pub fn finest_level(&self) -> usize {
        self.finest_level
    }

    /// Level `level`, or `None` when it is not built (below the finest level, or beyond the
    /// coarsest).
    pub fn level(&self, level: usize) -> Option<&PyramidLevel> {
        if level < self.finest_level {
            return None;
        }
        self.levels.get(level)
    }

    /// Rebuilds every level from a new frame, allocating nothing.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when `gray` or `depth_m` is not the pyramid's size.
    pub fn build(&mut self, gray: &GrayF32, depth_m: &DepthMeters) -> Result<()> {
        for (what, s) in [("pyramid gray", gray.size()), ("pyramid depth", depth_m.size())] {
            if s != self.size {
                return Err(Error::SizeMismatch {
                    what: what.into(),
                    expected: self.size,
                    found: s,
                });
            }
        }
        if self.finest_level == 0 {
            self.levels[0].gray.copy_from(gray)?;
            self.levels[0].depth_m.copy_from(depth_m)?;
        }
        for l in 1..self.levels.len() {
            let (finer, coarser) = self.levels.split_at_mut(l);
            let dst = &mut coarser[0];
            let (src_gray, src_depth) = if l == 1 && self.finest_level > 0 {
                (gray, depth_m)
            } else {
                (&finer[l - 1].gray, &finer[l - 1].depth_m)
            };
            downsample_gray_into(src_gray, &mut dst.gray)?;
            downsample_depth_into(src_depth, &mut dst.depth_m)?;
        }
        for level in self.levels.iter_mut().skip(self.finest_level) {
            pack_samples_into(&level.gray, &level.depth_m, &mut level.samples)?;
        }
        Ok(())
    }
}

fn check_half_size(what: &str, src: ImageSize, dst: ImageSize) -> Result<()> {
    let expected = ImageSize::new(src.width / 2, src.height / 2);
    if dst != expected {
        return Err(Error::SizeMismatch {
            what: what.into(),
            expected,
            found: dst,
        });
    }
    Ok(())
}

/// 2×2 box mean of `src` into `dst` (half size, odd sides cropped).
///
/// # Errors
/// [`Error::SizeMismatch`] when `dst` is not half of `src`.
pub fn downsample_gray_into(src: &GrayF32, dst: &mut GrayF32) -> Result<()> {
    check_half_size("downsample_gray_into", src.size(), dst.size())?;
    let (sw, dw) = (src.width(), dst.width());
    if dw == 0 {
        return Ok(());
    }
    let src = src.as_slice();
    dst.as_mut_slice()
        .par_chunks_mut(dw * ROWS_PER_TASK)
        .enumerate()
        .for_each(|(chunk, rows)| {
            for (r, out) in rows.chunks_exact_mut(dw).enumerate() {
                let y = chunk * ROWS_PER_TASK + r;
                let a = &src[2 * y * sw..2 * y * sw + 2 * dw];
                let b = &src[(2 * y + 1) * sw..(2 * y + 1) * sw + 2 * dw];
                for (o, (a, b)) in out.iter_mut().zip(a.chunks_exact(2).zip(b.chunks_exact(2))) {
                    *o = 0.25 * (a[0] + a[1] + b[0] + b[1]);
                }
            }
        });
    Ok(())
}

/// The edge-aware depth of one 2×2 block (see the module docs): mean of the valid children
/// within [`DEPTH_EDGE_RELATIVE`] of the nearest valid child; 0 when no child is valid.
/// Branch-free: children that do not count add 0 (the sum stays exact) in the same order.
#[inline]
pub fn edge_aware_depth(children_m: [f32; 4]) -> f32 {
    let far = |z: f32| if z > 0.0 { z } else { f32::INFINITY };
    let nearest = far(children_m[0])
        .min(far(children_m[1]))
        .min(far(children_m[2]))
        .min(far(children_m[3]));
    let limit = nearest * (1.0 + DEPTH_EDGE_RELATIVE);
    let (mut sum, mut n) = (0.0f32, 0.0f32);
    for &z in &children_m {
        let counts = z > 0.0 && z <= limit;
        sum += if counts { z } else { 0.0 };
        n += if counts { 1.0 } else { 0.0 };
    }
    if nearest.is_finite() {
        sum / n
    } else {
        0.0
    }
}

/// Edge-aware 2×2 depth reduction of `src` into `dst` (half size), see [`edge_aware_depth`].
/// Non-finite or negative input depths count as invalid.
///
/// # Errors
/// [`Error::SizeMismatch`] when `dst` is not half of `src`.
pub fn downsample_depth_into(src: &DepthMeters, dst: &mut DepthMeters) -> Result<()> {
    check_half_size("downsample_depth_into", src.size(), dst.size())?;
    let (sw, dw) = (src.width(), dst.width());
    if dw == 0 {
        return Ok(());
    }
    let src = src.as_slice();
    let simd = Simd::detect();
    dst.as_mut_slice()
        .par_chunks_mut(dw * ROWS_PER_TASK)
        .enumerate()
        .for_each(|(chunk, rows)| {
            for (r, out) in rows.chunks_exact_mut(dw).enumerate() {
                let y = chunk * ROWS_PER_TASK + r;
                let a = &src[2 * y * sw..2 * y * sw + 2 * dw];
                let b = &src[(2 * y + 1) * sw..(2 * y + 1) * sw + 2 * dw];
                downsample_depth_row(simd, a, b, out);
            }
        });
    Ok(())
}

/// One output row of [`downsample_depth_into`] from its two source rows.
#[inline(always)]
fn downsample_depth_row_generic(a: &[f32], b: &[f32], out: &mut [f32]) {
    let clean = |z: f32| if z.is_finite() && z > 0.0 { z } else { 0.0 };
    for (x, o) in out.iter_mut().enumerate() {
        *o = edge_aware_depth([
            clean(a[2 * x]),
            clean(a[2 * x + 1]),
            clean(b[2 * x]),
            clean(b[2 * x + 1]),
        ]);
    }
}

simd_kernel!(
    downsample_depth_row,
    downsample_depth_row_avx2,
    downsample_depth_row_generic,
    (a: &[f32], b: &[f32], out: &mut [f32])
);

/// Depth derivative at a valid centre from its neighbours (0 = invalid or outside): central
/// difference when both neighbours are on the centre's surface (within
/// [`DEPTH_EDGE_RELATIVE`]), one-sided when only one is, NaN when neither is (isolated pixel or
/// a ridge between two depth edges). Branch-free: the one-sided differences are averaged with
/// 0/1 weights and 1/count picked by selects (no division, no branch, no table lookup).
#[inline(always)]
fn depth_derivative(prev: f32, centre: f32, next: f32) -> f32 {
    let limit = DEPTH_EDGE_RELATIVE * centre;
    let p_ok = prev > 0.0 && (prev - centre).abs() <= limit;
    let n_ok = next > 0.0 && (next - centre).abs() <= limit;
    let (wp, wn) = (f32::from(u8::from(p_ok)), f32::from(u8::from(n_ok)));
    // 1 / the number of valid neighbours (NaN for none): selects vectorise, a table lookup
    // did not (at 320×240 the row loop took 2× as long with it in SSE2, 3× in AVX2).
    let inv_count = if p_ok && n_ok {
        0.5
    } else if p_ok || n_ok {
        1.0
    } else {
        f32::NAN
    };
    (wn * (next - centre) + wp * (centre - prev)) * inv_count
}

/// A depth as the pyramid stores it: positive finite, else 0 (invalid).
#[inline(always)]
fn clean_depth(z: f32) -> f32 {
    if z > 0.0 && z < f32::INFINITY {
        z
    } else {
        0.0
    }
}

/// Fills the packed per-pixel samples of one level (see [`TargetSample`]). Intensity gradients
/// are central differences, one-sided on the image border. The border pixels of each row take
/// the general path, the others a straight one (the tests check it against a reference with
/// the border cases in every pixel).
///
/// # Errors
/// [`Error::SizeMismatch`] / [`Error::BufferLength`] when the sizes disagree.
pub fn pack_samples_into(gray: &GrayF32, depth_m: &DepthMeters, samples: &mut [TargetSample]) -> Result<()> {
    if depth_m.size() != gray.size() {
        return Err(Error::SizeMismatch {
            what: "pack_samples_into depth".into(),
            expected: gray.size(),
            found: depth_m.size(),
        });
    }
    if samples.len() != gray.size().area() {
        return Err(Error::BufferLength {
            expected: gray.size().area(),
            found: samples.len(),
            size: gray.size(),
        });
    }
    let (w, h) = (gray.width(), gray.height());
    if w == 0 || h == 0 {
        return Ok(());
    }
    let (g, d) = (gray.as_slice(), depth_m.as_slice());
    // 1 / (distance between the two samples of a difference): ½ inside, 1 on the border, and 0
    // for a one-pixel side (no derivative at all).
    let inv_spacing = |i: usize, n: usize| -> f32 {
        match (i > 0, i + 1 < n) {
            (true, true) => 0.5,
            (false, false) => 0.0,
            _ => 1.0,
        }
    };
    let simd = Simd::detect();
    samples
        .par_chunks_mut(w * ROWS_PER_TASK)
        .enumerate()
        .for_each(|(chunk, rows)| {
            for (r, out) in rows.chunks_exact_mut(w).enumerate() {
                let y = chunk * ROWS_PER_TASK + r;
                let (up, down) = (y.saturating_sub(1), (y + 1).min(h - 1));
                let row = SampleRow {
                    g: &g[y * w..(y + 1) * w],
                    g_up: &g[up * w..(up + 1) * w],
                    g_down: &g[down * w..(down + 1) * w],
                    d: &d[y * w..(y + 1) * w],
                    d_up: &d[up * w..(up + 1) * w],
                    d_down: &d[down * w..(down + 1) * w],
                    inv_dy: inv_spacing(y, h),
                    // Depth neighbours outside the image read as invalid.
                    has_up: y > 0,
                    has_down: y + 1 < h,
                };
                if w < 3 {
                    for (x, s) in out.iter_mut().enumerate() {
                        *s = row.sample(x, inv_spacing(x, w));
                    }
                    continue;
                }
                out[0] = row.sample(0, inv_spacing(0, w));
                out[w - 1] = row.sample(w - 1, inv_spacing(w - 1, w));
                pack_inner(simd, &row, &mut out[1..w - 1]);
            }
        });
    Ok(())
}

simd_kernel!(pack_inner, pack_inner_avx2, pack_inner_generic, (row: &SampleRow<'_>, inner: &mut [TargetSample]));

/// The samples of a row of at least 3 pixels but its first and last, `inner[i]` for pixel
/// `i + 1`: both horizontal neighbours exist, and the vertical ones are 0 for every pixel of a
/// border row. The same arithmetic as [`SampleRow::sample`].
#[inline(always)]
fn pack_inner_generic(row: &SampleRow<'_>, inner: &mut [TargetSample]) {
    let n = inner.len();
    let (g, g_up, g_down) = (&row.g[..n + 2], &row.g_up[1..n + 1], &row.g_down[1..n + 1]);
    let (d, d_up, d_down) = (&row.d[..n + 2], &row.d_up[1..n + 1], &row.d_down[1..n + 1]);
    let zero_up = if row.has_up { 1.0 } else { 0.0 };
    let zero_down = if row.has_down { 1.0 } else { 0.0 };
    for (i, s) in inner.iter_mut().enumerate() {
        let gx = (g[i + 2] - g[i]) * 0.5;
        let gy = (g_down[i] - g_up[i]) * row.inv_dy;
        let z = clean_depth(d[i + 1]);
        let zl = clean_depth(d[i]);
        let zr = clean_depth(d[i + 2]);
        // clean_depth is finite: × 1 keeps it, × 0 gives 0 as `sample` reads.
        let zu = clean_depth(d_up[i]) * zero_up;
        let zd = clean_depth(d_down[i]) * zero_down;
        let zx = depth_derivative(zl, z, zr);
        let zy = depth_derivative(zu, z, zd);
        let poison = 0.0 * (zx + zy);
        let valid = z > 0.0;
        let pick = |v: f32| if valid { v + poison } else { f32::NAN };
        *s = TargetSample([g[i + 1], gx, gy, pick(z), pick(zx), pick(zy), 0.0, 0.0]);
    }
}

/// One row of [`pack_samples_into`] and its neighbours (the row itself on the border).
struct SampleRow<'a> {
    g: &'a [f32],
    g_up: &'a [f32],
    g_down: &'a [f32],
    d: &'a [f32],
    d_up: &'a [f32],
    d_down: &'a [f32],
    inv_dy: f32,
    has_up: bool,
    has_down: bool,
}

impl SampleRow<'_> {
    /// The sample at `x`, any `x` (borders included); `inv_dx` as `inv_spacing`.
    #[inline(always)]
    fn sample(&self, x: usize, inv_dx: f32) -> TargetSample {
        let w = self.g.len();
        let (left, right) = (x.saturating_sub(1), (x + 1).min(w - 1));
        let gx = (self.g[right] - self.g[left]) * inv_dx;
        let gy = (self.g_down[x] - self.g_up[x]) * self.inv_dy;
        let z = clean_depth(self.d[x]);
        let (zv, zx, zy) = if z > 0.0 {
            let zl = if x > 0 { clean_depth(self.d[left]) } else { 0.0 };
            let zr = if x + 1 < w {
                clean_depth(self.d[right])
            } else {
                0.0
            };
            let zu = if self.has_up {
                clean_depth(self.d_up[x])
            } else {
                0.0
            };
            let zd = if self.has_down {
                clean_depth(self.d_down[x])
            } else {
                0.0
            };
            let zx = depth_derivative(zl, z, zr);
            let zy = depth_derivative(zu, z, zd);
            // A NaN in either derivative makes the whole depth channel unusable.
            let poison = 0.0 * (zx + zy);
            (z + poison, zx + poison, zy + poison)
        } else {
            (f32::NAN, f32::NAN, f32::NAN)
        };
        TargetSample([self.g[x], gx, gy, zv, zx, zy, 0.0, 0.0])
    }
}

#[cfg(test)]
mod tests;
