//! Completion of a detected part to the depth-connected body it belongs to (docs/method.md,
//! D26 and D27).
//!
//! Occlusion accumulation marks the part of a moving object that covers something farther away:
//! an object already in view when the recording starts, or one that slides along its own
//! surface, is marked only along the edge that sweeps over background, while the rest of it
//! looks like a static surface frame to frame (its depth does not change). Each connected
//! component of the mask large enough to be trusted grows breadth-first over 4-neighbours whose
//! depth is continuous with the pixel they grow from (|Z(n) − Z(f)| < `max_depth_step_fraction`
//! · Z(f)). Continuity stops the growth at the object's depth edges. A body that is continuous
//! with a surface extending far in depth (a person standing on the floor, a box sliding on a
//! desk) would take that surface in; so a component whose growth reaches a continuous pixel
//! farther than `max_depth_band_m` from its median depth keeps none of it, unless the surface
//! it is continuous with is a plane that can be taken out of the growth
//! (`support_plane_tolerance_inv_m`, D27): the growth is then grown again without it. A plane
//! the component itself lies on is one of its own faces, passed over in that search
//! (`max_own_planes`); a body completed over one is kept only when it stands in front of what
//! surrounds it. What is kept is a body bounded by depth edges, or by its support plane, on
//! every side that is not the image border.
//!
//! Small components are left as they are: the false positives of a static scene are components
//! near the minimum object size, and grown over the wall or cabinet they lie on they would
//! cover it.

use serde::{Deserialize, Serialize};

use super::scaled_pixels;
use crate::error::{Error, Result};
use crate::image_buf::{neighbours_4, DepthMeters, ImageSize, Mask, MASK_SET};
use crate::xorshift::XorShift64;

/// Parameters of [`BodyCompletion`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BodyCompletionConfig {
    /// Largest depth step between 4-neighbours, as a fraction of the depth grown from.
    pub max_depth_step_fraction: f32,
    /// A component whose growth reaches a continuous pixel this far (m) from its median depth
    /// is left as it was.
    pub max_depth_band_m: f32,
    /// Components with fewer pixels than this (given at 640 × 480, scaled to the image's area)
    /// are not grown.
    pub min_seed_pixels_vga: usize,
    /// A growth that reaches beyond the depth band is kept without its support surface when it
    /// has one: the largest plane among the grown pixels within the band, fitted with this
    /// tolerance in inverse depth (1/m; a plane is linear in inverse depth across the image),
    /// up to [`SUPPORT_MAX_PLANES`] of them until what the component reaches without them no
    /// longer leaks; that joins the mask. A plane the component lies on (more than
    /// [`SUPPORT_MAX_SEED_FRACTION`] of it) is never taken out (see `max_own_planes`).
    /// `None`: every leaking growth is dropped (docs/method.md D26 alone).
    pub support_plane_tolerance_inv_m: Option<f32>,
    /// Planes the component lies on (its own faces: a block's front and side) that the search
    /// for the support plane passes over, at most: their pixels stay in the growth, and the
    /// next plane is fitted to the rest of it. A body completed over such a face is kept only
    /// when it stands in front of its surroundings ([`OWN_FACE_MIN_FARTHER_FRACTION`]). 0: the
    /// growth is dropped at the first such plane (D27 as first built).
    pub max_own_planes: usize,
}

/// Default [`BodyCompletionConfig::max_depth_step_fraction`]: the step DVO's ignore-mask
/// completion uses (`dvo::completion`), about four times the depth sensor's step between
/// neighbouring pixels on a slanted surface, well below the step from an object to the wall
/// behind it.
pub const DEFAULT_MAX_DEPTH_STEP_FRACTION: f32 = 0.03;
/// Default [`BodyCompletionConfig::max_depth_band_m`]: the depth extent of a person seen from
/// any side, as for DVO's ignore-mask completion.
pub const DEFAULT_MAX_DEPTH_BAND_M: f32 = 0.5;
/// Default [`BodyCompletionConfig::min_seed_pixels_vga`]: three times the minimum object size
/// (`occlusion.min_object_pixels_vga`, 500). The components that grew over static surfaces on
/// the 7-Scenes kitchen (offline, DVO poses) had at most 1.4 times the minimum object size
/// (174 px at 320 × 240, where the minimum is 125); the board that fills the synthetic view
/// from the first frame is marked with at least 1.4 times as many from its first frames on
/// (docs/method.md, D26).
pub const DEFAULT_MIN_SEED_PIXELS_VGA: usize = 1500;

/// Default [`BodyCompletionConfig::support_plane_tolerance_inv_m`]: three times the Kinect's
/// disparity step in inverse depth (1/8 px over 525 px · 7.5 cm: 0.0032 /m), 2.3 cm of depth
/// at 1.5 m. Measured (docs/method.md D27): on people walking past the camera (Bonn "crowd",
/// offline) mask F1 0.932 → 0.948 with 0.01 /m, 0.941 with 0.005, 0.953 with 0.02; on the box
/// sliding on a desk 0.892 → 0.900 (0.907 with 0.005, 0.893 with 0.02).
pub const DEFAULT_SUPPORT_PLANE_TOLERANCE_INV_M: f32 = 0.01;
/// A plane on which more than this fraction of the component lies is the body's own surface
/// (a board's face), not the surface it stands on.
pub const SUPPORT_MAX_SEED_FRACTION: f32 = 0.3;
/// A support plane must hold at least this fraction of the grown pixels.
pub const SUPPORT_MIN_GROWN_FRACTION: f32 = 0.2;
/// Planes taken out of a leaking growth at most (a floor, the wall behind, a desk's front).
pub const SUPPORT_MAX_PLANES: usize = 3;
/// Default [`BodyCompletionConfig::max_own_planes`]: the two faces of a box seen from the side.
pub const DEFAULT_MAX_OWN_PLANES: usize = 2;
/// A body completed over a face of its own must stand in front of its surroundings: more than
/// this fraction of the depth steps at its outline lead to a farther surface (a false mark on a
/// wall, completed to the wall, has the desk and the people in front of it).
pub const OWN_FACE_MIN_FARTHER_FRACTION: f32 = 0.5;
/// Plane hypotheses tried per plane taken out.
const SUPPORT_HYPOTHESES: usize = 64;
/// Pixels of the growth (and of the component) the hypotheses are scored on, at most.
const SUPPORT_SAMPLE: usize = 1024;

impl Default for BodyCompletionConfig {
    fn default() -> Self {
        Self {
            max_depth_step_fraction: DEFAULT_MAX_DEPTH_STEP_FRACTION,
            max_depth_band_m: DEFAULT_MAX_DEPTH_BAND_M,
            min_seed_pixels_vga: DEFAULT_MIN_SEED_PIXELS_VGA,
            support_plane_tolerance_inv_m: Some(DEFAULT_SUPPORT_PLANE_TOLERANCE_INV_M),
            max_own_planes: DEFAULT_MAX_OWN_PLANES,
        }
    }
}

impl BodyCompletionConfig {
    /// Checks every field.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the bad field.
    pub fn validate(&self) -> Result<()> {
        Error::require_finite_positive(
            "body_completion.max_depth_step_fraction",
            self.max_depth_step_fraction,
        )?;
        Error::require_finite_positive("body_completion.max_depth_band_m", self.max_depth_band_m)?;
        if let Some(tolerance) = self.support_plane_tolerance_inv_m {
            Error::require_finite_positive("body_completion.support_plane_tolerance_inv_m", tolerance)?;
        }
        if self.min_seed_pixels_vga == 0 {
            return Err(Error::InvalidParameter {
                name: "body_completion.min_seed_pixels_vga",
                value: "0".into(),
                expected: ">= 1".into(),
            });
        }
        Ok(())
    }
}

/// What one [`BodyCompletion::complete`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BodyCompletionStats {
    /// Components grown and kept.
    pub completed: usize,
    /// Components whose growth reached beyond the depth band and was dropped.
    pub dropped: usize,
    /// Components whose growth reached beyond the depth band and kept what lies off its
    /// support plane (counted in `completed` too when that added pixels).
    pub supported: usize,
    /// Pixels added to the mask.
    pub added_pixels: usize,
}

/// Not yet part of any component or kept growth.
const FREE: u8 = 0;
/// In a component of the mask, or added by a kept growth.
const TAKEN: u8 = 1;
/// Grown within the band and on no support plane taken out yet.
const OFF_PLANE: u8 = 2;

/// Preallocated state of the completion for images of one size.
#[derive(Debug, Clone)]
pub struct BodyCompletion {
    config: BodyCompletionConfig,
    size: ImageSize,
    min_seed_pixels: usize,
    /// Per pixel: [`FREE`] or [`TAKEN`].
    state: Vec<u8>,
    /// The component being grown: its pixels, then the pixels its growth added.
    queue: Vec<u32>,
    /// Valid depths of the component being grown (for its median).
    depths: Vec<f32>,
    /// The component's pixels with depth that have a neighbour outside the mask: the only
    /// ones its growth can leave from (every other neighbour is in the mask, so taken).
    boundary: Vec<u32>,
    /// Tests: grow from every pixel of the component with depth (the reference the boundary
    /// must match).
    #[cfg(test)]
    grow_from_every_pixel: bool,
    /// A leaking growth while its support planes are taken out.
    leaked_growth: Vec<u32>,
    /// Points (column, row, inverse depth) sampled from the component and from what is left
    /// of its leaking growth, for the support planes (at most [`SUPPORT_SAMPLE`] each).
    seed_sample: Vec<[f32; 3]>,
    grown_sample: Vec<[f32; 3]>,
    /// The component's own faces passed over while its support planes are sought.
    own_planes: Vec<[f32; 3]>,
    /// What the next support plane is fitted to: the leaking growth off the planes taken out
    /// and off the own faces.
    fit_candidates: Vec<u32>,
}

/// Valid depth: positive and finite (0 and NaN mark missing measurements).
fn has_depth(z: f32) -> bool {
    z > 0.0 && z.is_finite()
}

impl BodyCompletion {
    /// State for `size` images.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for a bad config.
    pub fn new(size: ImageSize, config: BodyCompletionConfig) -> Result<Self> {
        config.validate()?;
        Ok(Self {
            config,
            size,
            min_seed_pixels: scaled_pixels(config.min_seed_pixels_vga, size),
            state: vec![FREE; size.area()],
            queue: Vec::with_capacity(size.area()),
            depths: Vec::with_capacity(size.area()),
            boundary: Vec::with_capacity(size.area()),
            #[cfg(test)]
            grow_from_every_pixel: false,
            leaked_growth: Vec::new(),
            seed_sample: Vec::with_capacity(SUPPORT_SAMPLE),
            grown_sample: Vec::with_capacity(SUPPORT_SAMPLE),
            own_planes: Vec::with_capacity(config.max_own_planes),
            fit_candidates: Vec::new(),
        })
    }

    /// The smallest component grown, in pixels of this size.
    pub fn min_seed_pixels(&self) -> usize {
        self.min_seed_pixels
    }

    /// Completes every large enough component of `mask` (0 / nonzero) in place to the body
    /// `depth_m` connects it to.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when an image is not the completion's size.
    pub fn complete(&mut self, mask: &mut Mask, depth_m: &DepthMeters) -> Result<BodyCompletionStats> {
        for (what, found) in [
            ("body completion mask", mask.size()),
            ("body completion depth", depth_m.size()),
        ] {
            if found != self.size {
                return Err(Error::SizeMismatch {
                    what: what.into(),
                    expected: self.size,
                    found,
                });
            }
        }
        let (w, h) = (self.size.width, self.size.height);
        let depth = depth_m.as_slice();
        let mut stats = BodyCompletionStats::default();
        self.state.fill(FREE);
        let m = mask.as_mut_slice();
        for start in 0..m.len() {
            if m[start] == 0 || self.state[start] != FREE {
                continue;
            }
            // The component (4-connected mask pixels) and its valid depths.
            self.queue.clear();
            self.depths.clear();
            self.boundary.clear();
            self.queue.push(start as u32);
            self.state[start] = TAKEN;
            let mut head = 0;
            while head < self.queue.len() {
                let i = self.queue[head] as usize;
                head += 1;
                let mut on_boundary = false;
                for j in neighbours_4(i, w, h) {
                    if m[j] == 0 {
                        on_boundary = true;
                    } else if self.state[j] == FREE {
                        self.state[j] = TAKEN;
                        self.queue.push(j as u32);
                    }
                }
                #[cfg(test)]
                let on_boundary = on_boundary || self.grow_from_every_pixel;
                if has_depth(depth[i]) {
                    self.depths.push(depth[i]);
                    if on_boundary {
                        self.boundary.push(i as u32);
                    }
                }
            }
            let seeds = self.queue.len();
            if seeds < self.min_seed_pixels || self.depths.is_empty() {
                continue;
            }
            let mid = self.depths.len() / 2;
            let median = *self.depths.select_nth_unstable_by(mid, f32::total_cmp).1;
            // The growth, breadth-first from every pixel of the component with depth; without
            // a support plane to take out it stops at the first continuous pixel outside the band.
            let with_support = self.config.support_plane_tolerance_inv_m.is_some();
            let leaked = self.grow(m, depth, median, FREE, !with_support);
            // A leaking growth is kept only without its support plane (and only when it has one).
            let keep = !leaked
                || self
                    .config
                    .support_plane_tolerance_inv_m
                    .is_some_and(|tolerance| {
                        self.keep_off_support_plane(seeds, m, depth, median, tolerance, start)
                    });
            let grown = &self.queue[seeds..];
            if !keep {
                for &i in grown {
                    self.state[i as usize] = FREE;
                }
                stats.dropped += 1;
                continue;
            }
            stats.supported += usize::from(leaked);
            if !grown.is_empty() {
                for &i in grown {
                    m[i as usize] = MASK_SET;
                }
                stats.completed += 1;
                stats.added_pixels += grown.len();
            }
        }
        Ok(stats)
    }
}

impl BodyCompletion {
    /// Grows `self.queue` (the component, all taken) breadth-first over 4-neighbours outside
    /// `mask` (empty: no mask) whose depth is continuous with the pixel they grow from: those in
    /// state `candidate` within the band around `median` join it (TAKEN); reaching one, free or
    /// candidate, beyond the band is a leak. Returns whether it leaked; stops at the first leak
    /// when `stop_at_leak`. The component's pixels are visited in `self.boundary` only (its
    /// other pixels reach nothing new): the same growth, in the same order, as from all of them.
    fn grow(&mut self, mask: &[u8], depth: &[f32], median: f32, candidate: u8, stop_at_leak: bool) -> bool {
        let (w, h) = (self.size.width, self.size.height);
        let (step, band) = (self.config.max_depth_step_fraction, self.config.max_depth_band_m);
        let Self {
            state,
            queue,
            boundary,
            ..
        } = self;
        // Visits pixel `i`: its continuous neighbours within the band join the growth; returns
        // whether one beyond the band was reached (at the first such one when `stop_at_leak`).
        let mut visit = |i: usize, queue: &mut Vec<u32>| {
            let z = depth[i];
            let mut leaked = false;
            if !has_depth(z) {
                return false;
            }
            for j in neighbours_4(i, w, h) {
                let (zj, state_j) = (depth[j], state[j]);
                if mask.get(j).is_some_and(|&v| v != 0)
                    || (state_j != candidate && state_j != FREE)
                    || !has_depth(zj)
                    || (zj - z).abs() >= step * z
                {
                    continue;
                }
                if (zj - median).abs() >= band {
                    leaked = true;
                    if stop_at_leak {
                        break;
                    }
                } else if state_j == candidate {
                    state[j] = TAKEN;
                    queue.push(j as u32);
                }
            }
            leaked
        };
        let mut leaked = false;
        let seeds = queue.len();
        for &i in boundary.iter() {
            leaked |= visit(i as usize, queue);
            if leaked && stop_at_leak {
                return true;
            }
        }
        let mut head = seeds;
        while head < queue.len() {
            let i = queue[head] as usize;
            head += 1;
            leaked |= visit(i, queue);
            if leaked && stop_at_leak {
                return true;
            }
        }
        leaked
    }

    /// For a growth that leaked (`self.queue[seeds..]`, the pixels within the band): takes out
    /// its support surface. Up to [`SUPPORT_MAX_PLANES`] times, the plane in (column, row, 1/Z)
    /// that holds the most of the remaining growth is taken out of it, unless it holds less
    /// than [`SUPPORT_MIN_GROWN_FRACTION`] of the growth (the search ends) or the component
    /// lies on it (more than [`SUPPORT_MAX_SEED_FRACTION`] of it: one of the body's own faces,
    /// which stays in the growth and is left out of the next fits; after
    /// `max_own_planes` of them the search ends); then the growth is grown again from the
    /// component without the planes taken out. Once that growth
    /// no longer reaches beyond the band, `self.queue` is cut to the component and it, and true
    /// is returned. Otherwise the whole growth is freed, `self.queue` cut to the component, and
    /// false returned.
    fn keep_off_support_plane(
        &mut self,
        seeds: usize,
        mask: &[u8],
        depth: &[f32],
        median: f32,
        tolerance: f32,
        rng_seed: usize,
    ) -> bool {
        let w = self.size.width;
        self.leaked_growth.clear();
        self.leaked_growth.extend_from_slice(&self.queue[seeds..]);
        self.queue.truncate(seeds);
        for &i in &self.leaked_growth {
            self.state[i as usize] = OFF_PLANE;
        }
        let point = |i: u32| {
            let i = i as usize;
            [(i % w) as f32, (i / w) as f32, 1.0 / depth[i]]
        };
        let on = |plane: &[f32; 3], p: &[f32; 3]| {
            (plane[0] * p[0] + plane[1] * p[1] + plane[2] - p[2]).abs() < tolerance
        };
        let stride = |n: usize| n.div_ceil(SUPPORT_SAMPLE).max(1);
        // Taken out while `grow` needs `self`, and put back with their capacity.
        let (mut seed_sample, mut grown_sample) = (
            std::mem::take(&mut self.seed_sample),
            std::mem::take(&mut self.grown_sample),
        );
        seed_sample.clear();
        seed_sample.extend(
            self.queue[..seeds]
                .iter()
                .step_by(stride(seeds))
                .filter(|&&i| has_depth(depth[i as usize]))
                .map(|&i| point(i)),
        );
        // Hypotheses from triples of grown pixels, drawn by a fixed generator per component.
        let mut rng = XorShift64::new((rng_seed as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1);
        let mut next = |n: usize| rng.below(n);
        let mut kept = false;
        // The component's own faces found so far: passed over, and left out of later fits.
        let mut own_planes = std::mem::take(&mut self.own_planes);
        own_planes.clear();
        let mut candidates = std::mem::take(&mut self.fit_candidates);
        let mut taken_out = 0;
        while taken_out < SUPPORT_MAX_PLANES {
            candidates.clear();
            candidates.extend(self.leaked_growth.iter().copied().filter(|&i| {
                self.state[i as usize] == OFF_PLANE && !own_planes.iter().any(|plane| on(plane, &point(i)))
            }));
            grown_sample.clear();
            grown_sample.extend(
                candidates
                    .iter()
                    .step_by(stride(candidates.len()))
                    .map(|&i| point(i)),
            );
            if grown_sample.len() < 3 {
                break;
            }
            let mut best: Option<([f32; 3], usize)> = None;
            for _ in 0..SUPPORT_HYPOTHESES {
                let n = grown_sample.len();
                let (p, q, r) = (
                    grown_sample[next(n)],
                    grown_sample[next(n)],
                    grown_sample[next(n)],
                );
                let Some(plane) = plane_through(&p, &q, &r) else {
                    continue;
                };
                let count = grown_sample.iter().filter(|p| on(&plane, p)).count();
                if best.is_none_or(|(_, c)| count > c) {
                    best = Some((plane, count));
                }
            }
            let Some((plane, count)) = best else {
                break;
            };
            if (count as f32) < SUPPORT_MIN_GROWN_FRACTION * grown_sample.len() as f32 {
                break;
            }
            let on_seed = seed_sample.iter().filter(|p| on(&plane, p)).count();
            if on_seed as f32 > SUPPORT_MAX_SEED_FRACTION * seed_sample.len() as f32 {
                if own_planes.len() == self.config.max_own_planes {
                    break;
                }
                own_planes.push(plane);
                continue;
            }
            taken_out += 1;
            for &i in &self.leaked_growth {
                if self.state[i as usize] == OFF_PLANE && on(&plane, &point(i)) {
                    self.state[i as usize] = FREE;
                }
            }
            // Grow again from the component over what is left; stop where it leaks.
            let leaks = self.grow(&[], depth, median, OFF_PLANE, true);
            if !leaks {
                kept = true;
                break;
            }
            for &i in &self.queue[seeds..] {
                self.state[i as usize] = OFF_PLANE;
            }
            self.queue.truncate(seeds);
        }
        // A face passed over may be a static surface (a false mark on a wall, completed to the
        // wall once the desk in front of it is taken out): a body stands in front of what
        // surrounds it.
        if kept && !own_planes.is_empty() {
            kept = self.stands_in_front(mask, depth);
        }
        for &i in &self.leaked_growth {
            if self.state[i as usize] == OFF_PLANE || (!kept && self.state[i as usize] == TAKEN) {
                self.state[i as usize] = FREE;
            }
        }
        if !kept {
            self.queue.truncate(seeds);
        }
        (
            self.seed_sample,
            self.grown_sample,
            self.own_planes,
            self.fit_candidates,
        ) = (seed_sample, grown_sample, own_planes, candidates);
        kept
    }

    /// Whether the body in `self.queue` (the component and its growth, all taken) stands in
    /// front of what surrounds it: of the depth steps from its pixels to 4-neighbours outside
    /// it and outside `mask` (continuous neighbours, as in [`Self::grow`], are no step), more
    /// than [`OWN_FACE_MIN_FARTHER_FRACTION`] lead to a farther surface.
    fn stands_in_front(&self, mask: &[u8], depth: &[f32]) -> bool {
        let (w, h) = (self.size.width, self.size.height);
        let step = self.config.max_depth_step_fraction;
        let (mut farther, mut nearer) = (0usize, 0usize);
        for &i in &self.queue {
            let (i, z) = (i as usize, depth[i as usize]);
            if !has_depth(z) {
                continue;
            }
            for j in neighbours_4(i, w, h) {
                let zj = depth[j];
                if self.state[j] == TAKEN || mask[j] != 0 || !has_depth(zj) || (zj - z).abs() < step * z {
                    continue;
                }
                if zj > z {
                    farther += 1;
                } else {
                    nearer += 1;
                }
            }
        }
        farther as f32 > OWN_FACE_MIN_FARTHER_FRACTION * (farther + nearer) as f32
    }
}

/// The plane `1/Z = a·u + b·v + c` through three points `[u, v, 1/Z]` (`None` when they are
/// collinear in the image).
fn plane_through(p: &[f32; 3], q: &[f32; 3], r: &[f32; 3]) -> Option<[f32; 3]> {
    let (du1, dv1, ds1) = (q[0] - p[0], q[1] - p[1], q[2] - p[2]);
    let (du2, dv2, ds2) = (r[0] - p[0], r[1] - p[1], r[2] - p[2]);
    let det = du1 * dv2 - du2 * dv1;
    if det.abs() < 1.0 {
        return None;
    }
    let a = (ds1 * dv2 - ds2 * dv1) / det;
    let b = (du1 * ds2 - du2 * ds1) / det;
    Some([a, b, p[2] - a * p[0] - b * p[1]])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Depth of the floor in row `y` (30..48) of [`scene`]: a plane, so its inverse depth is
    /// linear in the row, from 2.9 m (row 30) to 2.0 m (row 47).
    fn floor_m(y: usize) -> f32 {
        1.0 / (1.0 / 2.9 + (1.0 / 2.0 - 1.0 / 2.9) * (y - 30) as f32 / 17.0)
    }

    /// 64 × 48: a wall at 3 m; rows 30.. a floor rising from 2.9 m (row 30) to 2.0 m (row 47),
    /// continuous with the wall; a board (x 10..30, y 5..25) floating at 1.5 m; a box (x 40..56,
    /// y 20..41) standing on the floor, at the floor's depth where it stands.
    fn scene() -> DepthMeters {
        let mut depth = wall_and_floor();
        set_depth(&mut depth, 10..30, 5..25, 1.5);
        // The box's front is at the floor's depth where it stands (row 40): continuous with
        // the floor's row 41 below it.
        set_depth(&mut depth, 40..56, 20..41, floor_m(40));
        depth
    }

    /// The wall and the floor of [`scene`] alone.
    fn wall_and_floor() -> DepthMeters {
        let mut depth = DepthMeters::filled(ImageSize::new(64, 48), 3.0);
        for y in 30..48 {
            set_depth(&mut depth, 0..64, y..y + 1, floor_m(y));
        }
        depth
    }

    /// The default support planes ([`completion`]'s `support_plane_tolerance_inv_m`).
    const SUPPORT: Option<f32> = Some(DEFAULT_SUPPORT_PLANE_TOLERANCE_INV_M);

    /// A completion of 64×48 images; `support_plane_tolerance_inv_m` `None` drops every growth
    /// reaching beyond the band (D26 alone).
    fn completion(min_seed_pixels_vga: usize, support_plane_tolerance_inv_m: Option<f32>) -> BodyCompletion {
        BodyCompletion::new(
            ImageSize::new(64, 48),
            BodyCompletionConfig {
                min_seed_pixels_vga,
                support_plane_tolerance_inv_m,
                ..BodyCompletionConfig::default()
            },
        )
        .unwrap()
    }

    fn set_depth(depth: &mut DepthMeters, xs: std::ops::Range<usize>, ys: std::ops::Range<usize>, z: f32) {
        for y in ys {
            for x in xs.clone() {
                depth.set(x, y, z);
            }
        }
    }

    fn mark(mask: &mut Mask, xs: std::ops::Range<usize>, ys: std::ops::Range<usize>) {
        for y in ys {
            for x in xs.clone() {
                mask.set(x, y, MASK_SET);
            }
        }
    }

    /// Marks the rectangle `xs × ys`, completes it over `depth` and checks that its growth was
    /// dropped: nothing completed, supported or added, the mask as it was.
    fn assert_growth_dropped(
        depth: &DepthMeters,
        xs: std::ops::Range<usize>,
        ys: std::ops::Range<usize>,
        support_plane_tolerance_inv_m: Option<f32>,
    ) {
        let mut mask = Mask::filled(depth.size(), 0);
        mark(&mut mask, xs, ys);
        let before = mask.clone();
        let stats = completion(50 * VGA_PER_PIXEL, support_plane_tolerance_inv_m)
            .complete(&mut mask, depth)
            .unwrap();
        assert_eq!(
            (
                stats.completed,
                stats.dropped,
                stats.supported,
                stats.added_pixels
            ),
            (0, 1, 0, 0)
        );
        assert_eq!(mask, before);
    }

    fn count(mask: &Mask) -> usize {
        mask.as_slice().iter().filter(|&&v| v != 0).count()
    }

    /// 640 × 480 pixels per pixel of the 64 × 48 test image.
    const VGA_PER_PIXEL: usize = 100;

    #[test]
    fn a_strip_of_a_floating_board_grows_to_the_whole_board_and_no_further() {
        let depth = scene();
        let mut mask = Mask::filled(depth.size(), 0);
        mark(&mut mask, 26..30, 5..25);
        let stats = completion(50 * VGA_PER_PIXEL, SUPPORT)
            .complete(&mut mask, &depth)
            .unwrap();
        assert_eq!(
            (stats.completed, stats.dropped, stats.added_pixels),
            (1, 0, 16 * 20)
        );
        for y in 0..48 {
            for x in 0..64 {
                let board = (10..30).contains(&x) && (5..25).contains(&y);
                assert_eq!(mask.get(x, y) != 0, board, "({x}, {y})");
            }
        }
    }

    #[test]
    fn without_the_support_plane_a_box_continuous_with_the_floor_keeps_its_mask() {
        assert_growth_dropped(&scene(), 40..44, 20..41, None);
    }

    #[test]
    fn a_box_standing_on_the_floor_grows_to_the_box_without_the_floor() {
        let depth = scene();
        let mut mask = Mask::filled(depth.size(), 0);
        mark(&mut mask, 40..44, 20..41);
        let stats = completion(50 * VGA_PER_PIXEL, SUPPORT)
            .complete(&mut mask, &depth)
            .unwrap();
        assert_eq!((stats.completed, stats.dropped, stats.supported), (1, 0, 1));
        // The whole box but its rows that lie within the tolerance of the floor's plane: its
        // front is at the floor's depth in row 40, one row of floor further in row 39.
        let tolerance = DEFAULT_SUPPORT_PLANE_TOLERANCE_INV_M;
        let on_floor = |y: usize| y >= 30 && (1.0 / floor_m(40) - 1.0 / floor_m(y)).abs() < tolerance;
        assert_eq!((30..41).filter(|&y| on_floor(y)).collect::<Vec<_>>(), [39, 40]);
        for y in 0..48 {
            for x in 0..64 {
                let marked = (40..44).contains(&x) && (20..41).contains(&y);
                let box_off_floor = (40..56).contains(&x) && (20..41).contains(&y) && !on_floor(y);
                assert_eq!(mask.get(x, y) != 0, marked || box_off_floor, "({x}, {y})");
            }
        }
    }

    /// A block standing on the floor whose front outweighs the floor in the growth (a strip of
    /// it marked): the front is the block's own face, passed over, and the floor below is taken
    /// out. Without passing over own faces the growth is dropped.
    #[test]
    fn a_block_whose_own_face_outweighs_the_floor_grows_to_the_face_without_the_floor() {
        let mut depth = wall_and_floor();
        set_depth(&mut depth, 16..60, 8..41, floor_m(40));
        let mut marked = Mask::filled(depth.size(), 0);
        mark(&mut marked, 54..60, 8..41);
        let config = |max_own_planes| BodyCompletionConfig {
            min_seed_pixels_vga: 50 * VGA_PER_PIXEL,
            max_own_planes,
            ..BodyCompletionConfig::default()
        };

        let mut mask = marked.clone();
        let mut completion = BodyCompletion::new(depth.size(), config(0)).unwrap();
        let stats = completion.complete(&mut mask, &depth).unwrap();
        assert_eq!((stats.completed, stats.dropped, stats.supported), (0, 1, 0));
        assert_eq!(mask, marked);

        let mut completion = BodyCompletion::new(depth.size(), config(DEFAULT_MAX_OWN_PLANES)).unwrap();
        let stats = completion.complete(&mut mask, &depth).unwrap();
        assert_eq!((stats.completed, stats.dropped, stats.supported), (1, 0, 1));
        // As in the box test above, the front's rows 39 and 40 lie on the floor's plane.
        for y in 0..48 {
            for x in 0..64 {
                let face_off_floor = (16..60).contains(&x) && (8..39).contains(&y);
                let expected = marked.get(x, y) != 0 || face_off_floor;
                assert_eq!(mask.get(x, y) != 0, expected, "({x}, {y})");
            }
        }
    }

    /// A false mark on a wall that meets the floor, a board in front of the wall: the wall is
    /// the mark's own face and the floor its support, but the wall does not stand in front of
    /// what surrounds it (the board is nearer), so the growth is dropped.
    #[test]
    fn a_mark_on_a_wall_behind_a_nearer_object_is_not_grown_over_the_wall() {
        let mut depth = wall_and_floor();
        // The wall continuous with the floor's farthest row.
        set_depth(&mut depth, 0..64, 0..30, floor_m(30));
        set_depth(&mut depth, 10..30, 5..25, 1.5);
        assert_growth_dropped(&depth, 34..40, 2..28, SUPPORT);
    }

    #[test]
    fn a_component_lying_on_the_extended_surface_is_not_grown() {
        // 120 px of floor.
        assert_growth_dropped(&scene(), 2..14, 34..44, SUPPORT);
    }

    #[test]
    fn components_below_the_seed_size_are_not_grown_and_each_component_is_judged_alone() {
        let depth = scene();
        let mut mask = Mask::filled(depth.size(), 0);
        mark(&mut mask, 26..30, 5..25); // 80 px on the board
        mark(&mut mask, 40..44, 20..41); // 84 px on the box
        let mut small = mask.clone();
        completion(85 * VGA_PER_PIXEL, SUPPORT)
            .complete(&mut small, &depth)
            .unwrap();
        assert_eq!(small, mask, "both components are below 85 px");
        let stats = completion(80 * VGA_PER_PIXEL, None)
            .complete(&mut mask, &depth)
            .unwrap();
        assert_eq!((stats.completed, stats.dropped), (1, 1));
        assert_eq!(count(&mask), 20 * 20 + 84);
    }

    #[test]
    fn pixels_without_depth_are_never_added_and_growth_is_4_connected() {
        let mut depth = scene();
        // A column without depth splits the board: the part beyond it is not reached.
        for y in 5..25 {
            depth.set(20, y, 0.0);
        }
        depth.set(21, 10, f32::NAN);
        let mut mask = Mask::filled(depth.size(), 0);
        mark(&mut mask, 26..30, 5..25);
        completion(50 * VGA_PER_PIXEL, SUPPORT)
            .complete(&mut mask, &depth)
            .unwrap();
        assert_eq!(mask.get(20, 10), 0);
        assert_eq!(mask.get(21, 10), 0);
        assert_eq!(mask.get(22, 10), MASK_SET);
        assert_eq!(mask.get(19, 10), 0, "the column without depth spans the board");
        assert_eq!(count(&mask), 9 * 20 - 1);
    }

    #[test]
    fn growing_from_the_boundary_matches_growing_from_every_component_pixel() {
        let mut rng = XorShift64::new(0x2545_f491_4f6c_dd1d);
        let mut next = |n: usize| rng.below(n);
        let mut seen = (0, 0, 0);
        for round in 0..200 {
            // The scene with holes in its depth and a few rectangles of mask over it.
            let mut depth = scene();
            for _ in 0..next(60) {
                depth.as_mut_slice()[next(64 * 48)] = 0.0;
            }
            let mut mask = Mask::filled(depth.size(), 0);
            for _ in 0..1 + next(4) {
                let (x, y) = (next(60), next(44));
                mark(
                    &mut mask,
                    x..(x + 2 + next(20)).min(64),
                    y..(y + 2 + next(20)).min(48),
                );
            }
            let support = if round % 4 == 0 { None } else { SUPPORT };
            let mut fast = completion(20 * VGA_PER_PIXEL, support);
            let mut reference = completion(20 * VGA_PER_PIXEL, support);
            reference.grow_from_every_pixel = true;
            let mut reference_mask = mask.clone();
            let stats = fast.complete(&mut mask, &depth).unwrap();
            let reference_stats = reference.complete(&mut reference_mask, &depth).unwrap();
            assert_eq!(stats, reference_stats, "round {round}");
            assert_eq!(mask, reference_mask, "round {round}");
            seen.0 += stats.completed;
            seen.1 += stats.dropped;
            seen.2 += stats.supported;
        }
        // Every path is taken (93 completed, 285 dropped, 10 kept without support planes).
        assert!(
            seen.0 > 50 && seen.1 > 5 && seen.2 >= 5,
            "completed, dropped, supported: {seen:?}"
        );
    }

    #[test]
    fn the_completion_is_idempotent_and_mismatched_sizes_are_errors() {
        let depth = scene();
        let mut mask = Mask::filled(depth.size(), 0);
        mark(&mut mask, 26..30, 5..25);
        let mut c = completion(50 * VGA_PER_PIXEL, SUPPORT);
        c.complete(&mut mask, &depth).unwrap();
        let once = mask.clone();
        let stats = c.complete(&mut mask, &depth).unwrap();
        assert_eq!(stats.added_pixels, 0);
        assert_eq!(mask, once);
        let mut wrong = Mask::filled(ImageSize::new(32, 24), 0);
        assert!(matches!(
            c.complete(&mut wrong, &depth),
            Err(Error::SizeMismatch { .. })
        ));
    }

    #[test]
    fn invalid_parameters_are_named() {
        for config in [
            BodyCompletionConfig {
                max_depth_step_fraction: 0.0,
                ..Default::default()
            },
            BodyCompletionConfig {
                max_depth_band_m: f32::NAN,
                ..Default::default()
            },
            BodyCompletionConfig {
                min_seed_pixels_vga: 0,
                ..Default::default()
            },
        ] {
            let err = BodyCompletion::new(ImageSize::new(8, 8), config).unwrap_err();
            assert!(err.to_string().contains("body_completion."), "{err}");
        }
    }
}
