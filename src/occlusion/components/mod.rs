//! Connected components, small-object suppression, occlusion prediction into the newly
//! discovered area (paper Eq. 10, as the release implements it) and pruning of unattached
//! predictions (docs/method.md steps 10 and 12).
//! Labelling by runs ([`super::runs`]), on preallocated buffers.

use super::runs::{Run, RunLabelling};
use super::transport::PixelBounds;
use super::{Adjacency, OcclusionConfig, PREDICTED, THIN_ERASED};
use crate::image_buf::{DepthMeters, Image, ImageSize, Mask, MASK_SET};

mod morphology;
#[cfg(test)]
mod oracles;
#[cfg(test)]
mod tests;

use morphology::{square_columns, square_filter, square_rows};

const NEIGHBOURS_4: [(isize, isize); 4] = [(-1, 0), (1, 0), (0, -1), (0, 1)];
#[cfg(test)]
pub(super) use crate::image_buf::NEIGHBOURS_8;

/// Counts of one labelling/prediction pass.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct LabelStats {
    pub thin_pixels_erased: usize,
    pub components: usize,
    pub small_components_erased: usize,
    pub predicted_pixels: usize,
    /// Bounding box of the predicted (filled) pixels, None when none.
    pub predicted_bounds: Option<PixelBounds>,
}

#[derive(Debug, Clone)]
pub(super) struct Components {
    width: usize,
    height: usize,
    /// The object set O₀ (0 / 1 per pixel, written by the transport), thinned by the opening,
    /// then labelled.
    object_set: Vec<u8>,
    /// Prediction target, shared by the components: 1 on the interior pixels of Ñ not filled
    /// yet. Set from `target_pixels` when a labelling starts and cleared when it ends, so all 0
    /// in between (no whole-image copy of Ñ per frame).
    target: Vec<u8>,
    /// The interior pixels of Ñ (where prediction may write), in row-major order.
    target_pixels: Vec<u32>,
    /// Per row, the columns `[first, last + 1)` spanned by its target pixels at the start of
    /// the labelling ((0, 0) when none): a superset of the row's target for the whole
    /// labelling (the target only shrinks).
    target_columns: Vec<(u32, u32)>,
    /// `source_stamp[u] == source_epoch` ⇔ u is in the current component's source set.
    source_stamp: Vec<u32>,
    source_epoch: u32,
    /// `candidate_stamp[u] == candidate_epoch` ⇔ u is already a candidate of the current ring.
    candidate_stamp: Vec<u32>,
    candidate_epoch: u32,
    frontier: Vec<u32>,
    candidates: Vec<u32>,
    updates: Vec<(u32, f32)>,
    /// Morphology scratch (0 / 1 per pixel).
    morph_a: Vec<u8>,
    morph_b: Vec<u8>,
    /// The pixels the thin-structure filter erased in the latest labelling.
    thin_erased: Vec<u32>,
    /// Scratch of the thin-structure filter (the previous frame's erased pixels in its box).
    thin_advance: Vec<u32>,
    /// Components of the object set.
    runs: RunLabelling,
    /// Stamp every pixel of a component as prediction source (the reference for the agreement
    /// test; the detector stamps only pixels next to the target).
    stamp_all_sources: bool,
}

/// `values.iter().position(|&v| v != 0)`, skipping 32 zero bytes at a time as four u64 words
/// (Ñ is sparse: most of its rows hold no pixel).
#[inline]
pub(super) fn position_nonzero_u8(values: &[u8]) -> Option<usize> {
    let (chunks, remainder) = values.as_chunks::<32>();
    for (k, chunk) in chunks.iter().enumerate() {
        let (words, _) = chunk.as_chunks::<8>();
        if words.iter().fold(0, |any, w| any | u64::from_ne_bytes(*w)) != 0 {
            return chunk.iter().position(|&v| v != 0).map(|i| k * 32 + i);
        }
    }
    let base = chunks.len() * 32;
    remainder.iter().position(|&v| v != 0).map(|i| base + i)
}

/// `values.iter().position(|&v| v == 0)`, skipping 32 non-zero bytes at a time as four u64
/// words (the run ends of the labelled sets: runs are mostly tens to hundreds of pixels long).
/// A word holds a zero byte iff `(w − 0x01…01) & !w & 0x80…80` is non-zero (the borrow only
/// propagates past a byte that is zero).
#[inline]
pub(super) fn position_zero_u8(values: &[u8]) -> Option<usize> {
    const ONES: u64 = u64::from_ne_bytes([0x01; 8]);
    const HIGHS: u64 = u64::from_ne_bytes([0x80; 8]);
    let (chunks, remainder) = values.as_chunks::<32>();
    for (k, chunk) in chunks.iter().enumerate() {
        let (words, _) = chunk.as_chunks::<8>();
        let zero_bytes = words.iter().fold(0, |any, w| {
            let w = u64::from_ne_bytes(*w);
            any | (w.wrapping_sub(ONES) & !w & HIGHS)
        });
        if zero_bytes != 0 {
            return chunk.iter().position(|&v| v == 0).map(|i| k * 32 + i);
        }
    }
    let base = chunks.len() * 32;
    remainder.iter().position(|&v| v == 0).map(|i| base + i)
}

/// Opening of the 0 / 1 image `set_box` (row y at `set_box[y * stride]`, `width` × `height`,
/// outside counts as 0) with a (2r+1)² square into `opened` (compact rows), then `reconnect_px`
/// 3×3 dilations each intersected with the set: the set's pixels within that geodesic distance
/// (8-connected paths inside the set) of the opening rejoin it. `scratch` holds the row passes.
fn open_reconnected(
    set_box: &[u8],
    stride: usize,
    (width, height): (usize, usize),
    radius: usize,
    reconnect_px: usize,
    scratch: &mut [u8],
    opened: &mut [u8],
) {
    square_filter(set_box, stride, scratch, opened, width, height, radius, true);
    square_rows(opened, width, scratch, width, height, radius, false);
    square_columns(scratch, opened, width, height, radius, false);
    for _ in 0..reconnect_px {
        square_rows(opened, width, scratch, width, height, 1, false);
        square_columns(scratch, opened, width, height, 1, false);
        for (opened_row, set_row) in opened.chunks_exact_mut(width).zip(set_box.chunks(stride)) {
            for (o, &s) in opened_row.iter_mut().zip(set_row) {
                *o &= s;
            }
        }
    }
}

/// Columns and rows of `bounds`.
fn box_dims(bounds: PixelBounds) -> (usize, usize) {
    (bounds.x1 - bounds.x0 + 1, bounds.y1 - bounds.y0 + 1)
}

/// Advances an epoch counter; on wrap-around clears the stamps so stale values never match.
fn next_epoch(epoch: &mut u32, stamps: &mut [u32]) -> u32 {
    if *epoch == u32::MAX {
        stamps.fill(0);
        *epoch = 0;
    }
    *epoch += 1;
    *epoch
}

/// The thin-structure filter's buffers, borrowed from [`Components`] apart from the target
/// list's (the two run side by side).
struct ThinStructureFilter<'a> {
    /// The object set O₀ (0 / 1).
    object_set: &'a mut [u8],
    /// Morphology scratch (0 / 1 per pixel).
    opened: &'a mut [u8],
    scratch: &'a mut [u8],
    /// The pixels it erases (cleared first).
    erased_pixels: &'a mut Vec<u32>,
    /// Scratch: the previous frame's erased pixels that join this frame's opening.
    advance_pixels: &'a mut Vec<u32>,
    width: usize,
    height: usize,
}

impl ThinStructureFilter<'_> {
    /// Thin-structure filter (see `OcclusionConfig::thin_structure_radius_px`): opening of the
    /// object set (inside its bounding box `bounds`) with a (2r+1)² square, then
    /// `reconnect_px` 3×3 dilations each intersected with the set (the set's pixels within that
    /// geodesic distance of the opening rejoin it). Object pixels not covered by the result and
    /// farther than `border_margin_px` from the image border (where an object entering the view
    /// first appears as a thin sliver) leave the object set and lose their accumulation, like
    /// small components. With `previous_erased` (the carried flags of the previous frame's
    /// erased pixels, see [`THIN_ERASED`]), those pixels count as set pixels in the opening and
    /// the reconnection without joining the set. Returns the pixels erased; lists them in
    /// `erased_pixels`.
    fn erase(
        self,
        radius: usize,
        reconnect_px: usize,
        border_margin_px: usize,
        bounds: PixelBounds,
        previous_erased: Option<&[u8]>,
        accumulation_m: &mut DepthMeters,
    ) -> usize {
        let (width, height) = (self.width, self.height);
        self.erased_pixels.clear();
        self.advance_pixels.clear();
        // A previous frame's pixel helps a set pixel stay only within the opening's square
        // (2r) plus the reconnection's reach of it.
        let bounds = match previous_erased {
            None => bounds,
            Some(previous) => {
                let margin = 2 * radius + reconnect_px;
                let grown = PixelBounds {
                    x0: bounds.x0.saturating_sub(margin),
                    x1: (bounds.x1 + margin).min(width - 1),
                    y0: bounds.y0.saturating_sub(margin),
                    y1: (bounds.y1 + margin).min(height - 1),
                };
                for y in grown.y0..=grown.y1 {
                    let row = y * width;
                    for x in grown.x0..=grown.x1 {
                        let i = row + x;
                        if previous[i] & THIN_ERASED != 0 && self.object_set[i] == 0 {
                            self.object_set[i] = 1;
                            self.advance_pixels.push(i as u32);
                        }
                    }
                }
                grown
            }
        };
        // The opening runs on the set's bounding box only: pixels outside the box are
        // background, both in the set and in its erosion (a subset of the set), which is
        // exactly how the filter treats pixels outside its image.
        let (box_width, box_height) = box_dims(bounds);
        let box_area = box_width * box_height;
        let (opened, scratch) = (&mut self.opened[..box_area], &mut self.scratch[..box_area]);
        let set_box = &self.object_set[bounds.y0 * width + bounds.x0..];
        open_reconnected(
            set_box,
            width,
            (box_width, box_height),
            radius,
            reconnect_px,
            scratch,
            opened,
        );
        for &i in self.advance_pixels.iter() {
            self.object_set[i as usize] = 0;
        }
        let mut erased = 0;
        let a = accumulation_m.as_mut_slice();
        // Interior columns of the box (pixels nearer the border than the margin are kept).
        let x_first = bounds.x0.max(border_margin_px);
        let x_end = (bounds.x1 + 1).min(width.saturating_sub(border_margin_px));
        if x_first >= x_end {
            return 0;
        }
        let columns = x_first - bounds.x0..x_end - bounds.x0;
        for (box_y, opened_row) in opened.chunks_exact(box_width).enumerate() {
            let y = bounds.y0 + box_y;
            if y < border_margin_px || y + border_margin_px >= height {
                continue;
            }
            let set_row = &mut self.object_set[y * width + x_first..y * width + x_end];
            let opened_row = &opened_row[columns.clone()];
            // Both are 0 / 1: erased = set ∧ ¬opened. A branch-free count first (it vectorises;
            // most rows erase nothing), then the rare erasing rows pixel by pixel.
            let row_erased = set_row
                .iter()
                .zip(opened_row)
                .fold(0u32, |n, (&s, &o)| n + u32::from(s & (o ^ 1)));
            if row_erased == 0 {
                continue;
            }
            let a_row = &mut a[y * width + x_first..y * width + x_end];
            for (x, ((s, &o), a)) in set_row.iter_mut().zip(opened_row).zip(a_row).enumerate() {
                if *s & (o ^ 1) != 0 {
                    *s = 0;
                    *a = 0.0;
                    self.erased_pixels.push((y * width + x_first + x) as u32);
                }
            }
            erased += row_erased as usize;
        }
        erased
    }
}

/// The prediction target's buffers, borrowed from [`Components`] (see its fields).
struct PredictionTargets<'a> {
    pixels: &'a mut Vec<u32>,
    columns: &'a mut [(u32, u32)],
    target: &'a mut [u8],
    width: usize,
}

impl PredictionTargets<'_> {
    /// Lists the interior pixels of Ñ with each row's column span, and marks them in the target.
    fn collect(self, newly_discovered: &Image<u8>) {
        let width = self.width;
        let height = self.columns.len();
        self.pixels.clear();
        // Interior rows and columns only (none in images narrower or lower than 3 px).
        let interior_rows = if width > 2 {
            1..height.saturating_sub(1)
        } else {
            0..0
        };
        self.columns.fill((0, 0));
        for y in interior_rows {
            let first = y * width + 1;
            let interior = &newly_discovered.as_slice()[first..(y + 1) * width - 1];
            let row_start = self.pixels.len();
            let mut x = 0;
            while let Some(offset) = position_nonzero_u8(&interior[x..]) {
                self.pixels.push((first + x + offset) as u32);
                x += offset + 1;
            }
            if let (Some(&first_pixel), Some(&last_pixel)) = (self.pixels.get(row_start), self.pixels.last())
            {
                let row = (y * width) as u32;
                self.columns[y] = (first_pixel - row, last_pixel - row + 1);
            }
        }
        for &t in self.pixels.iter() {
            self.target[t as usize] = 1;
        }
    }
}

/// The size a component of A must have to stay (step 10).
#[derive(Debug, Clone, Copy)]
pub(super) struct MinObjectSize<'a> {
    /// Pixels of a component at least.
    pub pixels: usize,
    /// Smaller components that are a leaving object's remainder stay too
    /// ([`crate::occlusion::OcclusionConfig::exit_min_object_fraction`]).
    pub leaving: Option<LeavingObject<'a>>,
}

/// What a leaving object's remainder is ([`MinObjectSize::leaving`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct LeavingObject<'a> {
    /// The previous frame's final mask (nonzero = object).
    pub previous_mask: &'a [u8],
    /// Pixels of such a component at least.
    pub min_pixels: usize,
    /// How near the image border it must reach (px).
    pub border_margin_px: usize,
}

impl MinObjectSize<'_> {
    /// Whether the component of `pixels` pixels in `runs` of a `width` × `height` image stays:
    /// it has [`Self::pixels`], or it is a leaving object's remainder (at least
    /// [`LeavingObject::min_pixels`], within [`LeavingObject::border_margin_px`] of the border,
    /// and on the previous frame's mask at one pixel or more).
    fn keeps(&self, runs: &[Run], pixels: usize, width: usize, height: usize) -> bool {
        pixels >= self.pixels
            || self.leaving.is_some_and(|leaving| {
                pixels >= leaving.min_pixels
                    && runs
                        .iter()
                        .any(|run| run_near_border(run, width, height, leaving.border_margin_px))
                    && runs
                        .iter()
                        .any(|run| leaving.previous_mask[run.pixels(width)].iter().any(|&m| m != 0))
            })
    }
}

/// Whether `run` reaches within `margin_px` of the border of a `width` × `height` image (a run
/// does when its first or last pixel does).
fn run_near_border(run: &Run, width: usize, height: usize, margin_px: usize) -> bool {
    let (x_first, x_last, y) = (run.x0 as usize, run.x1 as usize - 1, run.y as usize);
    x_first < margin_px || y < margin_px || x_last + margin_px >= width || y + margin_px >= height
}

impl Components {
    pub(super) fn new(size: ImageSize) -> Self {
        let n = size.area();
        Self {
            width: size.width,
            height: size.height,
            object_set: vec![0; n],
            target: vec![0; n],
            target_pixels: Vec::with_capacity(n),
            target_columns: vec![(0, 0); size.height],
            source_stamp: vec![0; n],
            source_epoch: 0,
            candidate_stamp: vec![0; n],
            candidate_epoch: 0,
            frontier: Vec::with_capacity(n),
            candidates: Vec::with_capacity(n),
            updates: Vec::with_capacity(n),
            morph_a: vec![0; n],
            morph_b: vec![0; n],
            thin_erased: Vec::with_capacity(n),
            thin_advance: Vec::with_capacity(n),
            runs: RunLabelling::new(size.width, size.height),
            stamp_all_sources: false,
        }
    }

    /// The buffers of the thin-structure filter and of the prediction target, apart.
    fn thin_filter_and_targets(&mut self) -> (ThinStructureFilter<'_>, PredictionTargets<'_>) {
        let (width, height) = (self.width, self.height);
        let thin = ThinStructureFilter {
            object_set: &mut self.object_set,
            opened: &mut self.morph_a,
            scratch: &mut self.morph_b,
            erased_pixels: &mut self.thin_erased,
            advance_pixels: &mut self.thin_advance,
            width,
            height,
        };
        let targets = PredictionTargets {
            pixels: &mut self.target_pixels,
            columns: &mut self.target_columns,
            target: &mut self.target,
            width,
        };
        (thin, targets)
    }

    /// The object-set buffer: the transport writes O₀ into it (1 on set pixels, 0 elsewhere)
    /// before [`Components::suppress_and_predict`].
    pub(super) fn object_set_mut(&mut self) -> &mut [u8] {
        &mut self.object_set
    }

    /// Step 10: labels the object set already in the object-set buffer (bounding box `bounds`),
    /// erases components below `min_size` from A and, when enabled, grows the others
    /// into Ñ. Components are handled in the row-major order of their first pixel (they share
    /// the prediction target, so the order matters). The thin-structure filter's advance rule
    /// reads the previous frame's erased pixels ([`THIN_ERASED`]) in `predicted_carried`.
    pub(super) fn suppress_and_predict(
        &mut self,
        config: &OcclusionConfig,
        min_size: MinObjectSize<'_>,
        bounds: Option<PixelBounds>,
        compensated_m: &DepthMeters,
        (newly_discovered, predicted_carried): (&Image<u8>, &Image<u8>),
        accumulation_m: &mut DepthMeters,
    ) -> LabelStats {
        let mut stats = LabelStats::default();
        self.thin_erased.clear();
        let Some(bounds) = bounds else {
            return stats;
        };
        // The opening and the target list read and write disjoint buffers: run them side by side.
        let (thin, targets) = self.thin_filter_and_targets();
        let (thin_pixels_erased, ()) = rayon::join(
            || match config.thin_structure_radius_px {
                0 => 0,
                radius => thin.erase(
                    radius,
                    config.thin_structure_reconnect_px,
                    config.thin_structure_border_margin_px,
                    bounds,
                    config
                        .thin_structure_advance
                        .then(|| predicted_carried.as_slice()),
                    accumulation_m,
                ),
            },
            || {
                if config.predict_newly_discovered {
                    targets.collect(newly_discovered);
                }
            },
        );
        stats.thin_pixels_erased = thin_pixels_erased;
        let (box_width, box_height) = box_dims(bounds);
        stats.components = self.runs.label(
            &self.object_set[bounds.y0 * self.width + bounds.x0..],
            self.width,
            box_width,
            box_height,
            (bounds.x0, bounds.y0),
        );
        for k in 0..stats.components {
            if !min_size.keeps(self.runs.runs(k), self.runs.pixels(k), self.width, self.height) {
                let a = accumulation_m.as_mut_slice();
                for run in self.runs.runs(k) {
                    a[run.pixels(self.width)].fill(0.0);
                }
                stats.small_components_erased += 1;
            } else if config.predict_newly_discovered {
                let (filled, filled_bounds) = self.predict(k, config, compensated_m, accumulation_m);
                stats.predicted_pixels += filled;
                stats.predicted_bounds = PixelBounds::union(stats.predicted_bounds, filled_bounds);
            }
        }
        if config.predict_newly_discovered {
            for &t in &self.target_pixels {
                self.target[t as usize] = 0;
            }
        }
        stats
    }

    /// Breadth-first ring growth of component `k` of the last labelling into the shared
    /// target set (paper Eq. 10 with the release's sign A(n) + Z(n) − Z(ũ)). Returns the pixels
    /// filled and their bounding box.
    fn predict(
        &mut self,
        k: usize,
        config: &OcclusionConfig,
        depth_m: &DepthMeters,
        accumulation_m: &mut DepthMeters,
    ) -> (usize, Option<PixelBounds>) {
        let (width, height) = (self.width, self.height);
        let epoch = next_epoch(&mut self.source_epoch, &mut self.source_stamp);
        self.frontier.clear();
        // The source set is only ever looked up at 4-neighbours of target pixels (candidates
        // are target pixels, and the first ring tests the neighbours of target pixels), and the
        // target only shrinks while a labelling runs: so only the component's pixels next to
        // a current target pixel need a stamp: the run's pixels within one column of the
        // target span of its own row or a neighbouring row (Ñ is a thin band; the components
        // are large), a superset found without a scan.
        for run in self.runs.runs(k) {
            let (y, row, x0, x1) = (
                run.y as usize,
                run.y as usize * width,
                run.x0 as usize,
                run.x1 as usize,
            );
            if self.stamp_all_sources {
                self.source_stamp[row + x0..row + x1].fill(epoch);
                continue;
            }
            for ny in [y.wrapping_sub(1), y, y + 1] {
                let Some(&(first, end)) = self.target_columns.get(ny) else {
                    continue;
                };
                // Pixels within one column of the row's target span.
                let start = (first as usize).saturating_sub(1).max(x0);
                let stop = (end as usize + 1).min(x1);
                if first < end && start < stop {
                    self.source_stamp[row + start..row + stop].fill(epoch);
                }
            }
        }
        let z = depth_m.as_slice();
        let gate = config.prediction_depth_gate_m;
        let mut filled = 0;
        let mut filled_bounds: Option<PixelBounds> = None;
        let mut first_ring = true;
        loop {
            // Candidates: interior target pixels 4-adjacent to the last ring (or the component).
            let ring = next_epoch(&mut self.candidate_epoch, &mut self.candidate_stamp);
            self.candidates.clear();
            if first_ring {
                // Same set, found from the other side: the target list is usually far smaller
                // than the component. Target pixels are interior, so all 4-neighbours exist.
                first_ring = false;
                self.frontier.clear();
                for &t in &self.target_pixels {
                    let t = t as usize;
                    let stamp = &self.source_stamp;
                    let adjacent = stamp[t - 1] == epoch
                        || stamp[t + 1] == epoch
                        || stamp[t - width] == epoch
                        || stamp[t + width] == epoch;
                    if self.target[t] != 0 && adjacent {
                        self.candidate_stamp[t] = ring;
                        self.candidates.push(t as u32);
                    }
                }
            }
            for &f in &self.frontier {
                let f = f as usize;
                let (x, y) = (f % width, f / width);
                // The 4-neighbours in NEIGHBOURS_4 order, each with "is interior" (x and y in
                // 1..size−1), evaluated before the target lookup; no division per neighbour.
                let (x_interior, y_interior) = (x > 0 && x + 1 < width, y > 0 && y + 1 < height);
                let neighbours = [
                    (f.wrapping_sub(1), y_interior && x >= 2),
                    (f + 1, y_interior && x + 2 < width),
                    (f.wrapping_sub(width), x_interior && y >= 2),
                    (f + width, x_interior && y + 2 < height),
                ];
                for (n, interior) in neighbours {
                    if interior && self.target[n] != 0 && self.candidate_stamp[n] != ring {
                        self.candidate_stamp[n] = ring;
                        self.candidates.push(n as u32);
                    }
                }
            }
            // Synchronous ring: every value uses A and the source set from before the ring.
            self.updates.clear();
            let mut terms = 0;
            for &u in &self.candidates {
                let u = u as usize;
                let (x, y) = (u % width, u / width);
                let (mut sum, mut count) = (0.0f32, 0usize);
                for &(dx, dy) in &NEIGHBOURS_4 {
                    // Candidates are interior, so every 4-neighbour exists.
                    let n = (y as isize + dy) as usize * width + (x as isize + dx) as usize;
                    if self.source_stamp[n] == epoch && (z[n] - z[u]).abs() < gate {
                        sum += accumulation_m.as_slice()[n] + z[n] - z[u];
                        count += 1;
                    }
                }
                if count > 0 {
                    self.updates.push((u as u32, sum / count as f32));
                    terms += count;
                }
            }
            self.frontier.clear();
            let a = accumulation_m.as_mut_slice();
            for &(u, value) in &self.updates {
                let u = u as usize;
                a[u] = value;
                self.target[u] = 0;
                self.source_stamp[u] = epoch;
                self.frontier.push(u as u32);
                let (x, y) = (u % width, u / width);
                filled_bounds = PixelBounds::union(
                    filled_bounds,
                    Some(PixelBounds {
                        x0: x,
                        x1: x,
                        y0: y,
                        y1: y,
                    }),
                );
            }
            filled += self.updates.len();
            if self.updates.is_empty() || terms <= config.prediction_stop_terms {
                break;
            }
        }
        (filled, filled_bounds)
    }

    /// Slow-change evidence (`OcclusionConfig::slow_evidence`): opens `evidence` (0 / 1, whole
    /// image, empty outside `bounds`) with a (2r+1)² square inside `bounds`, labels it, and sets
    /// every component of at least `min_pixels` pixels in `mask`. Returns the mask pixels added.
    pub(super) fn add_evidence_components(
        &mut self,
        evidence: &[u8],
        bounds: PixelBounds,
        radius: usize,
        min_pixels: usize,
        mask: &mut Mask,
    ) -> usize {
        let width = self.width;
        let (box_width, box_height) = box_dims(bounds);
        let box_area = box_width * box_height;
        let (opened, scratch) = (&mut self.morph_a[..box_area], &mut self.morph_b[..box_area]);
        let set_box = &evidence[bounds.y0 * width + bounds.x0..];
        // Radius 0 copies the evidence (a square filter of radius 0 is the identity).
        open_reconnected(
            set_box,
            width,
            (box_width, box_height),
            radius,
            0,
            scratch,
            opened,
        );
        let count = self
            .runs
            .label(opened, box_width, box_width, box_height, (bounds.x0, bounds.y0));
        let mut added = 0;
        let m = mask.as_mut_slice();
        for k in 0..count {
            if self.runs.pixels(k) < min_pixels {
                continue;
            }
            for run in self.runs.runs(k) {
                for v in &mut m[run.pixels(width)] {
                    added += usize::from(*v == 0);
                    *v = MASK_SET;
                }
            }
        }
        added
    }

    /// Flags the pixels the thin-structure filter erased in the latest labelling in `predicted`
    /// ([`THIN_ERASED`]) for the next frame's opening.
    pub(super) fn flag_thin_erased(&self, predicted: &mut Image<u8>) {
        let p = predicted.as_mut_slice();
        for &i in &self.thin_erased {
            p[i as usize] |= THIN_ERASED;
        }
    }

    /// Step 12: erases (from A, O and P) every 8-connected component of `predicted` that has no
    /// pixel adjacent to an object pixel outside `predicted`, unless it is a leaving object's
    /// remainder: it holds a pixel of `predicted_carried` (predicted object in the previous
    /// frame) and reaches within `config.prune_exit_margin_px` of the image border.
    /// `predicted` (0 / 1) must be empty outside the rows of `bounds` (its columns are not
    /// used). Erasing a component does not change the others' tests (its pixels were not
    /// non-predicted object pixels before either), so the order does not matter. P is cleared
    /// on erased components so that "carried from P" always means "predicted object that
    /// survived pruning" (the release leaves P set there). Returns the pixels erased.
    pub(super) fn prune_unattached_predictions(
        &mut self,
        config: &OcclusionConfig,
        bounds: PixelBounds,
        predicted_carried: &Image<u8>,
        predicted: &mut Image<u8>,
        mask: &mut Mask,
        accumulation_m: &mut DepthMeters,
    ) -> usize {
        let (width, height) = (self.width, self.height);
        let exit_margin_px = config.prune_exit_margin_px;
        let carried = predicted_carried.as_slice();
        let near_border = |run: &Run| run_near_border(run, width, height, exit_margin_px);
        let diagonal = config.prune_adjacency == Adjacency::Eight;
        let count = self.runs.label(
            &predicted.as_slice()[bounds.y0 * width..],
            width,
            width,
            bounds.y1 - bounds.y0 + 1,
            (0, bounds.y0),
        );
        let mut pruned = 0;
        for k in 0..count {
            let runs = self.runs.runs(k);
            let (m, p) = (mask.as_slice(), predicted.as_slice());
            let attached = runs
                .iter()
                .any(|run| run_attached(run, width, height, diagonal, m, p));
            // An object leaving the view: its non-predicted part went out through the border
            // and the rest, predicted at some earlier frame and object since, is still there.
            let leaving = exit_margin_px > 0
                && runs
                    .iter()
                    .any(|run| carried[run.pixels(width)].iter().any(|&c| c & PREDICTED != 0))
                && runs.iter().any(near_border);
            if !attached && !leaving {
                for run in runs {
                    mask.as_mut_slice()[run.pixels(width)].fill(0);
                    accumulation_m.as_mut_slice()[run.pixels(width)].fill(0.0);
                    predicted.as_mut_slice()[run.pixels(width)].fill(0);
                }
                pruned += self.runs.pixels(k);
            }
        }
        pruned
    }
}

/// Whether a pixel of `run` has a 4-neighbour (8-neighbour when `diagonal`) that is an object
/// pixel (`mask` ≠ 0) outside the predicted set (`predicted` = 0). The run is maximal, so only
/// its two ends have neighbours in its own row.
fn run_attached(
    run: &Run,
    width: usize,
    height: usize,
    diagonal: bool,
    mask: &[u8],
    predicted: &[u8],
) -> bool {
    let (x0, x1, y) = (run.x0 as usize, run.x1 as usize, run.y as usize);
    let row = y * width;
    let outside_object = |i: usize| mask[i] != 0 && predicted[i] == 0;
    if (x0 > 0 && outside_object(row + x0 - 1)) || (x1 < width && outside_object(row + x1)) {
        return true;
    }
    let (first, end) = if diagonal {
        (x0.saturating_sub(1), (x1 + 1).min(width))
    } else {
        (x0, x1)
    };
    [y.wrapping_sub(1), y + 1]
        .into_iter()
        .filter(|&ny| ny < height)
        .any(|ny| {
            let range = ny * width + first..ny * width + end;
            // Branch-free over the range (it vectorises).
            mask[range.clone()]
                .iter()
                .zip(&predicted[range])
                .fold(false, |any, (&m, &p)| any | ((m != 0) & (p == 0)))
        })
}
