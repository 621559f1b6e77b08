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

use super::OcclusionConfig;
use crate::geometry::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, GrayF32, Image, ImageSize, Mask};

mod kernels;

use kernels::{fill_ray_tables, Evidence, GrowthBuffers};

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
/// to 0 before it returns. Masks hold 0 or [`MASK_SET`](crate::image_buf::MASK_SET) otherwise.
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

#[cfg(test)]
mod tests;
