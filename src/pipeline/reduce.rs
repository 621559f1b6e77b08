//! Frames halved for processing at a lower resolution and results enlarged back: the offline
//! first pass's reduced frames ([`super::offline`]) and the working resolution of a whole
//! sequence ([`super::sequence`]).

use super::FrameInput;
use crate::error::Result;
use crate::image_buf::{DepthMeters, GrayF32, Image, ImageSize, Mask};
use crate::pyramid::{downsample_depth_into, downsample_gray_into, level_size};

/// How many times `size` can be halved (at most `at_most`) while its short side keeps at least
/// `min_side_px` pixels.
pub(crate) fn halvings_keeping_side(size: ImageSize, min_side_px: usize, at_most: usize) -> usize {
    (0..at_most)
        .take_while(|&k| {
            let next = level_size(size, k + 1);
            next.width.min(next.height) >= min_side_px
        })
        .count()
}

/// Scratch of a reduced frame: each halving's gray and depth.
pub(crate) struct Reduced {
    gray: Vec<GrayF32>,
    depth_m: Vec<DepthMeters>,
}

impl Reduced {
    /// `None` for 0 halvings.
    pub(crate) fn new(size: ImageSize, halvings: usize) -> Option<Self> {
        let sizes = || (1..=halvings).map(|k| level_size(size, k));
        (halvings > 0).then(|| Self {
            gray: sizes().map(|s| GrayF32::filled(s, 0.0)).collect(),
            depth_m: sizes().map(|s| DepthMeters::filled(s, 0.0)).collect(),
        })
    }

    /// `gray` halved by 2×2 box means and `depth_m` by edge-aware 2×2 reductions.
    ///
    /// # Errors
    /// [`crate::Error::SizeMismatch`] when the images are not of the size given to [`Self::new`].
    pub(crate) fn reduce<'a>(
        &'a mut self,
        gray: &'a GrayF32,
        depth_m: &'a DepthMeters,
    ) -> Result<(&'a GrayF32, &'a DepthMeters)> {
        for k in 0..self.depth_m.len() {
            let (done, rest) = self.gray.split_at_mut(k);
            downsample_gray_into(done.last().unwrap_or(gray), &mut rest[0])?;
            let (done, rest) = self.depth_m.split_at_mut(k);
            downsample_depth_into(done.last().unwrap_or(depth_m), &mut rest[0])?;
        }
        Ok(self.last().unwrap_or((gray, depth_m)))
    }

    /// The images of the last [`Self::reduce`] (of the size it reduces to).
    fn last(&self) -> Option<(&GrayF32, &DepthMeters)> {
        self.gray.last().zip(self.depth_m.last())
    }
}

/// A whole frame reduced to a working resolution: [`Reduced`] for its images, and its ignore
/// mask by [`reduce_mask_max`]. [`Self::reduce`] computes, [`Self::view`] reads the result (so
/// that a caller can reduce in one place and read in another).
pub(crate) struct FrameReduction {
    images: Reduced,
    ignore_in_previous: Mask,
}

impl FrameReduction {
    /// `None` for 0 halvings.
    pub(crate) fn new(size: ImageSize, halvings: usize) -> Option<Self> {
        Reduced::new(size, halvings).map(|images| Self {
            images,
            ignore_in_previous: Mask::filled(level_size(size, halvings), 0),
        })
    }

    /// The working resolution.
    pub(crate) fn size(&self) -> ImageSize {
        self.ignore_in_previous.size()
    }

    /// Reduces `frame`'s images and ignore mask.
    ///
    /// # Errors
    /// [`crate::Error::SizeMismatch`] when the images are not of the size given to [`Self::new`].
    pub(crate) fn reduce(&mut self, frame: &FrameInput<'_>) -> Result<()> {
        self.images.reduce(frame.gray, frame.depth_m)?;
        if let Some(full) = frame.ignore_in_previous {
            reduce_mask_max(full, &mut self.ignore_in_previous);
        }
        Ok(())
    }

    /// `frame` as the last [`Self::reduce`] of it left it.
    pub(crate) fn view<'a>(&'a self, frame: &FrameInput<'a>) -> FrameInput<'a> {
        let (gray, depth_m) = self.images.last().unwrap_or((frame.gray, frame.depth_m));
        FrameInput {
            gray,
            depth_m,
            ignore_in_previous: frame.ignore_in_previous.map(|_| &self.ignore_in_previous),
            ..*frame
        }
    }
}

/// `image` into `full`: copied at the same size, else enlarged by the nearest pixel from the
/// image halved some number of times; rows and columns beyond the reduced image's cover (odd
/// sides) take its last ones. Each reduced row is widened once and the full rows it covers
/// after the first are copies of that one (tested against the per-pixel
/// [`copy_or_enlarge_reference`]).
pub(crate) fn copy_or_enlarge<T: Copy + Default>(image: &Image<T>, full: &mut Image<T>) {
    if image.size() == full.size() {
        full.as_mut_slice().copy_from_slice(image.as_slice());
        return;
    }
    let (rw, rh) = (image.width(), image.height());
    let fw = full.width();
    if rw == 0 || rh == 0 || fw == 0 {
        full.fill(T::default());
        return;
    }
    let halvings = (fw / rw).max(1).ilog2();
    let factor = 1usize << halvings;
    let covered = (rw * factor).min(fw);
    let src = image.as_slice();
    let out = full.as_mut_slice();
    let mut previous_ry = None;
    for y in 0..out.len() / fw {
        let ry = (y >> halvings).min(rh - 1);
        let (done, rest) = out.split_at_mut(y * fw);
        let row = &mut rest[..fw];
        if previous_ry == Some(ry) {
            row.copy_from_slice(&done[(y - 1) * fw..]);
            continue;
        }
        let src_row = &src[ry * rw..(ry + 1) * rw];
        widen_row(src_row, &mut row[..covered], factor);
        row[covered..].fill(src_row[rw - 1]);
        previous_ry = Some(ry);
    }
}

/// `src` with each pixel repeated `factor` times into `out` (`src.len() × factor` pixels). The
/// common factor 2 is a plain pair loop: a `fill` per block is a `memset` call per pixel, which
/// cost more than the rest of emitting a frame.
fn widen_row<T: Copy>(src: &[T], out: &mut [T], factor: usize) {
    debug_assert_eq!(out.len(), src.len() * factor);
    if factor == 2 {
        for (pair, &v) in out.chunks_exact_mut(2).zip(src) {
            pair[0] = v;
            pair[1] = v;
        }
        return;
    }
    for (block, &v) in out.chunks_exact_mut(factor).zip(src) {
        for o in block {
            *o = v;
        }
    }
}

/// The per-pixel definition of [`copy_or_enlarge`]'s enlargement.
#[cfg(test)]
fn copy_or_enlarge_reference<T: Copy + Default>(image: &Image<T>, full: &mut Image<T>) {
    let (rw, rh) = (image.width(), image.height());
    let fw = full.width();
    let halvings = (fw / rw).max(1).ilog2();
    let src = image.as_slice();
    for (y, row) in full.as_mut_slice().chunks_exact_mut(fw).enumerate() {
        let ry = (y >> halvings).min(rh - 1);
        let src_row = &src[ry * rw..(ry + 1) * rw];
        for (x, m) in row.iter_mut().enumerate() {
            *m = src_row[(x >> halvings).min(rw - 1)];
        }
    }
}

/// `full` reduced into `reduced` (`full` halved some number of times): a reduced pixel is the
/// largest of the full pixels it covers (a mask keeps every marked pixel); the rows and columns
/// beyond the reduced image's cover (odd sides) are left out.
pub(crate) fn reduce_mask_max(full: &Mask, reduced: &mut Mask) {
    let (rw, rh) = (reduced.width(), reduced.height());
    if rw == 0 || rh == 0 {
        return;
    }
    let block = (full.width() / rw).max(1);
    reduced.fill(0);
    let rows = full.as_slice().chunks_exact(full.width()).take(rh * block);
    for (y, row) in rows.enumerate() {
        let out = reduced.row_mut(y / block);
        for (o, cover) in out.iter_mut().zip(row.chunks_exact(block)) {
            *o = cover.iter().fold(*o, |m, &v| m.max(v));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn enlarged_images_repeat_each_reduced_pixel_and_cover_odd_sides() {
        let mut reduced = Mask::filled(ImageSize::new(3, 2), 0);
        reduced.as_mut_slice().copy_from_slice(&[1, 0, 2, 0, 3, 0]);
        let mut full = Mask::filled(ImageSize::new(7, 5), 9);
        copy_or_enlarge(&reduced, &mut full);
        let expected: [[u8; 7]; 5] = [
            [1, 1, 0, 0, 2, 2, 2],
            [1, 1, 0, 0, 2, 2, 2],
            [0, 0, 3, 3, 0, 0, 0],
            [0, 0, 3, 3, 0, 0, 0],
            [0, 0, 3, 3, 0, 0, 0],
        ];
        assert_eq!(full.as_slice(), expected.concat().as_slice());
    }

    #[test]
    fn enlarging_matches_the_per_pixel_definition() {
        let mut rng = crate::xorshift::XorShift64::new(31);
        let mut checked = 0;
        for halvings in 1..=3u32 {
            for (rw, rh) in [(1, 1), (1, 5), (6, 1), (7, 4), (13, 9)] {
                let factor = 1usize << halvings;
                // The full image's odd sides: up to factor − 1 more columns and rows.
                for extra in [0, factor - 1] {
                    let reduced = DepthMeters::from_fn(ImageSize::new(rw, rh), |_, _| rng.below(1000) as f32);
                    let size = ImageSize::new(rw * factor + extra, rh * factor + extra / 2);
                    let mut fast = DepthMeters::filled(size, -1.0);
                    let mut reference = DepthMeters::filled(size, -2.0);
                    copy_or_enlarge(&reduced, &mut fast);
                    copy_or_enlarge_reference(&reduced, &mut reference);
                    assert!(fast.as_slice() == reference.as_slice(), "{rw}x{rh} into {size:?}");
                    checked += 1;
                }
            }
        }
        assert_eq!(checked, 30);
    }

    #[test]
    fn a_reduced_mask_keeps_every_marked_block_and_enlarges_back_over_it() {
        let size = ImageSize::new(9, 8);
        let mut full = Mask::filled(size, 0);
        full.set(5, 2, 255);
        full.set(0, 7, 255);
        full.set(8, 0, 255); // beyond the 4-px-block cover of a 9-px side: left out
        let mut reduced = Mask::filled(level_size(size, 2), 0);
        reduce_mask_max(&full, &mut reduced);
        assert_eq!(reduced.as_slice(), &[0, 255, 255, 0]);
        let mut back = Mask::filled(size, 0);
        copy_or_enlarge(&reduced, &mut back);
        for y in 0..8 {
            for x in 0..9 {
                if full.get(x, y) != 0 && x < 8 {
                    assert_eq!(back.get(x, y), 255, "({x}, {y})");
                }
            }
        }
    }

    #[test]
    fn halvings_stop_before_the_short_side_falls_below_the_minimum() {
        let vga = ImageSize::new(640, 480);
        assert_eq!(halvings_keeping_side(vga, 240, usize::MAX), 1);
        assert_eq!(halvings_keeping_side(vga, 241, usize::MAX), 0);
        assert_eq!(halvings_keeping_side(vga, 120, 1), 1);
        assert_eq!(
            halvings_keeping_side(ImageSize::new(1280, 720), 240, usize::MAX),
            1
        );
        assert_eq!(
            halvings_keeping_side(ImageSize::new(1920, 1080), 240, usize::MAX),
            2
        );
    }
}
