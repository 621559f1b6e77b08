//! The growth's kernels: the static-world backward warp, the per-pixel evidence (appearance
//! change, seed persistence, grown accumulation), the boundary scan and the ring search.

use nalgebra::Isometry3;
use rayon::prelude::*;

use super::{AppearanceGrowthConfig, GrowthFrame, SeedBand, LOOKED_AT};
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{GrayF32, Mask, MASK_SET};
use crate::occlusion::OcclusionConfig;

/// A seed candidate without a previous-image position (see [`Evidence::retain_seeds`]).
const NO_PREVIOUS_POSITION: u32 = u32::MAX;

/// The static-world backward warp in f32: a current pixel (x, y) with depth Z is at
/// R · (Z · ray) + t in the previous camera, projected into the previous image. The ray factors
/// (x − cx)/fx and (y − cy)/fy come from per-column and per-row tables.
#[derive(Debug, Clone, Copy)]
struct BackwardWarp<'a> {
    r: nalgebra::Matrix3<f32>,
    t: nalgebra::Vector3<f32>,
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    ray_x: &'a [f32],
    ray_y: &'a [f32],
}

/// Fills the ray-factor tables of [`BackwardWarp`] ((x − cx)/fx per column, (y − cy)/fy per row,
/// in f32 exactly as a per-pixel division would give them).
pub(super) fn fill_ray_tables(intrinsics: &PinholeIntrinsics, ray_x: &mut [f32], ray_y: &mut [f32]) {
    let (fx, fy, cx, cy) = (
        intrinsics.fx as f32,
        intrinsics.fy as f32,
        intrinsics.cx as f32,
        intrinsics.cy as f32,
    );
    for (x, ray) in ray_x.iter_mut().enumerate() {
        *ray = (x as f32 - cx) / fx;
    }
    for (y, ray) in ray_y.iter_mut().enumerate() {
        *ray = (y as f32 - cy) / fy;
    }
}

impl<'a> BackwardWarp<'a> {
    /// The warp of `previous_from_current`; `ray_x`, `ray_y` filled by [`fill_ray_tables`].
    fn new(
        intrinsics: &PinholeIntrinsics,
        previous_from_current: &Isometry3<f64>,
        (ray_x, ray_y): (&'a [f32], &'a [f32]),
    ) -> Self {
        Self {
            r: previous_from_current
                .rotation
                .to_rotation_matrix()
                .matrix()
                .map(|v| v as f32),
            t: previous_from_current.translation.vector.map(|v| v as f32),
            fx: intrinsics.fx as f32,
            fy: intrinsics.fy as f32,
            cx: intrinsics.cx as f32,
            cy: intrinsics.cy as f32,
            ray_x,
            ray_y,
        }
    }

    /// Pixel (x, y) with depth `z_m` in the previous image; None behind the previous camera.
    #[inline]
    fn apply(&self, x: usize, y: usize, z_m: f32) -> Option<(f32, f32)> {
        let (r, t) = (&self.r, &self.t);
        let p = [self.ray_x[x] * z_m, self.ray_y[y] * z_m, z_m];
        let q = [
            r[(0, 0)] * p[0] + r[(0, 1)] * p[1] + r[(0, 2)] * p[2] + t[0],
            r[(1, 0)] * p[0] + r[(1, 1)] * p[1] + r[(1, 2)] * p[2] + t[1],
            r[(2, 0)] * p[0] + r[(2, 1)] * p[1] + r[(2, 2)] * p[2] + t[2],
        ];
        (q[2] > 0.0).then(|| (self.fx * q[0] / q[2] + self.cx, self.fy * q[1] / q[2] + self.cy))
    }
}

/// The inputs every growth test reads.
pub(super) struct Evidence<'a> {
    growth: &'a AppearanceGrowthConfig,
    warp: BackwardWarp<'a>,
    width: usize,
    height: usize,
    depth_m: &'a [f32],
    current: &'a [f32],
    previous: &'a [f32],
    /// The previous frame's final mask.
    previous_mask: &'a [u8],
}

impl<'a> Evidence<'a> {
    /// The evidence of the current frame against the previous one (its gray image and final
    /// mask); `rays` filled by [`fill_ray_tables`].
    pub(super) fn new(
        frame: &GrowthFrame<'a>,
        rays: (&'a [f32], &'a [f32]),
        (previous_gray, previous_mask): (&'a GrayF32, &'a Mask),
    ) -> Self {
        let GrowthFrame { depth_m, gray, .. } = *frame;
        Self {
            growth: frame.growth,
            warp: BackwardWarp::new(frame.intrinsics, frame.previous_from_current, rays),
            width: depth_m.width(),
            height: depth_m.height(),
            depth_m: depth_m.as_slice(),
            current: gray.as_slice(),
            previous: previous_gray.as_slice(),
            previous_mask: previous_mask.as_slice(),
        }
    }

    /// Rule (b): pixel (x, y) changed appearance against the previous image at its warped
    /// position (bilinear) and against every previous pixel within the search radius.
    pub(super) fn changed(&self, x: usize, y: usize) -> bool {
        let (width, height, previous) = (self.width, self.height, self.previous);
        let n = y * width + x;
        let Some((u, v)) = self.warp.apply(x, y, self.depth_m[n]) else {
            return false;
        };
        // Bilinear needs the 2×2 neighbourhood; a pixel warped outside has no evidence.
        if !(u >= 0.0 && v >= 0.0 && u < (width - 1) as f32 && v < (height - 1) as f32) {
            return false;
        }
        let (u0, v0) = (u as usize, v as usize);
        let (a, b) = (u - u0 as f32, v - v0 as f32);
        let i = v0 * width + u0;
        let top = previous[i] + a * (previous[i + 1] - previous[i]);
        let bottom = previous[i + width] + a * (previous[i + width + 1] - previous[i + width]);
        let sampled = top + b * (bottom - top);
        let threshold = self.growth.photometric_threshold;
        let value = self.current[n];
        if (value - sampled).abs() <= threshold {
            return false;
        }
        // Every previous pixel within the radius of the nearest one must differ too.
        let radius = self.growth.photometric_search_radius_px;
        if radius == 0 {
            return true;
        }
        let (un, vn) = ((u + 0.5) as usize, (v + 0.5) as usize);
        let differs = |p: f32| (value - p).abs() > threshold;
        if radius == 1 && un >= 1 && vn >= 1 && un < width - 1 && vn < height - 1 {
            // The default radius away from the border: the 3×3 block, without branches.
            let c = vn * width + un;
            let rows = [
                &previous[c - width - 1..c - width + 2],
                &previous[c - 1..c + 2],
                &previous[c + width - 1..c + width + 2],
            ];
            return rows.iter().fold(true, |all, row| {
                all & differs(row[0]) & differs(row[1]) & differs(row[2])
            });
        }
        let (x0, x1) = (un.saturating_sub(radius), (un + radius).min(width - 1));
        let (y0, y1) = (vn.saturating_sub(radius), (vn + radius).min(height - 1));
        (y0..=y1).all(|y| {
            previous[y * width + x0..=y * width + x1]
                .iter()
                .all(|&p| differs(p))
        })
    }

    /// Pixel (x, y) may seed the growth: it was an object pixel in the previous frame too (at
    /// its static-world warp position), or any mask pixel may seed. (The growth filters its
    /// boundary pixels with [`Evidence::retain_seeds`], the batched form of this test.)
    #[cfg(test)]
    pub(super) fn may_seed(&self, x: usize, y: usize) -> bool {
        if !self.growth.persistent_seeds_only {
            return true;
        }
        self.previous_position(x, y, self.depth_m[y * self.width + x])
            .is_some_and(|i| self.previous_mask[i] != 0)
    }

    /// The previous-image pixel (index) nearest the static-world warp of pixel (x, y) at depth
    /// `z_m`; None for an invalid depth, behind the previous camera or outside its image.
    #[inline]
    fn previous_position(&self, x: usize, y: usize, z_m: f32) -> Option<usize> {
        if z_m <= 0.0 {
            return None;
        }
        let (u, v) = self.warp.apply(x, y, z_m)?;
        let (u, v) = (u + 0.5, v + 0.5);
        (u >= 0.0 && v >= 0.0 && (u as usize) < self.width && (v as usize) < self.height)
            .then(|| v as usize * self.width + u as usize)
    }

    /// Keeps the pixels of `candidates` (row-major indices) that may seed, in order: exactly
    /// [`Evidence::may_seed`] on each, in three passes (depth loads, warps, previous-mask
    /// loads) whose scattered loads are independent of each other, so many are in flight at
    /// once instead of one per candidate. `depths` and `positions` are scratch.
    fn retain_seeds(&self, candidates: &mut Vec<u32>, depths: &mut Vec<f32>, positions: &mut Vec<u32>) {
        if !self.growth.persistent_seeds_only {
            return;
        }
        depths.clear();
        depths.extend(candidates.iter().map(|&n| self.depth_m[n as usize]));
        positions.clear();
        positions.extend(candidates.iter().zip(depths.iter()).map(|(&n, &z_m)| {
            let n = n as usize;
            let y = n / self.width;
            self.previous_position(n - y * self.width, y, z_m)
                .map_or(NO_PREVIOUS_POSITION, |i| i as u32)
        }));
        let mut kept = 0;
        for i in 0..candidates.len() {
            let position = positions[i];
            if position != NO_PREVIOUS_POSITION && self.previous_mask[position as usize] != 0 {
                candidates[kept] = candidates[i];
                kept += 1;
            }
        }
        candidates.truncate(kept);
    }

    /// The accumulation a pixel of depth `zn_m` grown from `zf_m` (accumulation `af_m`) gets.
    pub(super) fn grown_accumulation(
        &self,
        config: &OcclusionConfig,
        af_m: f32,
        zf_m: f32,
        zn_m: f32,
    ) -> f32 {
        let floor = config.threshold(config.alpha, zn_m) * (1.0 + self.growth.accumulation_margin);
        if self.growth.inherit_accumulation {
            (af_m + zf_m - zn_m).max(floor)
        } else {
            floor
        }
    }
}

/// OR of all bytes (no early exit, so it vectorises): rows without mask pixels cost a few
/// vector loads.
fn any_set(row: &[u8]) -> bool {
    row.iter().fold(0u8, |acc, &v| acc | v) != 0
}

/// Calls `visit(x, y)` for every interior mask pixel with an unset 8-neighbour in `rows`, row
/// by row.
/// Mask values are 0 or 255: a pixel is on the boundary when it is set and the AND of its 3×3
/// neighbourhood is 0. The ANDs run on whole rows (vectorised); the flags are then read 8 at a
/// time. `vertical` and `boundary` are scratch rows of the mask's width.
fn for_each_boundary_pixel(
    mask: &[u8],
    width: usize,
    rows: std::ops::Range<usize>,
    vertical: &mut [u8],
    boundary: &mut [u8],
    mut visit: impl FnMut(usize, usize),
) {
    /// Boundary flags are read as one u64 per 8 pixels.
    const FLAGS_PER_WORD: usize = 8;
    for y in rows {
        let row = &mask[y * width..(y + 1) * width];
        if !any_set(row) {
            continue;
        }
        let up = &mask[(y - 1) * width..y * width];
        let down = &mask[(y + 1) * width..(y + 2) * width];
        let vertical = &mut vertical[..width];
        for x in 0..width {
            vertical[x] = up[x] & row[x] & down[x];
        }
        // boundary[i] is pixel x = i + 1.
        let interior = &mut boundary[..width - 2];
        let (centre, left, middle, right) = (
            &row[1..width - 1],
            &vertical[..width - 2],
            &vertical[1..width - 1],
            &vertical[2..],
        );
        for i in 0..width - 2 {
            interior[i] = centre[i] & !(left[i] & middle[i] & right[i]);
        }
        let mut words = interior.chunks_exact(FLAGS_PER_WORD);
        for (word_index, chunk) in words.by_ref().enumerate() {
            let mut bytes = [0u8; FLAGS_PER_WORD];
            bytes.copy_from_slice(chunk);
            let mut word = u64::from_le_bytes(bytes);
            while word != 0 {
                let k = word.trailing_zeros() as usize / 8;
                visit(1 + word_index * FLAGS_PER_WORD + k, y);
                word &= !(0xFF << (8 * k));
            }
        }
        let tail_start = interior.len() - words.remainder().len();
        for (k, &b) in words.remainder().iter().enumerate() {
            if b != 0 {
                visit(1 + tail_start + k, y);
            }
        }
    }
}

/// Sets the unset border pixels of `mask` to `from` → `to` (the growth never enters the
/// border: with it marked, the 8 neighbours of an interior pixel need no bounds checks).
fn relabel_unset_border(mask: &mut [u8], width: usize, height: usize, from: u8, to: u8) {
    let mut relabel = |i: usize| {
        if mask[i] == from {
            mask[i] = to;
        }
    };
    for x in 0..width {
        relabel(x);
        relabel((height - 1) * width + x);
    }
    for y in 1..height - 1 {
        relabel(y * width);
        relabel(y * width + width - 1);
    }
}

/// How many frontier pixels ahead the rings prefetch. The rings wait on scattered loads: in a
/// `perf` profile, a third of their samples sit on the depth, current and previous gray loads
/// around the frontier. Distances 4 to 16 measured alike; 8 is in the middle.
const RING_PREFETCH_DISTANCE: usize = 8;

/// Hints the cache line holding `values[index]` into L1 (nothing when `index` is out of
/// bounds, or off x86-64). Changes no result.
#[inline(always)]
fn prefetch<T>(values: &[T], index: usize) {
    #[cfg(target_arch = "x86_64")]
    if let Some(value) = values.get(index) {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        // SAFETY: SSE is in the x86-64 baseline, and a prefetch of a valid address has no
        // effect on memory.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(std::ptr::from_ref(value).cast::<i8>()) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (values, index);
}

/// The growth's buffers, borrowed apart from the images it reads.
pub(super) struct GrowthBuffers<'a> {
    pub(super) looked_at: &'a mut Vec<u32>,
    pub(super) frontier: &'a mut Vec<u32>,
    pub(super) next: &'a mut Vec<u32>,
    pub(super) bands: &'a mut [SeedBand],
}

impl GrowthBuffers<'_> {
    /// The seeds, into the frontier: interior boundary pixels of `mask` that may seed
    /// (rule of `persistent_seeds_only`), found band by band in parallel, in row-major order.
    pub(super) fn find_seeds(&mut self, evidence: &Evidence, mask: &[u8]) {
        let width = evidence.width;
        self.bands.par_iter_mut().for_each(|band| {
            band.seeds.clear();
            let seeds = &mut band.seeds;
            for_each_boundary_pixel(
                mask,
                width,
                band.rows.clone(),
                &mut band.vertical_row,
                &mut band.boundary_row,
                |x, y| seeds.push((y * width + x) as u32),
            );
            evidence.retain_seeds(&mut band.seeds, &mut band.depths, &mut band.positions);
        });
        self.frontier.clear();
        for band in self.bands.iter() {
            self.frontier.extend_from_slice(&band.seeds);
        }
    }

    /// Grows from the frontier (the seeds) ring by ring; returns the pixels grown.
    pub(super) fn grow_rings(
        self,
        evidence: &Evidence,
        config: &OcclusionConfig,
        m: &mut [u8],
        a: &mut [f32],
    ) -> usize {
        let (width, height, growth) = (evidence.width, evidence.height, evidence.growth);
        let z = evidence.depth_m;
        relabel_unset_border(m, width, height, 0, LOOKED_AT);
        self.looked_at.clear();
        let w = width as isize;
        let neighbour_offsets = [-w - 1, -w, -w + 1, -1, 1, w - 1, w, w + 1];
        let mut grown = 0;
        for _ in 0..growth.max_rings {
            self.next.clear();
            let frontier = &self.frontier[..];
            for (i, &f) in frontier.iter().enumerate() {
                // What a later (interior) frontier pixel's tests read: the lines holding its
                // column in the rows above, at and below, in the depth and the current image,
                // and in the previous image too (a warp moves a pixel by a few at most between
                // frames; a wrong guess only costs the hint).
                if let Some(&ahead) = frontier.get(i + RING_PREFETCH_DISTANCE) {
                    let ahead = ahead as usize;
                    for row_pixel in [ahead - width, ahead, ahead + width] {
                        prefetch(z, row_pixel);
                        prefetch(evidence.current, row_pixel);
                        prefetch(evidence.previous, row_pixel);
                    }
                }
                let f = f as usize;
                let zf = z[f];
                if zf <= 0.0 {
                    continue;
                }
                let tolerance = growth.depth_tolerance * zf;
                // f is interior (seeds are, and the border is marked), so are its neighbours.
                for offset in neighbour_offsets {
                    let n = f.wrapping_add_signed(offset);
                    if m[n] != 0 {
                        continue;
                    }
                    let zn = z[n];
                    if zn <= 0.0 || (zn - zf).abs() > tolerance {
                        continue;
                    }
                    let y = n / width;
                    if !evidence.changed(n - y * width, y) {
                        m[n] = LOOKED_AT;
                        self.looked_at.push(n as u32);
                        continue;
                    }
                    m[n] = MASK_SET;
                    a[n] = evidence.grown_accumulation(config, a[f], zf, zn);
                    self.next.push(n as u32);
                }
            }
            grown += self.next.len();
            if self.next.is_empty() {
                break;
            }
            std::mem::swap(self.frontier, self.next);
        }
        for &n in self.looked_at.iter() {
            m[n as usize] = 0;
        }
        relabel_unset_border(m, width, height, LOOKED_AT, 0);
        grown
    }
}
