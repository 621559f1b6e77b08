//! `occmask process` for one file: read an RGB-D MCAP, pair colour with depth, run a
//! [`FrameProcessor`] per pair, and write the annotated copy or sidecar.
//!
//! Three threads per file, so the pipeline (DVO + detector, itself row-parallel on rayon) is
//! the only serial part: a prefetch thread reads, decompresses and decodes the images; the
//! frame loop (the calling thread) pairs colour with depth and runs the pipeline; a writer
//! thread encodes the new messages (mask, outlines, poses, stats), copies the input messages
//! and compresses the chunks. The writer makes the same calls in the same order as one
//! thread would, so the output bytes do not depend on thread timing. [`LoopTimings`] in the
//! report says where the frame loop waited.
//!
//! Memory is bounded whatever the file length: messages stream through (indexed, log-time
//! order when the file has a summary) with at most [`PREFETCH_BYTES`] read ahead and
//! [`WRITE_QUEUE_BYTES`] queued for writing, at most [`MAX_QUEUED_IMAGES`] colour and depth
//! images wait for a partner, and input messages wait only until no new message can be written
//! before them (new messages take the colour message's log time, so the output stays in
//! log-time order). The estimated trajectory is not kept: each pose goes to
//! [`ProcessHooks::frame_done`]. What does grow with the file is what the MCAP format puts in
//! the summary (one chunk index per output chunk, written at the end) and, with
//! `--pose-topic`, the external pose stream, which is read whole before the first frame.
//!
//! The module's parts: [`config`] (what the caller gives), [`report`] (what it gets back),
//! [`adapter`] (the [`FrameProcessor`] boundary and the pipeline behind it), `streams`
//! (calibration, depth scale, first images, image decoding), `poses` (what a pose source and
//! the anchor read from the input), `pairing` (colour–depth pairing), `threads` (prefetch and
//! writer threads), `frame_loop` (the loop over pairs), [`rectify`] (registration and
//! undistortion), [`batch`] (several files in parallel), `existing` (whether an output that
//! exists is a finished run of the same input and parameters); [`process_file`] here puts them
//! together.

use std::collections::{BTreeMap, VecDeque};
use std::io::{Seek, Write};
use std::time::Instant;

use crate::error::{CalibrationGap, Error, Result};
use crate::geometry::distortion::CameraModel;
use crate::image_buf::{DepthMeters, GrayF32, ImageSize, Rgb8};
use crate::mcap_io::annotate::{
    earlier_annotation_topics, AnnotatedWriter, METADATA_ODOMETRY_ANCHOR, METADATA_PROCESS,
    METADATA_PROCESSOR_CONFIG,
};
use crate::mcap_io::input::decode::{unsupported_schema, IMAGE_SCHEMA};
use crate::mcap_io::input::detect::detect_topics;
use crate::mcap_io::input::McapInput;
use crate::mcap_io::DEPTH_UNITS_KEY;
use crate::point_cloud::PointGrid;

pub mod adapter;
pub mod batch;
pub mod config;
mod existing;
mod frame_loop;
mod pairing;
mod poses;
mod queue;
pub mod rectify;
pub mod report;
mod streams;
mod threads;

pub use adapter::{
    pipeline_factory, FrameProcessor, FrameSink, PipelineOptions, PipelineProcessor, ProcessorFactory,
};
pub use config::{
    NoHooks, OdometryAnchor, ProcessConfig, ProcessHooks, DEFAULT_DEPTH_UNITS_PER_METER,
    DEFAULT_MAX_POSE_GAP_NS, DEFAULT_PAIR_TOLERANCE_NS,
};
pub use existing::{check_existing_output, recorded_input_difference, InputDifference};
pub use pairing::MAX_QUEUED_IMAGES;
pub use report::{truncation_metadata, AnchorFrame, LoopTimings, ProcessReport, UnreadablePoses};
pub use threads::{PREFETCH_BYTES, PREFETCH_MAX_MESSAGES, WRITE_QUEUE_BYTES, WRITE_QUEUE_MAX_OPS};

use frame_loop::{FrameContext, FrameLoop};
use pairing::{Pairer, TimeRange};
use poses::{topic_overrides, AnchorStream, InputPoses};
use queue::byte_queue;
use rectify::{plan_geometry, Rectifier};
use streams::{first_calibration, first_image_info, missing_calibration, ImageDecoder};
use threads::{write_ops, BufferPool, OutputQueue, Prefetched, WriteOp};

/// Processes one input file into `sink`; see the module documentation. The pose source, DVO,
/// detector and failure parameters come from [`ProcessConfig::processor`]; `make_processor`
/// builds the [`FrameProcessor`] once the image size is known ([`pipeline_factory`] for the
/// pipeline).
///
/// # Errors
/// [`Error::BadMcap`] for a file that is not a usable MCAP; [`Error::NoTopic`],
/// [`Error::AmbiguousTopic`] and [`Error::UnknownTopic`] for channels that cannot be chosen;
/// [`Error::MissingCalibration`],
/// [`Error::CalibrationSize`], [`Error::BadDepthUnits`], [`Error::NoPoses`],
/// [`Error::AnchorPoses`], [`Error::DepthNotRegistered`] and [`Error::MissingTransform`] for
/// what the file lacks (the CLI names the flag that supplies it); [`Error::Decode`] for
/// undecodable or unsupported messages; [`Error::SizeMismatch`] when colour and depth differ
/// in size; [`Error::AlreadyAnnotated`] for an input an earlier run annotated, unless
/// [`crate::mcap_io::annotate::AnnotateOptions::replace_earlier`]; I/O and MCAP errors.
pub fn process_file<W: Write + Seek + Send>(
    input: &McapInput,
    sink: W,
    config: &ProcessConfig,
    make_processor: &mut ProcessorFactory<'_>,
    hooks: &mut dyn ProcessHooks,
) -> Result<(W, ProcessReport)> {
    let earlier = earlier_annotation_topics(input);
    if !earlier.is_empty() && !config.annotate.replace_earlier {
        return Err(Error::AlreadyAnnotated { topics: earlier });
    }
    let topics = detect_topics(input, &topic_overrides(config))?;

    // Calibration: the flag, else the first message of the calibration channel.
    let color_calibration = match &topics.calibration {
        Some(channel) => Some(first_calibration(input, &topics, channel)?),
        None => None,
    };
    let (intrinsics, distortion, calibration_size) = match (config.intrinsics, &color_calibration) {
        (Some(k), _) => (k, config.camera_distortion, None),
        (None, Some(calibration)) => {
            let topic = topics.calibration.as_ref().map_or("", |c| c.topic.as_str());
            let distortion = if config.geometry.no_undistort {
                // Reported, not used: an unsupported model is no error then.
                calibration.distortion(topic).ok().flatten()
            } else {
                calibration.distortion(topic)?
            };
            (calibration.intrinsics(topic)?, distortion, Some(calibration.size))
        }
        (None, None) => return Err(missing_calibration(input, &topics, CalibrationGap::NoChannel)),
    };
    let depth_calibration = match &topics.depth_calibration {
        Some(channel) => Some(first_calibration(input, &topics, channel)?),
        None => None,
    };
    let depth_units_per_meter = streams::depth_units_per_meter(&topics, config.depth_units_per_meter)?;
    let color_stream = first_image_info(input, &topics.color, true, depth_units_per_meter)?;
    let depth_stream = first_image_info(input, &topics.depth, false, depth_units_per_meter)?;
    let geometry = plan_geometry(
        input,
        &topics,
        &color_stream,
        &depth_stream,
        CameraModel {
            size: color_stream.size,
            intrinsics,
            distortion,
        },
        color_calibration.as_ref(),
        depth_calibration.as_ref(),
        &config.geometry,
    )?;
    let (rectifier, publisher) = Rectifier::new(&geometry)?;
    // Points come from the pipeline's (undistorted, registered) depth, their colours from the
    // published colour image through the lens.
    let point_grid = config
        .annotate
        .points_stride_px
        .map(|stride| {
            PointGrid::new(
                &geometry.pipeline,
                geometry.undistort_color.then_some(&geometry.color),
                stride,
            )
        })
        .transpose()?;
    let input_poses = InputPoses::open(input, &topics, config)?;
    let (anchor, anchor_skipped) = match AnchorStream::open(input, config) {
        Ok(anchor) => (anchor, None),
        Err(e) if matches!(config.anchor, OdometryAnchor::IfPresent(_)) => (None, Some(e.to_string())),
        Err(e) => return Err(e),
    };

    let mut writer = AnnotatedWriter::new(sink, input, &config.annotate)?;
    if anchor.is_some() {
        writer.add_anchor_path()?;
    }
    let mut metadata = BTreeMap::from([
        ("tool".to_owned(), crate::mcap_io::LIBRARY.to_owned()),
        (
            "intrinsics".to_owned(),
            format!(
                "{},{},{},{}",
                intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy
            ),
        ),
        (DEPTH_UNITS_KEY.to_owned(), depth_units_per_meter.to_string()),
        (
            METADATA_PROCESSOR_CONFIG.to_owned(),
            existing::recorded_processor_config(&config.processor)?,
        ),
    ]);
    metadata.extend(existing::recorded_run_choices(&topics, config));
    metadata.extend(existing::input_identity(input));
    metadata.extend(geometry.metadata());
    if let Some(grid) = &point_grid {
        metadata.insert("points_stride_px".to_owned(), grid.stride_px().to_string());
    }
    if let Some(anchor) = &anchor {
        metadata.insert(METADATA_ODOMETRY_ANCHOR.to_owned(), anchor.topic().to_owned());
    }
    if let Some(t) = input.truncation() {
        // Recorded only for damaged inputs, so complete inputs keep their exact bytes.
        metadata.extend(truncation_metadata(t));
    }
    writer.write_metadata(METADATA_PROCESS, metadata)?;

    let color_ct = topics
        .color
        .channel_type
        .ok_or_else(|| unsupported_schema(&topics.color, IMAGE_SCHEMA))?;
    let depth_ct = topics
        .depth
        .channel_type
        .ok_or_else(|| unsupported_schema(&topics.depth, IMAGE_SCHEMA))?;
    let copy = config.annotate.copy_input;
    let read_topics: Option<Vec<String>> = if copy {
        None
    } else {
        let mut read = vec![topics.color.topic.clone(), topics.depth.topic.clone()];
        if config.processor.pose_source.is_external() {
            read.extend(topics.pose.as_ref().map(|p| p.topic.clone()));
        }
        read.extend(anchor.as_ref().map(|a| a.topic().to_owned()));
        Some(read)
    };

    // Image buffers go back from the frame loop to the prefetch thread once processed, so
    // decoding reuses them instead of allocating and zero-filling 2.4 MB per VGA frame.
    let (gray_tx, gray_rx) = std::sync::mpsc::channel();
    let (depth_tx, depth_rx) = std::sync::mpsc::channel();
    let (colors_tx, colors_rx) = std::sync::mpsc::channel();
    let pool_rx = BufferPool {
        gray: gray_rx,
        depth: depth_rx,
        point_colors: colors_rx,
    };
    let mut state = FrameLoop {
        pairer: Pairer::new(config.pair_tolerance_ns),
        pending: VecDeque::new(),
        unposed: VecDeque::new(),
        poses: input_poses,
        in_flight: VecDeque::new(),
        waiting: VecDeque::new(),
        unanchored: Vec::new(),
        anchor,
        gray: GrayF32::filled(ImageSize::new(0, 0), 0.0),
        depth_m: DepthMeters::filled(ImageSize::new(0, 0), 0.0),
        recycle: (gray_tx, depth_tx),
        recycle_point_colors: colors_tx,
        spare_point_depth: Vec::new(),
        publisher,
        processor: None,
        world_from_odometry: None,
        first_color_ns: None,
        processing_done: false,
        paths_ended: false,
        report: ProcessReport {
            topics: topics.clone(),
            intrinsics: geometry.pipeline.intrinsics,
            geometry: geometry.clone(),
            depth_units_per_meter,
            color_messages: 0,
            depth_messages: 0,
            frames: 0,
            unpaired_color: 0,
            unpaired_depth: 0,
            outside_time_range: 0,
            outside_pose_stream: 0,
            copied_messages: 0,
            replaced_messages: 0,
            new_messages: 0,
            input_truncated: input.is_truncated(),
            input_truncation: input.truncation().copied(),
            out_of_order_frames: 0,
            last_timestamp_ns: None,
            timings: LoopTimings::default(),
            anchor_skipped,
            anchor_frame: None,
            anchor_unreadable: None,
            colour_registration: None,
        },
    };
    let ctx = FrameContext {
        config,
        topics: &topics,
        // The pipeline sees the undistorted pinhole camera (its K when the lens was undistorted
        // into a magnified K; see rectify::inscribed_pinhole).
        intrinsics: geometry.pipeline.intrinsics,
        calibration_size,
        point_grid: point_grid.as_ref(),
        range: TimeRange::of(config),
    };
    // A prefetch thread reads and decodes (PNG/JPEG, depth scaling) while this thread runs the
    // pipeline and writes: decoding then overlaps with processing.
    let decoder = ImageDecoder {
        topics: &topics,
        color_ct,
        depth_ct,
        depth_units_per_meter,
        timings: config.timings,
        point_grid: point_grid.as_ref(),
        range: ctx.range,
    };
    let loop_start = Instant::now();
    let mut output_wait = std::time::Duration::ZERO;
    let (mut loop_s, mut writer_tail_s) = (0.0, 0.0);
    let (loop_result, writer_result) = std::thread::scope(|scope| {
        let (write_tx, write_rx) = byte_queue::<WriteOp>(WRITE_QUEUE_BYTES, WRITE_QUEUE_MAX_OPS);
        let writer_thread = scope.spawn(move || write_ops(writer, write_rx));
        let output = OutputQueue {
            ops: write_tx,
            waited: std::cell::Cell::new(std::time::Duration::ZERO),
        };
        let (tx, rx) = byte_queue::<Result<Prefetched>>(PREFETCH_BYTES, PREFETCH_MAX_MESSAGES);
        let read_topics = read_topics.as_deref();
        let decoder = &decoder;
        let mut rectifier = rectifier;
        scope.spawn(move || {
            let mut rgb = Rgb8::filled(ImageSize::new(0, 0), [0; 3]);
            let mut first_color_ns = None;
            let result = input.for_each_message(read_topics, None, |message| {
                let item = decoder
                    .decode(&message, &pool_rx, &mut rectifier, &mut rgb, &mut first_color_ns)
                    .map(|image| Prefetched { message, image });
                let bytes = item.as_ref().map_or(0, Prefetched::bytes);
                let failed = item.is_err();
                // A closed channel means the consumer stopped (error or Ctrl-C): stop reading.
                Ok(tx.send(item, bytes).is_ok() && !failed)
            });
            if let Err(e) = result {
                let _ = tx.send(Err(e), 0);
            }
        });
        let frame_loop = || -> Result<()> {
            let mut read = 0u64;
            // `rx` moves into the loop and is dropped on any early return, which stops the
            // prefetch thread.
            let mut rx = rx;
            loop {
                let wait_start = Instant::now();
                let Some(item) = rx.next() else { break };
                state.report.timings.input_wait_s += wait_start.elapsed().as_secs_f64();
                let Prefetched { message, image } = item?;
                read += 1;
                state.poses.observe(&message)?;
                if let Some(anchor) = &mut state.anchor {
                    anchor.observe(&message)?;
                }
                if hooks.messages_read(read).is_break() {
                    return Err(Error::Interrupted {
                        done: read as usize,
                        total: input.message_count().unwrap_or(read) as usize,
                    });
                }
                match image {
                    Some((true, queued)) => {
                        state.report.color_messages += 1;
                        state.first_color_ns.get_or_insert(queued.timestamp_ns);
                        state.pairer.color.push_back(queued);
                    }
                    Some((false, queued)) => {
                        state.report.depth_messages += 1;
                        state.pairer.depth.push_back(queued);
                    }
                    None => {}
                }
                if copy {
                    state.pending.push_back(message);
                }
                state.drain(&ctx, &output, make_processor, hooks, false)?;
                if !copy && state.paths_ended && state.report.frames > 0 {
                    // A sidecar past the range's last frame: nothing more is written, so the
                    // rest of the input is not read (with no frame processed, it is, for the
                    // counts the error reports).
                    break;
                }
            }
            state.poses.finish(input.path())?;
            if let Some(anchor) = &mut state.anchor {
                anchor.finish();
            }
            state.drain(&ctx, &output, make_processor, hooks, true)
        };
        let loop_result = frame_loop();
        loop_s = loop_start.elapsed().as_secs_f64();
        output_wait = output.waited.get();
        // Closing the queue ends the writer thread once it has written everything queued.
        drop(output);
        let writer_result = writer_thread
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        writer_tail_s = loop_start.elapsed().as_secs_f64() - loop_s;
        (loop_result, writer_result)
    });
    // A writer error (e.g. a full disk) is the cause when both failed: the frame loop only
    // saw the closed queue.
    let writer = writer_result?;
    loop_result?;
    state.report.timings.output_wait_s = output_wait.as_secs_f64();
    state.report.timings.loop_s = loop_s;
    state.report.timings.writer_tail_s = writer_tail_s;
    state.report.anchor_unreadable = state.anchor.and_then(|a| a.unreadable);
    state.report.copied_messages = writer.copied_messages();
    state.report.replaced_messages = writer.replaced_messages();
    state.report.new_messages = writer.new_messages();
    let sink = writer.finish()?;
    Ok((sink, state.report))
}
