//! Connected components, small-object suppression, occlusion prediction into the newly
//! discovered area (algorithm.md §5.1, §9-Q5) and pruning of unattached predictions (§5.3).
//! Sequential (flood fills), on preallocated buffers.

use super::transport::{PixelBounds, UNLABELLED};
use super::{Adjacency, OcclusionConfig};
use crate::image_buf::{DepthMeters, Image, ImageSize, Mask};

const NEIGHBOURS_4: [(isize, isize); 4] = [(-1, 0), (1, 0), (0, -1), (0, 1)];
/// The 8 neighbours as (dx, dy).
pub(super) const NEIGHBOURS_8: [(isize, isize); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

/// Counts of one labelling/prediction pass.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct LabelStats {
    pub thin_pixels_erased: usize,
    pub components: usize,
    pub small_components_erased: usize,
    pub predicted_pixels: usize,
}

#[derive(Debug, Clone)]
pub(super) struct Components {
    width: usize,
    height: usize,
    /// 0 = not in the set, UNLABELLED = in the set, else component id.
    labels: Vec<u32>,
    stack: Vec<u32>,
    component: Vec<u32>,
    /// Prediction target (a copy of Ñ from which filled pixels are removed; shared by components).
    target: Vec<u8>,
    /// The interior pixels of Ñ (where prediction may write), in row-major order.
    target_pixels: Vec<u32>,
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
}

/// Elements per step of [`position_chunked`]: one or two AVX2 registers of u32 / u8.
const SCAN_CHUNK: usize = 32;

/// `values.iter().position(hit)`, but skips whole chunks of [`SCAN_CHUNK`] elements with a
/// branch-free test the compiler vectorises (the scans for seeds, run ends and the newly
/// discovered pixels mostly cross long stretches without a hit). Reference: `Iterator::position`
/// (agreement test below).
#[inline]
fn position_chunked<T: Copy>(values: &[T], hit: impl Fn(T) -> bool) -> Option<usize> {
    let (chunks, remainder) = values.as_chunks::<SCAN_CHUNK>();
    for (k, chunk) in chunks.iter().enumerate() {
        if chunk.iter().fold(false, |any, &v| any | hit(v)) {
            return chunk.iter().position(|&v| hit(v)).map(|i| k * SCAN_CHUNK + i);
        }
    }
    let base = chunks.len() * SCAN_CHUNK;
    remainder.iter().position(|&v| hit(v)).map(|i| base + i)
}

/// `values.iter().position(|&v| v != 0)`, skipping 32 zero bytes at a time as four u64 words
/// (Ñ is sparse: most of its rows hold no pixel).
#[inline]
fn position_nonzero_u8(values: &[u8]) -> Option<usize> {
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

/// Neighbour (x + dx, y + dy) if inside the image.
#[inline]
fn neighbour(x: usize, y: usize, dx: isize, dy: isize, width: usize, height: usize) -> Option<usize> {
    let nx = x.checked_add_signed(dx)?;
    let ny = y.checked_add_signed(dy)?;
    (nx < width && ny < height).then_some(ny * width + nx)
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

impl Components {
    pub(super) fn new(size: ImageSize) -> Self {
        let n = size.area();
        Self {
            width: size.width,
            height: size.height,
            labels: vec![0; n],
            stack: Vec::with_capacity(n),
            component: Vec::with_capacity(n),
            target: vec![0; n],
            target_pixels: Vec::with_capacity(n),
            source_stamp: vec![0; n],
            source_epoch: 0,
            candidate_stamp: vec![0; n],
            candidate_epoch: 0,
            frontier: Vec::with_capacity(n),
            candidates: Vec::with_capacity(n),
            updates: Vec::with_capacity(n),
            morph_a: vec![0; n],
            morph_b: vec![0; n],
        }
    }

    /// Flood-fills the 8-connected component of `seed` (labels must hold UNLABELLED on set
    /// pixels) with `id`, leaving its pixels in `self.component` (in scanline-run order; every
    /// consumer of `self.component` is order-independent). Scanline algorithm: each popped seed
    /// is extended to its whole horizontal run, and the rows above and below are scanned once
    /// over the run's 8-neighbourhood, pushing one seed per unlabelled segment. Reference:
    /// [`Components::flood_scalar`].
    fn flood(&mut self, seed: usize, id: u32) {
        let (width, height) = (self.width, self.height);
        let labels = &mut self.labels;
        self.component.clear();
        self.stack.clear();
        self.stack.push(seed as u32);
        while let Some(p) = self.stack.pop() {
            let p = p as usize;
            if labels[p] != UNLABELLED {
                continue;
            }
            let y = p / width;
            let row_start = y * width;
            let mut left = p;
            while left > row_start && labels[left - 1] == UNLABELLED {
                left -= 1;
            }
            let row_end = row_start + width;
            let right =
                p + position_chunked(&labels[p + 1..row_end], |l| l != UNLABELLED).unwrap_or(row_end - 1 - p);
            labels[left..=right].fill(id);
            self.component.extend(left as u32..=right as u32);
            // 8-adjacency: the neighbour rows are scanned one column beyond the run on each side.
            let x_first = (left - row_start).saturating_sub(1);
            let x_last = (right - row_start + 1).min(width - 1);
            for ny in [y.wrapping_sub(1), y + 1] {
                if ny >= height {
                    continue;
                }
                let neighbour_row = &labels[ny * width..(ny + 1) * width];
                let mut x = x_first;
                while x <= x_last {
                    if neighbour_row[x] == UNLABELLED {
                        self.stack.push((ny * width + x) as u32);
                        while x <= x_last && neighbour_row[x] == UNLABELLED {
                            x += 1;
                        }
                    } else {
                        x += 1;
                    }
                }
            }
        }
    }

    /// Reference flood fill: depth-first over the 8 neighbours of every pixel (for the
    /// agreement test of [`Components::flood`]).
    #[cfg(test)]
    fn flood_scalar(&mut self, seed: usize, id: u32) {
        let (width, height) = (self.width, self.height);
        self.component.clear();
        self.stack.clear();
        self.labels[seed] = id;
        self.stack.push(seed as u32);
        while let Some(p) = self.stack.pop() {
            let p = p as usize;
            self.component.push(p as u32);
            let (x, y) = (p % width, p / width);
            for &(dx, dy) in &NEIGHBOURS_8 {
                if let Some(n) = neighbour(x, y, dx, dy, width, height) {
                    if self.labels[n] == UNLABELLED {
                        self.labels[n] = id;
                        self.stack.push(n as u32);
                    }
                }
            }
        }
    }

    /// The next [`UNLABELLED`] pixel in row-major order inside `bounds`, from `cursor` (row,
    /// column) on; the cursor moves past it. Reference: the row-major loop over the box with a
    /// label test per pixel.
    fn next_unlabelled(&self, cursor: &mut (usize, usize), bounds: PixelBounds) -> Option<usize> {
        let width = self.width;
        while cursor.0 <= bounds.y1 {
            let (y, x) = *cursor;
            let row = &self.labels[y * width..y * width + bounds.x1 + 1];
            if x < row.len() {
                if let Some(offset) = position_chunked(&row[x..], |l| l == UNLABELLED) {
                    *cursor = (y, x + offset + 1);
                    return Some(y * width + x + offset);
                }
            }
            *cursor = (y + 1, bounds.x0);
        }
        None
    }

    /// The label buffer: the transport writes the object set O₀ into it ([`UNLABELLED`] on set
    /// pixels, 0 elsewhere) before [`Components::suppress_and_predict`].
    pub(super) fn labels_mut(&mut self) -> &mut [u32] {
        &mut self.labels
    }

    /// Step 10: labels the object set already in the label buffer (bounding box `bounds`),
    /// erases components below `min_object_pixels` from A and, when enabled, grows the others
    /// into Ñ.
    pub(super) fn suppress_and_predict(
        &mut self,
        config: &OcclusionConfig,
        min_object_pixels: usize,
        bounds: Option<PixelBounds>,
        compensated_m: &DepthMeters,
        newly_discovered: &Image<u8>,
        accumulation_m: &mut DepthMeters,
    ) -> LabelStats {
        let mut stats = LabelStats::default();
        let Some(bounds) = bounds else {
            return stats;
        };
        if config.thin_structure_radius_px > 0 {
            stats.thin_pixels_erased = self.erase_thin_structures(
                config.thin_structure_radius_px,
                config.thin_structure_border_margin_px,
                bounds,
                accumulation_m,
            );
        }
        if config.predict_newly_discovered {
            self.target.copy_from_slice(newly_discovered.as_slice());
            self.target_pixels.clear();
            let (width, height) = (self.width, self.height);
            // Interior rows and columns only (none in images narrower or lower than 3 px).
            let interior_rows = if width > 2 {
                1..height.saturating_sub(1)
            } else {
                0..0
            };
            for y in interior_rows {
                let first = y * width + 1;
                let interior = &self.target[first..(y + 1) * width - 1];
                let mut x = 0;
                while let Some(offset) = position_nonzero_u8(&interior[x..]) {
                    self.target_pixels.push((first + x + offset) as u32);
                    x += offset + 1;
                }
            }
        }
        let mut next_id = 0u32;
        // Seeds in row-major order; the set (and so every seed) lies in the bounding box. A
        // flood only relabels pixels, so the scan goes on after the seed.
        let mut cursor = (bounds.y0, bounds.x0);
        while let Some(seed) = self.next_unlabelled(&mut cursor, bounds) {
            next_id += 1;
            self.flood(seed, next_id);
            stats.components += 1;
            if self.component.len() < min_object_pixels {
                let a = accumulation_m.as_mut_slice();
                for &p in &self.component {
                    a[p as usize] = 0.0;
                }
                stats.small_components_erased += 1;
            } else if config.predict_newly_discovered {
                stats.predicted_pixels += self.predict(config, compensated_m, accumulation_m);
            }
        }
        stats
    }

    /// Thin-structure filter (see `OcclusionConfig::thin_structure_radius_px`): opening of the
    /// object set (labels ≠ 0) with a (2r+1)² square. Object pixels not covered by the opening
    /// and farther than `border_margin_px` from the image border (where an object entering the
    /// view first appears as a thin sliver) leave the object set and lose their accumulation,
    /// like small components. Returns the pixels erased.
    fn erase_thin_structures(
        &mut self,
        radius: usize,
        border_margin_px: usize,
        bounds: PixelBounds,
        accumulation_m: &mut DepthMeters,
    ) -> usize {
        let (width, height) = (self.width, self.height);
        // The opening runs on the set's bounding box only, copied to a compact image: pixels
        // outside the box are background, both in the set and in its erosion (a subset of the
        // set), which is exactly how the filter treats pixels outside its image.
        let (box_width, box_height) = (bounds.x1 - bounds.x0 + 1, bounds.y1 - bounds.y0 + 1);
        let box_area = box_width * box_height;
        for (m_row, l_row) in self.morph_a[..box_area]
            .chunks_exact_mut(box_width)
            .zip(self.labels.chunks_exact(width).skip(bounds.y0))
        {
            for (m, &l) in m_row.iter_mut().zip(&l_row[bounds.x0..=bounds.x1]) {
                *m = u8::from(l != 0);
            }
        }
        // Erosion (outside the image counts as background), then dilation.
        for erode in [true, false] {
            square_filter(
                &mut self.morph_a[..box_area],
                &mut self.morph_b[..box_area],
                box_width,
                box_height,
                radius,
                erode,
            );
        }
        let mut erased = 0;
        let a = accumulation_m.as_mut_slice();
        // Interior columns of the box (pixels nearer the border than the margin are kept).
        let x_first = bounds.x0.max(border_margin_px);
        let x_end = (bounds.x1 + 1).min(width.saturating_sub(border_margin_px));
        if x_first >= x_end {
            return 0;
        }
        for (box_y, opened_row) in self.morph_a[..box_area].chunks_exact(box_width).enumerate() {
            let y = bounds.y0 + box_y;
            if y < border_margin_px || y + border_margin_px >= height {
                continue;
            }
            // Branch-free over the row's interior columns, so the loop vectorises.
            let row = y * width + x_first..y * width + x_end;
            let opened_row = &opened_row[x_first - bounds.x0..x_end - bounds.x0];
            let (labels, a_row) = (&mut self.labels[row.clone()], &mut a[row]);
            let mut row_erased = 0u32;
            for ((label, a), &opened) in labels.iter_mut().zip(a_row.iter_mut()).zip(opened_row) {
                let erase = (*label != 0) & (opened == 0);
                *label = if erase { 0 } else { *label };
                *a = if erase { 0.0 } else { *a };
                row_erased += u32::from(erase);
            }
            erased += row_erased as usize;
        }
        erased
    }

    /// Breadth-first ring growth of the current component (`self.component`) into the shared
    /// target set (algorithm.md §5.1, release sign A(n) + Z(n) − Z(ũ)). Returns pixels filled.
    fn predict(
        &mut self,
        config: &OcclusionConfig,
        depth_m: &DepthMeters,
        accumulation_m: &mut DepthMeters,
    ) -> usize {
        let (width, height) = (self.width, self.height);
        let epoch = next_epoch(&mut self.source_epoch, &mut self.source_stamp);
        self.frontier.clear();
        for &p in &self.component {
            self.source_stamp[p as usize] = epoch;
        }
        let z = depth_m.as_slice();
        let gate = config.prediction_depth_gate_m;
        let mut filled = 0;
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
            }
            filled += self.updates.len();
            if self.updates.is_empty() || terms <= config.prediction_stop_terms {
                break;
            }
        }
        filled
    }

    /// Step 12: erases (from A, O and P) every 8-connected component of `predicted` that has no
    /// pixel adjacent to an object pixel outside `predicted`, unless it is a leaving object's
    /// remainder: it holds a pixel of `predicted_carried` (predicted object in the previous
    /// frame) and reaches within `config.prune_exit_margin_px` of the image border. The label
    /// buffer must hold [`UNLABELLED`] on `predicted` pixels and 0 elsewhere (the detector's
    /// object-mask pass writes it), and `predicted` must be empty outside `bounds`. P is cleared
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
        let near_border = |q: u32| {
            let (x, y) = (q as usize % width, q as usize / width);
            x < exit_margin_px
                || y < exit_margin_px
                || x + exit_margin_px >= width
                || y + exit_margin_px >= height
        };
        let neighbours: &[(isize, isize)] = match config.prune_adjacency {
            Adjacency::Four => &NEIGHBOURS_4,
            Adjacency::Eight => &NEIGHBOURS_8,
        };
        let mut pruned = 0;
        let mut next_id = 0u32;
        let mut cursor = (bounds.y0, bounds.x0);
        while let Some(seed) = self.next_unlabelled(&mut cursor, bounds) {
            next_id += 1;
            self.flood(seed, next_id);
            let (m, p) = (mask.as_slice(), predicted.as_slice());
            let attached = self.component.iter().any(|&q| {
                let (x, y) = (q as usize % width, q as usize / width);
                neighbours.iter().any(|&(dx, dy)| {
                    neighbour(x, y, dx, dy, width, height).is_some_and(|n| m[n] != 0 && p[n] == 0)
                })
            });
            // An object leaving the view: its non-predicted part went out through the border
            // and the rest, predicted at some earlier frame and object since, is still there.
            let leaving = exit_margin_px > 0
                && self.component.iter().any(|&q| carried[q as usize] != 0)
                && self.component.iter().any(|&q| near_border(q));
            if !attached && !leaving {
                let (m, a, p) = (
                    mask.as_mut_slice(),
                    accumulation_m.as_mut_slice(),
                    predicted.as_mut_slice(),
                );
                for &q in &self.component {
                    m[q as usize] = 0;
                    a[q as usize] = 0.0;
                    p[q as usize] = 0;
                }
                pruned += self.component.len();
            }
        }
        pruned
    }
}

/// Separable square min (`erode`) or max filter of radius `r` over the 0/1 image `image`, in place
/// (`scratch` holds the row pass); pixels outside the image count as 0. Each pass combines the
/// image with its shifts by 1..=r pixels (rows), whole slices at a time so the compiler
/// vectorises it: O(r) per pixel, at 16+ pixels per instruction (r is 1 by default).
fn square_filter(image: &mut [u8], scratch: &mut [u8], width: usize, height: usize, r: usize, erode: bool) {
    let combine = |a: u8, b: u8| if erode { a.min(b) } else { a.max(b) };
    // Row pass: scratch[x] = op of row[x − r ..= x + r].
    for (row, out) in image.chunks_exact(width).zip(scratch.chunks_exact_mut(width)) {
        out.copy_from_slice(row);
        for k in 1..=r.min(width) {
            for (o, &v) in out[..width - k].iter_mut().zip(&row[k..]) {
                *o = combine(*o, v);
            }
            for (o, &v) in out[k..].iter_mut().zip(&row[..width - k]) {
                *o = combine(*o, v);
            }
        }
        if erode {
            // A window reaching outside the image holds a 0.
            let edge = r.min(width);
            out[..edge].fill(0);
            out[width - edge..].fill(0);
        }
    }
    // Column pass: image row y = op of scratch rows y − r ..= y + r.
    for y in 0..height {
        let out = &mut image[y * width..(y + 1) * width];
        if erode && (y < r || y + r >= height) {
            out.fill(0);
            continue;
        }
        out.copy_from_slice(&scratch[y * width..(y + 1) * width]);
        let first = y.saturating_sub(r);
        let last = (y + r).min(height - 1);
        for other in (first..=last).filter(|&other| other != y) {
            for (o, &v) in out.iter_mut().zip(&scratch[other * width..(other + 1) * width]) {
                *o = combine(*o, v);
            }
        }
    }
}

/// Reference square filter: the definition, pixel by pixel (for the agreement test).
#[cfg(test)]
fn square_filter_scalar(image: &[u8], width: usize, height: usize, r: usize, erode: bool) -> Vec<u8> {
    let mut out = vec![0; image.len()];
    for y in 0..height {
        for x in 0..width {
            let mut all = true;
            let mut any = false;
            for dy in -(r as isize)..=r as isize {
                for dx in -(r as isize)..=r as isize {
                    let (xx, yy) = (x as isize + dx, y as isize + dy);
                    let inside = xx >= 0 && yy >= 0 && xx < width as isize && yy < height as isize;
                    let v = inside && image[yy as usize * width + xx as usize] != 0;
                    all &= v;
                    any |= v;
                }
            }
            out[y * width + x] = u8::from(if erode { all } else { any });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Labels every component of `set` with `fill` and returns the labels and each component's
    /// sorted pixels.
    fn label_all(set: &[u8], size: ImageSize, scanline: bool) -> (Vec<u32>, Vec<Vec<u32>>) {
        let mut components = Components::new(size);
        for (l, &v) in components.labels.iter_mut().zip(set) {
            *l = if v != 0 { UNLABELLED } else { 0 };
        }
        let mut found = Vec::new();
        let mut id = 0;
        for seed in 0..set.len() {
            if components.labels[seed] == UNLABELLED {
                id += 1;
                if scanline {
                    components.flood(seed, id);
                } else {
                    components.flood_scalar(seed, id);
                }
                let mut pixels = components.component.clone();
                pixels.sort_unstable();
                found.push(pixels);
            }
        }
        (components.labels, found)
    }

    #[test]
    fn chunked_scans_match_the_reference_scans() {
        let mut state = 4242u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as u32
        };
        // Hits from dense to absent, lengths around the chunk size.
        for len in [0, 1, 31, 32, 33, 64, 100, 257] {
            for one_in in [1, 5, 40, 1000, u32::MAX] {
                let values: Vec<u32> = (0..len)
                    .map(|_| {
                        if next() % one_in == 0 {
                            UNLABELLED
                        } else {
                            next() % 3
                        }
                    })
                    .collect();
                for start in [0, len / 3, len] {
                    let hit = |l: u32| l == UNLABELLED;
                    assert_eq!(
                        position_chunked(&values[start..], hit),
                        values[start..].iter().position(|&l| hit(l)),
                        "len {len} one in {one_in} start {start}"
                    );
                }
            }
        }
        for len in [0, 1, 31, 32, 33, 64, 100, 257] {
            for one_in in [1, 5, 40, 1000, u32::MAX] {
                let values: Vec<u8> = (0..len)
                    .map(|_| {
                        if next() % one_in == 0 {
                            1 + (next() % 255) as u8
                        } else {
                            0
                        }
                    })
                    .collect();
                for start in [0, len / 3, len] {
                    assert_eq!(
                        position_nonzero_u8(&values[start..]),
                        values[start..].iter().position(|&v| v != 0),
                        "len {len} one in {one_in} start {start}"
                    );
                }
            }
        }
        // Seeds inside boxes: the cursor walk visits the box's unlabelled pixels in row-major order.
        let size = ImageSize::new(75, 21);
        let mut components = Components::new(size);
        for l in components.labels.iter_mut() {
            *l = if next() % 7 == 0 { UNLABELLED } else { next() % 4 };
        }
        for bounds in [
            PixelBounds {
                x0: 0,
                x1: 74,
                y0: 0,
                y1: 20,
            },
            PixelBounds {
                x0: 3,
                x1: 40,
                y0: 5,
                y1: 5,
            },
            PixelBounds {
                x0: 33,
                x1: 74,
                y0: 2,
                y1: 19,
            },
        ] {
            let expected: Vec<usize> = (bounds.y0..=bounds.y1)
                .flat_map(|y| (bounds.x0..=bounds.x1).map(move |x| y * size.width + x))
                .filter(|&i| components.labels[i] == UNLABELLED)
                .collect();
            let mut cursor = (bounds.y0, bounds.x0);
            let found: Vec<usize> =
                std::iter::from_fn(|| components.next_unlabelled(&mut cursor, bounds)).collect();
            assert!(!expected.is_empty());
            assert_eq!(found, expected, "{bounds:?}");
        }
    }

    #[test]
    fn scanline_flood_fill_matches_the_reference() {
        let size = ImageSize::new(53, 31);
        let mut state = 987654321u64;
        for density in [3u64, 4, 6] {
            let set: Vec<u8> = (0..size.area())
                .map(|_| {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    u8::from((state >> 33) % 10 < density)
                })
                .collect();
            let (fast_labels, fast_components) = label_all(&set, size, true);
            let (slow_labels, slow_components) = label_all(&set, size, false);
            assert!(slow_components.len() > 1, "density {density}");
            assert_eq!(fast_labels, slow_labels, "density {density}");
            assert_eq!(fast_components, slow_components, "density {density}");
        }
    }

    #[test]
    fn thin_structure_opening_on_the_bounding_box_matches_the_whole_image() {
        let size = ImageSize::new(61, 47);
        let mut state = 555u64;
        // A blob with noisy edges and thin strips inside [10, 50) × [5, 40).
        let set: Vec<u8> = (0..size.area())
            .map(|i| {
                let (x, y) = (i % size.width, i / size.width);
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let inside = (10..50).contains(&x) && (5..40).contains(&y);
                u8::from(inside && (state >> 33) % 10 < 7)
            })
            .collect();
        let bounding = PixelBounds {
            x0: 10,
            x1: 49,
            y0: 5,
            y1: 39,
        };
        let whole = PixelBounds {
            x0: 0,
            x1: size.width - 1,
            y0: 0,
            y1: size.height - 1,
        };
        for (radius, margin) in [(1, 0), (1, 12), (2, 3)] {
            let run = |bounds: PixelBounds| {
                let mut components = Components::new(size);
                for (l, &v) in components.labels.iter_mut().zip(&set) {
                    *l = if v != 0 { UNLABELLED } else { 0 };
                }
                let mut a = DepthMeters::filled(size, 1.0);
                let erased = components.erase_thin_structures(radius, margin, bounds, &mut a);
                (erased, components.labels, a.into_vec())
            };
            let (fast, slow) = (run(bounding), run(whole));
            assert!(slow.0 > 0, "radius {radius}");
            assert_eq!(fast, slow, "radius {radius} margin {margin}");
        }
    }

    #[test]
    fn sliding_square_filter_matches_the_definition() {
        let (width, height) = (37, 23);
        let mut state = 12345u64;
        let image: Vec<u8> = (0..width * height)
            .map(|_| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                u8::from(!(state >> 33).is_multiple_of(3))
            })
            .collect();
        for r in 0..4 {
            for erode in [true, false] {
                let mut fast = image.clone();
                let mut scratch = vec![0; image.len()];
                square_filter(&mut fast, &mut scratch, width, height, r, erode);
                assert_eq!(
                    fast,
                    square_filter_scalar(&image, width, height, r, erode),
                    "r {r} erode {erode}"
                );
            }
        }
    }
}
