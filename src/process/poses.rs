//! Where `occmask process` gets camera poses besides DVO: the pose source's input stream
//! (external poses read from a topic and interpolated to each frame) and the anchor channel
//! that puts the estimated trajectory in its frame ([`OdometryAnchor`]).
//!
//! The pose source itself is [`crate::pipeline::PoseSource`] (in
//! [`ProcessConfig::processor`]); what a source needs from the input file is here, so a new
//! source is a change to the pipeline, this module and the CLI's argument.

use nalgebra::Isometry3;

use crate::error::{Error, PoseRole, Result};
use crate::mcap_io::input::decode::{decode_poses, read_poses, unsupported_schema, POSE_SCHEMA};
use crate::mcap_io::input::detect::{RgbdTopics, TopicOverrides};
use crate::mcap_io::input::McapInput;
use crate::trajectory::{interpolate, StampedPose};

use super::config::{OdometryAnchor, ProcessConfig};

/// Results held while no frame is covered by the anchor channel, at most (10 s at 30 Hz): a
/// pose stream that starts later than this is not used as the anchor (the first camera is
/// `world`, and the report says why), so memory stays bounded.
pub(super) const MAX_UNANCHORED_FRAMES: usize = 300;

/// The topics to look for: the pose topic only when the pose source reads one.
pub(super) fn topic_overrides(config: &ProcessConfig) -> TopicOverrides {
    let mut topics = config.topics.clone();
    if !config.processor.pose_source.is_external() {
        topics.pose = None;
    }
    topics
}

/// The poses that come with the input for the pose source, per frame.
pub(super) struct InputPoses {
    /// External poses in time order (`None`: the pose source estimates them).
    external: Option<Vec<StampedPose>>,
    max_gap_ns: u64,
}

/// The pose of one frame from [`InputPoses::at`].
pub(super) enum FramePose {
    /// The pose source estimates it (DVO).
    Estimated,
    /// Given by the input: `world_from_marker`.
    Given(Isometry3<f64>),
    /// The input's poses do not cover the frame: it is not processed.
    Outside,
}

impl InputPoses {
    /// Reads what the pose source needs (the whole pose stream for external poses).
    ///
    /// # Errors
    /// As [`load_external_poses`].
    pub(super) fn load(input: &McapInput, topics: &RgbdTopics, config: &ProcessConfig) -> Result<Self> {
        let external = if config.processor.pose_source.is_external() {
            Some(load_external_poses(input, topics, config)?)
        } else {
            None
        };
        Ok(Self {
            external,
            max_gap_ns: config.max_pose_gap_ns,
        })
    }

    /// The pose for a frame stamped `stamp`: interpolated from samples at most
    /// [`ProcessConfig::max_pose_gap_ns`] apart.
    pub(super) fn at(&self, stamp: u64) -> FramePose {
        match &self.external {
            None => FramePose::Estimated,
            Some(poses) => {
                interpolate(poses, stamp, self.max_gap_ns).map_or(FramePose::Outside, FramePose::Given)
            }
        }
    }
}

/// The external poses of [`RgbdTopics::pose`] for [`ProcessConfig::pose_child_frame`] (else
/// the first child frame seen), sorted and deduplicated by stamp.
///
/// # Errors
/// No pose topic, an undecodable pose message, or no poses.
fn load_external_poses(
    input: &McapInput,
    topics: &RgbdTopics,
    config: &ProcessConfig,
) -> Result<Vec<StampedPose>> {
    let Some(channel) = &topics.pose else {
        return Err(Error::MissingPoseTopic);
    };
    let ct = channel
        .channel_type
        .ok_or_else(|| unsupported_schema(channel, POSE_SCHEMA))?;
    let mut child = config.pose_child_frame.clone();
    let mut poses = Vec::new();
    input.for_each_message(Some(std::slice::from_ref(&channel.topic)), None, |m| {
        for sample in decode_poses(ct, &channel.topic, &m.data)? {
            if let Some(c) = &sample.child_frame {
                if c == crate::mcap_io::annotate::FRAME_CAMERA_ESTIMATED {
                    continue;
                }
                match &child {
                    None => child = Some(c.clone()),
                    Some(wanted) if wanted != c => continue,
                    Some(_) => {}
                }
            }
            poses.push(StampedPose {
                timestamp_ns: sample.timestamp_ns,
                world_from_camera: sample.parent_from_child,
            });
        }
        Ok(true)
    })?;
    poses.sort_by_key(|p| p.timestamp_ns);
    poses.dedup_by_key(|p| p.timestamp_ns);
    if poses.is_empty() {
        return Err(Error::NoPoses {
            path: input.path().to_owned(),
            role: PoseRole::External,
            topic: channel.topic.clone(),
            child_frame: child,
            channels: Vec::new(),
        });
    }
    Ok(poses)
}

/// The poses of the [`OdometryAnchor`] channel, with its topic; `None` when not anchoring.
pub(super) fn load_anchor_poses(
    input: &McapInput,
    config: &ProcessConfig,
) -> Result<Option<(String, Vec<StampedPose>)>> {
    if config.processor.pose_source.is_external() {
        return Ok(None); // external poses are already in their own world frame
    }
    let (topic, required) = match &config.anchor {
        OdometryAnchor::FirstCamera => return Ok(None),
        OdometryAnchor::IfPresent(t) => (t, false),
        OdometryAnchor::Required(t) => (t, true),
    };
    let poses = read_poses(input, topic).map_err(|e| match e {
        Error::Decode { .. } if required => Error::AnchorPoses {
            topic: topic.clone(),
            error: Box::new(e),
        },
        other => other,
    })?;
    match (poses.is_empty(), required) {
        (false, _) => Ok(Some((topic.clone(), poses))),
        (true, false) => Ok(None),
        (true, true) => Err(Error::NoPoses {
            path: input.path().to_owned(),
            role: PoseRole::Anchor,
            topic: topic.clone(),
            child_frame: None,
            channels: input.channels().values().map(|c| c.topic.clone()).collect(),
        }),
    }
}

/// `world_from_odometry` (for the whole file) from the anchor channel's pose at `stamp`: `None` when the channel
/// does not cover `stamp`.
pub(super) fn anchor_at(
    poses: &[StampedPose],
    max_gap_ns: u64,
    stamp: u64,
    odometry_from_camera: &Isometry3<f64>,
) -> Option<Isometry3<f64>> {
    interpolate(poses, stamp, max_gap_ns)
        .map(|world_from_camera| world_from_camera * odometry_from_camera.inverse())
}
