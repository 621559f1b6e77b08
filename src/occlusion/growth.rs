//! Appearance-gated object completion (not in the paper; see docs/method.md, "Deviations").
//!
//! Occlusion accumulation only sees the pixels where an object covers something farther away.
//! An object that stood still and starts moving occludes nothing inside its old footprint: its
//! interior sees object → object (ΔZ of a few centimetres, wiped by τ_α every frame), so only the
//! strips it sweeps over background are detected, and the rest of it stays background until it
//! has left its old footprint entirely. A moving *textured* object, though, changes the
//! intensity inside its own depth footprint, while static surfaces, once warped with the camera
//! motion, do not.
//!
//! After the detector's mask is final, each object is grown, breadth-first from its boundary
//! pixels that were object pixels in the previous frame too (`persistent_seeds_only`: a
//! one-frame false positive, such as a band along a depth edge after a poor motion, never
//! grows), into 8-neighbours that
//! (a) have a measured depth continuous with the pixel they grow from
//!     (|Z(n) − Z(f)| ≤ `depth_tolerance` · Z(f)): growth stops at depth edges, so it does not
//!     leak onto background at another depth;
//! (b) changed appearance: |I_current(n) − I_previous(warp(n))| > `photometric_threshold`, with
//!     warp(n) the static-world backward warp of n with its current depth and the frame's camera
//!     motion, bilinear in the previous gray image, and also against every previous pixel within
//!     `photometric_search_radius_px` of the warped position (a static surface whose gray is
//!     misregistered by a pixel, as on real RGB-D data, finds its own texture there);
//! (c) lie within `max_rings` pixels (chessboard distance) of the detected mask, so a static
//!     surface touching an object at the same depth is never swallowed in one frame.
//!
//! A grown pixel enters the mask and gets the accumulation of the pixel it grew from, moved to
//! its depth like Eq. 10's prediction (A(f) + Z(f) − Z(n), at least just above τ_α): the
//! transport then carries it like any accumulated pixel, background reappearing behind it
//! resets it (τ_β), and an object that stops keeps its mask as the paper's objects do. Without
//! detected objects (a static view) the stage does nothing but keep the gray image.

use nalgebra::Isometry3;
use rayon::prelude::*;

use super::OcclusionConfig;
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, GrayF32, Image, ImageSize, Mask, MASK_SET};

/// Parameters of appearance-gated object completion ([`OcclusionConfig::appearance_growth`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AppearanceGrowthConfig {
    /// A pixel must change by more than this much gray (0..1 scale) against the previous image
    /// warped with the camera motion to be grown into.
    pub photometric_threshold: f32,
    /// Depth continuity: a pixel is grown into from a neighbour only when their measured depths
    /// differ by at most this fraction of the neighbour's depth (m/m).
    pub depth_tolerance: f32,
    /// Growth per frame stops this many pixels (8-connected rings) away from the detected mask.
    pub max_rings: usize,
    /// A grown pixel's accumulation is at least τ_α · (1 + this margin) (unitless), so that it
    /// survives the next frame's truncation when its ΔZ is noise.
    pub accumulation_margin: f32,
    /// The change must hold against every previous pixel within this many pixels (Chebyshev)
    /// of the warped position, not just the interpolated one: a static surface misregistered by
    /// up to this much (gray and depth not taken at the same instant, calibration) finds its
    /// own texture there, a moving object's texture moved farther does not. 0 = the bilinear
    /// sample only.
    pub photometric_search_radius_px: usize,
    /// A grown pixel inherits the accumulation of the pixel it grew from (moved to its depth,
    /// Eq. 10's rule); false = it gets exactly τ_α · (1 + `accumulation_margin`).
    pub inherit_accumulation: bool,
    /// Only mask pixels that were object pixels in the previous frame too (at their
    /// static-world warp position) seed the growth: an object is grown from its second frame
    /// on, a one-frame false positive (a band along a depth edge after a poor motion) never.
    pub persistent_seeds_only: bool,
}

impl Default for AppearanceGrowthConfig {
    fn default() -> Self {
        Self {
            photometric_threshold: DEFAULT_PHOTOMETRIC_THRESHOLD,
            depth_tolerance: DEFAULT_DEPTH_TOLERANCE,
            max_rings: DEFAULT_MAX_RINGS,
            accumulation_margin: DEFAULT_ACCUMULATION_MARGIN,
            photometric_search_radius_px: DEFAULT_SEARCH_RADIUS_PX,
            inherit_accumulation: true,
            persistent_seeds_only: true,
        }
    }
}

/// Default `photometric_threshold`: 0.04 gray ≈ 10 levels of 255.
const DEFAULT_PHOTOMETRIC_THRESHOLD: f32 = 0.04;
/// Default `depth_tolerance`: 2 % of Z.
const DEFAULT_DEPTH_TOLERANCE: f32 = 0.02;
/// Default `max_rings`.
const DEFAULT_MAX_RINGS: usize = 32;
/// Default `accumulation_margin`.
const DEFAULT_ACCUMULATION_MARGIN: f32 = 0.5;
/// Default `photometric_search_radius_px`.
const DEFAULT_SEARCH_RADIUS_PX: usize = 1;

impl AppearanceGrowthConfig {
    /// Checks every parameter.
    pub(super) fn validate(&self) -> crate::error::Result<()> {
        let check = |name: &'static str, value: f32| {
            if value.is_finite() && value >= 0.0 {
                Ok(())
            } else {
                Err(crate::error::Error::InvalidParameter {
                    name,
                    value: value.to_string(),
                    expected: "a finite number ≥ 0".into(),
                })
            }
        };
        check(
            "appearance_growth.photometric_threshold",
            self.photometric_threshold,
        )?;
        check("appearance_growth.depth_tolerance", self.depth_tolerance)?;
        check("appearance_growth.accumulation_margin", self.accumulation_margin)?;
        Ok(())
    }
}

/// Mask value of a pixel the growth looked at this frame and did not grow into (depth
/// continuous but no photometric change), and of the unset image-border pixels, which are
/// never grown into. Exists only inside [`AppearanceGrowth::grow`]: every such pixel is reset
/// to 0 before it returns. Masks hold 0 or [`MASK_SET`] otherwise.
const LOOKED_AT: u8 = 1;

/// Preallocated state of the growth: the previous gray image and BFS buffers.
#[derive(Debug, Clone)]
pub(super) struct AppearanceGrowth {
    width: usize,
    height: usize,
    /// Gray image of the detector's previous frame.
    previous_gray: GrayF32,
    /// `previous_gray` and `previous_mask` belong to the detector's previous frame (false after
    /// a reset or a frame without gray).
    previous_valid: bool,
    /// Final mask of the detector's previous frame (after growth), handed over by
    /// [`AppearanceGrowth::keep_mask`].
    previous_mask: Mask,
    /// This frame's gray image, copied while the growth runs; [`AppearanceGrowth::remember`]
    /// swaps it in instead of copying.
    staged_gray: GrayF32,
    /// `staged_gray` holds the gray image `grow` was given this frame.
    staged: bool,
    /// Pixels marked [`LOOKED_AT`] this frame (reset to 0 at the end).
    looked_at: Vec<u32>,
    frontier: Vec<u32>,
    next: Vec<u32>,
    /// The seed scan's row bands (one parallel task each).
    bands: Vec<SeedBand>,
    /// Ray-factor tables of the backward warp (per column, per row).
    ray_x: Vec<f32>,
    ray_y: Vec<f32>,
}

/// Rows of the seed scan per parallel task: a band's seeds are found independently and the
/// bands' lists concatenated in row order, so the frontier is the sequential scan's.
const SEED_ROWS_PER_TASK: usize = 64;

/// A seed candidate without a previous-image position (see [`Evidence::retain_seeds`]).
const NO_PREVIOUS_POSITION: u32 = u32::MAX;

/// One band of the seed scan: its seeds and scratch rows.
#[derive(Debug, Clone)]
struct SeedBand {
    /// First and one-past-last row (interior rows only).
    rows: std::ops::Range<usize>,
    /// The band's boundary pixels, then its seeds.
    seeds: Vec<u32>,
    /// Per boundary pixel: its depth and previous-image position ([`Evidence::retain_seeds`]).
    depths: Vec<f32>,
    positions: Vec<u32>,
    /// The vertical AND of three mask rows, and the boundary flags of one row.
    vertical_row: Vec<u8>,
    boundary_row: Vec<u8>,
}

/// One frame's inputs to the growth: its parameters, the camera, the motion since the previous
/// frame, and the current depth and gray image.
#[derive(Debug, Clone, Copy)]
pub(super) struct GrowthFrame<'a> {
    pub growth: &'a AppearanceGrowthConfig,
    pub config: &'a OcclusionConfig,
    pub intrinsics: &'a PinholeIntrinsics,
    pub previous_from_current: &'a Isometry3<f64>,
    pub depth_m: &'a DepthMeters,
    pub gray: &'a GrayF32,
}

/// What one growth pass did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(super) struct GrowthCounts {
    /// Pixels added to the mask.
    pub grown: usize,
}

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
fn fill_ray_tables(intrinsics: &PinholeIntrinsics, ray_x: &mut [f32], ray_y: &mut [f32]) {
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
struct Evidence<'a> {
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
    fn new(
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
    fn changed(&self, x: usize, y: usize) -> bool {
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
    fn may_seed(&self, x: usize, y: usize) -> bool {
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
    fn grown_accumulation(&self, config: &OcclusionConfig, af_m: f32, zf_m: f32, zn_m: f32) -> f32 {
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

impl AppearanceGrowth {
    pub(super) fn new(size: ImageSize) -> Self {
        Self {
            width: size.width,
            height: size.height,
            previous_gray: Image::filled(size, 0.0),
            previous_valid: false,
            previous_mask: Image::filled(size, 0),
            staged_gray: Image::filled(size, 0.0),
            staged: false,
            looked_at: Vec::with_capacity(size.area()),
            frontier: Vec::with_capacity(size.area()),
            next: Vec::with_capacity(size.area()),
            bands: (1..size.height.saturating_sub(1))
                .step_by(SEED_ROWS_PER_TASK)
                .map(|start| SeedBand {
                    rows: start..(start + SEED_ROWS_PER_TASK).min(size.height - 1),
                    seeds: Vec::with_capacity(SEED_ROWS_PER_TASK * size.width),
                    depths: Vec::with_capacity(SEED_ROWS_PER_TASK * size.width),
                    positions: Vec::with_capacity(SEED_ROWS_PER_TASK * size.width),
                    vertical_row: vec![0; size.width],
                    boundary_row: vec![0; size.width],
                })
                .collect(),
            ray_x: vec![0.0; size.width],
            ray_y: vec![0.0; size.height],
        }
    }

    /// Forgets the previous image (the next frame has nothing to compare with).
    pub(super) fn invalidate(&mut self) {
        self.previous_valid = false;
        self.staged = false;
    }

    /// Keeps `gray` for the next frame (None: there is nothing to compare with). The frame's
    /// final mask is handed over by [`AppearanceGrowth::keep_mask`] before the next frame
    /// overwrites it.
    pub(super) fn remember(&mut self, gray: Option<&GrayF32>) {
        match gray {
            Some(g) if g.size() == self.previous_gray.size() => {
                if std::mem::take(&mut self.staged) {
                    std::mem::swap(&mut self.previous_gray, &mut self.staged_gray);
                } else {
                    self.previous_gray.as_mut_slice().copy_from_slice(g.as_slice());
                }
                self.previous_valid = true;
            }
            _ => self.invalidate(),
        }
    }

    /// Takes `mask`, the final mask of the frame last remembered, as the previous mask: the
    /// buffers are swapped (no copy), so `mask` then holds stale values and must be
    /// overwritten whole (the detector calls this right before its object-mask pass).
    pub(super) fn keep_mask(&mut self, mask: &mut Mask) {
        std::mem::swap(&mut self.previous_mask, mask);
    }

    /// Grows the objects of `mask` (final for this frame) into neighbours with continuous depth
    /// and changed appearance, writing grown pixels into `mask` and `accumulation_m`.
    /// `depth_m` is the current measured depth, `gray` the current image, `mask_pixels` the
    /// number of set pixels of `mask` (nothing happens when 0). Copies `gray` aside while it
    /// works, for [`AppearanceGrowth::remember`] to keep without a copy: call `remember` with
    /// the same `gray` next.
    pub(super) fn grow(
        &mut self,
        frame: &GrowthFrame,
        mask: &mut Mask,
        accumulation_m: &mut DepthMeters,
        mask_pixels: usize,
    ) -> GrowthCounts {
        let growth = frame.growth;
        let mut counts = GrowthCounts::default();
        if !self.previous_valid || mask_pixels == 0 || growth.max_rings == 0 {
            return counts;
        }
        let (width, height) = (self.width, self.height);
        if width < 3 || height < 3 {
            return counts;
        }
        fill_ray_tables(frame.intrinsics, &mut self.ray_x, &mut self.ray_y);
        let evidence = Evidence::new(
            frame,
            (&self.ray_x, &self.ray_y),
            (&self.previous_gray, &self.previous_mask),
        );
        let mut state = GrowthBuffers {
            looked_at: &mut self.looked_at,
            frontier: &mut self.frontier,
            next: &mut self.next,
            bands: &mut self.bands,
        };
        let mask = mask.as_mut_slice();
        state.find_seeds(&evidence, mask);
        // The copy of this frame's gray image (for the next frame) overlaps the rings: both
        // are memory-bound, and the rings are sequential (the seed scan before uses every core).
        let staged_gray = self.staged_gray.as_mut_slice();
        let ((), grown) = rayon::join(
            || staged_gray.copy_from_slice(frame.gray.as_slice()),
            || state.grow_rings(&evidence, frame.config, mask, accumulation_m.as_mut_slice()),
        );
        self.staged = true;
        counts.grown = grown;
        counts
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
struct GrowthBuffers<'a> {
    looked_at: &'a mut Vec<u32>,
    frontier: &'a mut Vec<u32>,
    next: &'a mut Vec<u32>,
    bands: &'a mut [SeedBand],
}

impl GrowthBuffers<'_> {
    /// The seeds, into the frontier: interior boundary pixels of `mask` that may seed
    /// (rule of `persistent_seeds_only`), found band by band in parallel, in row-major order.
    fn find_seeds(&mut self, evidence: &Evidence, mask: &[u8]) {
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
    fn grow_rings(self, evidence: &Evidence, config: &OcclusionConfig, m: &mut [u8], a: &mut [f32]) -> usize {
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

#[cfg(test)]
mod tests {
    use super::super::components::NEIGHBOURS_8;
    use super::*;

    /// The detector's end of frame: keeps `gray` and hands `mask` over as the previous mask.
    fn remember_frame(state: &mut AppearanceGrowth, gray: &GrayF32, mask: &Mask) {
        state.remember(Some(gray));
        state.keep_mask(&mut mask.clone());
    }

    /// The growth written plainly (the reference of [`AppearanceGrowth::grow`]): seeds by
    /// testing each mask pixel's 8 neighbours, breadth-first rings with bounds checks and a
    /// separate "decided" image; same rules, same order.
    fn grow_reference(
        state: &AppearanceGrowth,
        frame: &GrowthFrame,
        mask: &mut Mask,
        accumulation_m: &mut DepthMeters,
    ) -> usize {
        let growth = frame.growth;
        let (width, height) = (state.width, state.height);
        if !state.previous_valid || growth.max_rings == 0 {
            return 0;
        }
        let (mut ray_x, mut ray_y) = (vec![0.0; width], vec![0.0; height]);
        fill_ray_tables(frame.intrinsics, &mut ray_x, &mut ray_y);
        let evidence = Evidence::new(
            frame,
            (&ray_x, &ray_y),
            (&state.previous_gray, &state.previous_mask),
        );
        let interior =
            |x: isize, y: isize| x >= 1 && y >= 1 && x < width as isize - 1 && y < height as isize - 1;
        let set = |mask: &Mask, x: isize, y: isize| mask.get(x as usize, y as usize) != 0;
        let mut frontier = Vec::new();
        for y in 1..height - 1 {
            for x in 1..width - 1 {
                let (xi, yi) = (x as isize, y as isize);
                let on_boundary =
                    set(mask, xi, yi) && NEIGHBOURS_8.iter().any(|&(dx, dy)| !set(mask, xi + dx, yi + dy));
                if on_boundary && evidence.may_seed(x, y) {
                    frontier.push((x, y));
                }
            }
        }
        let mut decided = vec![false; width * height];
        let mut grown = 0;
        for _ in 0..growth.max_rings {
            let mut next = Vec::new();
            for &(fx, fy) in &frontier {
                let zf = frame.depth_m.get(fx, fy);
                if zf <= 0.0 {
                    continue;
                }
                for &(dx, dy) in &NEIGHBOURS_8 {
                    let (nx, ny) = (fx as isize + dx, fy as isize + dy);
                    if !interior(nx, ny) || set(mask, nx, ny) || decided[ny as usize * width + nx as usize] {
                        continue;
                    }
                    let (nx, ny) = (nx as usize, ny as usize);
                    let zn = frame.depth_m.get(nx, ny);
                    if zn <= 0.0 || (zn - zf).abs() > growth.depth_tolerance * zf {
                        continue;
                    }
                    decided[ny * width + nx] = true;
                    if evidence.changed(nx, ny) {
                        mask.set(nx, ny, MASK_SET);
                        let af = accumulation_m.get(fx, fy);
                        accumulation_m.set(nx, ny, evidence.grown_accumulation(frame.config, af, zf, zn));
                        next.push((nx, ny));
                    }
                }
            }
            grown += next.len();
            if next.is_empty() {
                break;
            }
            frontier = next;
        }
        grown
    }

    const SIZE: ImageSize = ImageSize::new(160, 120);
    /// The box: [40, 100) × [30, 90) at 2 m in front of a wall at 3 m.
    const BOX_X: std::ops::Range<usize> = 40..100;
    const BOX_Y: std::ops::Range<usize> = 30..90;
    /// Object pixels already detected: the box's right 6 columns (a swept strip).
    const SEED_X: std::ops::Range<usize> = 94..100;

    fn intrinsics() -> PinholeIntrinsics {
        PinholeIntrinsics::new(131.25, 131.25, 79.5, 59.5)
    }

    /// The fixed test scenes' camera: default detector config, the test intrinsics, no motion.
    struct StillCamera {
        config: OcclusionConfig,
        intrinsics: PinholeIntrinsics,
        motion: Isometry3<f64>,
    }

    impl StillCamera {
        fn new() -> Self {
            Self {
                config: OcclusionConfig::default(),
                intrinsics: intrinsics(),
                motion: Isometry3::identity(),
            }
        }

        /// A frame of depth `depth_m` and gray image `gray` grown with `growth`.
        fn frame<'a>(
            &'a self,
            growth: &'a AppearanceGrowthConfig,
            depth_m: &'a DepthMeters,
            gray: &'a GrayF32,
        ) -> GrowthFrame<'a> {
            GrowthFrame {
                growth,
                config: &self.config,
                intrinsics: &self.intrinsics,
                previous_from_current: &self.motion,
                depth_m,
                gray,
            }
        }
    }

    fn in_box(x: usize, y: usize) -> bool {
        BOX_X.contains(&x) && BOX_Y.contains(&y)
    }

    fn depth() -> DepthMeters {
        Image::from_fn(SIZE, |x, y| if in_box(x, y) { 2.0 } else { 3.0 })
    }

    /// Vertical stripes 2 px wide, shifted by `phase_px`: a 2 px shift inverts every pixel.
    fn stripes(x: usize, phase_px: usize) -> f32 {
        0.3 + 0.4 * (((x + phase_px) / 2) % 2) as f32
    }

    /// A static textured scene whose box texture is misregistered by 1 px between the frames.
    fn misregistered_pair() -> (GrayF32, GrayF32) {
        let previous = Image::from_fn(SIZE, |x, _| stripes(x, 0));
        let current = Image::from_fn(SIZE, |x, y| stripes(x, usize::from(in_box(x, y))));
        (previous, current)
    }

    /// Box and wall textured (2 px stripes); a moved texture puts the box's (or the wall's)
    /// bright part where its dark part was: every pixel changes by at least 0.3, and no
    /// previous pixel nearby matches it.
    fn moved_pair(box_moved: bool, wall_moved: bool) -> (GrayF32, GrayF32) {
        let texture = |x: usize, y: usize, moved: bool| {
            let base = if in_box(x, y) { 0.1 } else { 0.3 };
            base + 0.1 * ((x / 2) % 2) as f32 + if moved { 0.4 } else { 0.0 }
        };
        let previous = Image::from_fn(SIZE, |x, y| texture(x, y, false));
        let current = Image::from_fn(SIZE, |x, y| {
            texture(x, y, if in_box(x, y) { box_moved } else { wall_moved })
        });
        (previous, current)
    }

    /// Runs one growth step from the seed strip with A = 1 m on it; returns the mask, A and
    /// the count.
    fn grow(
        previous: &GrayF32,
        current: &GrayF32,
        growth: AppearanceGrowthConfig,
    ) -> (Mask, DepthMeters, usize) {
        let seed = |x: usize, y: usize| SEED_X.contains(&x) && BOX_Y.contains(&y);
        let mut mask = Image::from_fn(SIZE, |x, y| if seed(x, y) { MASK_SET } else { 0 });
        let mut accumulation = Image::from_fn(SIZE, |x, y| if seed(x, y) { 1.0 } else { 0.0 });
        let mask_pixels = SEED_X.len() * BOX_Y.len();
        let mut state = AppearanceGrowth::new(SIZE);
        // The strip was already detected in the previous frame (the growth's seeds).
        remember_frame(&mut state, previous, &mask);
        let counts = state.grow(
            &StillCamera::new().frame(&growth, &depth(), current),
            &mut mask,
            &mut accumulation,
            mask_pixels,
        );
        let set = mask.as_slice().iter().filter(|&&m| m != 0).count();
        assert_eq!(set, mask_pixels + counts.grown);
        (mask, accumulation, counts.grown)
    }

    fn unbounded() -> AppearanceGrowthConfig {
        AppearanceGrowthConfig {
            max_rings: 1000,
            ..AppearanceGrowthConfig::default()
        }
    }

    /// xorshift64*: deterministic pseudo-random numbers for the agreement test.
    struct Random(u64);

    impl Random {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
        }

        /// Uniform in [0, 1).
        fn unit(&mut self) -> f32 {
            (self.next() >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    /// A random scene: depth steps between a few planes (with holes), random textures, masks
    /// of random rectangles with speckle holes touching the image border, a previous mask
    /// that overlaps them, and a small camera motion.
    struct Scene {
        size: ImageSize,
        depth: DepthMeters,
        previous_gray: GrayF32,
        gray: GrayF32,
        previous_mask: Mask,
        mask: Mask,
        accumulation: DepthMeters,
        motion: Isometry3<f64>,
    }

    fn random_scene(seed: u64) -> Scene {
        let mut random = Random(seed | 1);
        // Odd sizes: the seed scan's 8-pixel words end in a partial word.
        let size = ImageSize::new(
            61 + (random.next() % 40) as usize,
            37 + (random.next() % 30) as usize,
        );
        let planes: Vec<f32> = (0..3).map(|_| 1.0 + 3.0 * random.unit()).collect();
        let split = (random.next() % size.width as u64) as usize;
        let depth = Image::from_fn(size, |x, y| {
            let plane = usize::from(x >= split) + usize::from(y % 17 < 5);
            let slope = 0.002 * x as f32;
            if (x * 7 + y * 13) % 29 == 0 {
                0.0
            } else {
                planes[plane] + slope
            }
        });
        let previous_gray = Image::from_fn(size, |_, _| random.unit());
        // Half the pixels keep their previous value, the others change (texture moved).
        let gray = Image::from_fn(size, |x, y| {
            if random.next().is_multiple_of(2) {
                previous_gray.get(x, y)
            } else {
                random.unit()
            }
        });
        let mut mask: Mask = Image::filled(size, 0);
        for _ in 0..4 {
            let (x0, y0) = (
                random.next() as usize % size.width,
                random.next() as usize % size.height,
            );
            let (w, h) = (1 + random.next() as usize % 25, 1 + random.next() as usize % 20);
            for y in y0..(y0 + h).min(size.height) {
                for x in x0..(x0 + w).min(size.width) {
                    if !random.next().is_multiple_of(11) {
                        mask.set(x, y, MASK_SET);
                    }
                }
            }
        }
        let previous_mask = Image::from_fn(size, |x, y| {
            if x > 0 && mask.get(x - 1, y) != 0 || random.next().is_multiple_of(5) {
                MASK_SET
            } else {
                0
            }
        });
        let accumulation = Image::from_fn(size, |x, y| {
            if mask.get(x, y) != 0 {
                0.2 + random.unit()
            } else {
                0.0
            }
        });
        let motion = Isometry3::new(
            nalgebra::Vector3::new(0.01 * f64::from(random.unit()), -0.005, 0.02),
            nalgebra::Vector3::new(0.0, 0.01 * f64::from(random.unit()), 0.003),
        );
        Scene {
            size,
            depth,
            previous_gray,
            gray,
            previous_mask,
            mask,
            accumulation,
            motion,
        }
    }

    #[test]
    fn growth_matches_the_plain_reference_on_random_scenes() {
        let config = OcclusionConfig::default();
        let growths = [
            AppearanceGrowthConfig::default(),
            unbounded(),
            AppearanceGrowthConfig {
                max_rings: 2,
                photometric_search_radius_px: 0,
                ..AppearanceGrowthConfig::default()
            },
            AppearanceGrowthConfig {
                persistent_seeds_only: false,
                inherit_accumulation: false,
                depth_tolerance: 0.5,
                ..unbounded()
            },
        ];
        let mut total_grown = 0;
        for seed in 0..40u64 {
            let scene = random_scene(0x9E37_79B9_7F4A_7C15 ^ seed);
            let intrinsics = PinholeIntrinsics::new(60.0, 60.0, scene.size.width as f64 / 2.0, 25.0);
            for growth in &growths {
                let mut state = AppearanceGrowth::new(scene.size);
                remember_frame(&mut state, &scene.previous_gray, &scene.previous_mask);
                let mask_pixels = scene.mask.as_slice().iter().filter(|&&m| m != 0).count();
                let frame = GrowthFrame {
                    growth,
                    config: &config,
                    intrinsics: &intrinsics,
                    previous_from_current: &scene.motion,
                    depth_m: &scene.depth,
                    gray: &scene.gray,
                };
                let (mut mask, mut accumulation) = (scene.mask.clone(), scene.accumulation.clone());
                let counts = state.grow(&frame, &mut mask, &mut accumulation, mask_pixels);
                let (mut expected_mask, mut expected_accumulation) =
                    (scene.mask.clone(), scene.accumulation.clone());
                let expected_grown =
                    grow_reference(&state, &frame, &mut expected_mask, &mut expected_accumulation);
                assert_eq!(counts.grown, expected_grown, "seed {seed}, {growth:?}");
                assert!(mask == expected_mask, "seed {seed}, {growth:?}: masks differ");
                assert!(
                    accumulation == expected_accumulation,
                    "seed {seed}, {growth:?}: accumulations differ"
                );
                total_grown += counts.grown;
            }
        }
        // The scenes exercise the growth (not a comparison of two empty results).
        assert!(total_grown > 2000, "{total_grown}");
    }

    #[test]
    fn remember_keeps_the_gray_image_whether_or_not_the_growth_staged_it() {
        let (previous, current) = moved_pair(true, false);
        let seeds = Image::from_fn(SIZE, |x, y| if in_box(x, y) && x >= 94 { MASK_SET } else { 0 });
        let mut state = AppearanceGrowth::new(SIZE);
        remember_frame(&mut state, &previous, &seeds);
        assert!(state.previous_gray == previous, "copied without a growth");
        let (mut mask, mut accumulation) = (seeds.clone(), Image::filled(SIZE, 1.0f32));
        let counts = state.grow(
            &StillCamera::new().frame(&unbounded(), &depth(), &current),
            &mut mask,
            &mut accumulation,
            360,
        );
        assert!(counts.grown > 0);
        remember_frame(&mut state, &current, &mask);
        assert!(state.previous_gray == current, "swapped in after a growth");
        assert!(state.previous_mask == mask);
        // The next frame without a growth (no objects) copies again.
        remember_frame(&mut state, &previous, &Image::filled(SIZE, 0));
        assert!(
            state.previous_gray == previous,
            "copied after the staged image was used"
        );
    }

    #[test]
    fn grows_over_a_moved_texture_and_stops_at_the_depth_edge() {
        // The wall's texture changes too (as if it were misregistered): only depth stops growth.
        let (previous, current) = moved_pair(true, true);
        let (mask, accumulation, grown) = grow(&previous, &current, unbounded());
        assert_eq!(grown, BOX_X.len() * BOX_Y.len() - SEED_X.len() * BOX_Y.len());
        for y in 0..SIZE.height {
            for x in 0..SIZE.width {
                assert_eq!(mask.get(x, y) != 0, in_box(x, y), "pixel ({x}, {y})");
                if in_box(x, y) {
                    // Same depth as the seed: its accumulation, carried over unchanged.
                    assert_eq!(accumulation.get(x, y), 1.0, "pixel ({x}, {y})");
                } else {
                    assert_eq!(accumulation.get(x, y), 0.0);
                }
            }
        }
    }

    #[test]
    fn a_static_texture_misregistered_by_a_pixel_is_not_grown_into() {
        // The box's texture shifted by 1 px only (gray and depth not quite registered): with
        // the default 1 px search every pixel finds its own value nearby; the bilinear sample
        // alone sees half the pixels change.
        let (previous, current) = misregistered_pair();
        let (_, _, grown) = grow(&previous, &current, unbounded());
        assert_eq!(grown, 0);
        let point = AppearanceGrowthConfig {
            photometric_search_radius_px: 0,
            ..unbounded()
        };
        let (_, _, grown) = grow(&previous, &current, point);
        assert!(grown > 0);
    }

    #[test]
    fn a_component_new_in_this_frame_is_not_grown() {
        let (previous, current) = moved_pair(true, false);
        let seed = |x: usize, y: usize| SEED_X.contains(&x) && BOX_Y.contains(&y);
        let run = |growth: AppearanceGrowthConfig| {
            let mut mask = Image::from_fn(SIZE, |x, y| if seed(x, y) { MASK_SET } else { 0 });
            let mut accumulation = Image::from_fn(SIZE, |x, y| if seed(x, y) { 1.0 } else { 0.0 });
            let mut state = AppearanceGrowth::new(SIZE);
            // Nothing was detected in the previous frame.
            remember_frame(&mut state, &previous, &Image::filled(SIZE, 0));
            state
                .grow(
                    &StillCamera::new().frame(&growth, &depth(), &current),
                    &mut mask,
                    &mut accumulation,
                    SEED_X.len() * BOX_Y.len(),
                )
                .grown
        };
        assert_eq!(run(unbounded()), 0);
        let any_seed = AppearanceGrowthConfig {
            persistent_seeds_only: false,
            ..unbounded()
        };
        assert_eq!(run(any_seed), (BOX_X.len() - SEED_X.len()) * BOX_Y.len());
    }

    #[test]
    fn does_not_grow_without_a_photometric_change() {
        // A static scene: nothing changed (same texture phase in both images).
        let (previous, current) = moved_pair(false, false);
        let (_, _, grown) = grow(&previous, &current, unbounded());
        assert_eq!(grown, 0);
        // A change below the threshold: sensor noise, not motion.
        let noisy = Image::from_fn(SIZE, |x, y| {
            previous.get(x, y) + if (x + y) % 2 == 0 { 0.03 } else { -0.03 }
        });
        let (_, _, grown) = grow(&previous, &noisy, unbounded());
        assert_eq!(grown, 0);
    }

    #[test]
    fn growth_per_frame_is_bounded_by_the_ring_count() {
        let (previous, current) = moved_pair(true, false);
        let rings = 5;
        let bounded = AppearanceGrowthConfig {
            max_rings: rings,
            ..AppearanceGrowthConfig::default()
        };
        let (mask, _, grown) = grow(&previous, &current, bounded);
        // 5 columns left of the strip (the strip spans the box's full height).
        assert_eq!(grown, rings * BOX_Y.len());
        for y in 0..SIZE.height {
            for x in 0..SIZE.width {
                let expected = in_box(x, y) && x >= SEED_X.start - rings;
                assert_eq!(mask.get(x, y) != 0, expected, "pixel ({x}, {y})");
            }
        }
    }

    #[test]
    fn grown_accumulation_follows_the_depth_and_stays_above_tau_alpha() {
        // A slanted box face (depth rising 1 mm per column towards the left): the accumulation
        // moves with the depth like Eq. 10's prediction; a seed with A barely above τ_α gives its
        // neighbours at least τ_α · (1 + margin).
        let config = OcclusionConfig::default();
        let growth = unbounded();
        let slanted = Image::from_fn(SIZE, |x, y| {
            if in_box(x, y) {
                2.0 + 0.001 * (BOX_X.end - x) as f32
            } else {
                3.0
            }
        });
        let (previous, current) = moved_pair(true, false);
        for seed_a in [1.0f32, 0.31] {
            let seed = |x: usize, y: usize| SEED_X.contains(&x) && BOX_Y.contains(&y);
            let mut mask = Image::from_fn(SIZE, |x, y| if seed(x, y) { MASK_SET } else { 0 });
            let mut accumulation = Image::from_fn(SIZE, |x, y| if seed(x, y) { seed_a } else { 0.0 });
            let mut state = AppearanceGrowth::new(SIZE);
            remember_frame(&mut state, &previous, &mask);
            let counts = state.grow(
                &StillCamera::new().frame(&growth, &slanted, &current),
                &mut mask,
                &mut accumulation,
                SEED_X.len() * BOX_Y.len(),
            );
            assert_eq!(counts.grown, (SEED_X.start - BOX_X.start) * BOX_Y.len());
            for x in BOX_X.start..SEED_X.start {
                let z = slanted.get(x, 60);
                let floor = config.threshold(config.alpha, z) * (1.0 + growth.accumulation_margin);
                let carried = seed_a + slanted.get(SEED_X.start, 60) - z;
                let expected = carried.max(floor);
                assert!(
                    (accumulation.get(x, 60) - expected).abs() < 1e-4,
                    "seed A {seed_a}, x {x}: {} vs {expected}",
                    accumulation.get(x, 60)
                );
            }
        }
    }

    #[test]
    fn bad_parameters_are_rejected_by_name() {
        for (name, bad) in [
            (
                "appearance_growth.photometric_threshold",
                AppearanceGrowthConfig {
                    photometric_threshold: f32::NAN,
                    ..AppearanceGrowthConfig::default()
                },
            ),
            (
                "appearance_growth.depth_tolerance",
                AppearanceGrowthConfig {
                    depth_tolerance: -0.1,
                    ..AppearanceGrowthConfig::default()
                },
            ),
            (
                "appearance_growth.accumulation_margin",
                AppearanceGrowthConfig {
                    accumulation_margin: f32::INFINITY,
                    ..AppearanceGrowthConfig::default()
                },
            ),
        ] {
            let config = OcclusionConfig {
                appearance_growth: Some(bad),
                ..OcclusionConfig::default()
            };
            match config.validate() {
                Err(crate::error::Error::InvalidParameter { name: found, .. }) => assert_eq!(found, name),
                other => panic!("{name}: {other:?}"),
            }
        }
        assert!(OcclusionConfig::default().validate().is_ok());
    }

    #[test]
    fn nothing_happens_without_a_previous_image_or_objects() {
        let (_, current) = moved_pair(true, false);
        let mut state = AppearanceGrowth::new(SIZE);
        let mut mask = Image::from_fn(SIZE, |x, y| if in_box(x, y) && x >= 94 { MASK_SET } else { 0 });
        let mut accumulation = Image::filled(SIZE, 0.0f32);
        let run = |state: &mut AppearanceGrowth, mask: &mut Mask, accumulation: &mut DepthMeters, pixels| {
            state
                .grow(
                    &StillCamera::new().frame(&unbounded(), &depth(), &current),
                    mask,
                    accumulation,
                    pixels,
                )
                .grown
        };
        assert_eq!(
            run(&mut state, &mut mask, &mut accumulation, 360),
            0,
            "no previous image"
        );
        let seeds = mask.clone();
        remember_frame(&mut state, &current, &seeds);
        state.invalidate();
        assert_eq!(
            run(&mut state, &mut mask, &mut accumulation, 360),
            0,
            "after a reset"
        );
        remember_frame(&mut state, &current, &seeds);
        let mut empty = Image::filled(SIZE, 0u8);
        assert_eq!(run(&mut state, &mut empty, &mut accumulation, 0), 0, "no objects");
    }
}
