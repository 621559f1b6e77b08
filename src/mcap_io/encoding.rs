//! Image encodings as enums: the `encoding` string of uncompressed images (`foxglove.RawImage`,
//! `sensor_msgs/Image`) and the `format` string of compressed ones (`foxglove.CompressedImage`,
//! `sensor_msgs/CompressedImage`) are parsed here and nowhere else, and every writer takes its
//! string from here.
//!
//! A new depth encoding is a variant here and nothing else: its names (`FromStr`, `as_str`),
//! bytes per pixel, unit scale and conversion of a row to metres are all [`DepthEncoding`]'s
//! (and [`CompressedDepthFormat`]'s when it can be compressed); the pixel decoding in
//! [`crate::mcap_io::input::decode`] only calls them. A new colour encoding is a variant here
//! and its pixel conversion there.

use std::fmt;
use std::str::FromStr;

/// An encoding string that names no encoding of the kind asked for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownEncoding(pub String);

impl fmt::Display for UnknownEncoding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "unknown image encoding {:?}", self.0)
    }
}

impl std::error::Error for UnknownEncoding {}

/// The colour filter layout of a Bayer mosaic, named by its top-left 2×2 cell in row order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BayerFilter {
    /// `bayer_rggb8`.
    Rggb,
    /// `bayer_bggr8`.
    Bggr,
    /// `bayer_gbrg8`.
    Gbrg,
    /// `bayer_grbg8`.
    Grbg,
}

/// Encodings of uncompressed colour (or grey) images.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ColorEncoding {
    /// `rgb8`: 3 bytes, red first.
    Rgb8,
    /// `bgr8` (also read as OpenCV's `8UC3`): 3 bytes, blue first.
    Bgr8,
    /// `rgba8`: 4 bytes, red first.
    Rgba8,
    /// `bgra8` (also read as `8UC4`): 4 bytes, blue first.
    Bgra8,
    /// `mono8` (also read as `8UC1`): one grey byte; also the encoding of masks.
    Mono8,
    /// Packed 4:2:2 `uyvy` (also read as `yuv422`, `UYVY`): U Y0 V Y1.
    Uyvy,
    /// Packed 4:2:2 `yuyv` (also read as `yuv422_yuy2`, `YUYV`): Y0 U Y1 V.
    Yuyv,
    /// An 8-bit Bayer mosaic (`bayer_rggb8`, ...).
    Bayer8(BayerFilter),
}

impl ColorEncoding {
    /// The string written for this encoding (ROS and Foxglove spell them the same).
    pub const fn as_str(self) -> &'static str {
        match self {
            ColorEncoding::Rgb8 => "rgb8",
            ColorEncoding::Bgr8 => "bgr8",
            ColorEncoding::Rgba8 => "rgba8",
            ColorEncoding::Bgra8 => "bgra8",
            ColorEncoding::Mono8 => "mono8",
            ColorEncoding::Uyvy => "uyvy",
            ColorEncoding::Yuyv => "yuyv",
            ColorEncoding::Bayer8(BayerFilter::Rggb) => "bayer_rggb8",
            ColorEncoding::Bayer8(BayerFilter::Bggr) => "bayer_bggr8",
            ColorEncoding::Bayer8(BayerFilter::Gbrg) => "bayer_gbrg8",
            ColorEncoding::Bayer8(BayerFilter::Grbg) => "bayer_grbg8",
        }
    }

    /// Bytes per pixel of a row (packed 4:2:2 averages two per pixel).
    pub const fn bytes_per_pixel(self) -> usize {
        match self {
            ColorEncoding::Rgb8 | ColorEncoding::Bgr8 => 3,
            ColorEncoding::Rgba8 | ColorEncoding::Bgra8 => 4,
            ColorEncoding::Mono8 | ColorEncoding::Bayer8(_) => 1,
            ColorEncoding::Uyvy | ColorEncoding::Yuyv => 2,
        }
    }
}

impl FromStr for ColorEncoding {
    type Err = UnknownEncoding;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(match s {
            "rgb8" => ColorEncoding::Rgb8,
            "bgr8" | "8UC3" => ColorEncoding::Bgr8,
            "rgba8" => ColorEncoding::Rgba8,
            "bgra8" | "8UC4" => ColorEncoding::Bgra8,
            "mono8" | "8UC1" => ColorEncoding::Mono8,
            "yuv422" | "uyvy" | "UYVY" => ColorEncoding::Uyvy,
            "yuv422_yuy2" | "yuyv" | "YUYV" => ColorEncoding::Yuyv,
            "bayer_rggb8" => ColorEncoding::Bayer8(BayerFilter::Rggb),
            "bayer_bggr8" => ColorEncoding::Bayer8(BayerFilter::Bggr),
            "bayer_gbrg8" => ColorEncoding::Bayer8(BayerFilter::Gbrg),
            "bayer_grbg8" => ColorEncoding::Bayer8(BayerFilter::Grbg),
            other => return Err(UnknownEncoding(other.to_owned())),
        })
    }
}

impl fmt::Display for ColorEncoding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Encodings of uncompressed depth images.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DepthEncoding {
    /// `16UC1` (also read as `mono16`): unsigned 16-bit sensor units, 0 = no measurement.
    U16,
    /// `32FC1`: 32-bit float metres; NaN, ±inf and values ≤ 0 are no measurement.
    F32,
}

impl DepthEncoding {
    /// The string written for this encoding.
    pub const fn as_str(self) -> &'static str {
        match self {
            DepthEncoding::U16 => "16UC1",
            DepthEncoding::F32 => "32FC1",
        }
    }

    /// Bytes per pixel.
    pub const fn bytes_per_pixel(self) -> usize {
        match self {
            DepthEncoding::U16 => 2,
            DepthEncoding::F32 => 4,
        }
    }

    /// Metres per stored unit: `1 / units_per_meter` for sensor units (in f32, as
    /// `image_buf::depth_m_from_u16_into` computes it, so depth decoded from MCAP equals depth
    /// read from dataset files bit for bit); 1 for encodings in metres, which ignore it.
    pub fn metres_per_unit(self, units_per_meter: f64) -> f32 {
        match self {
            DepthEncoding::U16 => 1.0 / units_per_meter as f32,
            DepthEncoding::F32 => 1.0,
        }
    }

    /// Converts rows of raw pixels to metres (0 = no measurement). Each item is one image row
    /// of [`Self::bytes_per_pixel`] bytes a pixel, in the byte order `big_endian` gives, and its
    /// output row; `metres_per_unit` comes from [`Self::metres_per_unit`]. The encoding and
    /// byte order are matched once for all rows, so the pixel loops have no branch on them.
    pub fn metres_from_rows<'a>(
        self,
        rows: impl Iterator<Item = (&'a [u8], &'a mut [f32])>,
        big_endian: bool,
        metres_per_unit: f32,
    ) {
        match (self, big_endian) {
            (DepthEncoding::U16, false) => {
                convert_rows(rows, |b| f32::from(u16::from_le_bytes(b)) * metres_per_unit)
            }
            (DepthEncoding::U16, true) => {
                convert_rows(rows, |b| f32::from(u16::from_be_bytes(b)) * metres_per_unit)
            }
            (DepthEncoding::F32, false) => convert_rows(rows, |b| measured_or_zero(f32::from_le_bytes(b))),
            (DepthEncoding::F32, true) => convert_rows(rows, |b| measured_or_zero(f32::from_be_bytes(b))),
        }
    }
}

/// Writes `metres(pixel)` for every `N`-byte pixel of each row into its output row.
#[inline(always)]
fn convert_rows<'a, const N: usize>(
    rows: impl Iterator<Item = (&'a [u8], &'a mut [f32])>,
    metres: impl Fn([u8; N]) -> f32,
) {
    for (row, out) in rows {
        let (pixels, _) = row.as_chunks::<N>();
        for (o, px) in out.iter_mut().zip(pixels) {
            *o = metres(*px);
        }
    }
}

/// A depth in metres, or 0 (no measurement) for NaN, ±inf and values ≤ 0.
#[inline(always)]
fn measured_or_zero(metres: f32) -> f32 {
    if metres.is_finite() && metres > 0.0 {
        metres
    } else {
        0.0
    }
}

impl FromStr for DepthEncoding {
    type Err = UnknownEncoding;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "16UC1" | "mono16" => Ok(DepthEncoding::U16),
            "32FC1" => Ok(DepthEncoding::F32),
            other => Err(UnknownEncoding(other.to_owned())),
        }
    }
}

impl fmt::Display for DepthEncoding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// How `compressed_depth_image_transport` compressed a depth image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DepthCodec {
    /// A 16-bit PNG (the default; also a format that names no codec).
    Png,
    /// Run-length / variable-length coding (`rvl`).
    Rvl,
}

/// A `compressedDepth` format string: `"<encoding>; compressedDepth [png|rvl]"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CompressedDepthFormat {
    /// The depth's own encoding: [`DepthEncoding::U16`] raw units or [`DepthEncoding::F32`]
    /// metres, stored as quantised inverse depth.
    pub depth: DepthEncoding,
    /// The compression.
    pub codec: DepthCodec,
}

/// The marker of depth formats in a `CompressedImage.format`.
const COMPRESSED_DEPTH: &str = "compressedDepth";

impl CompressedDepthFormat {
    /// True when `format` claims to be compressed depth (whether or not it is supported).
    pub fn is_compressed_depth(format: &str) -> bool {
        format.contains(COMPRESSED_DEPTH)
    }

    /// Converts the decoded 16-bit values of a compressed depth image to metres (0 = no
    /// measurement). [`DepthEncoding::U16`] values are sensor units, scaled by
    /// `metres_per_unit` ([`DepthEncoding::metres_per_unit`]); [`DepthEncoding::F32`] is stored
    /// as quantised inverse depth q: depth = a / (q − b), q = 0 invalid, with `[a, b]` =
    /// `inverse_depth_params`, the two floats of the compressed image's header.
    pub fn metres_from_values(
        self,
        values: &[u16],
        inverse_depth_params: [f32; 2],
        metres_per_unit: f32,
        out: &mut [f32],
    ) {
        match self.depth {
            DepthEncoding::U16 => {
                for (o, v) in out.iter_mut().zip(values) {
                    *o = f32::from(*v) * metres_per_unit;
                }
            }
            DepthEncoding::F32 => {
                let [a, b] = inverse_depth_params;
                for (o, v) in out.iter_mut().zip(values) {
                    let d = if *v == 0 { 0.0 } else { a / (f32::from(*v) - b) };
                    *o = measured_or_zero(d);
                }
            }
        }
    }
}

impl FromStr for CompressedDepthFormat {
    type Err = UnknownEncoding;

    fn from_str(format: &str) -> Result<Self, Self::Err> {
        let depth = if format.starts_with(DepthEncoding::U16.as_str()) {
            DepthEncoding::U16
        } else if format.starts_with(DepthEncoding::F32.as_str()) {
            DepthEncoding::F32
        } else {
            return Err(UnknownEncoding(format.to_owned()));
        };
        if !Self::is_compressed_depth(format) {
            return Err(UnknownEncoding(format.to_owned()));
        }
        let codec = if format.contains("compressedDepth rvl") {
            DepthCodec::Rvl
        } else {
            DepthCodec::Png
        };
        Ok(Self { depth, codec })
    }
}

/// The container format of a compressed colour image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColorFormat {
    /// PNG (`\x89PNG\r\n\x1a\n`).
    Png,
    /// JPEG (`FF D8 FF`).
    Jpeg,
}

impl ColorFormat {
    /// The `CompressedImage.format` string Foxglove expects.
    pub const fn as_str(self) -> &'static str {
        match self {
            ColorFormat::Png => "png",
            ColorFormat::Jpeg => "jpeg",
        }
    }

    /// Recognises the format from the first bytes of a file; `None` for anything else.
    pub fn from_magic(bytes: &[u8]) -> Option<Self> {
        if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
            Some(ColorFormat::Png)
        } else if bytes.starts_with(&[0xFF, 0xD8, 0xFF]) {
            Some(ColorFormat::Jpeg)
        } else {
            None
        }
    }

    /// Parses a `CompressedImage.format` string exactly (`png`, `jpeg`, `jpg`;
    /// case-insensitive).
    pub fn parse(format: &str) -> Option<Self> {
        match format.to_ascii_lowercase().as_str() {
            "png" => Some(ColorFormat::Png),
            "jpeg" | "jpg" => Some(ColorFormat::Jpeg),
            _ => None,
        }
    }

    /// The format a recorder's `CompressedImage.format` names, read leniently as ROS image
    /// transports write it (`rgb8; jpeg compressed bgr8`, `PNG`, ...): any mention of png,
    /// else of jpeg or jpg, case-insensitive.
    pub fn from_transport_format(format: &str) -> Option<Self> {
        let lower = format.to_ascii_lowercase();
        if lower.contains("png") {
            Some(ColorFormat::Png)
        } else if lower.contains("jpeg") || lower.contains("jpg") {
            Some(ColorFormat::Jpeg)
        } else {
            None
        }
    }

    /// The `image` crate's format, for decoding.
    pub fn image_format(self) -> image::ImageFormat {
        match self {
            ColorFormat::Png => image::ImageFormat::Png,
            ColorFormat::Jpeg => image::ImageFormat::Jpeg,
        }
    }
}

/// Colour encodings accepted by `input::decode::gray_from_image_into`.
pub const SUPPORTED_COLOR_ENCODINGS: &str = "rgb8, bgr8, rgba8, bgra8, mono8/8UC1, yuv422/uyvy, \
    yuv422_yuy2/yuyv, bayer_rggb8/bggr8/gbrg8/grbg8, PNG, JPEG";
/// Depth encodings accepted by `input::decode::depth_from_image_into`.
pub const SUPPORTED_DEPTH_ENCODINGS: &str = "16UC1/mono16 (raw units), 32FC1 (metres), \
    compressedDepth png or rvl (16UC1 raw units, 32FC1 inverse-depth quantised)";

#[cfg(test)]
mod tests {
    use super::*;

    const COLOR: [ColorEncoding; 11] = [
        ColorEncoding::Rgb8,
        ColorEncoding::Bgr8,
        ColorEncoding::Rgba8,
        ColorEncoding::Bgra8,
        ColorEncoding::Mono8,
        ColorEncoding::Uyvy,
        ColorEncoding::Yuyv,
        ColorEncoding::Bayer8(BayerFilter::Rggb),
        ColorEncoding::Bayer8(BayerFilter::Bggr),
        ColorEncoding::Bayer8(BayerFilter::Gbrg),
        ColorEncoding::Bayer8(BayerFilter::Grbg),
    ];

    #[test]
    fn every_encoding_parses_back_from_its_string() {
        for e in COLOR {
            assert_eq!(e.as_str().parse::<ColorEncoding>(), Ok(e));
        }
        for e in [DepthEncoding::U16, DepthEncoding::F32] {
            assert_eq!(e.as_str().parse::<DepthEncoding>(), Ok(e));
        }
    }

    #[test]
    fn aliases_and_unknown_names() {
        for (alias, e) in [
            ("8UC3", ColorEncoding::Bgr8),
            ("8UC4", ColorEncoding::Bgra8),
            ("8UC1", ColorEncoding::Mono8),
            ("yuv422", ColorEncoding::Uyvy),
            ("UYVY", ColorEncoding::Uyvy),
            ("yuv422_yuy2", ColorEncoding::Yuyv),
            ("YUYV", ColorEncoding::Yuyv),
        ] {
            assert_eq!(alias.parse::<ColorEncoding>(), Ok(e), "{alias}");
        }
        assert_eq!("mono16".parse::<DepthEncoding>(), Ok(DepthEncoding::U16));
        for unknown in ["nv12", "bayer_rggb16", "RGB8", ""] {
            assert!(unknown.parse::<ColorEncoding>().is_err(), "{unknown}");
        }
        // Depth and colour names do not overlap: an image is one or the other.
        for e in COLOR {
            assert!(e.as_str().parse::<DepthEncoding>().is_err(), "{e}");
        }
        assert!("8UC1".parse::<DepthEncoding>().is_err());
    }

    #[test]
    fn compressed_depth_formats() {
        let parse = |s: &str| s.parse::<CompressedDepthFormat>().ok();
        let f = |depth, codec| Some(CompressedDepthFormat { depth, codec });
        assert_eq!(
            parse("16UC1; compressedDepth png"),
            f(DepthEncoding::U16, DepthCodec::Png)
        );
        assert_eq!(
            parse("16UC1; compressedDepth"),
            f(DepthEncoding::U16, DepthCodec::Png)
        );
        assert_eq!(
            parse("32FC1; compressedDepth rvl"),
            f(DepthEncoding::F32, DepthCodec::Rvl)
        );
        assert_eq!(parse("16UC1"), None);
        assert_eq!(parse("8UC1; compressedDepth png"), None);
        assert!(CompressedDepthFormat::is_compressed_depth(
            "8UC1; compressedDepth png"
        ));
        assert!(!CompressedDepthFormat::is_compressed_depth("png"));
    }

    #[test]
    fn depth_rows_become_metres_in_either_byte_order() {
        let convert = |e: DepthEncoding, rows: &[Vec<u8>], big_endian: bool| {
            let mut out = vec![vec![-1.0f32; 2]; rows.len()];
            let scale = e.metres_per_unit(1000.0);
            e.metres_from_rows(
                rows.iter()
                    .map(Vec::as_slice)
                    .zip(out.iter_mut().map(Vec::as_mut_slice)),
                big_endian,
                scale,
            );
            out
        };
        let u16_rows = |f: fn(u16) -> [u8; 2]| vec![[f(1500), f(0)].concat(), [f(65535), f(1)].concat()];
        // The same f32 product as dataset depth (`image_buf::depth_m_from_u16_into`).
        let m = |units: u16| f32::from(units) * (1.0 / 1000.0f32);
        let expected = vec![vec![m(1500), 0.0], vec![m(65535), m(1)]];
        assert_eq!(
            convert(DepthEncoding::U16, &u16_rows(u16::to_le_bytes), false),
            expected
        );
        assert_eq!(
            convert(DepthEncoding::U16, &u16_rows(u16::to_be_bytes), true),
            expected
        );
        let f32_rows = |f: fn(f32) -> [u8; 4]| {
            vec![
                [f(1.25), f(f32::NAN)].concat(),
                [f(-2.0), f(f32::INFINITY)].concat(),
            ]
        };
        let expected = vec![vec![1.25, 0.0], vec![0.0, 0.0]];
        assert_eq!(
            convert(DepthEncoding::F32, &f32_rows(f32::to_le_bytes), false),
            expected
        );
        assert_eq!(
            convert(DepthEncoding::F32, &f32_rows(f32::to_be_bytes), true),
            expected
        );
        assert_eq!(DepthEncoding::F32.metres_per_unit(1000.0), 1.0);
    }

    #[test]
    fn compressed_depth_values_become_metres() {
        let format = |depth| CompressedDepthFormat {
            depth,
            codec: DepthCodec::Png,
        };
        let mut out = [0.0f32; 3];
        format(DepthEncoding::U16).metres_from_values(&[5000, 0, 1], [0.0; 2], 1.0 / 5000.0, &mut out);
        assert_eq!(out, [1.0, 0.0, 1.0 / 5000.0]);
        // Inverse depth a / (q − b); q = 0 and negative depths are no measurement.
        format(DepthEncoding::F32).metres_from_values(&[0, 4, 1], [6.0, 2.0], 1.0, &mut out);
        assert_eq!(out, [0.0, 3.0, 0.0]);
    }

    #[test]
    fn compressed_colour_formats() {
        assert_eq!(ColorFormat::parse("JPG"), Some(ColorFormat::Jpeg));
        assert_eq!(ColorFormat::parse("rgb8; jpeg compressed bgr8"), None);
        assert_eq!(
            ColorFormat::from_transport_format("rgb8; jpeg compressed bgr8"),
            Some(ColorFormat::Jpeg)
        );
        assert_eq!(ColorFormat::from_transport_format("PNG"), Some(ColorFormat::Png));
        assert_eq!(ColorFormat::from_transport_format("webp"), None);
        for f in [ColorFormat::Png, ColorFormat::Jpeg] {
            assert_eq!(ColorFormat::parse(f.as_str()), Some(f));
        }
    }
}
