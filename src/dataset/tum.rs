//! TUM RGB-D layout (also used by ICSL sequences): `rgb.txt`, `depth.txt`, optional
//! `groundtruth.txt`, images under `rgb/` and `depth/` (docs/method.md "Datasets").

use std::path::Path;

use crate::error::{Error, Result};

use super::{folder_name, read_groundtruth, read_image_list, require_dir, DatasetKind, Sequence};

/// Lists a TUM-layout folder. `kind` is [`DatasetKind::Tum`], [`DatasetKind::Icsl`] or
/// [`DatasetKind::Bonn`] (same layout, different units and camera; a Bonn sequence's ground
/// truth is converted by [`super::bonn::load`]).
///
/// # Errors
/// [`Error::DatasetLayout`] when the folder or a list file is missing or a list is empty;
/// [`Error::Parse`] for malformed or unsorted lines and listed files that do not exist.
///
/// # Example
/// ```
/// use occmask::dataset::{tum, DatasetKind};
///
/// let sequence = tum::load(std::path::Path::new("fixtures/tum_fr2_desk_10"), DatasetKind::Tum)?;
/// assert_eq!((sequence.color.len(), sequence.depth.len()), (10, 10));
/// assert!(sequence.color.windows(2).all(|w| w[0].timestamp_ns < w[1].timestamp_ns));
/// # Ok::<(), occmask::Error>(())
/// ```
pub fn load(root: &Path, kind: DatasetKind) -> Result<Sequence> {
    require_dir(root, "a TUM RGB-D dataset")?;
    let list = |name: &str, what: &str| {
        let path = root.join(name);
        if !path.is_file() {
            let hint = if root.join("rgb").is_dir() && root.join("depth").is_dir() {
                " (for folders of <time>.png images without lists, use `occmask convert larr`)"
            } else {
                ""
            };
            let found = if path.is_dir() {
                "a directory"
            } else {
                "no such file"
            };
            return Err(Error::DatasetLayout {
                path: path.clone(),
                expected: format!("{name} listing the {what} images ('timestamp path' per line)"),
                found: format!("{found}{hint}"),
            });
        }
        let images = read_image_list(&path, root)?;
        if images.is_empty() {
            return Err(Error::DatasetLayout {
                path,
                expected: format!("at least one {what} image"),
                found: "an empty list (empty sequence)".to_owned(),
            });
        }
        Ok((path, images))
    };
    let (rgb_list, color) = list("rgb.txt", "colour")?;
    let (depth_list, depth) = list("depth.txt", "depth")?;
    let mut text_files = vec![rgb_list, depth_list];
    let gt_path = root.join("groundtruth.txt");
    if gt_path.exists() && !gt_path.is_file() {
        return Err(Error::DatasetLayout {
            path: gt_path,
            expected: "groundtruth.txt to be a text file of poses".to_owned(),
            found: "a directory or device".to_owned(),
        });
    }
    let groundtruth = if gt_path.is_file() {
        text_files.push(gt_path.clone());
        read_groundtruth(&gt_path)?
    } else {
        Vec::new()
    };
    Ok(Sequence {
        kind,
        root: root.to_owned(),
        name: folder_name(root),
        color,
        depth,
        given_pairs: None,
        masks: Vec::new(),
        unmatched_masks: Vec::new(),
        groundtruth,
        text_files,
    })
}
