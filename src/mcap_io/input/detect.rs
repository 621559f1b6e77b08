//! Choosing the colour, depth, calibration and pose channels of an input file.
//!
//! Without explicit topics, image channels are classified by schema, then by the encoding of
//! their first message (`16UC1`/`mono16`/`32FC1`/compressedDepth = depth, anything else =
//! colour). Topics under `/occmask/` (our own outputs) and `/groundtruth/` are never chosen
//! automatically. Ties are broken by the usual names (`color`/`rgb`, `aligned`), and otherwise
//! reported with the candidates ([`Error::AmbiguousTopic`]).

use crate::error::{Error, Result, TopicRole};

use super::decode::{decode_image, MessageType};
use super::{InputChannel, McapInput};

/// Topics given on the command line (each overrides detection).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TopicOverrides {
    /// `--rgb-topic`.
    pub rgb: Option<String>,
    /// `--depth-topic`.
    pub depth: Option<String>,
    /// `--camera-info-topic`.
    pub camera_info: Option<String>,
    /// `--depth-camera-info-topic`.
    pub depth_camera_info: Option<String>,
    /// `--pose-topic`.
    pub pose: Option<String>,
}

/// The chosen channels.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RgbdTopics {
    /// Colour images.
    pub color: InputChannel,
    /// Depth images.
    pub depth: InputChannel,
    /// Calibration of the colour camera, if any was found.
    pub calibration: Option<InputChannel>,
    /// Calibration of the depth camera: the calibration channel beside the depth topic when it
    /// is another than [`Self::calibration`] (or `--depth-camera-info-topic`).
    pub depth_calibration: Option<InputChannel>,
    /// External poses (`--pose-topic`).
    pub pose: Option<InputChannel>,
}

/// Topic prefixes never chosen automatically: our own outputs and ground truth.
const EXCLUDED_PREFIXES: [&str; 2] = ["/occmask/", "/groundtruth/"];

fn excluded(topic: &str) -> bool {
    EXCLUDED_PREFIXES.iter().any(|p| topic.starts_with(p))
}

fn namespace(topic: &str) -> &str {
    topic.rsplit_once('/').map_or("", |(ns, _)| ns)
}

/// Lists every channel as `topic (schema, encoding)` for error messages.
pub fn describe_channels(input: &McapInput) -> String {
    if input.channels().is_empty() {
        return "the file has no channels".into();
    }
    let list: Vec<String> = input
        .channels()
        .values()
        .map(|c| {
            let schema = if c.schema_name.is_empty() {
                "no schema"
            } else {
                c.schema_name.as_str()
            };
            format!("{} ({schema}, {})", c.topic, c.message_encoding)
        })
        .collect();
    format!("topics seen: {}", list.join(", "))
}

fn by_topic<'a>(
    input: &'a McapInput,
    topic: &str,
    role: TopicRole,
    want: &[MessageType],
) -> Result<&'a InputChannel> {
    let channel = input.channel_by_topic(topic).ok_or_else(|| Error::UnknownTopic {
        path: input.path().to_owned(),
        role,
        topic: topic.to_owned(),
        channels: describe_channels(input),
    })?;
    match channel.channel_type {
        Some(ct) if want.contains(&ct.message) => Ok(channel),
        _ => Err(Error::UnsupportedTopic {
            path: input.path().to_owned(),
            role,
            topic: topic.to_owned(),
            schema: channel.schema_name.clone(),
            message_encoding: channel.message_encoding.clone(),
        }),
    }
}

fn pick<'a>(
    input: &McapInput,
    candidates: Vec<&'a InputChannel>,
    preferred: &[&str],
    role: TopicRole,
) -> Result<Option<&'a InputChannel>> {
    if candidates.len() <= 1 {
        return Ok(candidates.into_iter().next());
    }
    let lower = |c: &&InputChannel| c.topic.to_ascii_lowercase();
    for word in preferred {
        let matching: Vec<_> = candidates.iter().filter(|c| lower(c).contains(word)).collect();
        if matching.len() == 1 {
            return Ok(Some(matching[0]));
        }
    }
    Err(Error::AmbiguousTopic {
        path: input.path().to_owned(),
        role,
        candidates: candidates.iter().map(|c| c.topic.clone()).collect(),
    })
}

fn no_topic(input: &McapInput, role: TopicRole, found: String) -> Error {
    Error::NoTopic {
        path: input.path().to_owned(),
        role,
        found,
        channels: describe_channels(input),
    }
}

/// Chooses the channels to process.
///
/// # Errors
/// [`Error::NoTopic`] when no colour or depth channel is found (listing every topic and
/// schema), [`Error::UnknownTopic`] / [`Error::UnsupportedTopic`] when a given topic does not
/// exist or has an unsupported schema, [`Error::AmbiguousTopic`] when several candidates remain.
pub fn detect_topics(input: &McapInput, overrides: &TopicOverrides) -> Result<RgbdTopics> {
    let images = [MessageType::RawImage, MessageType::CompressedImage];
    let mut colors = Vec::new();
    let mut depths = Vec::new();
    let mut image_encodings: Vec<String> = Vec::new();
    if overrides.rgb.is_none() || overrides.depth.is_none() {
        for channel in input.channels().values() {
            let Some(ct) = channel.channel_type else { continue };
            if !ct.is_image() || excluded(&channel.topic) {
                continue;
            }
            let Some(first) = input.first_message(channel.id)? else {
                continue;
            };
            // A first message that does not decode is reported when the channel is read.
            let decoded = decode_image(ct, &channel.topic, &first.data);
            let is_depth = decoded.as_ref().is_ok_and(|m| m.is_depth());
            if let Ok(m) = &decoded {
                image_encodings.push(format!("{} {}", channel.topic, m.encoding()));
            }
            if is_depth {
                depths.push(channel);
            } else {
                colors.push(channel);
            }
        }
    }
    let color = match &overrides.rgb {
        Some(t) => by_topic(input, t, TopicRole::Color, &images)?,
        None => pick(input, colors, &["color", "colour", "rgb"], TopicRole::Color)?
            .ok_or_else(|| no_topic(input, TopicRole::Color, String::new()))?,
    };
    let depth = match &overrides.depth {
        Some(t) => by_topic(input, t, TopicRole::Depth, &images)?,
        None => pick(
            input,
            depths,
            &["aligned", "registered", "depth"],
            TopicRole::Depth,
        )?
        .ok_or_else(|| {
            let found = if image_encodings.is_empty() {
                String::new()
            } else {
                format!(" among the image topics ({})", image_encodings.join(", "))
            };
            no_topic(
                input,
                TopicRole::Depth,
                format!(" (16UC1, mono16 or 32FC1; 8-bit depth is not supported){found}"),
            )
        })?,
    };
    let calibrations: Vec<&InputChannel> = input
        .channels()
        .values()
        .filter(|c| {
            c.channel_type
                .is_some_and(|ct| ct.message == MessageType::Calibration)
        })
        .filter(|c| c.message_count != Some(0))
        .collect();
    let same_ns = |topic: &str| {
        calibrations
            .iter()
            .copied()
            .find(|c| namespace(&c.topic) == namespace(topic))
    };
    let calibration = match &overrides.camera_info {
        Some(t) => Some(by_topic(
            input,
            t,
            TopicRole::Calibration,
            &[MessageType::Calibration],
        )?),
        None => same_ns(&color.topic)
            .or_else(|| same_ns(&depth.topic))
            .or_else(|| (calibrations.len() == 1).then(|| calibrations[0])),
    };
    let depth_calibration = match &overrides.depth_camera_info {
        Some(t) => Some(by_topic(
            input,
            t,
            TopicRole::DepthCalibration,
            &[MessageType::Calibration],
        )?),
        None => same_ns(&depth.topic).filter(|c| calibration.is_none_or(|colour| colour.id != c.id)),
    };
    let pose = match &overrides.pose {
        Some(t) => Some(by_topic(
            input,
            t,
            TopicRole::Poses,
            &[
                MessageType::PoseInFrame,
                MessageType::FrameTransform,
                MessageType::FrameTransforms,
            ],
        )?),
        None => None,
    };
    Ok(RgbdTopics {
        color: color.clone(),
        depth: depth.clone(),
        calibration: calibration.cloned(),
        depth_calibration: depth_calibration.cloned(),
        pose: pose.cloned(),
    })
}
