//! The input streams of `occmask process` before and during the frame loop: the calibration,
//! the depth scale and the first image of each stream (what the geometry plan needs), and the
//! decoding of each colour or depth message into the pipeline's pixels.

use std::time::Instant;

use crate::error::{CalibrationGap, Error, MessageAt, Result};
use crate::image_buf::{DepthMeters, GrayF32, ImageSize, Rgb8};
use crate::mcap_io::input::decode::{
    decode_calibration, decode_image, depth_from_image_into, gray_from_image_into, rgb_from_image_into,
    unsupported_schema, CalibrationMsg, IMAGE_SCHEMA,
};
use crate::mcap_io::input::detect::RgbdTopics;
use crate::mcap_io::input::{ChannelType, InputChannel, McapInput, RawMessage};
use crate::mcap_io::DEPTH_UNITS_KEY;
use crate::point_cloud::PointGrid;

use super::config::DEFAULT_DEPTH_UNITS_PER_METER;
use super::pairing::{Pixels, Queued, TimeRange};
#[cfg(doc)]
use super::rectify::plan_geometry;
use super::rectify::{Rectifier, StreamInfo};
use super::threads::BufferPool;

/// Adds which message failed (log time and sequence number, as a player shows them) to a
/// decode error, so the user can find the frame.
pub(super) fn at_message(error: Error, header: &mcap::records::MessageHeader) -> Error {
    match error {
        Error::Decode { topic, problem, .. } => Error::Decode {
            topic,
            at: Some(MessageAt {
                log_time_ns: header.log_time,
                sequence: header.sequence,
            }),
            problem,
        },
        other => other,
    }
}

pub(super) fn missing_calibration(input: &McapInput, topics: &RgbdTopics, reason: CalibrationGap) -> Error {
    Error::MissingCalibration {
        path: input.path().to_owned(),
        color_topic: topics.color.topic.clone(),
        reason,
    }
}

/// The first message of a calibration channel, decoded.
pub(super) fn first_calibration(
    input: &McapInput,
    topics: &RgbdTopics,
    channel: &InputChannel,
) -> Result<CalibrationMsg> {
    let first = input.first_message(channel.id)?.ok_or_else(|| {
        missing_calibration(
            input,
            topics,
            CalibrationGap::NoMessages {
                topic: channel.topic.clone(),
            },
        )
    })?;
    let ct = channel.channel_type.ok_or_else(|| {
        missing_calibration(
            input,
            topics,
            CalibrationGap::UnsupportedSchema {
                topic: channel.topic.clone(),
            },
        )
    })?;
    decode_calibration(ct, &channel.topic, &first.data).map_err(|e| at_message(e, &first.header))
}

/// `frame_id` and size of the first image of a colour (`is_color`) or depth channel: what
/// [`plan_geometry`] needs before the first frame.
pub(super) fn first_image_info(
    input: &McapInput,
    channel: &InputChannel,
    is_color: bool,
    depth_units_per_meter: f64,
) -> Result<StreamInfo> {
    let ct = channel
        .channel_type
        .ok_or_else(|| unsupported_schema(channel, IMAGE_SCHEMA))?;
    let Some(first) = input.first_message(channel.id)? else {
        return Ok(StreamInfo {
            frame_id: String::new(),
            size: ImageSize::default(),
        });
    };
    let decode = || -> Result<StreamInfo> {
        let msg = decode_image(ct, &channel.topic, &first.data)?;
        let size = if is_color {
            let mut gray = GrayF32::filled(ImageSize::default(), 0.0);
            gray_from_image_into(&msg, &channel.topic, &mut gray)?;
            gray.size()
        } else {
            let mut depth = DepthMeters::filled(ImageSize::default(), 0.0);
            depth_from_image_into(&msg, &channel.topic, depth_units_per_meter, &mut depth)?;
            depth.size()
        };
        Ok(StreamInfo {
            frame_id: msg.frame_id,
            size,
        })
    };
    decode().map_err(|e| at_message(e, &first.header))
}

/// Depth units per metre for 16-bit depth: `configured` (`--depth-units-per-meter`), else the
/// depth channel's [`DEPTH_UNITS_KEY`] metadata, else [`DEFAULT_DEPTH_UNITS_PER_METER`].
///
/// # Errors
/// [`Error::BadDepthUnits`] when the metadata is not a positive number.
pub(super) fn depth_units_per_meter(topics: &RgbdTopics, configured: Option<f64>) -> Result<f64> {
    if let Some(u) = configured {
        return Ok(u);
    }
    match topics.depth.metadata.get(DEPTH_UNITS_KEY) {
        Some(text) => text
            .trim()
            .parse::<f64>()
            .ok()
            .filter(|u| u.is_finite() && *u > 0.0)
            .ok_or_else(|| Error::BadDepthUnits {
                topic: topics.depth.topic.clone(),
                key: DEPTH_UNITS_KEY,
                value: text.clone(),
            }),
        None => Ok(DEFAULT_DEPTH_UNITS_PER_METER),
    }
}

/// Decodes the colour and depth messages of the prefetch thread into the pipeline's pixels
/// (grey 0..1 and metres), undistorted and registered by the [`Rectifier`].
pub(super) struct ImageDecoder<'a> {
    pub(super) topics: &'a RgbdTopics,
    pub(super) color_ct: ChannelType,
    pub(super) depth_ct: ChannelType,
    pub(super) depth_units_per_meter: f64,
    /// Measure the decoding time (written to `/occmask/stats` with `--timings`).
    pub(super) timings: bool,
    /// `--points`: colour images are also sampled at the grid's points.
    pub(super) point_grid: Option<&'a PointGrid>,
    /// The frames processed: images that no such frame can use are not decoded.
    pub(super) range: TimeRange,
}

impl ImageDecoder<'_> {
    /// The decoded image when `m` is on the colour (`true`) or depth topic; `None` for other
    /// topics. Buffers come from `pool` when the frame loop has returned some; `rgb` is the
    /// scratch of `--points`' colour decode. `first_color_ns`: the stamp of the first colour
    /// image so far (set here from the first one); an image outside [`Self::range`] is only
    /// parsed for its stamp ([`Pixels::Skipped`]).
    ///
    /// # Errors
    /// Undecodable images (naming the message), size changes, rectification errors.
    pub(super) fn decode(
        &self,
        m: &RawMessage,
        pool: &BufferPool,
        rectifier: &mut Rectifier,
        rgb: &mut Rgb8,
        first_color_ns: &mut Option<u64>,
    ) -> Result<Option<(bool, Queued)>> {
        let topics = self.topics;
        let id = m.header.channel_id;
        if id != topics.color.id && id != topics.depth.id {
            return Ok(None);
        }
        let is_color = id == topics.color.id;
        let start = self.timings.then(Instant::now);
        let (ct, topic) = if is_color {
            (self.color_ct, &topics.color.topic)
        } else {
            (self.depth_ct, &topics.depth.topic)
        };
        let decoded = decode_image(ct, topic, &m.data).and_then(|msg| {
            if is_color {
                first_color_ns.get_or_insert(msg.timestamp_ns);
            }
            if !self.range.may_use(is_color, msg.timestamp_ns, *first_color_ns) {
                return Ok((msg, Pixels::Skipped, 0.0, None));
            }
            // Decoded, then undistorted and registered for the pipeline.
            let mut point_colors = None;
            let (pixels, rectify_s) = if is_color {
                let mut gray = pool
                    .gray
                    .try_recv()
                    .unwrap_or_else(|_| GrayF32::filled(ImageSize::new(0, 0), 0.0));
                let s = rectifier.color(topic, &mut gray, |g| gray_from_image_into(&msg, topic, g))?;
                if let Some(grid) = self.point_grid {
                    // A second decode, into RGB (the grey one keeps its own conversion, so
                    // the masks do not depend on --points); only the samples are kept.
                    rgb_from_image_into(&msg, topic, rgb)?;
                    let mut colors = pool.point_colors.try_recv().unwrap_or_default();
                    grid.sample_colors_into(rgb, &mut colors)?;
                    point_colors = Some(colors);
                }
                (Pixels::Gray(gray), s)
            } else {
                let mut depth = pool
                    .depth
                    .try_recv()
                    .unwrap_or_else(|_| DepthMeters::filled(ImageSize::new(0, 0), 0.0));
                let s = rectifier.depth(topic, &mut depth, |d| {
                    depth_from_image_into(&msg, topic, self.depth_units_per_meter, d)
                })?;
                (Pixels::Depth(depth), s)
            };
            Ok((msg, pixels, rectify_s, point_colors))
        });
        let (msg, pixels, rectify_s, point_colors) = decoded.map_err(|e| at_message(e, &m.header))?;
        Ok(Some((
            is_color,
            Queued {
                log_time_ns: m.header.log_time,
                timestamp_ns: msg.timestamp_ns,
                frame_id: msg.frame_id,
                pixels,
                decode_ms: start.map_or(0.0, |t| t.elapsed().as_secs_f64() * 1e3),
                rectify_s,
                point_colors,
            },
        )))
    }
}
