//! The two threads beside `occmask process`'s frame loop and the queues to them: a prefetch
//! thread reads, decompresses and decodes the input ([`Prefetched`] items, at most
//! [`PREFETCH_BYTES`] ahead), a writer thread encodes and compresses the output ([`WriteOp`]s,
//! at most [`WRITE_QUEUE_BYTES`] queued). The writer makes the same calls in the same order as
//! one thread would, so the output bytes do not depend on thread timing.

use std::io::{Seek, Write};
use std::sync::mpsc::Receiver;
use std::time::Instant;

use nalgebra::Isometry3;

use crate::error::{Error, Result};
use crate::image_buf::{DepthMeters, GrayF32, Image, Mask};
use prost::bytes::Bytes;

use crate::mcap_io::annotate::{AnnotatedWriter, FrameAnnotation, FrameStatsMsg};
use crate::mcap_io::input::RawMessage;

use super::pairing::{Pixels, Queued};
use super::queue::{ByteReceiver, ByteSender};

/// Processed image buffers on their way back to the prefetch thread.
pub(super) struct BufferPool {
    pub(super) gray: Receiver<GrayF32>,
    pub(super) depth: Receiver<DepthMeters>,
    pub(super) point_colors: Receiver<Vec<[u8; 3]>>,
}

/// What the prefetch thread hands over per input message.
pub(super) struct Prefetched {
    /// The message (copied to the output in copy mode).
    pub(super) message: RawMessage,
    /// The decoded image when the message is on the colour (`true`) or depth topic.
    pub(super) image: Option<(bool, Queued)>,
}

/// Bytes (messages plus decoded pixels) the prefetch thread may read ahead of processing:
/// two VGA frames (1.5 MB of messages and 2.5 MB of decoded grey and depth each), so the next
/// frame is decoded while the current one is processed even with many small messages (pose
/// streams) between images, while memory stays flat. (It was 8 messages: less than one
/// TUM frame, whose 100 Hz motion capture puts ~36 messages between images, so decoding
/// stalled until the pipeline had finished the frame before.)
pub const PREFETCH_BYTES: usize = 8 << 20;
/// Messages the prefetch thread may read ahead, whatever their size.
pub const PREFETCH_MAX_MESSAGES: usize = 4096;

/// Bytes (copied messages, masks) the frame loop may queue ahead of the writer thread: about
/// four VGA frames (1.5 MB of copied messages and a 0.3 MB mask each), so a chunk flush does
/// not stall the pipeline.
pub const WRITE_QUEUE_BYTES: usize = 8 << 20;
/// Output operations queued ahead of the writer thread, whatever their size.
pub const WRITE_QUEUE_MAX_OPS: usize = 4096;

impl Prefetched {
    /// What the item holds in memory, for the prefetch queue's budget.
    pub(super) fn bytes(&self) -> usize {
        let image = self.image.as_ref().map_or(0, |(_, q)| {
            let pixels = match &q.pixels {
                Pixels::Gray(g) => std::mem::size_of_val(g.as_slice()),
                Pixels::Depth(d) => std::mem::size_of_val(d.as_slice()),
                Pixels::Skipped => 0,
            };
            let colors = q
                .point_colors
                .as_ref()
                .map_or(0, |c| std::mem::size_of_val(c.as_slice()));
            pixels + colors
        });
        self.message.data.len() + image
    }
}

/// What the frame loop hands to the writer thread, in output order.
pub(super) enum WriteOp {
    /// An input message, copied unchanged (annotated copy).
    Copy(RawMessage),
    /// One processed frame's new messages.
    Frame(Box<FrameWrite>),
    /// The last frame is written: publish the paths up to it
    /// ([`AnnotatedWriter::end_paths`]).
    EndPaths,
}

/// Owned [`FrameAnnotation`]: everything the writer thread needs to encode one frame.
pub(super) struct FrameWrite {
    pub(super) log_time_ns: u64,
    pub(super) timestamp_ns: u64,
    pub(super) frame_id: String,
    pub(super) mask: Mask,
    pub(super) world_from_camera: Isometry3<f64>,
    pub(super) anchor_pose: Option<Isometry3<f64>>,
    pub(super) accumulation: Option<Image<f32>>,
    pub(super) points: Option<Bytes>,
    pub(super) stats: FrameStatsMsg,
}

impl WriteOp {
    /// What the op holds in memory, for the queue's budget.
    pub(super) fn bytes(&self) -> usize {
        match self {
            WriteOp::Copy(m) => m.data.len(),
            WriteOp::EndPaths => 0,
            WriteOp::Frame(f) => {
                f.mask.as_slice().len()
                    + f.accumulation
                        .as_ref()
                        .map_or(0, |a| std::mem::size_of_val(a.as_slice()))
                    + f.points.as_ref().map_or(0, Bytes::len)
            }
        }
    }
}

/// The frame loop's end of the writer thread's queue.
pub(super) struct OutputQueue {
    pub(super) ops: ByteSender<WriteOp>,
    /// Time spent waiting for room in the queue.
    pub(super) waited: std::cell::Cell<std::time::Duration>,
}

impl OutputQueue {
    /// Queues `op`. Fails only when the writer thread has stopped on an error, which
    /// [`super::process_file`] then reports instead of this placeholder.
    pub(super) fn send(&self, op: WriteOp) -> Result<()> {
        let wait_start = Instant::now();
        let bytes = op.bytes();
        let sent = self.ops.send(op, bytes);
        self.waited.set(self.waited.get() + wait_start.elapsed());
        sent.map_err(|_| Error::WriterStopped)
    }
}

/// The writer thread: encodes the new messages (mask, contours, poses, path, stats),
/// copies input messages and compresses chunks, in queue order, so the frame loop only runs
/// the pipeline. Same calls in the same order as on one thread: the output bytes do not
/// change.
pub(super) fn write_ops<W: Write + Seek>(
    mut writer: AnnotatedWriter<W>,
    ops: ByteReceiver<WriteOp>,
) -> Result<AnnotatedWriter<W>> {
    for op in ops {
        match op {
            WriteOp::Copy(m) => writer.copy_message(&m.header, &m.data)?,
            WriteOp::Frame(f) => writer.write_frame(&FrameAnnotation {
                log_time_ns: f.log_time_ns,
                timestamp_ns: f.timestamp_ns,
                frame_id: &f.frame_id,
                mask: &f.mask,
                world_from_camera: &f.world_from_camera,
                anchor_pose: f.anchor_pose.as_ref(),
                accumulation: f.accumulation.as_ref(),
                points: f.points.as_ref(),
                stats: &f.stats,
            })?,
            WriteOp::EndPaths => writer.end_paths()?,
        }
    }
    Ok(writer)
}
