//! Putting depth and colour into one pinhole camera before odometry and detection (pure: no
//! files, no MCAP): lens undistortion by remap tables, depth registration from another camera
//! by z-buffered reprojection, and the way back for masks.
//!
//! Everything is built once per sequence as a table; applying it per frame is a table walk.
//!
//! - [`BilinearMap`]: each output pixel samples the source bilinearly (grey images);
//! - [`NearestMap`]: each output pixel copies one source pixel or is left at the default value
//!   (depth aligned to a distorted colour image, masks mapped back to the published pixels):
//!   depth is never interpolated, so no value is invented across a depth edge;
//! - [`DepthRegistration`]: every depth pixel is lifted to 3D with its own depth, moved into
//!   the colour camera (`color_from_depth`) and splatted over the colour pixels its footprint
//!   covers, the nearest surface winning (z-buffer). Colour pixels no depth pixel covers stay
//!   invalid (0): holes are never filled by interpolation.
//!
//! Every optimised kernel has a scalar reference (`*_reference`) and a test that they agree.

use nalgebra::{Isometry3, Point3};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geometry::camera::PinholeIntrinsics;
use crate::geometry::distortion::CameraModel;
use crate::image_buf::{DepthMeters, GrayF32, Image, ImageSize};

mod depth;

pub use depth::DepthRegistration;

/// Output rows per rayon task: a 640-px row of a remap costs ≈ 1–2 µs, so 16 rows amortise
/// the task overhead and still leave 30 tasks per VGA frame.
const ROWS_PER_TASK: usize = 16;

/// Marks a [`NearestMap`] entry with no source pixel.
const NO_SOURCE: u32 = u32::MAX;

/// Largest image a table indexes: pixel indices are `u32`.
const MAX_TABLE_PIXELS: usize = u32::MAX as usize - 1;

fn check_table_size(what: &str, size: ImageSize) -> Result<()> {
    if size.width < 2 || size.height < 2 || size.area() > MAX_TABLE_PIXELS {
        return Err(Error::InvalidParameter {
            name: "image size",
            value: format!("{size} ({what})"),
            expected: format!("at least 2x2 and at most {MAX_TABLE_PIXELS} pixels"),
        });
    }
    Ok(())
}

fn check_sizes(what: &str, expected: ImageSize, found: ImageSize) -> Result<()> {
    if expected != found {
        return Err(Error::SizeMismatch {
            what: what.into(),
            expected,
            found,
        });
    }
    Ok(())
}

/// A source position `(x, y)` in pixels is inside the source image's area (pixel centres at
/// integers, so the area reaches half a pixel beyond the outer centres).
fn inside(size: ImageSize, x: f64, y: f64) -> bool {
    x >= -0.5 && y >= -0.5 && x <= size.width as f64 - 0.5 && y <= size.height as f64 - 0.5
}

/// One output pixel of a [`BilinearMap`]: the top-left source pixel of the 2×2 neighbourhood
/// and the weights of its right and lower neighbours.
#[derive(Debug, Clone, Copy, PartialEq)]
struct BilinearEntry {
    top_left: u32,
    wx: f32,
    wy: f32,
}

/// Bilinear resampling table: output pixel (u, v) takes the source value at a fixed position.
/// Positions outside the source are clamped to its border, so the output has no holes; the
/// table remembers those pixels ([`Self::clear_outside`]) so depth there can be invalidated.
#[derive(Debug, Clone, PartialEq)]
pub struct BilinearMap {
    source_size: ImageSize,
    output_size: ImageSize,
    entries: Vec<BilinearEntry>,
    /// Output pixels whose position lies outside the source image (or has none).
    outside: Vec<u32>,
}

impl BilinearMap {
    /// The table of `source_at(u, v)`, the source position (pixels) of output pixel (u, v);
    /// `None` or a non-finite position reads the source's centre and counts as outside.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for images smaller than 2×2 or too large to index.
    pub fn from_fn(
        source_size: ImageSize,
        output_size: ImageSize,
        source_at: impl Fn(f64, f64) -> Option<(f64, f64)> + Sync,
    ) -> Result<Self> {
        check_table_size("remap source", source_size)?;
        check_table_size("remap output", output_size)?;
        let (w, h) = (source_size.width, source_size.height);
        let entry = |u: usize, v: usize| {
            let position = source_at(u as f64, v as f64).filter(|(x, y)| x.is_finite() && y.is_finite());
            let is_inside = position.is_some_and(|(x, y)| inside(source_size, x, y));
            let (x, y) = position.unwrap_or(((w as f64 - 1.0) * 0.5, (h as f64 - 1.0) * 0.5));
            let x = x.clamp(0.0, w as f64 - 1.0);
            let y = y.clamp(0.0, h as f64 - 1.0);
            let ix = (x.floor() as usize).min(w - 2);
            let iy = (y.floor() as usize).min(h - 2);
            let entry = BilinearEntry {
                top_left: (iy * w + ix) as u32,
                wx: (x - ix as f64) as f32,
                wy: (y - iy as f64) as f32,
            };
            (entry, is_inside)
        };
        let (entries, is_inside): (Vec<_>, Vec<_>) = table(output_size, entry).into_iter().unzip();
        let outside = (0..is_inside.len() as u32)
            .filter(|&i| !is_inside[i as usize])
            .collect();
        Ok(Self {
            source_size,
            output_size,
            entries,
            outside,
        })
    }

    /// Sets `value` at every output pixel whose position lay outside the source image (e.g.
    /// 0 in the depth that goes with a remapped grey image: the grey value there is only the
    /// clamped border).
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when `image` does not have the output size.
    pub fn clear_outside<T: Copy>(&self, image: &mut Image<T>, value: T) -> Result<()> {
        check_sizes("remap output", self.output_size, image.size())?;
        let data = image.as_mut_slice();
        for &i in &self.outside {
            data[i as usize] = value;
        }
        Ok(())
    }

    /// Fraction of output pixels whose position lies inside the source image.
    pub fn covered_fraction(&self) -> f64 {
        1.0 - self.outside.len() as f64 / self.entries.len().max(1) as f64
    }

    /// Size of the images the table reads.
    pub fn source_size(&self) -> ImageSize {
        self.source_size
    }

    /// Size of the images the table writes.
    pub fn output_size(&self) -> ImageSize {
        self.output_size
    }

    /// Resamples `source` into `output` (caller-owned), row-parallel.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when an image does not have the table's size.
    pub fn apply_into(&self, source: &GrayF32, output: &mut GrayF32) -> Result<()> {
        self.check(source, output)?;
        let (src, w) = (source.as_slice(), self.source_size.width);
        let ow = self.output_size.width;
        output
            .as_mut_slice()
            .par_chunks_mut(ow * ROWS_PER_TASK)
            .zip(self.entries.par_chunks(ow * ROWS_PER_TASK))
            .for_each(|(out, entries)| {
                for (o, e) in out.iter_mut().zip(entries) {
                    *o = bilinear(src, w, e);
                }
            });
        Ok(())
    }

    /// [`Self::apply_into`] on the calling thread (its scalar reference, and the kernel for
    /// threads outside a rayon pool, which would otherwise hand the work to the global pool).
    ///
    /// # Errors
    /// As [`Self::apply_into`].
    pub fn apply_serial(&self, source: &GrayF32, output: &mut GrayF32) -> Result<()> {
        self.check(source, output)?;
        for (o, e) in output.as_mut_slice().iter_mut().zip(&self.entries) {
            *o = bilinear(source.as_slice(), self.source_size.width, e);
        }
        Ok(())
    }

    /// Resamples depth (m, 0 = invalid) into `output`: bilinear between neighbours on one
    /// surface ([`MAX_INTERPOLATED_DEPTH_STEP`]), else the nearest neighbour; positions
    /// outside the source are 0. Row-parallel.
    ///
    /// # Errors
    /// As [`Self::apply_into`].
    pub fn apply_depth_into(&self, source: &DepthMeters, output: &mut DepthMeters) -> Result<()> {
        self.check(source, output)?;
        let (src, w) = (source.as_slice(), self.source_size.width);
        let ow = self.output_size.width;
        output
            .as_mut_slice()
            .par_chunks_mut(ow * ROWS_PER_TASK)
            .zip(self.entries.par_chunks(ow * ROWS_PER_TASK))
            .for_each(|(out, entries)| {
                for (o, e) in out.iter_mut().zip(entries) {
                    *o = depth_bilinear(src, w, e);
                }
            });
        self.clear_outside(output, 0.0)
    }

    /// [`Self::apply_depth_into`] on the calling thread (its scalar reference, and the kernel
    /// for threads outside a rayon pool).
    ///
    /// # Errors
    /// As [`Self::apply_into`].
    pub fn apply_depth_serial(&self, source: &DepthMeters, output: &mut DepthMeters) -> Result<()> {
        self.check(source, output)?;
        for (o, e) in output.as_mut_slice().iter_mut().zip(&self.entries) {
            *o = depth_bilinear(source.as_slice(), self.source_size.width, e);
        }
        self.clear_outside(output, 0.0)
    }

    fn check(&self, source: &GrayF32, output: &GrayF32) -> Result<()> {
        check_sizes("remap source", self.source_size, source.size())?;
        check_sizes("remap output", self.output_size, output.size())
    }
}

/// Depths of the four neighbours of a resampling position are interpolated when they differ by
/// at most this fraction of the nearest: one surface (a floor seen at 75° from its normal at
/// 5 m changes by 3 % per VGA pixel; Kinect-class noise is below 1 % at 4 m), while the
/// silhouette of one object against another is a larger step. Across a larger step the
/// nearest neighbour is taken, so no depth between two surfaces is invented.
pub const MAX_INTERPOLATED_DEPTH_STEP: f32 = 0.05;

/// Depth at a resampling position: bilinear on one surface, else the nearest neighbour
/// (which may be a hole, 0).
#[inline]
fn depth_bilinear(src: &[f32], width: usize, e: &BilinearEntry) -> f32 {
    let i = e.top_left as usize;
    let (a, b) = (src[i], src[i + 1]);
    let (c, d) = (src[i + width], src[i + width + 1]);
    let lo = a.min(b).min(c).min(d);
    let hi = a.max(b).max(c).max(d);
    if lo > 0.0 && hi <= lo * (1.0 + MAX_INTERPOLATED_DEPTH_STEP) {
        let top = a + (b - a) * e.wx;
        let bottom = c + (d - c) * e.wx;
        top + (bottom - top) * e.wy
    } else {
        src[i + usize::from(e.wx >= 0.5) + usize::from(e.wy >= 0.5) * width]
    }
}

#[inline]
fn bilinear(src: &[f32], width: usize, e: &BilinearEntry) -> f32 {
    let i = e.top_left as usize;
    let (a, b) = (src[i], src[i + 1]);
    let (c, d) = (src[i + width], src[i + width + 1]);
    let top = a + (b - a) * e.wx;
    let bottom = c + (d - c) * e.wx;
    top + (bottom - top) * e.wy
}

/// Builds a per-output-pixel table row-parallel.
fn table<E: Send>(size: ImageSize, entry: impl Fn(usize, usize) -> E + Sync) -> Vec<E> {
    (0..size.height)
        .into_par_iter()
        .flat_map_iter(|v| (0..size.width).map(move |u| (u, v)))
        .map(|(u, v)| entry(u, v))
        .collect()
}

/// Nearest-pixel table: output pixel (u, v) copies one source pixel, or is set to
/// `T::default()` (0: invalid depth, not moving) where no source pixel maps to it.
#[derive(Debug, Clone, PartialEq)]
pub struct NearestMap {
    source_size: ImageSize,
    output_size: ImageSize,
    source_index: Vec<u32>,
}

impl NearestMap {
    /// The table of `source_at(u, v)` (source position in pixels, rounded to the nearest
    /// pixel); `None` or a position outside the source image leaves the output pixel empty.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for images smaller than 2×2 or too large to index.
    pub fn from_fn(
        source_size: ImageSize,
        output_size: ImageSize,
        source_at: impl Fn(f64, f64) -> Option<(f64, f64)> + Sync,
    ) -> Result<Self> {
        check_table_size("remap source", source_size)?;
        check_table_size("remap output", output_size)?;
        let w = source_size.width;
        let entry = |u: usize, v: usize| match source_at(u as f64, v as f64) {
            Some((x, y)) if inside(source_size, x, y) => {
                // Inside the area, so rounding lands on a pixel (the clamp only catches the
                // outer half-pixel edge, which rounds to w or h).
                let ix = (x.round().max(0.0) as usize).min(w - 1);
                let iy = (y.round().max(0.0) as usize).min(source_size.height - 1);
                (iy * w + ix) as u32
            }
            _ => NO_SOURCE,
        };
        Ok(Self {
            source_size,
            output_size,
            source_index: table(output_size, entry),
        })
    }

    /// Size of the images the table reads.
    pub fn source_size(&self) -> ImageSize {
        self.source_size
    }

    /// Size of the images the table writes.
    pub fn output_size(&self) -> ImageSize {
        self.output_size
    }

    /// Fraction of output pixels that have a source pixel.
    pub fn covered_fraction(&self) -> f64 {
        let covered = self.source_index.iter().filter(|&&i| i != NO_SOURCE).count();
        covered as f64 / self.source_index.len().max(1) as f64
    }

    /// Copies `source` into `output` (caller-owned) through the table, row-parallel.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when an image does not have the table's size.
    pub fn apply_into<T: Copy + Default + Send + Sync>(
        &self,
        source: &Image<T>,
        output: &mut Image<T>,
    ) -> Result<()> {
        self.check(source.size(), output.size())?;
        let src = source.as_slice();
        let ow = self.output_size.width;
        output
            .as_mut_slice()
            .par_chunks_mut(ow * ROWS_PER_TASK)
            .zip(self.source_index.par_chunks(ow * ROWS_PER_TASK))
            .for_each(|(out, index)| {
                for (o, &i) in out.iter_mut().zip(index) {
                    *o = nearest(src, i);
                }
            });
        Ok(())
    }

    /// [`Self::apply_into`] on the calling thread (its scalar reference, and the kernel for
    /// threads outside a rayon pool).
    ///
    /// # Errors
    /// As [`Self::apply_into`].
    pub fn apply_serial<T: Copy + Default>(&self, source: &Image<T>, output: &mut Image<T>) -> Result<()> {
        self.check(source.size(), output.size())?;
        for (o, &i) in output.as_mut_slice().iter_mut().zip(&self.source_index) {
            *o = nearest(source.as_slice(), i);
        }
        Ok(())
    }

    fn check(&self, source: ImageSize, output: ImageSize) -> Result<()> {
        check_sizes("remap source", self.source_size, source)?;
        check_sizes("remap output", self.output_size, output)
    }
}

#[inline]
fn nearest<T: Copy + Default>(src: &[T], index: u32) -> T {
    if index == NO_SOURCE {
        T::default()
    } else {
        src[index as usize]
    }
}

/// Largest focal-length scale [`inscribed_pinhole`] considers: a lens whose undistorted image
/// would have to be magnified more than this to leave no pixel without data keeps its K (and
/// the pixels without data are marked).
const MAX_INSCRIBED_SCALE: f64 = 2.0;
/// Bisection steps of [`inscribed_pinhole`]: 2^-30 of the scale range, far below a pixel.
const INSCRIBED_SCALE_STEPS: usize = 30;

/// The pinhole camera to undistort `camera` into: its size, principal point and the smallest
/// focal lengths at or above its own (the same factor for x and y) for which every pixel
/// sees a ray the distorted image recorded (OpenCV's `getOptimalNewCameraMatrix` with
/// α = 0, the principal point kept). Lenses whose pinhole image with the same K lies inside
/// the recorded one (barrel distortion) keep K. With K itself the corners of a Kinect's
/// pinhole image (TUM freiburg1: 5 % of the pixels) would only hold the clamped image border,
/// and odometry near that edge drifts (measured: ATE +60 % on synthetic sequences).
///
/// Only the image border is checked: radial distortion moves points monotonically, so the
/// border's pixels reach farthest out.
pub fn inscribed_pinhole(camera: &CameraModel) -> CameraModel {
    let pinhole = camera.undistorted();
    if camera.distortion.is_none() {
        return pinhole;
    }
    let (w, h) = (camera.size.width, camera.size.height);
    let k = camera.intrinsics;
    let fits = |scale: f64| {
        let border = (0..w)
            .flat_map(|u| [(u, 0), (u, h - 1)])
            .chain((0..h).flat_map(|v| [(0, v), (w - 1, v)]));
        border.into_iter().all(|(u, v)| {
            let (x, y) = camera.pixel(
                (u as f64 - k.cx) / (scale * k.fx),
                (v as f64 - k.cy) / (scale * k.fy),
            );
            inside(camera.size, x, y)
        })
    };
    if fits(1.0) || !fits(MAX_INSCRIBED_SCALE) {
        return pinhole;
    }
    let (mut lo, mut hi) = (1.0, MAX_INSCRIBED_SCALE);
    for _ in 0..INSCRIBED_SCALE_STEPS {
        let mid = 0.5 * (lo + hi);
        if fits(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    CameraModel::pinhole(
        camera.size,
        PinholeIntrinsics::new(k.fx * hi, k.fy * hi, k.cx, k.cy),
    )
}

/// The table that undistorts an image of `camera` into the pinhole camera `pinhole` (its
/// size and K; e.g. [`inscribed_pinhole`]): [`BilinearMap::apply_into`] for grey,
/// [`BilinearMap::apply_depth_into`] for depth registered to the distorted pixels.
///
/// # Errors
/// As [`BilinearMap::from_fn`].
pub fn undistortion_map(camera: &CameraModel, pinhole: &CameraModel) -> Result<BilinearMap> {
    let k = pinhole.intrinsics;
    BilinearMap::from_fn(camera.size, pinhole.size, |u, v| {
        Some(camera.pixel((u - k.cx) / k.fx, (v - k.cy) / k.fy))
    })
}

/// The table that maps an image of the pinhole camera `pinhole` back to the pixels of
/// `camera` (masks computed on undistorted images, published on the original ones).
///
/// # Errors
/// As [`NearestMap::from_fn`].
pub fn distortion_map(camera: &CameraModel, pinhole: &CameraModel) -> Result<NearestMap> {
    NearestMap::from_fn(pinhole.size, camera.size, |u, v| {
        camera.ray(u, v).map(|(x, y)| pinhole.pixel(x, y))
    })
}

#[cfg(test)]
mod tests;
