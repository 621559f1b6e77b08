//! Reading any RGB-D MCAP file: Foxglove schemas in protobuf or JSON, ROS 2 messages in CDR,
//! ROS 1 messages (`ros1` profile, bags converted to MCAP).
//!
//! [`McapInput`] opens a file with bounded memory: when the file has a summary with chunk
//! indexes, messages are read chunk by chunk in log-time order through
//! [`mcap::sans_io::IndexedReader`]; otherwise (unfinished or unindexed recordings) a linear
//! pass with [`mcap::sans_io::LinearReader`] first collects schemas, channels, metadata and
//! attachments, and messages are then streamed in file order.
//!
//! - [`decode`]: channel classification and decoders for every supported flavour;
//! - [`detect`]: choosing colour, depth, calibration and pose topics by schema;
//! - [`transforms`]: fixed transforms between frames (`/tf_static`, `/tf`);
//! - `source` (where the bytes come from, record size limits), `truncation` (where a damaged
//!   file ends, what its last chunk still holds), `chunk_check` (chunk CRCs and damage reports);
//! - [`ros2`], [`ros1`], [`json`]: the serde layouts of ROS 2 (CDR), ROS 1 and Foxglove JSON
//!   messages.

mod cdr_read;
mod chunk_check;
pub mod decode;
pub mod detect;
pub mod json;
pub mod pixels;
pub mod ros1;
pub mod ros2;
mod source;
pub mod transforms;
mod truncation;

use std::collections::BTreeMap;
use std::io::{BufReader, Cursor, Read, Seek, SeekFrom};
use std::path::Path;
use std::sync::{Arc, Mutex};

use mcap::records::{MessageHeader, Record};
use mcap::sans_io::indexed_reader::ReadOrder;
use mcap::sans_io::{
    IndexedReadEvent, IndexedReader, IndexedReaderOptions, LinearReadEvent, LinearReader,
    LinearReaderOptions, SummaryReadEvent, SummaryReader, SummaryReaderOptions,
};

use crate::error::{ChunkDamage, Error, McapProblem, Result};

pub use decode::{ChannelType, Flavor, MessageType};
pub use source::ReadSeek;
pub use truncation::Truncation;

use chunk_check::{check_crc, chunk_header_crc, CheckedDecompressor, SharedCrc};
use source::{record_length_limit, Source, READ_BUFFER_BYTES};
use truncation::find_truncation;

/// A schema of the input file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InputSchema {
    /// Schema ID in the input.
    pub id: u16,
    /// Name (`foxglove.RawImage`, `sensor_msgs/msg/Image`, ...).
    pub name: String,
    /// Schema encoding (`protobuf`, `jsonschema`, `ros2msg`, ...).
    pub encoding: String,
    /// Schema bytes.
    pub data: Vec<u8>,
}

/// A channel of the input file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InputChannel {
    /// Channel ID in the input.
    pub id: u16,
    /// Schema ID (0 = no schema).
    pub schema_id: u16,
    /// Topic.
    pub topic: String,
    /// Message encoding (`protobuf`, `json`, `cdr`, ...).
    pub message_encoding: String,
    /// Channel metadata.
    pub metadata: BTreeMap<String, String>,
    /// Schema name, empty without a schema.
    pub schema_name: String,
    /// The supported type, `None` for channels occmask does not read.
    pub channel_type: Option<ChannelType>,
    /// Message count from the summary statistics, when present.
    pub message_count: Option<u64>,
}

/// One message as stored: header and bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawMessage {
    /// Channel ID, sequence, log and publish time, exactly as in the input.
    pub header: MessageHeader,
    /// The serialised message.
    pub data: Vec<u8>,
}

/// A metadata record or an attachment of the input.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ExtraRecord {
    /// A metadata record.
    Metadata(mcap::records::Metadata),
    /// An attachment.
    Attachment {
        /// Log time, ns.
        log_time: u64,
        /// Creation time, ns.
        create_time: u64,
        /// Name.
        name: String,
        /// Media type.
        media_type: String,
        /// Bytes.
        data: Vec<u8>,
    },
}

/// An open input MCAP file (or any seekable reader, [`McapInput::from_reader`]).
pub struct McapInput {
    source: Source,
    profile: String,
    summary: Option<mcap::Summary>,
    schemas: BTreeMap<u16, InputSchema>,
    channels: BTreeMap<u16, InputChannel>,
    /// Metadata and attachments collected by the linear scan (files without a usable summary).
    linear_extras: Vec<ExtraRecord>,
    /// First message of each supported channel, collected by the linear scan.
    linear_first: BTreeMap<u16, RawMessage>,
    /// The earliest and latest message log time, found by the linear scan.
    linear_log_time_span: Option<(u64, u64)>,
    truncation: Option<Truncation>,
    file_len: u64,
}

/// Reads the summary with the sans-IO summary reader (seeks to the footer; bounded memory).
fn read_summary(file: &mut impl ReadSeek, file_len: u64, path: &Path) -> Result<Option<mcap::Summary>> {
    let mut reader = SummaryReader::new_with_options(
        SummaryReaderOptions::default()
            .with_file_size(file_len)
            .with_record_length_limit(record_length_limit(file_len)),
    );
    while let Some(event) = reader.next_event() {
        match event? {
            SummaryReadEvent::ReadRequest(n) => {
                let read = file
                    .read(reader.insert(n))
                    .map_err(|e| Error::io("cannot read MCAP summary", path, e))?;
                reader.notify_read(read);
            }
            SummaryReadEvent::SeekRequest(to) => {
                let pos = file
                    .seek(to)
                    .map_err(|e| Error::io("cannot seek in MCAP file", path, e))?;
                reader.notify_seeked(pos);
            }
        }
    }
    Ok(reader.finish())
}

/// Reads the header record's profile (right after the 8-byte magic).
fn read_profile(file: &mut impl ReadSeek, path: &Path) -> Result<String> {
    const MAGIC_BYTES: usize = 8;
    const RECORD_PREFIX_BYTES: usize = 9;
    // Header records hold two short strings; anything larger is a corrupt file.
    const MAX_HEADER_BYTES: u64 = 1 << 20;
    file.seek(SeekFrom::Start(0))
        .map_err(|e| Error::io("cannot seek in MCAP file", path, e))?;
    let mut prefix = [0u8; MAGIC_BYTES + RECORD_PREFIX_BYTES];
    let mut filled = 0;
    while filled < prefix.len() {
        match file.read(&mut prefix[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(Error::io("cannot read MCAP header", path, e)),
        }
    }
    if filled < prefix.len() || &prefix[..MAGIC_BYTES] != mcap::MAGIC {
        return Err(Error::bad_mcap(path, McapProblem::NoMagic));
    }
    let opcode = prefix[MAGIC_BYTES];
    let mut len_bytes = [0u8; 8];
    len_bytes.copy_from_slice(&prefix[MAGIC_BYTES + 1..]);
    let len = u64::from_le_bytes(len_bytes);
    if opcode != mcap::records::op::HEADER || len > MAX_HEADER_BYTES {
        return Err(Error::bad_mcap(path, McapProblem::NoHeader));
    }
    let mut body = vec![0u8; len as usize];
    file.read_exact(&mut body)
        .map_err(|e| Error::io("cannot read MCAP header", path, e))?;
    match mcap::parse_record(opcode, &body)? {
        Record::Header(h) => Ok(h.profile),
        _ => Err(Error::bad_mcap(path, McapProblem::NoHeader)),
    }
}

/// Drives a [`LinearReader`] over a file, calling `f` for every record. A file that ends
/// early (a recorder killed mid-write) is read up to its last complete record and reported
/// with `Ok(true)` ("truncated"); other errors are errors.
fn linear_records(source: &Source, mut f: impl FnMut(Record<'_>) -> Result<()>) -> Result<bool> {
    let path = &source.path;
    let mut file = source.open()?;
    let file_len = source.len(&mut file)?;
    file.seek(SeekFrom::Start(0))
        .map_err(|e| Error::io("cannot read MCAP file", path, e))?;
    let mut unread = file_len;
    let mut file = BufReader::with_capacity(READ_BUFFER_BYTES, file);
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default().with_record_length_limit(record_length_limit(file_len)),
    );
    while let Some(event) = reader.next_event() {
        let event = match event {
            Ok(e) => e,
            // The linear reader decompresses chunks as a stream, so the complete messages at
            // the start of an incomplete last chunk have already been passed to `f`.
            Err(mcap::McapError::UnexpectedEof) => return Ok(true),
            Err(e) => return Err(e.into()),
        };
        match event {
            LinearReadEvent::ReadRequest(n) => {
                // The reader zero-fills the `n` bytes it asks for; never more than the file still
                // holds, so a record declaring a huge length costs nothing and ends as truncation.
                let n = usize::try_from(unread).map_or(n, |unread| n.min(unread));
                let read = file
                    .read(reader.insert(n))
                    .map_err(|e| Error::io("cannot read MCAP file", path, e))?;
                unread = unread.saturating_sub(read as u64);
                reader.notify_read(read);
            }
            LinearReadEvent::Record { data, opcode } => f(mcap::parse_record(opcode, data)?)?,
        }
    }
    Ok(false)
}

impl McapInput {
    /// Opens `path`: reads the header and summary, or scans the file linearly when it has no
    /// summary (or no chunk indexes).
    ///
    /// # Errors
    /// [`Error::Io`] when the file cannot be read; [`Error::BadMcap`] when it is not MCAP;
    /// [`Error::Mcap`] for corrupt records.
    pub fn open(path: &Path) -> Result<Self> {
        Self::from_source(Source {
            path: path.to_owned(),
            reader: None,
        })
    }

    /// Reads an MCAP recording from any seekable reader (a [`std::io::Cursor`] over bytes in
    /// memory, a file already open, ...); `name` is the path its errors and [`Self::path`]
    /// give. Passes over the input share the reader, each seeking to its own position.
    ///
    /// # Errors
    /// As [`Self::open`].
    pub fn from_reader(reader: impl ReadSeek + 'static, name: &Path) -> Result<Self> {
        Self::from_source(Source {
            path: name.to_owned(),
            reader: Some(Arc::new(Mutex::new(Box::new(reader)))),
        })
    }

    /// Reads an MCAP recording held in memory; `name` as in [`Self::from_reader`].
    ///
    /// # Errors
    /// As [`Self::open`].
    pub fn from_bytes(bytes: impl Into<Vec<u8>>, name: &Path) -> Result<Self> {
        Self::from_reader(Cursor::new(bytes.into()), name)
    }

    fn from_source(source: Source) -> Result<Self> {
        let path = source.path.clone();
        let path = path.as_path();
        let mut file = source.open()?;
        let file_len = source.len(&mut file)?;
        let profile = read_profile(&mut file, path)?;
        // A file without its footer (killed recorder) makes the summary reader fail: that is
        // the linear fallback's case, not an error.
        let summary = read_summary(&mut file, file_len, path)
            .ok()
            .flatten()
            .filter(|s| {
                !s.chunk_indexes.is_empty() || s.stats.as_ref().is_some_and(|s| s.message_count == 0)
            });
        let mut input = Self {
            source,
            profile,
            summary,
            schemas: BTreeMap::new(),
            channels: BTreeMap::new(),
            linear_extras: Vec::new(),
            linear_first: BTreeMap::new(),
            linear_log_time_span: None,
            truncation: None,
            file_len,
        };
        if let Some(summary) = &input.summary {
            for (id, s) in &summary.schemas {
                input.schemas.insert(
                    *id,
                    InputSchema {
                        id: *id,
                        name: s.name.clone(),
                        encoding: s.encoding.clone(),
                        data: s.data.to_vec(),
                    },
                );
            }
            let counts = summary.stats.as_ref().map(|s| &s.channel_message_counts);
            for (id, c) in &summary.channels {
                let count = counts.map(|m| m.get(id).copied().unwrap_or(0));
                input.channels.insert(*id, channel_info(c, count));
            }
        } else {
            input.linear_scan()?;
        }
        Ok(input)
    }

    fn linear_scan(&mut self) -> Result<()> {
        let mut schemas = BTreeMap::new();
        let mut channels: BTreeMap<u16, InputChannel> = BTreeMap::new();
        let mut extras = Vec::new();
        let mut first = BTreeMap::new();
        let mut counts: BTreeMap<u16, u64> = BTreeMap::new();
        let mut span: Option<(u64, u64)> = None;
        let truncated = linear_records(&self.source, |record| {
            match record {
                Record::Schema { header, data } => {
                    schemas.insert(
                        header.id,
                        InputSchema {
                            id: header.id,
                            name: header.name,
                            encoding: header.encoding,
                            data: data.into_owned(),
                        },
                    );
                }
                Record::Channel(c) => {
                    let schema_name = schemas
                        .get(&c.schema_id)
                        .map(|s: &InputSchema| s.name.clone())
                        .unwrap_or_default();
                    let channel_type = ChannelType::classify(&schema_name, &c.message_encoding);
                    channels.insert(
                        c.id,
                        InputChannel {
                            id: c.id,
                            schema_id: c.schema_id,
                            topic: c.topic,
                            message_encoding: c.message_encoding,
                            metadata: c.metadata,
                            schema_name,
                            channel_type,
                            message_count: None,
                        },
                    );
                }
                Record::Message { header, data } => {
                    *counts.entry(header.channel_id).or_default() += 1;
                    let t = header.log_time;
                    span = Some(span.map_or((t, t), |(first, last)| (first.min(t), last.max(t))));
                    let wanted = channels
                        .get(&header.channel_id)
                        .and_then(|c| c.channel_type)
                        .is_some();
                    if wanted && !first.contains_key(&header.channel_id) {
                        first.insert(
                            header.channel_id,
                            RawMessage {
                                header,
                                data: data.into_owned(),
                            },
                        );
                    }
                }
                Record::Metadata(m) => extras.push(ExtraRecord::Metadata(m)),
                Record::Attachment { header, data, .. } => extras.push(ExtraRecord::Attachment {
                    log_time: header.log_time,
                    create_time: header.create_time,
                    name: header.name,
                    media_type: header.media_type,
                    data: data.into_owned(),
                }),
                _ => {}
            }
            Ok(())
        })?;
        if truncated {
            self.truncation = Some(find_truncation(&self.source, self.file_len)?);
        }
        for (id, c) in &mut channels {
            c.message_count = Some(counts.get(id).copied().unwrap_or(0));
        }
        self.schemas = schemas;
        self.channels = channels;
        self.linear_extras = extras;
        self.linear_first = first;
        self.linear_log_time_span = span;
        Ok(())
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.source.path
    }

    /// File size in bytes.
    pub fn file_len(&self) -> u64 {
        self.file_len
    }

    /// The header's profile (`ros2`, empty, ...).
    pub fn profile(&self) -> &str {
        &self.profile
    }

    /// True when the file ends before its end magic (an unfinished recording): everything up
    /// to the last complete record is read.
    pub fn is_truncated(&self) -> bool {
        self.truncation.is_some()
    }

    /// Where a file that ends early was cut and what was lost (`None` for complete files).
    pub fn truncation(&self) -> Option<&Truncation> {
        self.truncation.as_ref()
    }

    /// True when messages are read through the summary's indexes (log-time order).
    pub fn is_indexed(&self) -> bool {
        self.summary.is_some()
    }

    /// Consecutive log-time ranges `[start, end)` that together hold every message, for
    /// reading a file in `parts` side by side: each range starts at a chunk's first message and
    /// holds about as many chunks as the others, so each chunk is decompressed by one reader
    /// (or two, where chunks overlap in time). [`Self::for_each_message`] over each range in
    /// turn gives the messages of one read over all of them, in the same order. A single
    /// `None` (everything) for files read without indexes or with fewer chunks than `parts`.
    pub fn log_time_parts(&self, parts: usize) -> Vec<Option<(u64, u64)>> {
        let Some(summary) = &self.summary else {
            return vec![None];
        };
        let chunks = &summary.chunk_indexes;
        // A message at u64::MAX is in no range `[start, end)`.
        if parts < 2 || chunks.len() < parts || chunks.iter().any(|c| c.message_end_time == u64::MAX) {
            return vec![None];
        }
        let mut starts: Vec<u64> = chunks.iter().map(|c| c.message_start_time).collect();
        starts.sort_unstable();
        let mut ranges = Vec::with_capacity(parts);
        let mut start = 0;
        for k in 1..parts {
            let end = starts[k * starts.len() / parts];
            if end > start {
                ranges.push(Some((start, end)));
                start = end;
            }
        }
        ranges.push(Some((start, u64::MAX)));
        ranges
    }

    /// The earliest and latest message log time (ns), from the summary's statistics or chunk
    /// indexes, or the linear scan; `None` for a file without messages.
    pub fn log_time_span(&self) -> Option<(u64, u64)> {
        let Some(summary) = &self.summary else {
            return self.linear_log_time_span;
        };
        match &summary.stats {
            Some(stats) if stats.message_count == 0 => None,
            Some(stats) => Some((stats.message_start_time, stats.message_end_time)),
            None => summary.chunk_indexes.iter().fold(None, |span, c| {
                let (first, last) = span.unwrap_or((c.message_start_time, c.message_end_time));
                Some((first.min(c.message_start_time), last.max(c.message_end_time)))
            }),
        }
    }

    /// Total messages, when known from the summary or the linear scan.
    pub fn message_count(&self) -> Option<u64> {
        self.channels.values().map(|c| c.message_count).sum()
    }

    /// Schemas by ID.
    pub fn schemas(&self) -> &BTreeMap<u16, InputSchema> {
        &self.schemas
    }

    /// Channels by ID.
    pub fn channels(&self) -> &BTreeMap<u16, InputChannel> {
        &self.channels
    }

    /// The channel with `topic` (the lowest ID when several share it).
    pub fn channel_by_topic(&self, topic: &str) -> Option<&InputChannel> {
        self.channels.values().find(|c| c.topic == topic)
    }

    /// The first message (in log-time order) on channel `id`.
    ///
    /// # Errors
    /// I/O and MCAP errors.
    pub fn first_message(&self, id: u16) -> Result<Option<RawMessage>> {
        if self.summary.is_none() {
            return Ok(self.linear_first.get(&id).cloned());
        }
        let Some(channel) = self.channels.get(&id) else {
            return Ok(None);
        };
        let mut found = None;
        self.for_each_message(Some(std::slice::from_ref(&channel.topic)), None, |m| {
            if m.header.channel_id == id {
                found = Some(m);
                return Ok(false);
            }
            Ok(true)
        })?;
        Ok(found)
    }

    /// Metadata records and attachments, in file order.
    ///
    /// # Errors
    /// I/O and MCAP errors.
    pub fn extras(&self) -> Result<Vec<ExtraRecord>> {
        let Some(summary) = &self.summary else {
            return Ok(self.linear_extras.clone());
        };
        let mut file = self.source.open()?;
        let mut spans: Vec<(u64, u64)> = summary
            .metadata_indexes
            .iter()
            .map(|i| (i.offset, i.length))
            .chain(summary.attachment_indexes.iter().map(|i| (i.offset, i.length)))
            .collect();
        spans.sort_unstable();
        let mut out = Vec::with_capacity(spans.len());
        for (offset, length) in spans {
            const RECORD_PREFIX_BYTES: u64 = 9;
            if length < RECORD_PREFIX_BYTES || offset.saturating_add(length) > self.file_len {
                return Err(Error::bad_mcap(
                    self.path(),
                    McapProblem::IndexOutsideFile { offset, length },
                ));
            }
            let mut buf = vec![0u8; length as usize];
            file.seek(SeekFrom::Start(offset))
                .and_then(|_| file.read_exact(&mut buf))
                .map_err(|e| Error::io("cannot read MCAP record", self.path(), e))?;
            match mcap::parse_record(buf[0], &buf[RECORD_PREFIX_BYTES as usize..])? {
                Record::Metadata(m) => out.push(ExtraRecord::Metadata(m)),
                Record::Attachment { header, data, .. } => out.push(ExtraRecord::Attachment {
                    log_time: header.log_time,
                    create_time: header.create_time,
                    name: header.name,
                    media_type: header.media_type,
                    data: data.into_owned(),
                }),
                _ => {
                    return Err(Error::bad_mcap(
                        self.path(),
                        McapProblem::IndexWrongRecord { offset },
                    ))
                }
            }
        }
        Ok(out)
    }

    /// Calls `f` for every message (only `topics` when given; only log times in
    /// `[start, end)` when `time_range` is given), in log-time order for indexed files and file
    /// order otherwise. `f` returns `false` to stop early.
    ///
    /// # Errors
    /// I/O and MCAP errors, or the first error `f` returns.
    pub fn for_each_message(
        &self,
        topics: Option<&[String]>,
        time_range: Option<(u64, u64)>,
        mut f: impl FnMut(RawMessage) -> Result<bool>,
    ) -> Result<()> {
        let wanted_ids: Option<Vec<u16>> = topics.map(|topics| {
            self.channels
                .values()
                .filter(|c| topics.contains(&c.topic))
                .map(|c| c.id)
                .collect()
        });
        let in_range = |t: u64| time_range.is_none_or(|(s, e)| t >= s && t < e);
        let Some(summary) = &self.summary else {
            let mut stopped = false;
            linear_records(&self.source, |record| {
                if stopped {
                    return Ok(());
                }
                if let Record::Message { header, data } = record {
                    let wanted = wanted_ids
                        .as_ref()
                        .is_none_or(|ids| ids.contains(&header.channel_id));
                    if wanted && in_range(header.log_time) {
                        stopped = !f(RawMessage {
                            header,
                            data: data.into_owned(),
                        })?;
                    }
                }
                Ok(())
            })?;
            return Ok(());
        };
        let mut options = IndexedReaderOptions::new()
            .with_order(ReadOrder::LogTime)
            .with_record_length_limit(record_length_limit(self.file_len));
        if let Some(topics) = topics {
            options = options.include_topics(topics.iter().cloned());
        }
        if let Some((start, end)) = time_range {
            options = options.starting_at(start).ending_before(end);
        }
        let mut reader = IndexedReader::new_with_options(summary, options)?;
        let crc: SharedCrc = Arc::default();
        for name in ["zstd", "lz4"] {
            reader.add_decompressor(CheckedDecompressor {
                name,
                crc: Arc::clone(&crc),
            })?;
        }
        let mut file = self.source.open()?;
        let mut chunk = Vec::new();
        while let Some(event) = reader.next_event() {
            match event? {
                IndexedReadEvent::ReadChunkRequest { offset, length } => {
                    // Read the chunk record from its start: its header holds the CRC.
                    let index = summary
                        .chunk_indexes
                        .iter()
                        .find(|c| c.compressed_data_offset().ok() == Some(offset));
                    let start = index.map_or(offset, |c| c.chunk_start_offset);
                    let header_len = (offset - start) as usize;
                    if offset.saturating_add(length as u64) > self.file_len {
                        return Err(self.chunk_error(index, ChunkDamage::PastEnd));
                    }
                    chunk.resize(header_len + length, 0);
                    file.seek(SeekFrom::Start(start))
                        .and_then(|_| file.read_exact(&mut chunk))
                        .map_err(|e| Error::io("cannot read MCAP chunk", self.path(), e))?;
                    let (header, data) = chunk.split_at(header_len);
                    let expected_crc = match index {
                        Some(index) => {
                            chunk_header_crc(header).map_err(|d| self.chunk_error(Some(index), d))?
                        }
                        None => 0,
                    };
                    if let Ok(mut c) = crc.lock() {
                        *c = None;
                    }
                    reader.insert_chunk_record_data(offset, data).map_err(|e| {
                        self.chunk_error(
                            index,
                            ChunkDamage::Decompression {
                                reason: e.to_string(),
                            },
                        )
                    })?;
                    let found = if index.is_some_and(|i| i.compression.is_empty()) {
                        Some(crc32fast::hash(data))
                    } else {
                        crc.lock().ok().and_then(|c| *c)
                    };
                    check_crc(expected_crc, found).map_err(|d| self.chunk_error(index, d))?;
                }
                IndexedReadEvent::Message { header, data } => {
                    let keep_going = f(RawMessage {
                        header,
                        data: data.to_vec(),
                    })?;
                    if !keep_going {
                        break;
                    }
                }
            }
        }
        Ok(())
    }
}

fn channel_info(c: &Arc<mcap::Channel<'static>>, count: Option<u64>) -> InputChannel {
    let schema_name = c.schema.as_ref().map(|s| s.name.clone()).unwrap_or_default();
    InputChannel {
        id: c.id,
        schema_id: c.schema.as_ref().map_or(0, |s| s.id),
        topic: c.topic.clone(),
        message_encoding: c.message_encoding.clone(),
        metadata: c.metadata.clone(),
        channel_type: ChannelType::classify(&schema_name, &c.message_encoding),
        schema_name,
        message_count: count,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every message of `input` (all, or the parts in turn) as (channel, log time, data).
    fn messages(input: &McapInput, ranges: &[Option<(u64, u64)>]) -> Vec<(u16, u64, Vec<u8>)> {
        let mut out = Vec::new();
        for &range in ranges {
            input
                .for_each_message(None, range, |m| {
                    out.push((m.header.channel_id, m.header.log_time, m.data));
                    Ok(true)
                })
                .unwrap();
        }
        out
    }

    #[test]
    fn log_time_parts_read_in_turn_give_the_messages_of_one_read() {
        // Small chunks; equal log times within and across chunks, a chunk that starts before
        // the previous one ends (a message written late), two channels.
        let mut writer = mcap::WriteOptions::new()
            .chunk_size(Some(64))
            .compression(None)
            .create(std::io::Cursor::new(Vec::new()))
            .unwrap();
        let channels: Vec<u16> = ["/a", "/b"]
            .iter()
            .map(|topic| writer.add_channel(0, topic, "raw", &BTreeMap::new()).unwrap())
            .collect();
        let times = [0u64, 5, 5, 5, 10, 12, 12, 3, 20, 20, 21, 30, 30, 30, 31, 40];
        for (i, &t) in times.iter().enumerate() {
            let header = mcap::records::MessageHeader {
                channel_id: channels[i % 2],
                sequence: i as u32,
                log_time: t,
                publish_time: t,
            };
            writer.write_to_known_channel(&header, &[i as u8; 40]).unwrap();
        }
        writer.finish().unwrap();
        let bytes = writer.into_inner().into_inner();
        let input = McapInput::from_bytes(bytes, Path::new("parts.mcap")).unwrap();
        let whole = messages(&input, &[None]);
        assert_eq!(whole.len(), times.len());
        for parts in 2..6 {
            let ranges = input.log_time_parts(parts);
            assert!(ranges.len() > 1, "{parts} parts: {ranges:?}");
            assert_eq!(messages(&input, &ranges), whole, "{parts} parts: {ranges:?}");
        }
        assert_eq!(input.log_time_parts(1), vec![None]);
    }
}
