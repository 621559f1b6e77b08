//! LARR RGB-D layout (Kim et al.; docs/method.md "Datasets"): `rgb/<time>.png`,
//! `depth/<time>.png` (millimetres), `groundtruth mask/<time>.png` (white = moving object),
//! optional `association.txt` and `groundtruth.txt` (VICON, TUM pose format).
//!
//! Tolerated variants: directory names compared without case, spaces, `_`/`-` and a
//! `.dir` suffix (`groundtruth mask`, `groundtruth_mask`, `GroundTruth-Mask.dir`); a missing
//! `association.txt` (frames are then paired by nearest time); colour as PNG or JPEG.
//! The `groundtruth/` folder of colour segmentation images is not read (the masks carry the
//! same information).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::error::{Error, Mismatch, Result};
use crate::time::parse_seconds_to_ns;

use super::{
    check_increasing, content_lines, folder_name, read_groundtruth, read_text, require_dir, DatasetKind,
    FramePair, ImageRef, MaskRef, Sequence,
};

/// Normalised directory names: lower case without spaces, `_`, `-` or a `.dir` suffix.
fn normalise(name: &str) -> String {
    let lower = name.to_ascii_lowercase();
    let lower = lower.strip_suffix(".dir").unwrap_or(&lower);
    lower.chars().filter(|c| !matches!(c, ' ' | '_' | '-')).collect()
}

/// The sub-directory of `root` whose normalised name is `wanted`, if exactly one exists.
fn find_dir(root: &Path, wanted: &str) -> Result<Option<PathBuf>> {
    let entries = std::fs::read_dir(root).map_err(|e| Error::io("cannot list", root, e))?;
    let mut found: Vec<PathBuf> = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| Error::io("cannot list", root, e))?;
        let path = entry.path();
        if path.is_dir() && normalise(&entry.file_name().to_string_lossy()) == wanted {
            found.push(path);
        }
    }
    found.sort();
    match found.len() {
        0 => Ok(None),
        1 => Ok(found.pop()),
        _ => Err(Error::DatasetLayout {
            path: root.to_owned(),
            expected: format!("one '{wanted}' directory"),
            found: format!(
                "{}: {}",
                found.len(),
                found
                    .iter()
                    .map(|p| p.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }),
    }
}

/// Image files in `dir` (`.png`, plus `.jpg`/`.jpeg` when `allow_jpeg`) named by their
/// capture time in seconds, sorted by time. Other files are ignored.
fn list_timed_images(dir: &Path, allow_jpeg: bool) -> Result<Vec<ImageRef>> {
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io("cannot list", dir, e))?;
    let mut out = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| Error::io("cannot list", dir, e))?;
        let path = entry.path();
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        let is_image = ext == "png" || (allow_jpeg && (ext == "jpg" || ext == "jpeg"));
        if !is_image || !path.is_file() {
            continue;
        }
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let timestamp_ns = parse_seconds_to_ns(&stem).map_err(|mismatch| Error::BadImage {
            path: path.clone(),
            expected: format!("a LARR image named by its capture time: {}", mismatch.expected),
            found: mismatch.found,
        })?;
        out.push(ImageRef { timestamp_ns, path });
    }
    out.sort_by(|a, b| {
        a.timestamp_ns
            .cmp(&b.timestamp_ns)
            .then_with(|| a.path.cmp(&b.path))
    });
    // Duplicates (e.g. `1.5.png` and `1.50.png`) are rejected by the same rule as lists;
    // "line" is the 1-based position in the sorted listing.
    check_increasing(
        dir,
        out.iter().map(|r| r.timestamp_ns).zip(1..),
        "image file-name",
    )?;
    Ok(out)
}

fn required_dir(root: &Path, wanted: &str, what: &str) -> Result<PathBuf> {
    find_dir(root, wanted)?.ok_or_else(|| Error::DatasetLayout {
        path: root.to_owned(),
        expected: format!("a '{wanted}/' directory of {what} images (LARR layout)"),
        found: "none".to_owned(),
    })
}

/// Parses `association.txt`: `rgb_time rgb_path depth_time depth_path` per line (TUM
/// `associate.py` output). Paths may be relative to `root` or bare file names.
fn read_association(path: &Path, color: &[ImageRef], depth: &[ImageRef]) -> Result<Vec<FramePair>> {
    parse_association(&read_text(path)?, path, color, depth)
}

/// Parses the text of a LARR `association.txt` (`rgb_time rgb_path depth_time depth_path` per
/// line) against the listed `color` and `depth` images; `source` is the path named in errors.
/// Pairs come back as indices into `color` and `depth`, in file order.
///
/// # Errors
/// [`Error::Parse`] with the line for malformed lines, times matching no listed image, or
/// colour times that do not increase strictly.
pub fn parse_association(
    text: &str,
    source: &Path,
    color: &[ImageRef],
    depth: &[ImageRef],
) -> Result<Vec<FramePair>> {
    let index = |refs: &[ImageRef]| -> HashMap<u64, usize> {
        refs.iter()
            .enumerate()
            .map(|(i, r)| (r.timestamp_ns, i))
            .collect()
    };
    let (color_at, depth_at) = (index(color), index(depth));
    let mut pairs = Vec::new();
    let mut line_numbers = Vec::new();
    for (line, text) in content_lines(text) {
        let err = |mismatch: Mismatch| mismatch.at_line(source, line);
        let fields: Vec<&str> = text.split_whitespace().collect();
        if fields.len() != 4 {
            return Err(err(Mismatch::new(
                "4 fields 'rgb_time rgb_path depth_time depth_path'",
                fields.len().to_string(),
            )));
        }
        let tc = parse_seconds_to_ns(fields[0]).map_err(err)?;
        let td = parse_seconds_to_ns(fields[2]).map_err(err)?;
        let no_image = |what: &str, dir: &str, time: &str| {
            err(Mismatch::new(
                format!("a {what} image with time {time} in {dir}"),
                "none",
            ))
        };
        let ci = *color_at
            .get(&tc)
            .ok_or_else(|| no_image("colour", "rgb/", fields[0]))?;
        let di = *depth_at
            .get(&td)
            .ok_or_else(|| no_image("depth", "depth/", fields[2]))?;
        pairs.push(FramePair { color: ci, depth: di });
        line_numbers.push(line);
    }
    check_increasing(
        source,
        pairs
            .iter()
            .map(|p| color[p.color].timestamp_ns)
            .zip(line_numbers),
        "association",
    )?;
    Ok(pairs)
}

/// Lists a LARR-layout folder. Masks are matched to the colour frame with the same time; a
/// mask whose time matches no colour frame goes to [`Sequence::unmatched_masks`].
///
/// # Errors
/// [`Error::DatasetLayout`] for missing or empty image directories; [`Error::Parse`] /
/// [`Error::BadImage`] for malformed text files or image names.
///
/// # Example
/// ```
/// let sequence = occmask::dataset::larr::load(std::path::Path::new("fixtures/larr_fr2_desk_mini"))?;
/// assert!(!sequence.color.is_empty() && !sequence.depth.is_empty());
/// # Ok::<(), occmask::Error>(())
/// ```
pub fn load(root: &Path) -> Result<Sequence> {
    require_dir(root, "a LARR RGB-D dataset")?;
    let rgb_dir = required_dir(root, "rgb", "colour")?;
    let depth_dir = required_dir(root, "depth", "depth")?;
    let color = list_timed_images(&rgb_dir, true)?;
    let depth = list_timed_images(&depth_dir, false)?;
    for (dir, list, what) in [(&rgb_dir, &color, "colour"), (&depth_dir, &depth, "depth")] {
        if list.is_empty() {
            return Err(Error::DatasetLayout {
                path: dir.clone(),
                expected: format!("{what} images named <time>.png"),
                found: "none (empty sequence)".to_owned(),
            });
        }
    }
    let mut text_files = Vec::new();
    let association_path = root.join("association.txt");
    let given_pairs = if association_path.is_file() {
        text_files.push(association_path.clone());
        Some(read_association(&association_path, &color, &depth)?)
    } else {
        None
    };
    let gt_path = root.join("groundtruth.txt");
    let groundtruth = if gt_path.is_file() {
        text_files.push(gt_path.clone());
        read_groundtruth(&gt_path)?
    } else {
        Vec::new()
    };
    let mut masks = Vec::new();
    let mut unmatched_masks = Vec::new();
    if let Some(mask_dir) = find_dir(root, "groundtruthmask")? {
        for m in list_timed_images(&mask_dir, false)? {
            match color.binary_search_by_key(&m.timestamp_ns, |c| c.timestamp_ns) {
                Ok(ci) => masks.push(MaskRef {
                    color: ci,
                    path: m.path,
                }),
                Err(_) => unmatched_masks.push(m.path),
            }
        }
    }
    Ok(Sequence {
        kind: DatasetKind::Larr,
        root: root.to_owned(),
        name: folder_name(root),
        color,
        depth,
        given_pairs,
        masks,
        unmatched_masks,
        groundtruth,
        text_files,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directory_name_variants_normalise_alike() {
        for name in [
            "groundtruth mask",
            "groundtruth_mask",
            "GroundTruth-Mask.dir",
            "groundtruthmask",
        ] {
            assert_eq!(normalise(name), "groundtruthmask", "{name}");
        }
        assert_eq!(normalise("rgb.dir"), "rgb");
    }
}
