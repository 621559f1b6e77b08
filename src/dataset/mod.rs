//! RGB-D dataset readers: TUM RGB-D (and ICSL, same layout) and LARR.
//!
//! A reader turns a dataset folder into a [`Sequence`]: lists of colour and depth images
//! with integer-nanosecond timestamps, the ground-truth trajectory, optional ground-truth
//! masks, and the text files worth attaching. Images are only opened later, one frame at a
//! time ([`read_color`], [`read_depth`], [`read_mask`]), so memory stays bounded.
//!
//! Timestamp policy: every list (rgb.txt, depth.txt, groundtruth.txt, directory listings)
//! must be strictly increasing. Out-of-order or duplicate stamps are **rejected** with the
//! file and line, not sorted: they mean a concatenated or corrupted list, and sorting would
//! silently mix two recordings.

pub mod bonn;
pub mod larr;
pub mod tum;

use std::fmt;
use std::path::{Path, PathBuf};

use prost::bytes::Bytes;

use crate::error::{Error, Mismatch, Result};
use crate::geometry::camera::{presets, PinholeIntrinsics};
use crate::geometry::distortion::LensDistortion;
use crate::image_buf::{
    depth_m_from_u16_into, gray_from_rgb8, DepthMeters, GrayF32, ImageSize, Mask, Rgb8, MASK_SET,
};
use crate::mcap_io::ColorFormat;
use crate::time::format_ns_as_seconds;
use crate::trajectory::{parse_tum_line, StampedPose};

/// TUM RGB-D depth PNGs: 5000 units per metre (0.2 mm).
pub const TUM_DEPTH_UNITS_PER_METER: f64 = 5000.0;
/// LARR and ICSL depth PNGs: millimetres.
pub const MILLIMETER_DEPTH_UNITS_PER_METER: f64 = 1000.0;
/// Default largest colour-depth time gap for a pair: TUM's `associate.py` default (20 ms,
/// less than one frame period at 30 Hz).
pub const DEFAULT_MAX_PAIR_GAP_NS: u64 = 20_000_000;

/// The dataset families occmask reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DatasetKind {
    /// TUM RGB-D benchmark layout.
    Tum,
    /// ICSL sequences: TUM layout, millimetre depth, ICSL camera.
    Icsl,
    /// LARR RGB-D dataset (Kim et al.).
    Larr,
}

impl DatasetKind {
    /// Lower-case name used on the command line and in metadata.
    pub fn as_str(self) -> &'static str {
        match self {
            DatasetKind::Tum => "tum",
            DatasetKind::Icsl => "icsl",
            DatasetKind::Larr => "larr",
        }
    }

    /// Raw depth units per metre of the family's PNGs.
    pub fn default_depth_units_per_meter(self) -> f64 {
        match self {
            DatasetKind::Tum => TUM_DEPTH_UNITS_PER_METER,
            DatasetKind::Icsl | DatasetKind::Larr => MILLIMETER_DEPTH_UNITS_PER_METER,
        }
    }
}

impl fmt::Display for DatasetKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// An image file and its capture time.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ImageRef {
    /// Capture time, nanoseconds.
    pub timestamp_ns: u64,
    /// Path of the file (dataset root joined with the listed name).
    pub path: PathBuf,
}

/// A colour frame and the depth frame paired with it (indexes into [`Sequence`]'s lists).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FramePair {
    /// Index into [`Sequence::color`].
    pub color: usize,
    /// Index into [`Sequence::depth`].
    pub depth: usize,
}

/// The outcome of pairing colour with depth frames.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Association {
    /// Pairs in colour order.
    pub pairs: Vec<FramePair>,
    /// Colour frames without a depth partner.
    pub unpaired_color: Vec<usize>,
    /// Depth frames without a colour partner.
    pub unpaired_depth: Vec<usize>,
}

/// A ground-truth mask and the colour frame it belongs to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MaskRef {
    /// Index into [`Sequence::color`].
    pub color: usize,
    /// The mask file.
    pub path: PathBuf,
}

/// A dataset folder, listed but not yet loaded.
#[derive(Debug, Clone)]
pub struct Sequence {
    /// Dataset family.
    pub kind: DatasetKind,
    /// The folder.
    pub root: PathBuf,
    /// Sequence name (the folder's name).
    pub name: String,
    /// Colour images, strictly increasing in time.
    pub color: Vec<ImageRef>,
    /// Depth images, strictly increasing in time.
    pub depth: Vec<ImageRef>,
    /// Colour/depth pairing given by the dataset (LARR `association.txt`); `None` = pair by
    /// nearest time.
    pub given_pairs: Option<Vec<FramePair>>,
    /// Ground-truth moving-object masks (LARR), in colour order.
    pub masks: Vec<MaskRef>,
    /// Mask files that match no colour frame (reported, not written).
    pub unmatched_masks: Vec<PathBuf>,
    /// Ground-truth camera trajectory (`world_from_camera` of the colour optical centre).
    pub groundtruth: Vec<StampedPose>,
    /// Small text files worth attaching to the output (ground truth, lists, associations).
    pub text_files: Vec<PathBuf>,
}

impl Sequence {
    /// Pairs colour with depth: the dataset's own association when it has one, otherwise
    /// [`associate`] with `max_gap_ns`.
    pub fn association(&self, max_gap_ns: u64) -> Association {
        match &self.given_pairs {
            Some(pairs) => {
                let mut color_used = vec![false; self.color.len()];
                let mut depth_used = vec![false; self.depth.len()];
                for p in pairs {
                    color_used[p.color] = true;
                    depth_used[p.depth] = true;
                }
                Association {
                    pairs: pairs.clone(),
                    unpaired_color: (0..self.color.len()).filter(|&i| !color_used[i]).collect(),
                    unpaired_depth: (0..self.depth.len()).filter(|&i| !depth_used[i]).collect(),
                }
            }
            None => associate(&self.color, &self.depth, max_gap_ns),
        }
    }
}

/// Pairs colour and depth frames one-to-one by nearest timestamp, as TUM's `associate.py`:
/// among all candidate pairs with |Δt| ≤ `max_gap_ns`, repeatedly take the closest pair whose
/// frames are both still free (ties: earlier colour, then earlier depth). Both lists must be
/// sorted by time.
pub fn associate(color: &[ImageRef], depth: &[ImageRef], max_gap_ns: u64) -> Association {
    let mut candidates: Vec<(u64, usize, usize)> = Vec::new();
    let mut start = 0;
    for (ci, c) in color.iter().enumerate() {
        while start < depth.len() && depth[start].timestamp_ns + max_gap_ns < c.timestamp_ns {
            start += 1;
        }
        for (di, d) in depth.iter().enumerate().skip(start) {
            if d.timestamp_ns > c.timestamp_ns.saturating_add(max_gap_ns) {
                break;
            }
            candidates.push((c.timestamp_ns.abs_diff(d.timestamp_ns), ci, di));
        }
    }
    candidates.sort_unstable();
    let mut color_partner = vec![None; color.len()];
    let mut depth_used = vec![false; depth.len()];
    for (_, ci, di) in candidates {
        if color_partner[ci].is_none() && !depth_used[di] {
            color_partner[ci] = Some(di);
            depth_used[di] = true;
        }
    }
    let mut out = Association::default();
    for (ci, partner) in color_partner.iter().enumerate() {
        match partner {
            Some(di) => out.pairs.push(FramePair {
                color: ci,
                depth: *di,
            }),
            None => out.unpaired_color.push(ci),
        }
    }
    out.unpaired_depth = (0..depth.len()).filter(|&i| !depth_used[i]).collect();
    out
}

/// Smallest |Δt| between any colour and any depth frame (for "no pairs" messages).
pub fn nearest_gap_ns(color: &[ImageRef], depth: &[ImageRef]) -> Option<u64> {
    color
        .iter()
        .filter_map(|c| {
            let i = depth.partition_point(|d| d.timestamp_ns < c.timestamp_ns);
            let after = depth.get(i).map(|d| d.timestamp_ns - c.timestamp_ns);
            let before = i.checked_sub(1).map(|j| c.timestamp_ns - depth[j].timestamp_ns);
            after.into_iter().chain(before).min()
        })
        .min()
}

/// Checks that stamps increase strictly. `items` yields (timestamp, line or file label).
fn check_increasing(path: &Path, items: impl Iterator<Item = (u64, usize)>, what: &str) -> Result<()> {
    let mut previous: Option<(u64, usize)> = None;
    for (t, line) in items {
        if let Some((pt, pline)) = previous {
            if t <= pt {
                let how = if t == pt { "duplicates" } else { "is earlier than" };
                return Err(Mismatch::new(
                    format!(
                        "{what} timestamps that increase strictly (occmask rejects unsorted or \
                         duplicate stamps instead of guessing an order)"
                    ),
                    format!(
                        "{}, which {how} {} on line {pline}",
                        format_ns_as_seconds(t, 6),
                        format_ns_as_seconds(pt, 6)
                    ),
                )
                .at_line(path, line));
            }
        }
        previous = Some((t, line));
    }
    Ok(())
}

/// Reads a text file as UTF-8.
fn read_text(path: &Path) -> Result<String> {
    let text = std::fs::read(path).map_err(|e| Error::io("cannot read", path, e))?;
    String::from_utf8(text).map_err(|e| {
        let line = 1 + e.as_bytes()[..e.utf8_error().valid_up_to()]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        Mismatch::new("UTF-8 text", "invalid bytes").at_line(path, line)
    })
}

/// Lines of a text without comments (`#`) and blank lines, trimmed, with 1-based line numbers.
fn content_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

/// Reads a TUM image list (`timestamp path` per line, `#` comments); paths are relative to
/// `root`. Every listed file must exist; stamps must increase strictly.
///
/// # Errors
/// [`Error::Io`] when the file cannot be read; [`Error::Parse`] with the line for invalid
/// UTF-8, malformed lines, bad stamps, missing files or order.
pub fn read_image_list(path: &Path, root: &Path) -> Result<Vec<ImageRef>> {
    image_list(&read_text(path)?, path, root, true)
}

/// Parses the text of a TUM image list (see [`read_image_list`]) without touching the file
/// system: listed files need not exist. `source` is the path named in errors.
///
/// # Errors
/// [`Error::Parse`] with the line for malformed lines, bad stamps or order.
pub fn parse_image_list(text: &str, source: &Path, root: &Path) -> Result<Vec<ImageRef>> {
    image_list(text, source, root, false)
}

fn image_list(text: &str, source: &Path, root: &Path, require_files: bool) -> Result<Vec<ImageRef>> {
    let mut out = Vec::new();
    let mut line_numbers = Vec::new();
    for (line, text) in content_lines(text) {
        let parse_err = |mismatch: Mismatch| mismatch.at_line(source, line);
        let fields: Vec<&str> = text.split_whitespace().collect();
        if fields.len() != 2 {
            return Err(parse_err(Mismatch::new(
                "2 fields 'timestamp path'",
                format!("{} in {text:?}", fields.len()),
            )));
        }
        let timestamp_ns = crate::time::parse_seconds_to_ns(fields[0]).map_err(parse_err)?;
        let image_path = root.join(fields[1]);
        if require_files && !image_path.is_file() {
            let found = if image_path.is_dir() {
                "a directory"
            } else {
                "nothing (it does not exist)"
            };
            return Err(parse_err(Mismatch::new(
                format!("the listed image {} to be an image file", image_path.display()),
                found,
            )));
        }
        out.push(ImageRef {
            timestamp_ns,
            path: image_path,
        });
        line_numbers.push(line);
    }
    check_increasing(
        source,
        out.iter().map(|r| r.timestamp_ns).zip(line_numbers),
        "image",
    )?;
    Ok(out)
}

/// Reads a TUM trajectory (`timestamp tx ty tz qx qy qz qw`, `#` comments).
///
/// # Errors
/// [`Error::Io`] when the file cannot be read; [`Error::Parse`] with the line for invalid
/// UTF-8, malformed lines or non-increasing stamps.
pub fn read_groundtruth(path: &Path) -> Result<Vec<StampedPose>> {
    parse_groundtruth(&read_text(path)?, path)
}

/// Parses the text of a TUM trajectory (see [`read_groundtruth`]); `source` is the path named
/// in errors.
///
/// # Errors
/// [`Error::Parse`] with the line for malformed lines or non-increasing stamps.
pub fn parse_groundtruth(text: &str, source: &Path) -> Result<Vec<StampedPose>> {
    let mut poses = Vec::new();
    let mut line_numbers = Vec::new();
    for (line, text) in content_lines(text) {
        let pose = parse_tum_line(text).map_err(|mismatch| mismatch.at_line(source, line))?;
        poses.push(pose);
        line_numbers.push(line);
    }
    check_increasing(
        source,
        poses.iter().map(|p| p.timestamp_ns).zip(line_numbers),
        "ground-truth",
    )?;
    Ok(poses)
}

/// A camera given on the command line: pinhole intrinsics and, for presets and the long
/// numeric form, the lens distortion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraSpec {
    /// Pinhole intrinsics.
    pub intrinsics: PinholeIntrinsics,
    /// Lens distortion; `None` = pinhole.
    pub distortion: Option<LensDistortion>,
}

impl CameraSpec {
    const fn pinhole(intrinsics: PinholeIntrinsics) -> Self {
        Self {
            intrinsics,
            distortion: None,
        }
    }
}

/// Accepted `--camera` forms, for error messages.
const CAMERA_FORMS: &str = "fr1, fr2, fr3, icsl, larr, kinect-default, bonn, fr1-distorted, fr2-distorted, \
    FX,FY,CX,CY in pixels (e.g. 520.9,521.0,325.1,249.7), or FX,FY,CX,CY followed by the \
    plumb_bob distortion K1,K2,P1,P2[,K3] or rational_polynomial K1,K2,P1,P2,K3,K4,K5,K6";

/// Parses `--camera`: a preset name ([`camera_preset`]) or `FX,FY,CX,CY` in pixels, optionally
/// followed by distortion coefficients in ROS order (4 or 5 for `plumb_bob`, 8 for
/// `rational_polynomial`).
///
/// # Errors
/// [`Error::InvalidParameter`] naming the accepted forms.
pub fn parse_camera(text: &str) -> Result<CameraSpec> {
    if let Some(preset) = camera_preset(text) {
        return Ok(preset);
    }
    let bad = || Error::InvalidParameter {
        name: "camera",
        value: text.to_owned(),
        expected: CAMERA_FORMS.into(),
    };
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| bad())?;
    let (k, d) = values.split_at_checked(4).ok_or_else(bad)?;
    let intrinsics = PinholeIntrinsics::new(k[0], k[1], k[2], k[3]);
    if !intrinsics.is_valid() {
        return Err(bad());
    }
    let model = match d.len() {
        0 | 4 | 5 => "plumb_bob",
        8 => "rational_polynomial",
        _ => return Err(bad()),
    };
    let distortion = LensDistortion::from_ros(model, d).map_err(|_| bad())?;
    Ok(CameraSpec {
        intrinsics,
        distortion,
    })
}

/// The camera preset called `name` (case-insensitive, `freiburgN` = `frN`). `fr1` and `fr2`
/// are pinhole, as the reference implementations use TUM's images; `fr1-distorted` and
/// `fr2-distorted` add TUM's published distortion (its fr1/fr2 images are not undistorted;
/// fr3's are). `bonn` is the Bonn RGB-D Dynamic Dataset's calibration with its distortion.
pub fn camera_preset(name: &str) -> Option<CameraSpec> {
    use crate::geometry::distortion::presets as lens;
    let distorted = |intrinsics, distortion| CameraSpec {
        intrinsics,
        distortion: Some(distortion),
    };
    match name.to_ascii_lowercase().as_str() {
        "fr1" | "freiburg1" => Some(CameraSpec::pinhole(presets::TUM_FR1)),
        "fr2" | "freiburg2" => Some(CameraSpec::pinhole(presets::TUM_FR2)),
        "fr3" | "freiburg3" => Some(CameraSpec::pinhole(presets::TUM_FR3)),
        "fr1-distorted" => Some(distorted(presets::TUM_FR1, lens::TUM_FR1)),
        "fr2-distorted" => Some(distorted(presets::TUM_FR2, lens::TUM_FR2)),
        "icsl" => Some(CameraSpec::pinhole(presets::ICSL)),
        "larr" => Some(CameraSpec::pinhole(presets::LARR)),
        "bonn" => Some(distorted(presets::BONN, lens::BONN)),
        "kinect-default" | "kinect" | "default" => Some(CameraSpec::pinhole(presets::KINECT_DEFAULT)),
        _ => None,
    }
}

/// The `--camera-from-marker` preset called `name` (`bonn`), as X, Y, Z, QX, QY, QZ, QW.
/// `bonn` is [`bonn::marker_from_camera`] inverted: the rigid part of the dataset's published
/// conversion (its 6 % ground-truth scale is no rigid transform and stays out; see
/// `examples/marker_check.rs` and docs/inputs.md).
pub fn camera_from_marker_preset(name: &str) -> Option<[f64; 7]> {
    match name.to_ascii_lowercase().as_str() {
        "bonn" => {
            let camera_from_marker = bonn::marker_from_camera().inverse();
            let (t, q) = (camera_from_marker.translation.vector, camera_from_marker.rotation);
            Some([t.x, t.y, t.z, q.i, q.j, q.k, q.w])
        }
        _ => None,
    }
}

/// The TUM camera named in a folder name: `freiburgN` or an `frN` token
/// (`rgbd_dataset_freiburg2_desk`, `tum_fr2_desk_50`). Returns the preset name.
pub fn camera_from_folder_name(name: &str) -> Option<&'static str> {
    let lower = name.to_ascii_lowercase();
    for (needle, preset) in [("freiburg1", "fr1"), ("freiburg2", "fr2"), ("freiburg3", "fr3")] {
        if lower.contains(needle) {
            return Some(preset);
        }
    }
    let tokens = lower.split(|c: char| !c.is_ascii_alphanumeric());
    for token in tokens {
        match token {
            "fr1" => return Some("fr1"),
            "fr2" => return Some("fr2"),
            "fr3" => return Some("fr3"),
            _ => {}
        }
    }
    None
}

/// A compressed colour image, read but not decoded.
#[derive(Debug, Clone)]
pub struct ColorImage {
    /// The file's bytes, unchanged.
    pub bytes: Bytes,
    /// PNG or JPEG, from the magic bytes.
    pub format: ColorFormat,
    /// Size from the image header.
    pub size: ImageSize,
}

fn bad_image(path: &Path, expected: impl Into<String>, found: impl Into<String>) -> Error {
    Error::BadImage {
        path: path.to_owned(),
        expected: expected.into(),
        found: found.into(),
    }
}

/// PNG files end with an empty `IEND` chunk: length 0, type, CRC.
const PNG_TRAILER: [u8; 12] = [0, 0, 0, 0, b'I', b'E', b'N', b'D', 0xAE, 0x42, 0x60, 0x82];
/// JPEG end-of-image marker.
const JPEG_EOI: [u8; 2] = [0xFF, 0xD9];

/// Reads a colour image's bytes and checks them without decoding the pixels: PNG or JPEG
/// magic, a readable header (size), and the end marker (`IEND` / `EOI`), which catches
/// truncated files. Trailing padding after a JPEG's `EOI` (some cameras add zeros) is allowed.
///
/// # Errors
/// [`Error::Io`] if unreadable, [`Error::BadImage`] for anything else.
pub fn read_color(path: &Path) -> Result<ColorImage> {
    let bytes = std::fs::read(path).map_err(|e| Error::io("cannot read colour image", path, e))?;
    let format = ColorFormat::from_magic(&bytes)
        .ok_or_else(|| bad_image(path, "a PNG or JPEG colour image", "neither signature"))?;
    let complete = match format {
        ColorFormat::Png => bytes.ends_with(&PNG_TRAILER),
        ColorFormat::Jpeg => {
            let trimmed = bytes
                .iter()
                .rposition(|&b| b != 0)
                .map_or(&bytes[..0], |i| &bytes[..=i]);
            trimmed.ends_with(&JPEG_EOI)
        }
    };
    if !complete {
        let format = format.as_str().to_uppercase();
        return Err(bad_image(
            path,
            format!("a complete {format} colour image"),
            format!(
                "a truncated {format} colour image: the end marker is missing ({} bytes)",
                bytes.len()
            ),
        ));
    }
    let image_format = match format {
        ColorFormat::Png => image::ImageFormat::Png,
        ColorFormat::Jpeg => image::ImageFormat::Jpeg,
    };
    let (width, height) = image::ImageReader::with_format(std::io::Cursor::new(&bytes), image_format)
        .into_dimensions()
        .map_err(|e| bad_image(path, "a readable colour image header", e.to_string()))?;
    Ok(ColorImage {
        bytes: Bytes::from(bytes),
        format,
        size: ImageSize::new(width as usize, height as usize),
    })
}

/// A decoded depth image in raw sensor units.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DepthImage {
    /// Image size.
    pub size: ImageSize,
    /// Raw units, row-major; 0 = no measurement.
    pub data: Vec<u16>,
}

/// Decodes a 16-bit single-channel PNG depth image.
///
/// # Errors
/// [`Error::Io`] if unreadable; [`Error::BadImage`] for a corrupt or truncated PNG or any
/// pixel format other than 16-bit grey (8-bit depth has lost its precision; convert it
/// from the sensor's original data instead).
pub fn read_depth(path: &Path) -> Result<DepthImage> {
    let bytes = std::fs::read(path).map_err(|e| Error::io("cannot read depth image", path, e))?;
    if ColorFormat::from_magic(&bytes) != Some(ColorFormat::Png) {
        return Err(bad_image(path, "a 16-bit PNG depth image", "no PNG signature"));
    }
    let image = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png).map_err(|e| {
        bad_image(
            path,
            "a 16-bit PNG depth image",
            format!("a corrupt or truncated depth PNG: {e}"),
        )
    })?;
    let size = ImageSize::new(image.width() as usize, image.height() as usize);
    match image {
        image::DynamicImage::ImageLuma16(buffer) => Ok(DepthImage {
            size,
            data: buffer.into_raw(),
        }),
        other => Err(bad_image(
            path,
            "a 16-bit single-channel depth PNG",
            format!(
                "{:?}{}",
                other.color(),
                if other.color().bytes_per_pixel() == 1 {
                    " (8-bit depth cannot hold sensor depth; use the original 16-bit PNGs)"
                } else {
                    ""
                }
            ),
        )),
    }
}

/// A colour/depth pair of a dataset decoded for the pipeline.
#[derive(Debug, Clone)]
pub struct DecodedPair {
    /// The colour image's time (the frame's time).
    pub timestamp_ns: u64,
    /// The depth image's time.
    pub depth_timestamp_ns: u64,
    /// Gray in [0, 1] (BT.601 luma of the colour image).
    pub gray: GrayF32,
    /// Depth in metres, 0 = no measurement.
    pub depth_m: DepthMeters,
}

/// Decodes pair `pair` of `sequence` (colour PNG/JPEG to gray, 16-bit depth PNG to metres
/// with `depth_units_per_meter`).
///
/// # Errors
/// [`Error::Io`] / [`Error::BadImage`] for unreadable images, [`Error::SizeMismatch`] when
/// colour and depth differ in size.
pub fn decode_pair(sequence: &Sequence, pair: &FramePair, depth_units_per_meter: f64) -> Result<DecodedPair> {
    let color = &sequence.color[pair.color];
    let depth = &sequence.depth[pair.depth];
    let bytes =
        std::fs::read(&color.path).map_err(|e| Error::io("cannot read colour image", &color.path, e))?;
    let rgb = image::load_from_memory(&bytes)
        .map_err(|e| bad_image(&color.path, "a decodable colour image", e.to_string()))?
        .to_rgb8();
    let size = ImageSize::new(rgb.width() as usize, rgb.height() as usize);
    let rgb = Rgb8::from_vec(size, rgb.pixels().map(|p| p.0).collect())?;
    let raw = read_depth(&depth.path)?;
    if raw.size != size {
        return Err(Error::SizeMismatch {
            what: format!(
                "depth {} vs colour {}",
                depth.path.display(),
                color.path.display()
            ),
            expected: size,
            found: raw.size,
        });
    }
    let mut depth_m = DepthMeters::filled(size, 0.0);
    depth_m_from_u16_into(&raw.data, depth_units_per_meter as f32, &mut depth_m)?;
    Ok(DecodedPair {
        timestamp_ns: color.timestamp_ns,
        depth_timestamp_ns: depth.timestamp_ns,
        gray: gray_from_rgb8(&rgb),
        depth_m,
    })
}

/// Grey level at or above which a mask pixel counts as set ("white = moving object").
const MASK_THRESHOLD: u8 = 128;

/// Decodes a ground-truth mask PNG (grey or colour; white = moving object) into a [`Mask`]
/// of 0 / [`MASK_SET`].
///
/// # Errors
/// [`Error::Io`] if unreadable; [`Error::BadImage`] for a corrupt image.
pub fn read_mask(path: &Path) -> Result<Mask> {
    let bytes = std::fs::read(path).map_err(|e| Error::io("cannot read mask image", path, e))?;
    let image = image::load_from_memory(&bytes)
        .map_err(|e| bad_image(path, "a mask image", format!("a corrupt one: {e}")))?;
    let gray = image.into_luma8();
    let size = ImageSize::new(gray.width() as usize, gray.height() as usize);
    let data = gray
        .into_raw()
        .into_iter()
        .map(|v| if v >= MASK_THRESHOLD { MASK_SET } else { 0 })
        .collect();
    Mask::from_vec(size, data)
}

/// The folder's name (for metadata and camera detection); the full path if it has none.
pub(crate) fn folder_name(root: &Path) -> String {
    root.canonicalize()
        .ok()
        .as_deref()
        .unwrap_or(root)
        .file_name()
        .map_or_else(
            || root.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        )
}

/// Checks `root` is a directory.
pub(crate) fn require_dir(root: &Path, what: &str) -> Result<()> {
    if !root.is_dir() {
        return Err(Error::DatasetLayout {
            path: root.to_owned(),
            expected: format!("{what} directory"),
            found: if root.exists() { "a file" } else { "nothing" }.to_owned(),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refs(times_ms: &[u64]) -> Vec<ImageRef> {
        times_ms
            .iter()
            .map(|&t| ImageRef {
                timestamp_ns: t * 1_000_000,
                path: PathBuf::new(),
            })
            .collect()
    }

    #[test]
    fn associate_is_one_to_one_nearest_within_gap() {
        // colour at 0, 33, 66, 100; depth at 5, 30, 90 (66 has no depth within 20 ms once 90 is
        // taken by 100? |90-66| = 24 > 20 anyway).
        let a = associate(&refs(&[0, 33, 66, 100]), &refs(&[5, 30, 90, 300]), 20_000_000);
        assert_eq!(
            a.pairs,
            vec![
                FramePair { color: 0, depth: 0 },
                FramePair { color: 1, depth: 1 },
                FramePair { color: 3, depth: 2 }
            ]
        );
        assert_eq!(a.unpaired_color, vec![2]);
        assert_eq!(a.unpaired_depth, vec![3]);
    }

    #[test]
    fn associate_gives_a_contested_depth_to_the_closer_colour() {
        let a = associate(&refs(&[0, 12]), &refs(&[10]), 20_000_000);
        assert_eq!(a.pairs, vec![FramePair { color: 1, depth: 0 }]);
        assert_eq!(a.unpaired_color, vec![0]);
        assert_eq!(nearest_gap_ns(&refs(&[0, 12]), &refs(&[10])), Some(2_000_000));
    }

    fn write_image(
        dir: &Path,
        name: &str,
        image: image::DynamicImage,
        format: image::ImageFormat,
    ) -> PathBuf {
        let path = dir.join(name);
        image.save_with_format(&path, format).unwrap();
        path
    }

    #[test]
    fn jpeg_colour_checks_end_marker_and_tolerates_padding() {
        let dir = tempfile::tempdir().unwrap();
        let img =
            image::DynamicImage::ImageRgb8(image::RgbImage::from_pixel(16, 8, image::Rgb([10, 200, 30])));
        let path = write_image(dir.path(), "a.jpg", img, image::ImageFormat::Jpeg);
        let c = read_color(&path).unwrap();
        assert_eq!((c.format, c.size), (ColorFormat::Jpeg, ImageSize::new(16, 8)));
        let mut bytes = std::fs::read(&path).unwrap();
        bytes.extend_from_slice(&[0, 0, 0]);
        std::fs::write(&path, &bytes).unwrap();
        assert!(read_color(&path).is_ok(), "zero padding after EOI is accepted");
        std::fs::write(&path, &bytes[..bytes.len() - 10]).unwrap();
        let err = read_color(&path).unwrap_err().to_string();
        assert!(err.contains("truncated JPEG") && err.contains("a.jpg"), "{err}");
    }

    #[test]
    fn depth_must_be_16_bit_grey() {
        let dir = tempfile::tempdir().unwrap();
        let d16 = image::DynamicImage::ImageLuma16(image::ImageBuffer::from_fn(3, 2, |x, y| {
            image::Luma([(x * 1000 + y * 7) as u16])
        }));
        let path = write_image(dir.path(), "d.png", d16, image::ImageFormat::Png);
        let d = read_depth(&path).unwrap();
        assert_eq!(d.size, ImageSize::new(3, 2));
        assert_eq!(d.data, vec![0, 1000, 2000, 7, 1007, 2007]);
        let rgb16 = image::DynamicImage::ImageRgb16(image::ImageBuffer::new(3, 2));
        let path = write_image(dir.path(), "c.png", rgb16, image::ImageFormat::Png);
        let err = read_depth(&path).unwrap_err().to_string();
        assert!(err.contains("found Rgb16") && !err.contains("8-bit"), "{err}");
    }

    #[test]
    fn mask_thresholds_white() {
        let dir = tempfile::tempdir().unwrap();
        let gray = image::DynamicImage::ImageLuma8(image::GrayImage::from_fn(4, 1, |x, _| {
            image::Luma([[0u8, 100, 128, 255][x as usize]])
        }));
        let path = write_image(dir.path(), "m.png", gray, image::ImageFormat::Png);
        assert_eq!(read_mask(&path).unwrap().as_slice(), &[0, 0, MASK_SET, MASK_SET]);
    }

    /// The preset is the inverse of the dataset module's marker-to-camera transform.
    #[test]
    fn bonn_marker_preset_is_the_dataset_conversion() {
        use nalgebra::{Quaternion, Translation3, UnitQuaternion};
        let [x, y, z, qx, qy, qz, qw] = camera_from_marker_preset("Bonn").unwrap();
        let preset = nalgebra::Isometry3::from_parts(
            Translation3::new(x, y, z),
            UnitQuaternion::from_quaternion(Quaternion::new(qw, qx, qy, qz)),
        );
        let expected = bonn::marker_from_camera().inverse();
        assert!((preset.to_homogeneous() - expected.to_homogeneous()).norm() < 1e-12);
        assert!(camera_from_marker_preset("tum").is_none());
    }

    #[test]
    fn camera_names() {
        assert_eq!(
            camera_from_folder_name("rgbd_dataset_freiburg2_desk"),
            Some("fr2")
        );
        assert_eq!(camera_from_folder_name("tum_fr3_walking"), Some("fr3"));
        assert_eq!(camera_from_folder_name("office"), None);
        assert_eq!(camera_from_folder_name("frame1"), None);
        assert_eq!(parse_camera("fr1").unwrap().intrinsics, presets::TUM_FR1);
        assert_eq!(parse_camera("fr1").unwrap().distortion, None);
        assert_eq!(
            parse_camera("500,501,320.5,240").unwrap(),
            CameraSpec::pinhole(PinholeIntrinsics::new(500.0, 501.0, 320.5, 240.0))
        );
        let bonn = parse_camera("Bonn").unwrap();
        assert_eq!(bonn.intrinsics, presets::BONN);
        assert_eq!(
            bonn.distortion.map(|d| d.to_ros()),
            Some(("plumb_bob", vec![0.039903, -0.099343, -0.000730, -0.000144, 0.0]))
        );
        assert_eq!(
            parse_camera(
                "542.822841,542.576870,315.593520,237.756098,0.039903,-0.099343,-0.000730,-0.000144,0"
            )
            .unwrap(),
            bonn
        );
        let rational = parse_camera("500,500,320,240,0.1,0.2,0,0,0.3,0.4,0.5,0.6").unwrap();
        assert_eq!(rational.distortion.map(|d| d.k6), Some(0.6));
        for bad in [
            "fr4",
            "1,2,3",
            "a,b,c,d",
            "-5,5,1,1",
            "500,500,320,240,0.1",
            "500,500,320,240,nan,0,0,0",
        ] {
            assert!(parse_camera(bad).is_err(), "{bad}");
        }
    }
}
