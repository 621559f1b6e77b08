//! Row-major image buffers shared by every layer.
//!
//! `Image<T>` is a plain `width × height` row-major buffer (no padding, no channels
//! dimension: multi-channel pixels are arrays such as `[u8; 3]`). Pixel (x, y) is column x,
//! row y, 0-based, stored at `y * width + x` (docs/method.md, "Conventions").

use std::fmt;

use crate::error::{Error, Result};

/// Width and height of an image in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct ImageSize {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
}

impl ImageSize {
    /// A size of `width × height`.
    pub const fn new(width: usize, height: usize) -> Self {
        Self { width, height }
    }

    /// Number of pixels.
    pub const fn area(self) -> usize {
        self.width * self.height
    }
}

impl fmt::Display for ImageSize {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}x{}", self.width, self.height)
    }
}

/// A row-major image of `T` pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct Image<T> {
    size: ImageSize,
    data: Vec<T>,
}

/// Gray intensity in [0, 1].
pub type GrayF32 = Image<f32>;
/// Depth in metres; 0.0 means "no measurement".
pub type DepthMeters = Image<f32>;
/// A binary mask: 0 = not set, [`MASK_SET`] = set (directly usable as `mono8`).
pub type Mask = Image<u8>;
/// 8-bit RGB colour.
pub type Rgb8 = Image<[u8; 3]>;

/// Value of a set pixel in a [`Mask`] (255, so a mask is a viewable `mono8` image).
pub const MASK_SET: u8 = 255;

/// The 4-neighbours of pixel `index` (row-major) inside a `width` × `height` grid.
pub(crate) fn neighbours_4(index: usize, width: usize, height: usize) -> impl Iterator<Item = usize> {
    let (x, y) = (index % width, index / width);
    [
        (x > 0).then(|| index - 1),
        (x + 1 < width).then_some(index + 1),
        (y > 0).then(|| index - width),
        (y + 1 < height).then_some(index + width),
    ]
    .into_iter()
    .flatten()
}

/// The 8 neighbours of a pixel as (dx, dy), row by row.
pub(crate) const NEIGHBOURS_8: [(isize, isize); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

impl<T: Copy> Image<T> {
    /// An image of `size` filled with `value`.
    pub fn filled(size: ImageSize, value: T) -> Self {
        Self {
            size,
            data: vec![value; size.area()],
        }
    }

    /// Wraps a row-major buffer.
    ///
    /// # Errors
    /// [`Error::BufferLength`] when `data.len() != size.area()`.
    pub fn from_vec(size: ImageSize, data: Vec<T>) -> Result<Self> {
        if data.len() != size.area() {
            return Err(Error::BufferLength {
                expected: size.area(),
                found: data.len(),
                size,
            });
        }
        Ok(Self { size, data })
    }

    /// Builds an image by calling `f(x, y)` for every pixel.
    pub fn from_fn(size: ImageSize, mut f: impl FnMut(usize, usize) -> T) -> Self {
        let mut data = Vec::with_capacity(size.area());
        for y in 0..size.height {
            for x in 0..size.width {
                data.push(f(x, y));
            }
        }
        Self { size, data }
    }

    /// The image size.
    #[inline]
    pub fn size(&self) -> ImageSize {
        self.size
    }

    /// Columns.
    #[inline]
    pub fn width(&self) -> usize {
        self.size.width
    }

    /// Rows.
    #[inline]
    pub fn height(&self) -> usize {
        self.size.height
    }

    /// The pixel at column `x`, row `y`. Panics when out of bounds (a bug, not bad input).
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> T {
        self.data[y * self.size.width + x]
    }

    /// Sets the pixel at column `x`, row `y`.
    #[inline]
    pub fn set(&mut self, x: usize, y: usize, value: T) {
        self.data[y * self.size.width + x] = value;
    }

    /// The whole buffer, row-major.
    #[inline]
    pub fn as_slice(&self) -> &[T] {
        &self.data
    }

    /// The whole buffer, row-major, mutable.
    #[inline]
    pub fn as_mut_slice(&mut self) -> &mut [T] {
        &mut self.data
    }

    /// Row `y`.
    #[inline]
    pub fn row(&self, y: usize) -> &[T] {
        let w = self.size.width;
        &self.data[y * w..(y + 1) * w]
    }

    /// Row `y`, mutable.
    #[inline]
    pub fn row_mut(&mut self, y: usize) -> &mut [T] {
        let w = self.size.width;
        &mut self.data[y * w..(y + 1) * w]
    }

    /// Sets every pixel to `value`.
    pub fn fill(&mut self, value: T) {
        self.data.fill(value);
    }

    /// Copies `other` into `self` (sizes must match).
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when the sizes differ.
    pub fn copy_from(&mut self, other: &Image<T>) -> Result<()> {
        if other.size != self.size {
            return Err(Error::SizeMismatch {
                what: "copy_from".into(),
                expected: self.size,
                found: other.size,
            });
        }
        self.data.copy_from_slice(&other.data);
        Ok(())
    }

    /// Consumes the image and returns its buffer.
    pub fn into_vec(self) -> Vec<T> {
        self.data
    }
}

/// Luma weights of ITU-R BT.601 (what Matlab's `rgb2gray`, and so the authors' release, uses).
pub const LUMA_WEIGHTS_BT601: [f32; 3] = [0.2989, 0.5870, 0.1140];

/// Writes the gray intensity in [0, 1] of `rgb` into `gray` (caller-owned, same size).
///
/// # Errors
/// [`Error::SizeMismatch`] when the sizes differ.
pub fn gray_from_rgb8_into(rgb: &Rgb8, gray: &mut GrayF32) -> Result<()> {
    if rgb.size() != gray.size() {
        return Err(Error::SizeMismatch {
            what: "gray_from_rgb8_into".into(),
            expected: rgb.size(),
            found: gray.size(),
        });
    }
    write_gray(rgb.as_slice(), gray.as_mut_slice());
    Ok(())
}

/// Allocating wrapper of [`gray_from_rgb8_into`].
pub fn gray_from_rgb8(rgb: &Rgb8) -> GrayF32 {
    let mut gray = GrayF32::filled(rgb.size(), 0.0);
    write_gray(rgb.as_slice(), gray.as_mut_slice());
    gray
}

fn write_gray(rgb: &[[u8; 3]], gray: &mut [f32]) {
    let [wr, wg, wb] = LUMA_WEIGHTS_BT601.map(|w| w / 255.0);
    for (g, p) in gray.iter_mut().zip(rgb) {
        *g = wr * f32::from(p[0]) + wg * f32::from(p[1]) + wb * f32::from(p[2]);
    }
}

/// Writes depth in metres (`raw / units_per_meter`, 0 stays 0 = invalid) into `depth_m`.
///
/// # Errors
/// [`Error::BufferLength`] when `raw.len()` differs from the image area.
pub fn depth_m_from_u16_into(raw: &[u16], units_per_meter: f32, depth_m: &mut DepthMeters) -> Result<()> {
    if raw.len() != depth_m.size().area() {
        return Err(Error::BufferLength {
            expected: depth_m.size().area(),
            found: raw.len(),
            size: depth_m.size(),
        });
    }
    let scale = 1.0 / units_per_meter;
    for (d, &r) in depth_m.as_mut_slice().iter_mut().zip(raw) {
        *d = f32::from(r) * scale;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn from_vec_checks_length() {
        let size = ImageSize::new(3, 2);
        assert!(Image::from_vec(size, vec![0u8; 6]).is_ok());
        let err = Image::from_vec(size, vec![0u8; 5]).unwrap_err();
        assert_eq!(err.to_string(), "image buffer has 5 elements, expected 6 for 3x2");
    }

    #[test]
    fn row_major_indexing() {
        let img = Image::from_fn(ImageSize::new(4, 3), |x, y| (10 * y + x) as u32);
        assert_eq!(img.get(3, 2), 23);
        assert_eq!(img.row(1), &[10, 11, 12, 13]);
    }

    #[test]
    fn gray_of_white_is_one_and_into_matches_allocating() {
        let rgb = Image::from_fn(ImageSize::new(5, 4), |x, y| [(x * 50) as u8, (y * 60) as u8, 255]);
        let a = gray_from_rgb8(&rgb);
        let mut b = GrayF32::filled(rgb.size(), -1.0);
        gray_from_rgb8_into(&rgb, &mut b).unwrap();
        assert_eq!(a, b);
        let white = gray_from_rgb8(&Image::filled(ImageSize::new(1, 1), [255, 255, 255]));
        assert!((white.get(0, 0) - 0.9999).abs() < 1e-3);
    }

    #[test]
    fn depth_conversion_keeps_zero_invalid() {
        let mut d = DepthMeters::filled(ImageSize::new(2, 1), 9.0);
        depth_m_from_u16_into(&[0, 5000], 5000.0, &mut d).unwrap();
        assert_eq!(d.as_slice(), &[0.0, 1.0]);
    }
}
