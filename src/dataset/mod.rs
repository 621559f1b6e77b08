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
mod camera;
mod images;
pub mod larr;
pub mod tum;

pub use camera::{
    camera_from_folder_name, camera_from_marker_preset, camera_preset, parse_camera, CameraSpec,
};
pub use images::{decode_pair, read_color, read_depth, read_mask, ColorImage, DecodedPair, DepthImage};

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
    /// Bonn RGB-D Dynamic dataset: TUM layout, 5000 depth units per metre, its own camera, and
    /// motion-capture poses of a marker that [`bonn::load`] converts to the camera's.
    Bonn,
}

impl DatasetKind {
    /// Lower-case name used on the command line and in metadata.
    pub fn as_str(self) -> &'static str {
        match self {
            DatasetKind::Tum => "tum",
            DatasetKind::Icsl => "icsl",
            DatasetKind::Larr => "larr",
            DatasetKind::Bonn => "bonn",
        }
    }

    /// Raw depth units per metre of the family's PNGs.
    pub fn default_depth_units_per_meter(self) -> f64 {
        match self {
            DatasetKind::Tum | DatasetKind::Bonn => TUM_DEPTH_UNITS_PER_METER,
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
mod tests;
