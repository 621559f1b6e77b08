//! The frame loop of `occmask process` (the calling thread): pairs colour with depth, runs the
//! [`FrameProcessor`], anchors the trajectory, and hands each frame's new messages and the
//! copied input messages to the writer thread in log-time order.

use std::collections::VecDeque;
use std::sync::mpsc::Sender;
use std::time::Instant;

use nalgebra::Isometry3;
use prost::bytes::Bytes;

use crate::error::{Error, Result};
use crate::geometry::camera::PinholeIntrinsics;
use crate::image_buf::{DepthMeters, GrayF32, ImageSize};
use crate::mcap_io::annotate::{moving_pixels, FrameStatsMsg, JsonTime};
use crate::mcap_io::input::detect::RgbdTopics;
use crate::mcap_io::input::RawMessage;
use crate::pipeline::{FrameInput, FrameResult, PoseSource};
use crate::point_cloud::{PointGrid, POINT_STRIDE_BYTES};
use crate::time::split_ns;
use crate::trajectory::{interpolate, StampedPose};

use super::adapter::{FrameProcessor, ProcessorFactory};
#[cfg(doc)]
use super::config::OdometryAnchor;
use super::config::{ProcessConfig, ProcessHooks};
use super::pairing::{Pairer, Pairing, Pixels, Queued, TimeRange};
use super::poses::{anchor_at, AnchorStream, FramePose, InputPoses, MAX_UNANCHORED_FRAMES};
use super::rectify::Publisher;
use super::report::{AnchorFrame, ProcessReport};
use super::threads::{FrameWrite, OutputQueue, WriteOp};

/// What the frame loop reads but does not change.
pub(super) struct FrameContext<'a> {
    pub(super) config: &'a ProcessConfig,
    pub(super) topics: &'a RgbdTopics,
    pub(super) intrinsics: PinholeIntrinsics,
    pub(super) calibration_size: Option<ImageSize>,
    /// The samples of `--points`.
    pub(super) point_grid: Option<&'a PointGrid>,
    /// The frames processed (`--start`, `--end`).
    pub(super) range: TimeRange,
}

/// The frame loop's state.
pub(super) struct FrameLoop {
    pub(super) pairer: Pairer,
    pub(super) pending: VecDeque<RawMessage>,
    /// Colour–depth pairs waiting for the pose source's channel to be read past them
    /// ([`InputPoses::settled`]; oldest first).
    pub(super) unposed: VecDeque<(Queued, Queued)>,
    /// The pose source's poses from the input.
    pub(super) poses: InputPoses,
    /// Frames given to the processor whose results have not come back yet (oldest first).
    pub(super) in_flight: VecDeque<InFlight>,
    /// Results waiting for the anchor channel to be read past them ([`AnchorStream::settled`];
    /// oldest first).
    pub(super) waiting: VecDeque<(InFlight, FrameResult)>,
    /// Results the anchor channel does not cover, waiting for the first frame it does (oldest
    /// first, all before `waiting`).
    pub(super) unanchored: Vec<(InFlight, FrameResult)>,
    /// [`OdometryAnchor`]: the channel, when the trajectory is anchored.
    pub(super) anchor: Option<AnchorStream>,
    pub(super) gray: GrayF32,
    pub(super) depth_m: DepthMeters,
    /// Maps masks back to the published colour pixels (the input side of the registration
    /// and undistortion runs on the prefetch thread).
    pub(super) publisher: Publisher,
    pub(super) processor: Option<Box<dyn FrameProcessor>>,
    /// Maps the processor's `world` (its first camera) into the output's `world`; set at the
    /// first processed frame ([`OdometryAnchor`]).
    pub(super) world_from_odometry: Option<Isometry3<f64>>,
    pub(super) first_color_ns: Option<u64>,
    /// No frame is processed any more (a frame past `--end` was reached, or the input ended):
    /// the processor has been finished.
    pub(super) processing_done: bool,
    /// [`WriteOp::EndPaths`] is sent: the last frame is written.
    pub(super) paths_ended: bool,
    pub(super) report: ProcessReport,
    /// Returns processed image buffers to the prefetch thread.
    pub(super) recycle: (Sender<GrayF32>, Sender<DepthMeters>),
    /// Returns the point colour samples to the prefetch thread.
    pub(super) recycle_point_colors: Sender<Vec<[u8; 3]>>,
    /// Depth sample buffers of `--points` not in use.
    pub(super) spare_point_depth: Vec<Vec<f32>>,
}

/// What the frame loop keeps of a frame while the processor works on it.
pub(super) struct InFlight {
    log_time_ns: u64,
    timestamp_ns: u64,
    frame_id: String,
    decode_ms: f64,
    process_ms: f64,
    /// `--points`: the frame's samples until its mask is known, then its packed points.
    points: Option<PointSamples>,
    cloud: Option<Bytes>,
}

/// The depth and colour of a frame at the [`PointGrid`] samples.
struct PointSamples {
    depth_m: Vec<f32>,
    colors: Vec<[u8; 3]>,
}

impl FrameLoop {
    /// Pairs what can be paired, processes the pairs whose pose source is read past them, writes
    /// the results whose anchor is, and copies input messages that can no longer have new
    /// messages written before them.
    pub(super) fn drain(
        &mut self,
        ctx: &FrameContext<'_>,
        output: &OutputQueue,
        make_processor: &mut ProcessorFactory<'_>,
        hooks: &mut dyn ProcessHooks,
        end_of_stream: bool,
    ) -> Result<()> {
        // The message just read may be the anchor sample that settles the waiting results.
        self.release(ctx, output, hooks)?;
        while let Some(p) = self.pairer.next(end_of_stream) {
            match p {
                Pairing::UnpairedColor => self.report.unpaired_color += 1,
                Pairing::UnpairedDepth => self.report.unpaired_depth += 1,
                Pairing::Pair(pair) => self.unposed.push_back(*pair),
            }
        }
        while let Some((color, depth)) = pop_front_if(&mut self.unposed, |(color, _)| {
            self.poses.settled(color.timestamp_ns, color.log_time_ns)
        }) {
            self.frame(ctx, output, make_processor, hooks, color, depth)?;
        }
        if end_of_stream {
            self.finish_processing(ctx, output, hooks)?;
        }
        // Every frame's result is in once processing is done and none waits for the anchor
        // channel (at the end of the input none does): the held ones will not be anchored by a
        // later frame, and the paths end here, before the input messages logged after the last
        // frame, which are copied below.
        if self.processing_done && (end_of_stream || self.waiting.is_empty()) && !self.paths_ended {
            if !self.unanchored.is_empty() {
                self.give_up_anchor(ctx);
                self.flush_unanchored(ctx, output, hooks)?;
            }
            output.send(WriteOp::EndPaths)?;
            self.paths_ended = true;
        }
        // New messages are still to come for frames being paired or processed: input messages
        // after the oldest of them wait.
        let limit = if end_of_stream {
            u64::MAX
        } else {
            let pairing = self
                .unposed
                .front()
                .map(|(color, _)| color.log_time_ns)
                .into_iter()
                .chain(self.pairer.oldest_color_log_time())
                .min()
                .unwrap_or(u64::MAX);
            let held = self
                .unanchored
                .first()
                .or(self.waiting.front())
                .map(|(f, _)| f.log_time_ns);
            let processing = held
                .or(self.in_flight.front().map(|f| f.log_time_ns))
                .unwrap_or(u64::MAX);
            pairing.min(processing)
        };
        while self.pending.front().is_some_and(|m| m.header.log_time <= limit) {
            if let Some(m) = self.pending.pop_front() {
                output.send(WriteOp::Copy(m))?;
            }
        }
        Ok(())
    }

    /// Finishes the processor, once: the results of the frames it holds are written as they
    /// become final, so the writer thread compresses while it finishes the later frames.
    fn finish_processing(
        &mut self,
        ctx: &FrameContext<'_>,
        output: &OutputQueue,
        hooks: &mut dyn ProcessHooks,
    ) -> Result<()> {
        if std::mem::replace(&mut self.processing_done, true) {
            return Ok(());
        }
        let Some(mut processor) = self.processor.take() else {
            return Ok(());
        };
        let pipeline_start = Instant::now();
        let mut writing_s = 0.0;
        let finished = processor.finish(&mut |result| {
            let write_start = Instant::now();
            let written = self.write_result(ctx, output, hooks, result);
            writing_s += write_start.elapsed().as_secs_f64();
            written
        });
        self.report.timings.pipeline_s += pipeline_start.elapsed().as_secs_f64() - writing_s;
        self.report.colour_registration = processor.colour_registration();
        self.processor = Some(processor);
        finished
    }

    fn frame(
        &mut self,
        ctx: &FrameContext<'_>,
        output: &OutputQueue,
        make_processor: &mut ProcessorFactory<'_>,
        hooks: &mut dyn ProcessHooks,
        color: Queued,
        depth: Queued,
    ) -> Result<()> {
        let stamp = color.timestamp_ns;
        let first_color_ns = self.first_color_ns.unwrap_or(stamp);
        if self.processing_done || !ctx.range.keeps(stamp, first_color_ns) {
            self.report.outside_time_range += 1;
            if ctx.range.is_past_end(stamp, first_color_ns) {
                // The range ends at the first frame past it: the frames the processor holds
                // are finished now, so the input read after them is not held in memory until
                // the end of the file.
                self.finish_processing(ctx, output, hooks)?;
            }
            return Ok(());
        }
        if self.report.last_timestamp_ns.is_some_and(|last| stamp <= last) {
            self.report.out_of_order_frames += 1;
            return Ok(());
        }
        let world_from_marker = match self.poses.at(stamp) {
            FramePose::Estimated => None,
            FramePose::Given(pose) => Some(pose),
            FramePose::Outside => {
                self.report.outside_pose_stream += 1;
                return Ok(());
            }
        };
        let decode_ms = color.decode_ms + depth.decode_ms;
        let rectify_s = color.rectify_s + depth.rectify_s;
        let point_colors = color.point_colors;
        let (Pixels::Gray(gray), Pixels::Depth(depth_m)) = (color.pixels, depth.pixels) else {
            // The prefetch thread left an image of the pair undecoded: by the same range, with
            // the pairing tolerance, so this does not happen; were it to, the frame is outside.
            self.report.outside_time_range += 1;
            return Ok(());
        };
        // The receiver is gone once the prefetch thread has finished: nothing to recycle.
        let _ = self.recycle.0.send(std::mem::replace(&mut self.gray, gray));
        let _ = self.recycle.1.send(std::mem::replace(&mut self.depth_m, depth_m));
        // The prefetch thread checked both sizes against the first images and rectified depth
        // into the colour camera.
        let size = self.gray.size();
        if let Some(cal) = ctx.calibration_size.filter(|c| c.area() > 0 && *c != size) {
            return Err(Error::CalibrationSize {
                color_topic: ctx.topics.color.topic.clone(),
                image: size,
                calibration: cal,
            });
        }
        // The depth the pipeline sees, sampled before its buffer goes back to the prefetch thread.
        let points = match (ctx.point_grid, point_colors) {
            (Some(grid), Some(colors)) => {
                let mut depth_m = self.spare_point_depth.pop().unwrap_or_default();
                grid.sample_depth_into(&self.depth_m, &mut depth_m)?;
                Some(PointSamples { depth_m, colors })
            }
            _ => None,
        };
        let processor = match &mut self.processor {
            Some(p) => p,
            None => self
                .processor
                .insert(make_processor(ctx.intrinsics, size, &ctx.config.processor)?),
        };
        let pipeline_start = Instant::now();
        let results = processor.push(&FrameInput {
            timestamp_ns: stamp,
            gray: &self.gray,
            depth_m: &self.depth_m,
            world_from_marker: world_from_marker.as_ref(),
            ignore_in_previous: None,
        })?;
        let pipeline_s = pipeline_start.elapsed().as_secs_f64();
        self.report.timings.pipeline_s += pipeline_s;
        self.report.timings.rectify_s += rectify_s;
        self.report.last_timestamp_ns = Some(stamp);
        self.in_flight.push_back(InFlight {
            log_time_ns: color.log_time_ns,
            timestamp_ns: stamp,
            frame_id: color.frame_id,
            decode_ms,
            // Measured always (the report), written only with --timings (output bytes).
            process_ms: if ctx.config.timings { pipeline_s * 1e3 } else { 0.0 },
            points,
            cloud: None,
        });
        for result in results {
            self.write_result(ctx, output, hooks, result)?;
        }
        Ok(())
    }

    /// Takes the oldest in-flight frame's result and writes it once the anchor channel has been
    /// read past it ([`Self::release`]).
    fn write_result(
        &mut self,
        ctx: &FrameContext<'_>,
        output: &OutputQueue,
        hooks: &mut dyn ProcessHooks,
        mut result: FrameResult,
    ) -> Result<()> {
        let mut frame = self
            .in_flight
            .pop_front()
            .ok_or_else(|| Error::InvalidParameter {
                name: "frame processor",
                value: "a result for a frame it was not given".into(),
                expected: "one result per frame pushed (internal error)".into(),
            })?;
        if let (Some(grid), Some(samples)) = (ctx.point_grid, frame.points.take()) {
            // Tinted by the mask in the pipeline's pixels, before it is mapped back.
            let mut data = Vec::with_capacity(grid.samples() * POINT_STRIDE_BYTES);
            grid.write_points(&samples.depth_m, &samples.colors, &result.mask, &mut data)?;
            frame.cloud = Some(Bytes::from(data));
            self.spare_point_depth.push(samples.depth_m);
            // The receiver is gone once the prefetch thread has finished: nothing to recycle.
            let _ = self.recycle_point_colors.send(samples.colors);
        }
        if !self.publisher.is_identity() {
            // Back from the pipeline's undistorted pixels to the published colour image's.
            let back_start = Instant::now();
            result.mask = self.publisher.to_published(result.mask)?;
            result.accumulation_m = result
                .accumulation_m
                .map(|a| self.publisher.to_published(a))
                .transpose()?;
            self.report.timings.rectify_s += back_start.elapsed().as_secs_f64();
        }
        self.waiting.push_back((frame, result));
        self.release(ctx, output, hooks)
    }

    /// Writes the waiting results that the anchor channel has been read past, in order: the
    /// first the channel covers anchors the odometry (and releases the uncovered ones before
    /// it); uncovered ones before that are held, up to [`MAX_UNANCHORED_FRAMES`].
    fn release(
        &mut self,
        ctx: &FrameContext<'_>,
        output: &OutputQueue,
        hooks: &mut dyn ProcessHooks,
    ) -> Result<()> {
        while let Some((frame, result)) = pop_front_if(&mut self.waiting, |(frame, _)| {
            self.anchor
                .as_ref()
                .is_none_or(|a| a.settled(frame.timestamp_ns, frame.log_time_ns))
        }) {
            if self.world_from_odometry.is_none() {
                match &self.anchor {
                    None => self.world_from_odometry = Some(Isometry3::identity()),
                    Some(anchor) => match anchor_at(
                        anchor.poses(),
                        ctx.config.max_pose_gap_ns,
                        frame.timestamp_ns,
                        &result.world_from_camera,
                    ) {
                        Some(world_from_odometry) => {
                            self.world_from_odometry = Some(world_from_odometry);
                            self.report.anchor_frame = Some(AnchorFrame {
                                index: self.report.frames + self.unanchored.len() as u64,
                                timestamp_ns: frame.timestamp_ns,
                            });
                            self.flush_unanchored(ctx, output, hooks)?;
                        }
                        None if self.unanchored.len() < MAX_UNANCHORED_FRAMES => {
                            self.unanchored.push((frame, result));
                            continue;
                        }
                        None => {
                            self.give_up_anchor(ctx);
                            self.flush_unanchored(ctx, output, hooks)?;
                        }
                    },
                }
            }
            self.emit(ctx, output, hooks, frame, result)?;
        }
        Ok(())
    }

    /// No frame is covered by the anchor channel (within [`MAX_UNANCHORED_FRAMES`]): the first
    /// camera is `world`.
    fn give_up_anchor(&mut self, ctx: &FrameContext<'_>) {
        if let Some(anchor) = &self.anchor {
            self.report.anchor_skipped = Some(format!(
                "{} has no pose within {} ms of the first {} processed frames",
                anchor.topic(),
                ctx.config.max_pose_gap_ns / 1_000_000,
                self.unanchored.len()
            ));
        }
        self.world_from_odometry = Some(Isometry3::identity());
    }

    /// Writes the held results, now that the odometry's frame is known.
    fn flush_unanchored(
        &mut self,
        ctx: &FrameContext<'_>,
        output: &OutputQueue,
        hooks: &mut dyn ProcessHooks,
    ) -> Result<()> {
        for (frame, result) in std::mem::take(&mut self.unanchored) {
            self.emit(ctx, output, hooks, frame, result)?;
        }
        Ok(())
    }

    /// Writes one frame's result (and the input messages before it) in the anchored frame.
    fn emit(
        &mut self,
        ctx: &FrameContext<'_>,
        output: &OutputQueue,
        hooks: &mut dyn ProcessHooks,
        frame: InFlight,
        result: FrameResult,
    ) -> Result<()> {
        let stamp = frame.timestamp_ns;
        // Copy everything that precedes this frame's new messages.
        while self
            .pending
            .front()
            .is_some_and(|m| m.header.log_time <= frame.log_time_ns)
        {
            if let Some(m) = self.pending.pop_front() {
                output.send(WriteOp::Copy(m))?;
            }
        }
        let stats = stats_message(
            self.report.frames,
            stamp,
            &ctx.config.processor.pose_source,
            &result,
            frame.decode_ms,
            frame.process_ms,
        );
        let world_from_odometry = self.world_from_odometry.unwrap_or_else(Isometry3::identity);
        let pose = StampedPose {
            timestamp_ns: stamp,
            world_from_camera: world_from_odometry * result.world_from_camera,
        };
        // The anchor channel's own pose here, for its path beside the estimated one.
        let anchor_pose = match (self.world_from_odometry, &self.anchor) {
            (Some(_), Some(anchor)) => interpolate(anchor.poses(), stamp, ctx.config.max_pose_gap_ns),
            _ => None,
        };
        hooks.frame_done(&pose, &result.mask)?;
        output.send(WriteOp::Frame(Box::new(FrameWrite {
            log_time_ns: frame.log_time_ns,
            timestamp_ns: stamp,
            frame_id: frame.frame_id,
            mask: result.mask,
            world_from_camera: pose.world_from_camera,
            anchor_pose,
            accumulation: result.accumulation_m,
            points: frame.cloud,
            stats,
        })))?;
        self.report.frames += 1;
        Ok(())
    }
}

/// The front of `queue`, taken when `ready` says so.
fn pop_front_if<T>(queue: &mut VecDeque<T>, ready: impl FnOnce(&T) -> bool) -> Option<T> {
    if queue.front().is_some_and(ready) {
        queue.pop_front()
    } else {
        None
    }
}

/// The `/occmask/stats` message of one frame.
fn stats_message(
    frame_index: u64,
    stamp: u64,
    pose_source: &PoseSource,
    result: &FrameResult,
    decode_ms: f64,
    process_ms: f64,
) -> FrameStatsMsg {
    let stats = &result.stats;
    let (dvo_iterations, dvo_cost) = match &stats.dvo {
        Some(d) if !pose_source.is_external() => (d.iterations_per_level.iter().sum(), d.final_cost),
        _ => (0, 0.0),
    };
    let moving = moving_pixels(&result.mask);
    let (sec, nsec) = split_ns(stamp);
    FrameStatsMsg {
        timestamp: JsonTime {
            sec: sec.into(),
            nsec,
        },
        frame_index,
        pose_source: pose_source.as_str().into(),
        dvo_status: stats.outcome.as_str().into(),
        dvo_iterations,
        dvo_cost: finite_or_zero(dvo_cost),
        pose_fallback: stats.pose_fallback.as_str().into(),
        consecutive_failures: stats.consecutive_failures,
        detector_reset: stats.detector_reset,
        valid_depth_fraction: finite_or_zero(stats.valid_depth_fraction),
        moving_fraction: moving as f64 / result.mask.size().area().max(1) as f64,
        moving_pixels: moving,
        decode_ms: finite_or_zero(decode_ms),
        process_ms: finite_or_zero(process_ms),
    }
}
/// `value`, or 0 when it is NaN or infinite (JSON has no NaN: serde_json would write `null`,
/// which the schema's `number` fields reject).
fn finite_or_zero(value: f64) -> f64 {
    if value.is_finite() {
        value
    } else {
        0.0
    }
}
