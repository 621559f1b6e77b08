//! Depth-connected completion of an ignore mask.
//!
//! The detector often marks only part of a moving person (a band along the edge that swept
//! over the background, the legs). DVO must not see the rest of the body either: its residuals
//! move with the person and pull the estimate along. The completion grows every connected
//! component of the mask breadth-first over 4-neighbours whose depth is continuous with the
//! pixel they grow from (|Z(n) − Z(f)| < `max_depth_step_fraction` · Z(f)) and stays within
//! `max_depth_band_m` of the component's median depth. Continuity stops the growth at depth
//! edges (the wall behind a person); the band stops it on surfaces that are continuous with
//! the object but extend far in depth (the floor a person stands on, a desk a box slides on)
//! after at most a band's worth of them. For an ignore mask the cost of taking too much is a
//! few lost background pixels; the cost of taking too little is a biased motion.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::image_buf::{neighbours_4, DepthMeters, ImageSize, Mask, MASK_SET};

/// Parameters of [`IgnoreCompletion`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IgnoreCompletionConfig {
    /// Largest depth step between neighbours, as a fraction of the depth grown from.
    pub max_depth_step_fraction: f32,
    /// Largest distance from the component's median depth, metres.
    pub max_depth_band_m: f32,
}

impl Default for IgnoreCompletionConfig {
    fn default() -> Self {
        Self {
            max_depth_step_fraction: DEFAULT_MAX_DEPTH_STEP_FRACTION,
            max_depth_band_m: DEFAULT_MAX_DEPTH_BAND_M,
        }
    }
}

/// Default [`IgnoreCompletionConfig::max_depth_step_fraction`]: 3 % of Z, about four times the
/// Kinect's depth step between neighbouring pixels on a slanted surface at 3 m (quantisation
/// and noise), well below the step from a person to the wall behind them.
pub const DEFAULT_MAX_DEPTH_STEP_FRACTION: f32 = 0.03;
/// Default [`IgnoreCompletionConfig::max_depth_band_m`]: 0.5 m around the median depth, the
/// depth extent of a person seen from any side (measured on the Bonn "crowd" window, see
/// docs/method.md: 0.3 m loses arms held forward, 1 m takes in metres of floor).
pub const DEFAULT_MAX_DEPTH_BAND_M: f32 = 0.5;

impl IgnoreCompletionConfig {
    /// Checks both fields.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the bad field.
    pub fn validate(&self) -> Result<()> {
        Error::require_finite_positive(
            "ignore_completion.max_depth_step_fraction",
            self.max_depth_step_fraction,
        )?;
        Error::require_finite_positive("ignore_completion.max_depth_band_m", self.max_depth_band_m)
    }
}

/// The completion runs on a grid of 2×2-pixel cells (mask: any child set; depth: the nearest
/// valid child): four times fewer pixels to visit, and DVO pools the mask to its finest level
/// (half resolution by default) and dilates it by 4 px anyway.
const CELL_PX: usize = 2;

/// Preallocated state of the completion for images of one size.
#[derive(Debug, Clone)]
pub struct IgnoreCompletion {
    config: IgnoreCompletionConfig,
    size: ImageSize,
    /// The cell grid's size.
    cells: ImageSize,
    /// Per cell: set (the mask, then the completion).
    set: Vec<bool>,
    /// Per cell: the nearest valid depth of its pixels (0 = none).
    depth_m: Vec<f32>,
    /// Component of every set cell (`UNLABELLED` elsewhere).
    labels: Vec<u32>,
    /// Median depth of each component (0 when it has no valid depth).
    medians: Vec<f32>,
    /// Depths of the component being labelled (for its median).
    depths: Vec<f32>,
    /// Breadth-first queue of cell indices.
    queue: Vec<u32>,
}

const UNLABELLED: u32 = u32::MAX;

impl IgnoreCompletion {
    /// State for `size` images.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for a bad config.
    pub fn new(size: ImageSize, config: IgnoreCompletionConfig) -> Result<Self> {
        config.validate()?;
        let cells = ImageSize::new(size.width.div_ceil(CELL_PX), size.height.div_ceil(CELL_PX));
        Ok(Self {
            config,
            size,
            cells,
            set: vec![false; cells.area()],
            depth_m: vec![0.0; cells.area()],
            labels: vec![UNLABELLED; cells.area()],
            medians: Vec::new(),
            depths: Vec::with_capacity(cells.area()),
            queue: Vec::with_capacity(cells.area()),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &IgnoreCompletionConfig {
        &self.config
    }

    /// Writes the completion of `mask` on `depth_m` into `out` (0 / [`MASK_SET`]): every 2×2
    /// cell that holds a mask pixel or that the growth reached. Returns the cells added.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when an image is not the completion's size.
    pub fn complete(&mut self, mask: &Mask, depth_m: &DepthMeters, out: &mut Mask) -> Result<usize> {
        for (what, found) in [
            ("ignore completion mask", mask.size()),
            ("ignore completion depth", depth_m.size()),
            ("ignore completion output", out.size()),
        ] {
            if found != self.size {
                return Err(Error::SizeMismatch {
                    what: what.into(),
                    expected: self.size,
                    found,
                });
            }
        }
        self.pool(mask, depth_m);
        self.label_components();
        let added = self.grow();
        // Every set cell (the mask's cells and those the growth added): each cell row's pixel
        // row is written once and copied to the cell's other rows.
        let (w, cw) = (self.size.width, self.cells.width);
        for (cell_row, out_rows) in self
            .set
            .chunks_exact(cw)
            .zip(out.as_mut_slice().chunks_mut(CELL_PX * w))
        {
            let (first, rest) = out_rows.split_at_mut(w);
            for (o, &set) in first.chunks_mut(CELL_PX).zip(cell_row) {
                o.fill(if set { MASK_SET } else { 0 });
            }
            for row in rest.chunks_exact_mut(w) {
                row.copy_from_slice(first);
            }
        }
        Ok(added)
    }

    /// The cell grid of `mask` and `depth_m`, a cell row (two pixel rows) at a time and
    /// branch-free. A partial cell at an odd right or bottom edge reads its one pixel column or
    /// row twice, which changes neither "any set" nor the minimum.
    fn pool(&mut self, mask: &Mask, depth_m: &DepthMeters) {
        let (w, h, cw) = (self.size.width, self.size.height, self.cells.width);
        if cw == 0 {
            return;
        }
        // Invalid depths (≤ 0 or NaN) count as infinitely far; a cell left infinite has none.
        let far = |z: f32| if z > 0.0 { z } else { f32::INFINITY };
        let none_if_far = |z: f32| if z == f32::INFINITY { 0.0 } else { z };
        let (mask, depth) = (mask.as_slice(), depth_m.as_slice());
        for (cy, (set_row, nearest_row)) in self
            .set
            .chunks_exact_mut(cw)
            .zip(self.depth_m.chunks_exact_mut(cw))
            .enumerate()
        {
            let y0 = cy * CELL_PX;
            let y1 = (y0 + 1).min(h - 1);
            let (m0, m1) = (&mask[y0 * w..][..w], &mask[y1 * w..][..w]);
            let (d0, d1) = (&depth[y0 * w..][..w], &depth[y1 * w..][..w]);
            let pairs = (m0.chunks_exact(CELL_PX).zip(m1.chunks_exact(CELL_PX)))
                .zip(d0.chunks_exact(CELL_PX).zip(d1.chunks_exact(CELL_PX)));
            for ((set, nearest), ((ma, mb), (da, db))) in
                set_row.iter_mut().zip(nearest_row.iter_mut()).zip(pairs)
            {
                *set = (ma[0] | ma[1] | mb[0] | mb[1]) != 0;
                *nearest = none_if_far(far(da[0]).min(far(da[1])).min(far(db[0])).min(far(db[1])));
            }
            if w % CELL_PX != 0 {
                let x = w - 1;
                set_row[cw - 1] = (m0[x] | m1[x]) != 0;
                nearest_row[cw - 1] = none_if_far(far(d0[x]).min(far(d1[x])));
            }
        }
    }

    /// [`Self::pool`] pixel by pixel (the reference it is tested against).
    #[cfg(test)]
    fn pool_reference(&mut self, mask: &Mask, depth_m: &DepthMeters) {
        self.set.fill(false);
        // The nearest valid depth, branch-free: invalid pixels (≤ 0 or NaN) count as infinitely
        // far, and a cell left infinite has none.
        self.depth_m.fill(f32::INFINITY);
        let (w, cw) = (self.size.width, self.cells.width);
        for (y, (mask_row, depth_row)) in mask
            .as_slice()
            .chunks_exact(w)
            .zip(depth_m.as_slice().chunks_exact(w))
            .enumerate()
        {
            let row = (y / CELL_PX) * cw;
            let cells = self.set[row..row + cw]
                .iter_mut()
                .zip(&mut self.depth_m[row..row + cw]);
            for ((set, nearest), (m, z)) in cells.zip(mask_row.chunks(CELL_PX).zip(depth_row.chunks(CELL_PX)))
            {
                *set |= m.iter().any(|&v| v != 0);
                for &z in z {
                    *nearest = nearest.min(if z > 0.0 { z } else { f32::INFINITY });
                }
            }
        }
        for nearest in &mut self.depth_m {
            if *nearest == f32::INFINITY {
                *nearest = 0.0;
            }
        }
    }

    /// 4-connected components of the set cells and their median depths.
    fn label_components(&mut self) {
        let (w, h) = (self.cells.width, self.cells.height);
        self.labels.fill(UNLABELLED);
        self.medians.clear();
        for start in 0..self.set.len() {
            if !self.set[start] || self.labels[start] != UNLABELLED {
                continue;
            }
            let label = self.medians.len() as u32;
            self.depths.clear();
            self.queue.clear();
            self.queue.push(start as u32);
            self.labels[start] = label;
            let mut head = 0;
            while head < self.queue.len() {
                let i = self.queue[head] as usize;
                head += 1;
                if self.depth_m[i] > 0.0 {
                    self.depths.push(self.depth_m[i]);
                }
                for j in neighbours_4(i, w, h) {
                    if self.set[j] && self.labels[j] == UNLABELLED {
                        self.labels[j] = label;
                        self.queue.push(j as u32);
                    }
                }
            }
            let median = if self.depths.is_empty() {
                0.0
            } else {
                let mid = self.depths.len() / 2;
                *self.depths.select_nth_unstable_by(mid, f32::total_cmp).1
            };
            self.medians.push(median);
        }
    }

    /// Breadth-first growth from every set cell with depth; returns the cells added.
    fn grow(&mut self) -> usize {
        let (w, h) = (self.cells.width, self.cells.height);
        let (set, depth) = (&mut self.set, &self.depth_m);
        self.queue.clear();
        self.queue.extend(
            (0..set.len())
                .filter(|&i| set[i] && depth[i] > 0.0)
                .map(|i| i as u32),
        );
        let (step, band) = (self.config.max_depth_step_fraction, self.config.max_depth_band_m);
        let mut added = 0;
        let mut head = 0;
        while head < self.queue.len() {
            let i = self.queue[head] as usize;
            head += 1;
            let label = self.labels[i];
            let median = self.medians[label as usize];
            let z = depth[i];
            for j in neighbours_4(i, w, h) {
                if set[j] {
                    continue;
                }
                let zj = depth[j];
                if zj > 0.0 && (zj - z).abs() < step * z && (zj - median).abs() < band {
                    set[j] = true;
                    self.labels[j] = label;
                    self.queue.push(j as u32);
                    added += 1;
                }
            }
        }
        added
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A wall at 3.2 m, a floor from the wall (3.2 m at row 30) to the bottom edge (2.2 m at row
    /// 63), and a box (x 20..40, y 10..45) at 2.75 m standing on the floor (the floor is at
    /// 2.745 m just below it, so box and floor are depth-continuous).
    fn scene() -> (ImageSize, DepthMeters) {
        let size = ImageSize::new(64, 64);
        let depth = DepthMeters::from_fn(size, |x, y| {
            if (20..40).contains(&x) && (10..45).contains(&y) {
                2.75
            } else if y >= 30 {
                3.2 - (y - 30) as f32 / 33.0
            } else {
                3.2
            }
        });
        (size, depth)
    }

    /// A band of 0.3 m keeps the wall (0.45 m behind the box) out.
    const CONFIG: IgnoreCompletionConfig = IgnoreCompletionConfig {
        max_depth_step_fraction: DEFAULT_MAX_DEPTH_STEP_FRACTION,
        max_depth_band_m: 0.3,
    };

    #[test]
    fn fills_the_object_and_stops_at_depth_edges_and_the_band() {
        let (size, depth) = scene();
        let mut completion = IgnoreCompletion::new(size, CONFIG).unwrap();
        // Only a strip of the box's left edge is detected.
        let mask = Mask::from_fn(size, |x, y| {
            if (20..23).contains(&x) && (12..20).contains(&y) {
                MASK_SET
            } else {
                0
            }
        });
        let mut out = Mask::filled(size, 0);
        let added = completion.complete(&mask, &depth, &mut out).unwrap();
        let on_box = |x: usize, y: usize| (20..40).contains(&x) && (10..45).contains(&y);
        for y in 0..64 {
            for x in 0..64 {
                let z = depth.get(x, y);
                if on_box(x, y) {
                    assert_eq!(out.get(x, y), MASK_SET, "box pixel ({x}, {y}) not completed");
                } else if (z - 2.75).abs() >= 0.3 + 0.06 {
                    // The wall and the floor beyond the band (plus one cell's depth change on
                    // the floor) stay out.
                    assert_eq!(out.get(x, y), 0, "({x}, {y}) at {z} m leaked into");
                }
            }
        }
        // In 2×2 cells: the box is 10 × 17.5 cells, the seed strip 1.5 × 4.
        assert!(added >= 10 * 17 - 2 * 4, "{added} cells");
        // The floor at the box's foot is continuous and within the band: taken (but only up to
        // 0.3 m from the box's depth, checked above).
        assert_eq!(out.get(30, 50), MASK_SET);
    }

    #[test]
    fn an_empty_mask_stays_empty_and_cells_without_depth_do_not_grow() {
        let (size, mut depth) = scene();
        let mut completion = IgnoreCompletion::new(size, CONFIG).unwrap();
        let mut out = Mask::filled(size, MASK_SET);
        assert_eq!(
            completion
                .complete(&Mask::filled(size, 0), &depth, &mut out)
                .unwrap(),
            0
        );
        assert!(out.as_slice().iter().all(|&m| m == 0));
        // A mask pixel in a cell without depth is kept (its cell) but grows nothing.
        for (x, y) in [(4, 4), (5, 4), (4, 5), (5, 5)] {
            depth.set(x, y, 0.0);
        }
        let mask = Mask::from_fn(size, |x, y| if (x, y) == (5, 5) { MASK_SET } else { 0 });
        assert_eq!(completion.complete(&mask, &depth, &mut out).unwrap(), 0);
        assert_eq!(out.get(5, 5), MASK_SET);
        assert_eq!(out.as_slice().iter().filter(|&&m| m != 0).count(), 4);
    }

    #[test]
    fn sizes_and_parameters_are_checked() {
        let (size, depth) = scene();
        let bad = IgnoreCompletionConfig {
            max_depth_band_m: f32::NAN,
            ..IgnoreCompletionConfig::default()
        };
        assert!(matches!(
            IgnoreCompletion::new(size, bad),
            Err(Error::InvalidParameter {
                name: "ignore_completion.max_depth_band_m",
                ..
            })
        ));
        let mut completion = IgnoreCompletion::new(size, IgnoreCompletionConfig::default()).unwrap();
        let mut out = Mask::filled(ImageSize::new(8, 8), 0);
        assert!(matches!(
            completion.complete(&Mask::filled(size, 0), &depth, &mut out),
            Err(Error::SizeMismatch { .. })
        ));
    }

    /// The cell-row pooling against the pixel-by-pixel one, on even and odd sizes with
    /// scattered mask pixels and invalid depths.
    #[test]
    fn pooling_agrees_with_its_scalar_reference() {
        for (width, height) in [(1, 1), (2, 2), (5, 3), (64, 48), (37, 23), (640, 480)] {
            let size = ImageSize::new(width, height);
            let depth = DepthMeters::from_fn(size, |x, y| match (x * 31 + y * 17) % 13 {
                0 => 0.0,
                1 => -0.5,
                2 => f32::NAN,
                3 => f32::INFINITY,
                k => 0.5 + k as f32 * 0.37 + ((x * 7 + y * 3) % 29) as f32 * 0.013,
            });
            let mask = Mask::from_fn(size, |x, y| if (x * 11 + y * 7) % 19 == 0 { MASK_SET } else { 0 });
            let mut fast = IgnoreCompletion::new(size, CONFIG).unwrap();
            let mut reference = fast.clone();
            fast.pool(&mask, &depth);
            reference.pool_reference(&mask, &depth);
            assert_eq!(fast.set, reference.set, "{width}x{height}");
            let bits = |v: &[f32]| v.iter().map(|z| z.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&fast.depth_m), bits(&reference.depth_m), "{width}x{height}");
        }
    }

    /// The cell grid against a per-pixel reference, on an odd size (partial cells at the right
    /// and bottom) with invalid depths (0, negative, NaN) scattered in.
    #[test]
    fn pooling_matches_the_per_pixel_reference() {
        let size = ImageSize::new(37, 23);
        let depth = DepthMeters::from_fn(size, |x, y| match (x * 7 + y * 13) % 11 {
            0 => 0.0,
            1 => -1.0,
            2 => f32::NAN,
            k => 1.0 + k as f32 * 0.1 + (x + y) as f32 * 0.01,
        });
        let mask = Mask::from_fn(size, |x, y| if (x * 5 + y * 3) % 17 == 0 { MASK_SET } else { 0 });
        let mut completion = IgnoreCompletion::new(size, CONFIG).unwrap();
        completion.pool(&mask, &depth);
        let cells = ImageSize::new(19, 12);
        assert_eq!(completion.cells, cells);
        for cy in 0..cells.height {
            for cx in 0..cells.width {
                let (mut set, mut nearest) = (false, 0.0f32);
                for y in (CELL_PX * cy)..(CELL_PX * cy + CELL_PX).min(size.height) {
                    for x in (CELL_PX * cx)..(CELL_PX * cx + CELL_PX).min(size.width) {
                        set |= mask.get(x, y) != 0;
                        let z = depth.get(x, y);
                        if z > 0.0 && (nearest == 0.0 || z < nearest) {
                            nearest = z;
                        }
                    }
                }
                let c = cy * cells.width + cx;
                assert_eq!(completion.set[c], set, "cell ({cx}, {cy})");
                assert_eq!(completion.depth_m[c], nearest, "cell ({cx}, {cy})");
            }
        }
        // Every output pixel, partial cells included, is its cell's state.
        let mut out = Mask::filled(size, 7);
        completion.complete(&mask, &depth, &mut out).unwrap();
        for y in 0..size.height {
            for x in 0..size.width {
                let set = completion.set[(y / CELL_PX) * cells.width + x / CELL_PX];
                assert_eq!(out.get(x, y), if set { MASK_SET } else { 0 }, "({x}, {y})");
            }
        }
    }
}
