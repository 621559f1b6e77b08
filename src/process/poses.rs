//! Where `occmask process` gets camera poses besides DVO: the pose source's input stream
//! (external poses read from a topic and interpolated to each frame) and the anchor channel
//! that puts the estimated trajectory in its frame ([`OdometryAnchor`]).
//!
//! The pose source itself is [`crate::pipeline::PoseSource`] (in
//! [`ProcessConfig::processor`]); what a source needs from the input file is here, so a new
//! source is a change to the pipeline, this module and the CLI's argument.

use std::path::Path;

use nalgebra::Isometry3;

use crate::error::{Error, PoseRole, Result};
use crate::mcap_io::input::decode::{decode_poses, unsupported_schema, ChannelType, PoseSample, POSE_SCHEMA};
use crate::mcap_io::input::detect::{RgbdTopics, TopicOverrides};
use crate::mcap_io::input::{McapInput, RawMessage};
use crate::trajectory::{interpolate, StampedPose};

use super::config::{OdometryAnchor, ProcessConfig};
use super::report::UnreadablePoses;

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

/// The poses that come with the input for the pose source, per frame: for external poses, the
/// pose channel's samples, read from the same pass over the input as the images
/// ([`StreamedPoses`]; a frame waits until the channel is read past it).
pub(super) struct InputPoses {
    /// `None`: the pose source estimates the poses.
    external: Option<ExternalPoses>,
    max_gap_ns: u64,
}

/// The pose channel of an external pose source.
struct ExternalPoses {
    channel: PoseChannel,
    /// The child frame whose poses are used ([`ProcessConfig::pose_child_frame`], else the
    /// first seen).
    child: Option<String>,
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
    /// What the pose source needs: for external poses, the pose channel of `topics`, whose
    /// first message is decoded here so that a channel that cannot be used fails before any
    /// output.
    ///
    /// # Errors
    /// No pose topic ([`Error::MissingPoseTopic`]), a schema that is not a pose, an empty
    /// channel ([`Error::NoPoses`]) or a first message that does not decode.
    pub(super) fn open(input: &McapInput, topics: &RgbdTopics, config: &ProcessConfig) -> Result<Self> {
        let external = if config.processor.pose_source.is_external() {
            let Some(channel) = &topics.pose else {
                return Err(Error::MissingPoseTopic);
            };
            let channel_type = channel
                .channel_type
                .ok_or_else(|| unsupported_schema(channel, POSE_SCHEMA))?;
            let external = ExternalPoses {
                channel: PoseChannel::new(channel.topic.clone(), channel.id, channel_type),
                child: config.pose_child_frame.clone(),
            };
            match input.first_message(channel.id)? {
                // Decoded here for its errors; read again, in its turn, by `observe`.
                Some(first) => {
                    decode_poses(channel_type, &channel.topic, &first.data)?;
                }
                None => return Err(external.no_poses(input.path())),
            }
            Some(external)
        } else {
            None
        };
        Ok(Self {
            external,
            max_gap_ns: config.max_pose_gap_ns,
        })
    }

    /// Takes the pose channel's samples from `message` (any input message, in read order).
    ///
    /// # Errors
    /// A pose message that does not decode.
    pub(super) fn observe(&mut self, message: &RawMessage) -> Result<()> {
        let Some(e) = &mut self.external else {
            return Ok(());
        };
        let Some(samples) = e.channel.read(message) else {
            return Ok(());
        };
        for sample in samples? {
            if !sample.follows(&mut e.child) {
                continue;
            }
            e.channel.samples.insert(&sample);
        }
        Ok(())
    }

    /// The input has been read to its end.
    ///
    /// # Errors
    /// [`Error::NoPoses`] when the channel had no pose of the child frame.
    pub(super) fn finish(&mut self, input_path: &Path) -> Result<()> {
        match &mut self.external {
            Some(e) if e.channel.samples.poses.is_empty() => Err(e.no_poses(input_path)),
            Some(e) => {
                e.channel.samples.complete = true;
                Ok(())
            }
            None => Ok(()),
        }
    }

    /// Whether the pose of a frame stamped `stamp_ns` and logged at `log_time_ns` is known
    /// ([`StreamedPoses::settled`]; always, when the pose source estimates it).
    pub(super) fn settled(&self, stamp_ns: u64, log_time_ns: u64) -> bool {
        self.external
            .as_ref()
            .is_none_or(|e| e.channel.samples.settled(stamp_ns, log_time_ns))
    }

    /// The pose for a frame stamped `stamp`: interpolated from samples at most
    /// [`ProcessConfig::max_pose_gap_ns`] apart.
    pub(super) fn at(&self, stamp: u64) -> FramePose {
        match &self.external {
            None => FramePose::Estimated,
            Some(e) => interpolate(&e.channel.samples.poses, stamp, self.max_gap_ns)
                .map_or(FramePose::Outside, FramePose::Given),
        }
    }
}

impl ExternalPoses {
    fn no_poses(&self, input_path: &Path) -> Error {
        Error::NoPoses {
            path: input_path.to_owned(),
            role: PoseRole::External,
            topic: self.channel.topic.clone(),
            child_frame: self.child.clone(),
            channels: Vec::new(),
        }
    }
}

/// A pose channel's samples, taken from the input's messages as the frame loop reads them, so
/// the input is read and decompressed once (reading a whole channel before the first frame
/// cost a second pass over every chunk, 5 % of the CPU on the Bonn window).
#[derive(Default)]
struct StreamedPoses {
    /// The samples read so far, sorted by stamp, the first read of each stamp (as a sort and
    /// deduplication of the whole channel keeps them).
    poses: Vec<StampedPose>,
    /// Log time of the last input message read.
    read_log_time_ns: u64,
    /// The input has been read to its end: every sample is in `poses`.
    complete: bool,
}

impl StreamedPoses {
    fn read(&mut self, log_time_ns: u64) {
        self.read_log_time_ns = self.read_log_time_ns.max(log_time_ns);
    }

    fn insert(&mut self, sample: &PoseSample) {
        let timestamp_ns = sample.timestamp_ns;
        if let Err(at) = self.poses.binary_search_by_key(&timestamp_ns, |p| p.timestamp_ns) {
            self.poses.insert(
                at,
                StampedPose {
                    timestamp_ns,
                    world_from_camera: sample.parent_from_child,
                },
            );
        }
    }

    /// Whether the samples read so far give the pose at `stamp_ns` as the whole channel would:
    /// a sample at or after it has been read (the channel's stamps rise in log-time order), the
    /// input is read to its end, or it has been read [`MAX_POSE_DELAY_NS`] past the frame's
    /// log time.
    fn settled(&self, stamp_ns: u64, log_time_ns: u64) -> bool {
        self.complete
            || self.poses.last().is_some_and(|p| p.timestamp_ns >= stamp_ns)
            || self.read_log_time_ns > log_time_ns.saturating_add(MAX_POSE_DELAY_NS)
    }
}

/// How far past a frame (in the input's log time) the frame loop reads before it settles the
/// frame's pose without a later sample: a pose channel's samples around a frame are normally
/// logged within milliseconds of it, and a pose stream that stops early then holds back at most
/// this much of the input (decoded frames waiting for an external pose, results waiting for
/// the anchor's).
pub(super) const MAX_POSE_DELAY_NS: u64 = 1_000_000_000;

/// A pose channel of the input and its samples so far ([`StreamedPoses`]).
struct PoseChannel {
    topic: String,
    id: u16,
    channel_type: ChannelType,
    samples: StreamedPoses,
}

impl PoseChannel {
    fn new(topic: String, id: u16, channel_type: ChannelType) -> Self {
        Self {
            topic,
            id,
            channel_type,
            samples: StreamedPoses::default(),
        }
    }

    /// Notes that `message` (any input message, in read order) was read; when it is one of
    /// this channel's, its decoded samples (the caller keeps those it wants).
    fn read(&mut self, message: &RawMessage) -> Option<Result<Vec<PoseSample>>> {
        self.samples.read(message.header.log_time);
        (message.header.channel_id == self.id)
            .then(|| decode_poses(self.channel_type, &self.topic, &message.data))
    }
}

/// The [`OdometryAnchor`] channel, read from the same pass over the input as the images
/// ([`StreamedPoses`]).
pub(super) struct AnchorStream {
    channel: PoseChannel,
    /// `--anchor-topic` named it: an unreadable message fails the file.
    required: bool,
    /// Messages left out because they did not decode (only when not required).
    pub(super) unreadable: Option<UnreadablePoses>,
}

impl AnchorStream {
    /// The anchor channel, when the configuration anchors and the file has it: its first
    /// message is decoded here, so a channel that cannot be read is known before any output.
    /// `Ok(None)` when not anchoring or when an optional channel is absent or empty.
    ///
    /// # Errors
    /// A required channel that is absent or empty ([`Error::NoPoses`]), a channel whose schema
    /// is not a pose, or whose first message does not decode ([`Error::AnchorPoses`] when
    /// required); the caller reports these for an optional channel and goes on without it.
    pub(super) fn open(input: &McapInput, config: &ProcessConfig) -> Result<Option<Self>> {
        if config.processor.pose_source.is_external() {
            return Ok(None); // external poses are already in their own world frame
        }
        let (topic, required) = match &config.anchor {
            OdometryAnchor::FirstCamera => return Ok(None),
            OdometryAnchor::IfPresent(t) => (t, false),
            OdometryAnchor::Required(t) => (t, true),
        };
        // An absent or empty channel: an error when required, else no anchor.
        let absent = || match required {
            false => Ok(None),
            true => Err(Error::NoPoses {
                path: input.path().to_owned(),
                role: PoseRole::Anchor,
                topic: topic.clone(),
                child_frame: None,
                channels: input.channels().values().map(|c| c.topic.clone()).collect(),
            }),
        };
        let Some(channel) = input.channel_by_topic(topic) else {
            return absent();
        };
        let Some(channel_type) = channel.channel_type.filter(|ct| ct.is_pose()) else {
            return Err(unreadable(
                topic,
                required,
                unsupported_schema(channel, POSE_SCHEMA),
            ));
        };
        let Some(first) = input.first_message(channel.id)? else {
            return absent();
        };
        decode_poses(channel_type, topic, &first.data).map_err(|e| unreadable(topic, required, e))?;
        // The first message is read again, in its turn, by `observe`.
        Ok(Some(Self {
            channel: PoseChannel::new(topic.clone(), channel.id, channel_type),
            required,
            unreadable: None,
        }))
    }

    /// Takes the channel's samples from `message` (any input message, in read order).
    ///
    /// # Errors
    /// A message of a required channel that does not decode ([`Error::AnchorPoses`]); one of an
    /// optional channel is left out and counted in [`Self::unreadable`].
    pub(super) fn observe(&mut self, message: &RawMessage) -> Result<()> {
        match self.channel.read(message) {
            None => Ok(()),
            Some(Ok(samples)) => {
                for sample in &samples {
                    self.channel.samples.insert(sample);
                }
                Ok(())
            }
            Some(Err(e)) if self.required => Err(unreadable(&self.channel.topic, true, e)),
            Some(Err(e)) => {
                let u = self.unreadable.get_or_insert_with(|| UnreadablePoses {
                    messages: 0,
                    first_error: e.to_string(),
                });
                u.messages += 1;
                Ok(())
            }
        }
    }

    /// The input has been read to its end.
    pub(super) fn finish(&mut self) {
        self.channel.samples.complete = true;
    }

    /// The channel's topic.
    pub(super) fn topic(&self) -> &str {
        &self.channel.topic
    }

    /// Whether the anchor pose of a frame stamped `stamp_ns` and logged at `log_time_ns` is
    /// known ([`StreamedPoses::settled`]).
    pub(super) fn settled(&self, stamp_ns: u64, log_time_ns: u64) -> bool {
        self.channel.samples.settled(stamp_ns, log_time_ns)
    }

    /// The samples read so far, sorted by stamp.
    pub(super) fn poses(&self) -> &[StampedPose] {
        &self.channel.samples.poses
    }
}

/// A decode error of the anchor channel: [`Error::AnchorPoses`] when the channel is required
/// (the CLI then names `--no-anchor`), else as it is (reported, and the channel not used).
fn unreadable(topic: &str, required: bool, error: Error) -> Error {
    match error {
        Error::Decode { .. } if required => Error::AnchorPoses {
            topic: topic.to_owned(),
            error: Box::new(error),
        },
        other => other,
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

#[cfg(test)]
mod tests {
    use super::*;
    use mcap::records::MessageHeader;
    use prost::Message;

    const CHANNEL: u16 = 7;
    const MS: u64 = 1_000_000;

    fn stream() -> AnchorStream {
        AnchorStream {
            channel: PoseChannel::new(
                "/groundtruth/pose".into(),
                CHANNEL,
                ChannelType::classify("foxglove.PoseInFrame", "protobuf").unwrap(),
            ),
            required: false,
            unreadable: None,
        }
    }

    fn message(channel_id: u16, log_time: u64, data: Vec<u8>) -> RawMessage {
        RawMessage {
            header: MessageHeader {
                channel_id,
                sequence: 0,
                log_time,
                publish_time: log_time,
            },
            data,
        }
    }

    /// A pose message stamped `stamp_ns` at x = `x`, logged at `log_time`.
    fn pose(stamp_ns: u64, x: f64, log_time: u64) -> RawMessage {
        let pose = Isometry3::translation(x, 0.0, 0.0);
        let msg = crate::mcap_io::codec::pose_in_frame(stamp_ns, "world", &pose);
        message(CHANNEL, log_time, msg.encode_to_vec())
    }

    #[test]
    fn a_frame_settles_once_a_sample_at_or_after_it_is_read_or_the_input_moves_on() {
        let mut s = stream();
        s.observe(&pose(100 * MS, 0.0, 105 * MS)).unwrap();
        // A frame at 130 ms (logged at 131 ms): only the sample before it is read.
        assert!(!s.settled(130 * MS, 131 * MS));
        // Other channels' messages move the read position, not the samples.
        s.observe(&message(1, 140 * MS, vec![1, 2, 3])).unwrap();
        assert!(!s.settled(130 * MS, 131 * MS));
        s.observe(&pose(133 * MS, 1.0, 141 * MS)).unwrap();
        assert!(s.settled(130 * MS, 131 * MS));
        assert!(s.settled(133 * MS, 134 * MS));
        assert!(!s.settled(150 * MS, 151 * MS));
        // No later sample: the frame settles once the input is read past its log time by the
        // bound, or at the end.
        s.observe(&message(1, 151 * MS + MAX_POSE_DELAY_NS, Vec::new()))
            .unwrap();
        assert!(!s.settled(150 * MS, 151 * MS));
        s.observe(&message(1, 152 * MS + MAX_POSE_DELAY_NS, Vec::new()))
            .unwrap();
        assert!(s.settled(150 * MS, 151 * MS));
        assert!(!s.settled(2_000 * MS, 2_001 * MS));
        s.finish();
        assert!(s.settled(2_000 * MS, 2_001 * MS));
    }

    #[test]
    fn samples_are_kept_in_stamp_order_with_the_first_of_each_stamp_as_a_whole_read_keeps_them() {
        let mut s = stream();
        for (stamp, x, log) in [
            (20, 2.0, 1),
            (10, 1.0, 2),
            (20, 9.0, 3),
            (30, 3.0, 4),
            (15, 1.5, 5),
        ] {
            s.observe(&pose(stamp * MS, x, log * MS)).unwrap();
        }
        let got: Vec<(u64, f64)> = s
            .poses()
            .iter()
            .map(|p| (p.timestamp_ns / MS, p.world_from_camera.translation.vector.x))
            .collect();
        assert_eq!(got, [(10, 1.0), (15, 1.5), (20, 2.0), (30, 3.0)]);
    }

    #[test]
    fn an_unreadable_sample_is_left_out_and_counted_unless_the_channel_is_required() {
        let mut s = stream();
        s.observe(&pose(10 * MS, 1.0, MS)).unwrap();
        let broken = message(CHANNEL, 2 * MS, vec![0xff; 5]);
        s.observe(&broken).unwrap();
        s.observe(&broken).unwrap();
        s.observe(&pose(20 * MS, 2.0, 3 * MS)).unwrap();
        assert_eq!(s.poses().len(), 2);
        let u = s.unreadable.as_ref().unwrap();
        assert_eq!(u.messages, 2);
        assert!(u.first_error.contains("/groundtruth/pose"), "{}", u.first_error);

        let mut required = AnchorStream {
            required: true,
            ..stream()
        };
        let e = required.observe(&broken).unwrap_err();
        assert!(
            matches!(&e, Error::AnchorPoses { topic, .. } if topic == "/groundtruth/pose"),
            "{e}"
        );
    }
}
