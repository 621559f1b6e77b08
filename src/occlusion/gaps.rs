//! Closing the mask across pixels without depth.
//!
//! The detector judges a pixel by its depth; where the sensor gives none (and the previous
//! frame's warped depth does not fill it), the pixel stays unmarked even inside an object. Two
//! cases show in every recording: the band of invalid depth that structured-light sensors leave
//! along the image border (10–30 px at VGA on TUM and Bonn), so that a person entering the view
//! is masked only from the band's inner edge on; and holes on dark or shiny parts of an object
//! (hair, black clothing). [`InvalidDepthGaps::fill`] marks a run of such pixels along a row or
//! a column when mask pixels bound it on both sides, or a mask pixel on one side and the image
//! border on the other, and it is at most `max_gap_px` long. Pixels with depth are never added,
//! so the fill cannot reach a surface the detector saw as static.

use crate::error::{Error, Result};
use crate::image_buf::{DepthMeters, ImageSize, Mask, MASK_SET};
use crate::simd::{simd_kernel, Simd};

/// [`Self::fill`]'s scratch, allocated once for an image size.
#[derive(Debug, Clone)]
pub struct InvalidDepthGaps {
    max_gap_px: usize,
    /// The pixels to add (0 / [`MASK_SET`]): both directions are judged on the mask as given.
    added: Mask,
    /// Per column: the row where its open run of unmarked pixels without depth started
    /// (`usize::MAX`: none), and what bounds the run from above (`None`: the top border).
    run_start: Vec<usize>,
    bounded_above: Vec<Option<bool>>,
    /// Per column: 1 while it has an open run (`run_start` set), as bytes that a row's scan
    /// skips 32 columns at a time.
    in_column_run: Vec<u8>,
    /// The open pixels of the current row (1 = unmarked without depth).
    open: Vec<u8>,
}

impl InvalidDepthGaps {
    /// Scratch for masks of `size`, filling runs of at most `max_gap_px` (0: none).
    pub fn new(size: ImageSize, max_gap_px: usize) -> Self {
        Self {
            max_gap_px,
            added: Mask::filled(size, 0),
            run_start: vec![usize::MAX; size.width],
            bounded_above: vec![None; size.width],
            in_column_run: vec![0; size.width],
            open: vec![0; size.width],
        }
    }

    /// Marks in `mask` every run of pixels without depth in `depth_m` (≤ 0 or NaN) along a row
    /// or a column that is at most `max_gap_px` long and bounded at both ends by a marked pixel
    /// or the image border, with at least one marked end (see the module docs). Both directions
    /// are judged on the mask as given. Returns the pixels added; allocates nothing.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when the mask or `depth_m` is not the scratch's size.
    pub fn fill(&mut self, mask: &mut Mask, depth_m: &DepthMeters) -> Result<usize> {
        let size = self.added.size();
        for (what, found) in [
            ("invalid-depth gap fill mask", mask.size()),
            ("invalid-depth gap fill depth", depth_m.size()),
        ] {
            if found != size {
                return Err(Error::SizeMismatch {
                    what: what.into(),
                    expected: size,
                    found,
                });
            }
        }
        let (w, h, max_gap_px) = (size.width, size.height, self.max_gap_px);
        if max_gap_px == 0 || w == 0 || h == 0 {
            return Ok(0);
        }
        let depth = depth_m.as_slice();
        let m = mask.as_slice();
        let set = |i: usize| m[i] != 0;
        // A filled run touches a marked pixel in its own row or column, so only the rows of the
        // marked pixels, and up to `max_gap_px` rows around them, can gain any: the passes stay
        // within `rows` (+1 above, whose pixel decides what bounds a column's run there).
        let marked_row = |row: &[u8]| row.iter().any(|&v| v != 0);
        let Some(first) = m.chunks_exact(w).position(marked_row) else {
            return Ok(0);
        };
        let last = h - 1 - m.chunks_exact(w).rev().position(marked_row).unwrap_or(0);
        let rows = first.saturating_sub(max_gap_px + 1)..(last + max_gap_px + 1).min(h);
        let added = &mut self.added.as_mut_slice()[rows.start * w..rows.end * w];
        added.fill(0);
        let added_at = |i: usize| i - rows.start * w;
        // One row at a time: its open pixels, then its row runs (only on rows with a marked
        // pixel) and the column runs it starts, continues or ends. One row past the range
        // closes the column runs there: a run that continues beyond it is longer than
        // `max_gap_px`, as is one that began above it.
        self.run_start.fill(usize::MAX);
        self.in_column_run.fill(0);
        let simd = Simd::detect();
        for y in rows.start..=rows.end {
            let row = y * w;
            let open = &mut self.open[..];
            if y < rows.end {
                open_pixels(simd, &m[row..row + w], &depth[row..row + w], open);
            } else {
                open.fill(0);
            }
            if (first..=last).contains(&y) {
                let mut x = 0;
                while let Some(offset) = open[x..].iter().position(|&o| o != 0) {
                    let start = x + offset;
                    x = open[start..]
                        .iter()
                        .position(|&o| o == 0)
                        .map_or(w, |n| start + n);
                    let before = (start > 0).then(|| set(row + start - 1));
                    let after = (x < w).then(|| set(row + x));
                    if bounded(before, after) && x - start <= max_gap_px {
                        added[added_at(row + start)..added_at(row + x)].fill(MASK_SET);
                    }
                }
            }
            // Only the columns with an open pixel here or an open run change.
            for (chunk, (open, in_run)) in open
                .chunks(COLUMN_CHUNK)
                .zip(self.in_column_run.chunks_mut(COLUMN_CHUNK))
                .enumerate()
            {
                let any = open
                    .iter()
                    .zip(in_run.iter())
                    .fold(0, |acc, (&o, &r)| acc | o | r);
                if any == 0 {
                    continue;
                }
                for (k, (&o, r)) in open.iter().zip(in_run.iter_mut()).enumerate() {
                    let x = chunk * COLUMN_CHUNK + k;
                    if o != 0 {
                        if *r == 0 {
                            *r = 1;
                            self.run_start[x] = y;
                            self.bounded_above[x] = (y > 0).then(|| set(row - w + x));
                        }
                        continue;
                    }
                    if *r == 0 {
                        continue;
                    }
                    *r = 0;
                    let start = std::mem::replace(&mut self.run_start[x], usize::MAX);
                    let below = (y < h).then(|| set(row + x));
                    if bounded(self.bounded_above[x], below) && y - start <= max_gap_px {
                        for yy in start..y {
                            added[added_at(yy * w + x)] = MASK_SET;
                        }
                    }
                }
            }
        }
        let mut count = 0;
        let in_rows = &mut mask.as_mut_slice()[rows.start * w..rows.end * w];
        for (m, &a) in in_rows.iter_mut().zip(added.iter()) {
            count += usize::from(a != 0);
            *m |= a;
        }
        Ok(count)
    }
}

/// Columns a row's column pass skips at once when none of them is open or in a run.
const COLUMN_CHUNK: usize = 32;

/// `open[x]` = 1 where the row's pixel is unmarked and has no depth (≤ 0 or NaN), else 0.
#[inline(always)]
fn open_pixels_generic(mask_row: &[u8], depth_row: &[f32], open: &mut [u8]) {
    for ((o, &m), &z) in open.iter_mut().zip(mask_row).zip(depth_row) {
        *o = u8::from((m == 0) & (z.is_nan() | (z <= 0.0)));
    }
}

simd_kernel!(
    open_pixels,
    open_pixels_avx2,
    open_pixels_generic,
    (mask_row: &[u8], depth_row: &[f32], open: &mut [u8])
);

/// A run is filled when each end is a marked pixel (`Some(true)`) or the border (`None`), and
/// at least one end is marked.
fn bounded(before: Option<bool>, after: Option<bool>) -> bool {
    match (before, after) {
        (Some(a), Some(b)) => a && b,
        (None, Some(b)) => b,
        (Some(a), None) => a,
        (None, None) => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mask and a depth image from rows of characters: `#` marked with depth, `o` marked
    /// without depth, `.` unmarked with depth, `_` unmarked without depth.
    fn scene(rows: &[&str]) -> (Mask, DepthMeters) {
        let size = ImageSize::new(rows[0].len(), rows.len());
        let mut mask = Mask::filled(size, 0);
        let mut depth = DepthMeters::filled(size, 1.0);
        for (y, row) in rows.iter().enumerate() {
            for (x, c) in row.chars().enumerate() {
                let i = y * size.width + x;
                if matches!(c, '#' | 'o') {
                    mask.as_mut_slice()[i] = MASK_SET;
                }
                if matches!(c, 'o' | '_') {
                    depth.as_mut_slice()[i] = 0.0;
                }
            }
        }
        (mask, depth)
    }

    fn fill(mask: &mut Mask, depth: &DepthMeters, max_gap_px: usize) -> Result<usize> {
        InvalidDepthGaps::new(mask.size(), max_gap_px).fill(mask, depth)
    }

    /// Every build flags the unmarked pixels without depth (≤ 0 or NaN), as a per-pixel loop.
    #[test]
    fn every_build_of_the_open_pixels_agrees_with_a_per_pixel_loop() {
        let values = [0.0, -0.5, f32::NAN, 1.0, f32::INFINITY, 2.5, -0.0];
        let depth: Vec<f32> = (0..1001).map(|i| values[i % values.len()]).collect();
        let mask: Vec<u8> = (0..1001).map(|i| if i % 3 == 0 { MASK_SET } else { 0 }).collect();
        let expected: Vec<u8> = mask
            .iter()
            .zip(&depth)
            .map(|(&m, &z)| u8::from(m == 0 && (z.is_nan() || z <= 0.0)))
            .collect();
        assert!(expected.iter().filter(|&&o| o != 0).count() > 200);
        for simd in Simd::available() {
            let mut open = vec![9u8; depth.len()];
            open_pixels(simd, &mask, &depth, &mut open);
            assert_eq!(open, expected, "{simd:?}");
        }
    }

    fn render(mask: &Mask) -> Vec<String> {
        mask.as_slice()
            .chunks(mask.width())
            .map(|r| r.iter().map(|&m| if m != 0 { '#' } else { '.' }).collect())
            .collect()
    }

    #[test]
    fn border_band_next_to_an_object_is_filled_up_to_the_limit() {
        let (mut mask, depth) = scene(&[
            "__##....", //
            "___#....", "____#...", "__......",
        ]);
        let added = fill(&mut mask, &depth, 3).unwrap();
        // Row 2's run of 4 is longer than 3; row 3's run has no marked end.
        assert_eq!(render(&mask), ["####....", "####....", "....#...", "........"]);
        assert_eq!(added, 5);
    }

    #[test]
    fn holes_inside_an_object_are_filled_in_both_directions_but_never_pixels_with_depth() {
        let (mut mask, depth) = scene(&[
            ".#.#.", //
            "#___#", ".#_#.", "..#..",
        ]);
        fill(&mut mask, &depth, 3).unwrap();
        // Row 1's run is bounded by marks; column 2's run (rows 1–2) by the marks above and below.
        assert_eq!(render(&mask), [".#.#.", "#####", ".###.", "..#.."]);
        let (mut mask, depth) = scene(&[".#.", "#.#", ".#."]);
        assert_eq!(fill(&mut mask, &depth, 3).unwrap(), 0);
    }

    #[test]
    fn runs_between_an_object_and_the_background_stay_unmarked() {
        let (mut mask, depth) = scene(&[
            "#__.", //
            "____", "..#_",
        ]);
        // Row 0's run ends at a pixel with depth, column 0's too, row 1's touches both borders:
        // unmarked. Row 2's run reaches the border from a mark and column 2's (rows 0–1) the
        // top border from one: filled.
        fill(&mut mask, &depth, 4).unwrap();
        assert_eq!(render(&mask), ["#.#.", "..#.", "..##"]);
    }

    /// The fill by its definition, pixel by pixel: each open pixel's maximal row and column run.
    fn fill_reference(mask: &Mask, depth: &DepthMeters, max_gap_px: usize) -> Mask {
        let (w, h) = (mask.width(), mask.height());
        let set = |x: usize, y: usize| mask.as_slice()[y * w + x] != 0;
        let open = |x: usize, y: usize| {
            !set(x, y) && depth.as_slice()[y * w + x].partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
        };
        let mut out = mask.clone();
        for y in 0..h {
            for x in 0..w {
                if !open(x, y) {
                    continue;
                }
                let (mut a, mut b) = (x, x);
                while a > 0 && open(a - 1, y) {
                    a -= 1;
                }
                while b + 1 < w && open(b + 1, y) {
                    b += 1;
                }
                let row = bounded((a > 0).then(|| set(a - 1, y)), (b + 1 < w).then(|| set(b + 1, y)))
                    && b - a < max_gap_px;
                let (mut a, mut b) = (y, y);
                while a > 0 && open(x, a - 1) {
                    a -= 1;
                }
                while b + 1 < h && open(x, b + 1) {
                    b += 1;
                }
                let column = bounded((a > 0).then(|| set(x, a - 1)), (b + 1 < h).then(|| set(x, b + 1)))
                    && b - a < max_gap_px;
                if row || column {
                    out.as_mut_slice()[y * w + x] = MASK_SET;
                }
            }
        }
        out
    }

    #[test]
    fn agrees_with_the_definition_on_random_scenes() {
        // Wider than two of the column pass's chunks, the last one partial.
        let size = ImageSize::new(71, 31);
        let mut rng = crate::xorshift::XorShift64::new(0x2545_f491_4f6c_dd1d);
        let mut next = || rng.next_u64();
        let mut filled = 0;
        for scene in 0..200 {
            let mut mask = Mask::filled(size, 0);
            let mut depth = DepthMeters::filled(size, 1.0);
            // A marked block somewhere (or none), invalid depth in blocks and speckle.
            if scene % 10 != 0 {
                let (x0, y0) = (next() as usize % 68, next() as usize % 28);
                for y in y0..(y0 + 1 + next() as usize % 8).min(size.height) {
                    for x in x0..(x0 + 1 + next() as usize % 8).min(size.width) {
                        mask.as_mut_slice()[y * size.width + x] = MASK_SET;
                    }
                }
            }
            for (i, z) in depth.as_mut_slice().iter_mut().enumerate() {
                let (x, y) = (i % size.width, i / size.width);
                if x < 3 || y + 2 >= size.height || next() % 4 == 0 {
                    *z = if next() % 2 == 0 { 0.0 } else { f32::NAN };
                }
            }
            let max_gap_px = 1 + scene % 6;
            let expected = fill_reference(&mask, &depth, max_gap_px);
            let mut scratch = InvalidDepthGaps::new(size, max_gap_px);
            let added = scratch.fill(&mut mask, &depth).unwrap();
            assert_eq!(render(&mask), render(&expected), "scene {scene}");
            filled += added;
        }
        // 376 pixels added over the 200 scenes.
        assert!(filled > 250, "the scenes must exercise the fill: {filled}");
    }

    #[test]
    fn no_limit_no_fill_and_a_size_mismatch_is_an_error() {
        let (mut mask, depth) = scene(&["_#"]);
        assert_eq!(fill(&mut mask, &depth, 0).unwrap(), 0);
        assert_eq!(render(&mask), [".#"]);
        let other = DepthMeters::filled(ImageSize::new(3, 1), 1.0);
        assert!(matches!(
            InvalidDepthGaps::new(mask.size(), 2).fill(&mut mask, &other),
            Err(Error::SizeMismatch { .. })
        ));
    }
}
