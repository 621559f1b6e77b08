//! Dataset → MCAP conversion (the work behind `occmask convert`).
//!
//! The converter merges four time-sorted streams (ground truth, colour, depth, masks riding
//! on their colour frame) into one log-time-ordered event list, then walks it in batches:
//! a producer thread reads and checks the images of the next batch in parallel (rayon) while
//! the calling thread writes the current one, so at most two batches of images are in
//! memory. Colour bytes pass through unchanged; depth PNGs are decoded to `16UC1`.

use std::cmp::Reverse;
use std::collections::{BTreeMap, BinaryHeap};
use std::io::{Seek, Write};
use std::ops::ControlFlow;
use std::sync::mpsc;

use rayon::prelude::*;

use crate::dataset::{
    self, camera_from_folder_name, camera_preset, nearest_gap_ns, parse_camera, Association, ColorImage,
    DatasetKind, DepthImage, Sequence,
};
use crate::error::{Error, Result};
use crate::geometry::camera::{presets, PinholeIntrinsics};
use crate::geometry::distortion::LensDistortion;
use crate::image_buf::{ImageSize, Mask};
use crate::mcap_io::encoding::{ColorEncoding, DepthEncoding};
use crate::mcap_io::writer::MessageKind;
use crate::mcap_io::{
    McapWriteOptions, RgbdMcapWriter, DEPTH_UNITS_KEY, FRAME_CAMERA_GROUNDTRUTH, FRAME_WORLD,
    METADATA_CONVERT, TOPIC_COLOR_CAMERA_INFO, TOPIC_COLOR_IMAGE, TOPIC_DEPTH_CAMERA_INFO, TOPIC_DEPTH_IMAGE,
    TOPIC_GROUNDTRUTH_MASK, TOPIC_GROUNDTRUTH_POSE, TOPIC_TF,
};
use crate::time::format_ns_as_seconds;

mod synthetic_recordings;

pub use synthetic_recordings::{
    rig_names, write_synthetic_rig_recording, write_synthetic_sequence, RIG_DEPTH_UNITS_PER_METER,
};

/// Events (images or poses) read per batch. 16 VGA frames ≈ 20 MB of images in flight per
/// batch (two batches at most): enough work to keep both cores busy, small enough that a
/// 10 000-frame sequence never sits in memory.
pub const DEFAULT_BATCH_EVENTS: usize = 16;

/// The camera intrinsics chosen for a sequence and where they came from.
#[derive(Debug, Clone, PartialEq)]
pub struct ResolvedIntrinsics {
    /// The intrinsics.
    pub intrinsics: PinholeIntrinsics,
    /// Human-readable source: `--camera fr2`, `folder name (fr2)`, `LARR dataset page`, ...
    pub source: String,
    /// True when nothing identified the camera and the Kinect default was used.
    pub is_fallback: bool,
    /// Lens distortion written into the calibrations (`--camera` presets and coefficients
    /// only; dataset images are otherwise taken as pinhole).
    pub distortion: Option<LensDistortion>,
}

/// Chooses intrinsics: `--camera` if given, else the dataset family's camera (LARR, ICSL, Bonn:
/// pinhole, as TUM's `fr1`/`fr2`, docs/method.md "Datasets"), else a TUM camera named in the
/// folder (`freiburg2`, `fr2`), else the Kinect default.
///
/// # Errors
/// [`Error::InvalidParameter`] for an unparsable `camera`.
pub fn resolve_intrinsics(
    kind: DatasetKind,
    folder_name: &str,
    camera: Option<&str>,
) -> Result<ResolvedIntrinsics> {
    let mut distortion = None;
    let (intrinsics, source, is_fallback) = if let Some(text) = camera {
        let spec = parse_camera(text)?;
        distortion = spec.distortion;
        (spec.intrinsics, format!("--camera {text}"), false)
    } else {
        match kind {
            DatasetKind::Larr => (presets::LARR, "LARR dataset page".to_owned(), false),
            DatasetKind::Icsl => (presets::ICSL, "ICSL (main.m)".to_owned(), false),
            DatasetKind::Bonn => (
                presets::BONN,
                "Bonn RGB-D Dynamic calibration (pinhole; --camera bonn adds its lens distortion)".to_owned(),
                false,
            ),
            DatasetKind::Tum => {
                match camera_from_folder_name(folder_name)
                    .and_then(|n| camera_preset(n).map(|c| (n, c.intrinsics)))
                {
                    Some((name, c)) => (c, format!("folder name ({name})"), false),
                    None => (
                        presets::KINECT_DEFAULT,
                        "Kinect default (no camera identified)".to_owned(),
                        true,
                    ),
                }
            }
        }
    };
    Ok(ResolvedIntrinsics {
        intrinsics,
        source,
        is_fallback,
        distortion,
    })
}

/// Everything the converter needs besides the sequence.
#[derive(Debug, Clone)]
pub struct ConvertConfig {
    /// Camera intrinsics written to every calibration message.
    pub intrinsics: ResolvedIntrinsics,
    /// Raw depth units per metre (channel metadata; the pixels are not rescaled).
    pub depth_units_per_meter: f64,
    /// Largest colour/depth time gap of a pair when pairing by nearest time.
    pub max_pair_gap_ns: u64,
    /// Also write colour and depth frames that have no partner.
    pub keep_unpaired: bool,
    /// MCAP chunking and compression.
    pub write: McapWriteOptions,
    /// Events per parallel read batch.
    pub batch_events: usize,
    /// The command line, recorded in the metadata.
    pub command_line: String,
}

/// What a conversion wrote.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ConvertReport {
    /// Colour images written.
    pub color_frames: usize,
    /// Depth images written.
    pub depth_frames: usize,
    /// Colour/depth pairs.
    pub pairs: usize,
    /// Timestamps of colour frames without depth (skipped unless `keep_unpaired`).
    pub unpaired_color_ns: Vec<u64>,
    /// Timestamps of depth frames without colour (skipped unless `keep_unpaired`).
    pub unpaired_depth_ns: Vec<u64>,
    /// Ground-truth poses written.
    pub groundtruth_poses: usize,
    /// Ground-truth masks written.
    pub masks: usize,
    /// Mask files that matched no colour frame (not written).
    pub unmatched_masks: Vec<std::path::PathBuf>,
    /// MCAP messages written.
    pub messages: u64,
    /// Bytes of image files read.
    pub input_image_bytes: u64,
    /// Image size of the sequence.
    pub image_size: ImageSize,
}

/// One item of the merged, time-ordered stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Event {
    /// Ground-truth pose index (pose + tf).
    Groundtruth(usize),
    /// Colour frame index (image + camera_info + mask).
    Color(usize),
    /// Depth frame index (image + camera_info).
    Depth(usize),
}

/// k-way merge of time-sorted streams into one stream ordered by (time, stream index):
/// at equal times ground truth comes first, then colour, then depth.
fn merge_by_time(streams: Vec<Vec<(u64, Event)>>) -> Vec<Event> {
    let total = streams.iter().map(Vec::len).sum();
    let mut heads: BinaryHeap<Reverse<(u64, usize, usize)>> = BinaryHeap::new();
    for (s, stream) in streams.iter().enumerate() {
        if let Some(&(t, _)) = stream.first() {
            heads.push(Reverse((t, s, 0)));
        }
    }
    let mut out = Vec::with_capacity(total);
    while let Some(Reverse((_, s, i))) = heads.pop() {
        out.push(streams[s][i].1);
        if let Some(&(t, _)) = streams[s].get(i + 1) {
            heads.push(Reverse((t, s, i + 1)));
        }
    }
    out
}

enum Loaded {
    Groundtruth(usize),
    Color(usize, ColorImage, Option<Mask>),
    Depth(usize, DepthImage),
}

fn load_event(seq: &Sequence, masks: &BTreeMap<usize, &std::path::Path>, event: Event) -> Result<Loaded> {
    Ok(match event {
        Event::Groundtruth(i) => Loaded::Groundtruth(i),
        Event::Color(i) => {
            let color = dataset::read_color(&seq.color[i].path)?;
            let mask = masks.get(&i).map(|p| dataset::read_mask(p)).transpose()?;
            Loaded::Color(i, color, mask)
        }
        Event::Depth(i) => Loaded::Depth(i, dataset::read_depth(&seq.depth[i].path)?),
    })
}

fn check_size(
    expected: &mut Option<ImageSize>,
    found: ImageSize,
    what: &str,
    path: &std::path::Path,
) -> Result<()> {
    match *expected {
        None => {
            *expected = Some(found);
            Ok(())
        }
        Some(size) if size == found => Ok(()),
        Some(size) => Err(Error::SizeMismatch {
            what: format!(
                "{what} {} (every colour, depth and mask image of a sequence must have the first colour image's size)",
                path.display()
            ),
            expected: size,
            found,
        }),
    }
}

/// Checks the pairing: a sequence without a single pair is an error.
fn check_association(seq: &Sequence, association: &Association, max_pair_gap_ns: u64) -> Result<()> {
    if association.pairs.is_empty() {
        return Err(Error::NoPairs {
            root: seq.root.clone(),
            max_pair_gap_ns,
            nearest_gap_ns: nearest_gap_ns(&seq.color, &seq.depth),
        });
    }
    Ok(())
}

/// The association as text in TUM `associate.py` form (`rgb_time rgb_path depth_time depth_path`).
fn association_text(seq: &Sequence, association: &Association) -> String {
    let rel = |p: &std::path::Path| {
        p.strip_prefix(&seq.root)
            .unwrap_or(p)
            .to_string_lossy()
            .replace('\\', "/")
    };
    let mut out = String::from(
        "# colour/depth pairs written by occmask convert: rgb_time rgb_path depth_time depth_path\n",
    );
    for p in &association.pairs {
        let (c, d) = (&seq.color[p.color], &seq.depth[p.depth]);
        out.push_str(&format!(
            "{} {} {} {}\n",
            format_ns_as_seconds(c.timestamp_ns, 6),
            rel(&c.path),
            format_ns_as_seconds(d.timestamp_ns, 6),
            rel(&d.path)
        ));
    }
    out
}

/// Converts `seq` into an MCAP file written to `sink`. `progress(done, total)` is called
/// after each event (image or pose) is written; returning `ControlFlow::Break` stops the
/// conversion with [`Error::Interrupted`]. Returns the sink (finished) and a report.
///
/// # Errors
/// Any read, decode, size or write error; nothing is committed by this function (the caller
/// owns the output file, see [`crate::mcap_io::AtomicOutput`]).
///
/// # Example
/// A TUM folder converted in memory and read back:
/// ```
/// use std::ops::ControlFlow;
/// use std::path::Path;
/// use occmask::convert::{convert_sequence, resolve_intrinsics, ConvertConfig, DEFAULT_BATCH_EVENTS};
/// use occmask::dataset::{tum, DatasetKind, DEFAULT_MAX_PAIR_GAP_NS, TUM_DEPTH_UNITS_PER_METER};
/// use occmask::mcap_io::McapWriteOptions;
/// use occmask::McapInput;
///
/// let sequence = tum::load(Path::new("fixtures/tum_fr2_desk_10"), DatasetKind::Tum)?;
/// let config = ConvertConfig {
///     intrinsics: resolve_intrinsics(DatasetKind::Tum, "tum_fr2_desk_10", Some("fr2"))?,
///     depth_units_per_meter: TUM_DEPTH_UNITS_PER_METER,
///     max_pair_gap_ns: DEFAULT_MAX_PAIR_GAP_NS,
///     keep_unpaired: false,
///     write: McapWriteOptions::default(),
///     batch_events: DEFAULT_BATCH_EVENTS,
///     command_line: "example".into(),
/// };
/// let sink = std::io::Cursor::new(Vec::new());
/// let (sink, report) = convert_sequence(&sequence, &config, sink, &mut |_, _| ControlFlow::Continue(()))?;
/// assert_eq!(report.pairs, 10);
/// let input = McapInput::from_bytes(sink.into_inner(), Path::new("tum.mcap"))?;
/// assert!(input.channel_by_topic(occmask::mcap_io::TOPIC_DEPTH_IMAGE).is_some());
/// # Ok::<(), occmask::Error>(())
/// ```
pub fn convert_sequence<W: Write + Seek>(
    seq: &Sequence,
    config: &ConvertConfig,
    sink: W,
    progress: &mut dyn FnMut(usize, usize) -> ControlFlow<()>,
) -> Result<(W, ConvertReport)> {
    if !(config.depth_units_per_meter.is_finite() && config.depth_units_per_meter > 0.0) {
        return Err(Error::InvalidParameter {
            name: "depth_units_per_meter",
            value: config.depth_units_per_meter.to_string(),
            expected: "a positive number (5000 for TUM, 1000 for millimetres)".into(),
        });
    }
    let association = seq.association(config.max_pair_gap_ns);
    check_association(seq, &association, config.max_pair_gap_ns)?;

    let mut color_selected: Vec<usize> = association.pairs.iter().map(|p| p.color).collect();
    let mut depth_selected: Vec<usize> = association.pairs.iter().map(|p| p.depth).collect();
    if config.keep_unpaired {
        color_selected.extend(&association.unpaired_color);
        depth_selected.extend(&association.unpaired_depth);
    }
    color_selected.sort_unstable();
    depth_selected.sort_unstable();
    let masks: BTreeMap<usize, &std::path::Path> =
        seq.masks.iter().map(|m| (m.color, m.path.as_path())).collect();

    let events = merge_by_time(vec![
        seq.groundtruth
            .iter()
            .enumerate()
            .map(|(i, p)| (p.timestamp_ns, Event::Groundtruth(i)))
            .collect(),
        color_selected
            .iter()
            .map(|&i| (seq.color[i].timestamp_ns, Event::Color(i)))
            .collect(),
        depth_selected
            .iter()
            .map(|&i| (seq.depth[i].timestamp_ns, Event::Depth(i)))
            .collect(),
    ]);

    let mut writer = RgbdMcapWriter::new(sink, &config.write)?;
    // Fixed registration order → stable channel IDs.
    writer.register_channel(TOPIC_COLOR_IMAGE, MessageKind::CompressedImage, BTreeMap::new())?;
    writer.register_channel(
        TOPIC_COLOR_CAMERA_INFO,
        MessageKind::CameraCalibration,
        BTreeMap::new(),
    )?;
    let depth_meta = BTreeMap::from([(
        DEPTH_UNITS_KEY.to_owned(),
        config.depth_units_per_meter.to_string(),
    )]);
    writer.register_channel(TOPIC_DEPTH_IMAGE, MessageKind::RawImage, depth_meta)?;
    writer.register_channel(
        TOPIC_DEPTH_CAMERA_INFO,
        MessageKind::CameraCalibration,
        BTreeMap::new(),
    )?;
    if !seq.groundtruth.is_empty() {
        writer.register_channel(TOPIC_GROUNDTRUTH_POSE, MessageKind::PoseInFrame, BTreeMap::new())?;
        writer.register_channel(TOPIC_TF, MessageKind::FrameTransform, BTreeMap::new())?;
    }
    let writes_masks = color_selected.iter().any(|i| masks.contains_key(i));
    if writes_masks {
        writer.register_channel(TOPIC_GROUNDTRUTH_MASK, MessageKind::RawImage, BTreeMap::new())?;
    }

    let mut report = ConvertReport {
        pairs: association.pairs.len(),
        unmatched_masks: seq.unmatched_masks.clone(),
        ..ConvertReport::default()
    };
    if !config.keep_unpaired {
        report.unpaired_color_ns = association
            .unpaired_color
            .iter()
            .map(|&i| seq.color[i].timestamp_ns)
            .collect();
        report.unpaired_depth_ns = association
            .unpaired_depth
            .iter()
            .map(|&i| seq.depth[i].timestamp_ns)
            .collect();
    }
    let intrinsics = config.intrinsics.intrinsics;
    let distortion = config.intrinsics.distortion.as_ref();
    let total = events.len();
    let batch = config.batch_events.max(1);
    let mut expected_size: Option<ImageSize> = None;
    let mut done = 0usize;

    std::thread::scope(|scope| -> Result<()> {
        // Capacity 1: one batch being written, one ready, one being read → bounded memory.
        let (tx, rx) = mpsc::sync_channel::<Result<Vec<Loaded>>>(1);
        let events = &events;
        let masks = &masks;
        scope.spawn(move || {
            for chunk in events.chunks(batch) {
                let loaded: Result<Vec<Loaded>> =
                    chunk.par_iter().map(|&e| load_event(seq, masks, e)).collect();
                let failed = loaded.is_err();
                if tx.send(loaded).is_err() || failed {
                    return;
                }
            }
        });
        for loaded in rx {
            for item in loaded? {
                match item {
                    Loaded::Groundtruth(i) => {
                        let pose = &seq.groundtruth[i];
                        writer.write_pose(
                            TOPIC_GROUNDTRUTH_POSE,
                            pose.timestamp_ns,
                            &pose.world_from_camera,
                        )?;
                        writer.write_tf(
                            pose.timestamp_ns,
                            FRAME_WORLD,
                            FRAME_CAMERA_GROUNDTRUTH,
                            &pose.world_from_camera,
                        )?;
                        report.groundtruth_poses += 1;
                    }
                    Loaded::Color(i, color, mask) => {
                        let r = &seq.color[i];
                        check_size(&mut expected_size, color.size, "colour image", &r.path)?;
                        report.input_image_bytes += color.bytes.len() as u64;
                        writer.write_color_compressed(
                            TOPIC_COLOR_IMAGE,
                            r.timestamp_ns,
                            color.bytes,
                            color.format,
                        )?;
                        writer.write_camera_info(
                            TOPIC_COLOR_CAMERA_INFO,
                            r.timestamp_ns,
                            &intrinsics,
                            color.size,
                            distortion,
                        )?;
                        report.color_frames += 1;
                        if let Some(mask) = mask {
                            let path = masks.get(&i).copied().unwrap_or(r.path.as_path());
                            check_size(&mut expected_size, mask.size(), "mask image", path)?;
                            writer.write_mask(TOPIC_GROUNDTRUTH_MASK, r.timestamp_ns, &mask)?;
                            report.masks += 1;
                        }
                    }
                    Loaded::Depth(i, depth) => {
                        let r = &seq.depth[i];
                        check_size(&mut expected_size, depth.size, "depth image", &r.path)?;
                        report.input_image_bytes += std::fs::metadata(&r.path).map_or(0, |m| m.len());
                        writer.write_depth_u16(
                            TOPIC_DEPTH_IMAGE,
                            r.timestamp_ns,
                            &depth.data,
                            depth.size,
                            config.depth_units_per_meter,
                        )?;
                        writer.write_camera_info(
                            TOPIC_DEPTH_CAMERA_INFO,
                            r.timestamp_ns,
                            &intrinsics,
                            depth.size,
                            distortion,
                        )?;
                        report.depth_frames += 1;
                    }
                }
                done += 1;
                if progress(done, total).is_break() {
                    return Err(Error::Interrupted { done, total });
                }
            }
        }
        Ok(())
    })?;
    if done != total {
        // Only reachable if the reader thread stopped without reporting an error.
        return Err(Error::ReaderStopped { done, total });
    }
    report.image_size = expected_size.unwrap_or_default();

    let first_ns = events
        .first()
        .map(|e| match *e {
            Event::Groundtruth(i) => seq.groundtruth[i].timestamp_ns,
            Event::Color(i) => seq.color[i].timestamp_ns,
            Event::Depth(i) => seq.depth[i].timestamp_ns,
        })
        .unwrap_or(0);
    let PinholeIntrinsics { fx, fy, cx, cy } = intrinsics;
    let mut metadata = BTreeMap::from(
        [
            ("dataset_kind", seq.kind.as_str().to_owned()),
            ("sequence_name", seq.name.clone()),
            ("intrinsics_fx_fy_cx_cy", format!("{fx},{fy},{cx},{cy}")),
            ("intrinsics_source", config.intrinsics.source.clone()),
            (
                "distortion",
                config.intrinsics.distortion.map_or_else(
                    || "none".to_owned(),
                    |d| {
                        let (model, coefficients) = d.to_ros();
                        format!("{model} {coefficients:?}")
                    },
                ),
            ),
            ("image_size", report.image_size.to_string()),
            (DEPTH_UNITS_KEY, config.depth_units_per_meter.to_string()),
            ("max_pair_gap_ns", config.max_pair_gap_ns.to_string()),
            ("pairs", report.pairs.to_string()),
            ("color_frames", report.color_frames.to_string()),
            ("depth_frames", report.depth_frames.to_string()),
            (
                "unpaired_color_skipped",
                report.unpaired_color_ns.len().to_string(),
            ),
            (
                "unpaired_depth_skipped",
                report.unpaired_depth_ns.len().to_string(),
            ),
            ("groundtruth_poses", report.groundtruth_poses.to_string()),
            ("masks", report.masks.to_string()),
            ("tool_version", crate::mcap_io::LIBRARY.to_owned()),
            ("command_line", config.command_line.clone()),
        ]
        .map(|(k, v)| (k.to_owned(), v)),
    );
    if seq.kind == DatasetKind::Bonn && !seq.groundtruth.is_empty() {
        metadata.insert(
            "groundtruth_conversion".to_owned(),
            dataset::bonn::groundtruth_conversion(),
        );
    }
    writer.write_metadata(METADATA_CONVERT, metadata)?;
    writer.attach(
        "occmask_association.txt",
        "text/plain",
        first_ns,
        association_text(seq, &association).as_bytes(),
    )?;
    for path in &seq.text_files {
        let data = std::fs::read(path).map_err(|e| Error::io("cannot read", path, e))?;
        let name = path
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
        writer.attach(&name, "text/plain", first_ns, &data)?;
    }
    report.messages = writer.message_count();
    Ok((writer.finish()?, report))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merge_orders_by_time_then_stream() {
        let merged = merge_by_time(vec![
            vec![(5, Event::Groundtruth(0)), (10, Event::Groundtruth(1))],
            vec![(5, Event::Color(0)), (7, Event::Color(1))],
            vec![(1, Event::Depth(0)), (10, Event::Depth(1))],
        ]);
        assert_eq!(
            merged,
            vec![
                Event::Depth(0),
                Event::Groundtruth(0),
                Event::Color(0),
                Event::Color(1),
                Event::Groundtruth(1),
                Event::Depth(1)
            ]
        );
    }

    #[test]
    fn intrinsics_resolution_order() {
        let r = resolve_intrinsics(DatasetKind::Tum, "rgbd_dataset_freiburg1_xyz", None).unwrap();
        assert_eq!(r.intrinsics, presets::TUM_FR1);
        assert!(!r.is_fallback);
        let r = resolve_intrinsics(DatasetKind::Tum, "office", None).unwrap();
        assert_eq!(r.intrinsics, presets::KINECT_DEFAULT);
        assert!(r.is_fallback);
        let r = resolve_intrinsics(DatasetKind::Tum, "rgbd_dataset_freiburg1_xyz", Some("fr3")).unwrap();
        assert_eq!(r.intrinsics, presets::TUM_FR3);
        assert_eq!(
            resolve_intrinsics(DatasetKind::Larr, "x", None)
                .unwrap()
                .intrinsics,
            presets::LARR
        );
        assert_eq!(
            resolve_intrinsics(DatasetKind::Icsl, "x", None)
                .unwrap()
                .intrinsics,
            presets::ICSL
        );
    }
}
