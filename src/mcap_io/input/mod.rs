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
//! - [`ros2`], [`ros1`], [`json`]: the serde layouts of ROS 2 (CDR), ROS 1 and Foxglove JSON
//!   messages.

mod cdr_read;
pub mod decode;
pub mod detect;
pub mod json;
pub mod pixels;
pub mod ros1;
pub mod ros2;
pub mod transforms;

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, Cursor, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use mcap::records::{MessageHeader, Record};
use mcap::sans_io::indexed_reader::ReadOrder;
use mcap::sans_io::{
    IndexedReadEvent, IndexedReader, IndexedReaderOptions, LinearReadEvent, LinearReader,
    LinearReaderOptions, SummaryReadEvent, SummaryReader, SummaryReaderOptions,
};

use crate::error::{Error, Result};

pub use decode::{ChannelType, Flavor, MessageType};

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

/// Where an input that ends early (a recorder killed mid-write, a full disk, an interrupted
/// copy) was cut, found by walking the record framing from the start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Truncation {
    /// Bytes from the start of the file to the end of its last complete record: everything in
    /// them was read.
    pub intact_bytes: u64,
    /// Bytes after that (an incomplete record): their messages are lost.
    pub lost_bytes: u64,
    /// True when the cut lies after the data section (only the summary, index or footer is
    /// missing), so no message was lost.
    pub messages_intact: bool,
    /// Log-time range (ns) of the messages lost in the incomplete chunk, when its header
    /// survived: from the last message salvaged from it (or its start) to its end.
    pub lost_log_time_range: Option<(u64, u64)>,
    /// Complete messages at the start of the incomplete chunk (the linear reader decompresses
    /// chunks as a stream, so these were read too).
    pub salvaged_messages: u64,
}

/// The complete records at the start of an incomplete trailing chunk at `offset` (a recorder
/// killed while writing it): the compressed prefix is decompressed as far as it goes (zstd and
/// lz4 decode block by block) and parsed up to the first incomplete record. Returns
/// (opcode, body) pairs; empty when the record at `offset` is not a chunk.
fn partial_chunk_records(source: &Source, offset: u64) -> Result<Vec<(u8, Vec<u8>)>> {
    // Chunk header after opcode and length: start, end, uncompressed size (u64 each), CRC (u32),
    // compression string (u32 length + bytes), compressed size (u64).
    const FIXED_BYTES: usize = 9 + 8 + 8 + 8 + 4;
    let mut file = source.open()?;
    let mut buf = Vec::new();
    file.seek(SeekFrom::Start(offset))
        .and_then(|_| file.read_to_end(&mut buf))
        .map_err(|e| Error::io("cannot read MCAP file", &source.path, e))?;
    if buf.len() < FIXED_BYTES + 4 || buf[0] != mcap::records::op::CHUNK {
        return Ok(Vec::new());
    }
    let u64_at = |i: usize| {
        let mut b = [0u8; 8];
        b.copy_from_slice(&buf[i..i + 8]);
        u64::from_le_bytes(b)
    };
    let uncompressed_size = u64_at(9 + 16);
    let mut len = [0u8; 4];
    len.copy_from_slice(&buf[FIXED_BYTES..FIXED_BYTES + 4]);
    let name_end = FIXED_BYTES + 4 + u32::from_le_bytes(len) as usize;
    let data_start = name_end + 8;
    if data_start > buf.len() {
        return Ok(Vec::new());
    }
    let compression = String::from_utf8_lossy(&buf[FIXED_BYTES + 4..name_end]).into_owned();
    let data = &buf[data_start..];
    let mut out = Vec::new();
    let read_partial = |mut r: Box<dyn Read + '_>, out: &mut Vec<u8>| {
        let mut block = vec![0u8; 64 * 1024];
        while out.len() < uncompressed_size as usize {
            match r.read(&mut block) {
                Ok(0) | Err(_) => break,
                Ok(n) => out.extend_from_slice(&block[..n]),
            }
        }
    };
    match compression.as_str() {
        "" => out.extend_from_slice(data),
        "zstd" => {
            if let Ok(d) = zstd::stream::read::Decoder::with_buffer(data) {
                read_partial(Box::new(d), &mut out);
            }
        }
        "lz4" => {
            if let Ok(d) = lz4::Decoder::new(data) {
                read_partial(Box::new(d), &mut out);
            }
        }
        _ => return Ok(Vec::new()),
    }
    out.truncate(uncompressed_size as usize);
    let mut records = Vec::new();
    let mut pos = 0usize;
    while pos + 9 <= out.len() {
        let mut len = [0u8; 8];
        len.copy_from_slice(&out[pos + 1..pos + 9]);
        let Ok(len) = usize::try_from(u64::from_le_bytes(len)) else {
            break;
        };
        let Some(end) = (pos + 9).checked_add(len).filter(|&e| e <= out.len()) else {
            break;
        };
        let opcode = out[pos];
        // Only records that parse are kept (the decompressed tail may be garbage).
        if mcap::parse_record(opcode, &out[pos + 9..end]).is_err() {
            break;
        }
        records.push((opcode, out[pos + 9..end].to_vec()));
        pos = end;
    }
    Ok(records)
}

/// Walks the top-level record framing (opcode, length, body) without reading bodies, and
/// returns where the last complete record ends, whether the data section was complete, and
/// the log-time range of an incomplete trailing chunk.
fn find_truncation(source: &Source, file_len: u64) -> Result<Truncation> {
    const MAGIC_BYTES: u64 = 8;
    const PREFIX_BYTES: u64 = 9;
    // Chunk body: message_start_time, message_end_time (u64 each) come first.
    const CHUNK_TIMES_BYTES: usize = 16;
    let mut file = BufReader::with_capacity(64 * 1024, source.open()?);
    let io = |e| Error::io("cannot read MCAP file", &source.path, e);
    file.seek(SeekFrom::Start(MAGIC_BYTES)).map_err(io)?;
    let mut pos = MAGIC_BYTES;
    let mut messages_intact = false;
    loop {
        let mut prefix = [0u8; PREFIX_BYTES as usize];
        if pos + PREFIX_BYTES > file_len {
            break;
        }
        file.read_exact(&mut prefix).map_err(io)?;
        let opcode = prefix[0];
        let mut len = [0u8; 8];
        len.copy_from_slice(&prefix[1..]);
        let len = u64::from_le_bytes(len);
        let end = pos.saturating_add(PREFIX_BYTES).saturating_add(len);
        if end > file_len {
            let mut lost_log_time_range = None;
            let mut salvaged_messages = 0;
            if opcode == mcap::records::op::CHUNK && len >= CHUNK_TIMES_BYTES as u64 {
                let mut times = [0u8; CHUNK_TIMES_BYTES];
                if file.read_exact(&mut times).is_ok() {
                    let mut start = u64::from_le_bytes(times[..8].try_into().unwrap_or([0; 8]));
                    let end = u64::from_le_bytes(times[8..].try_into().unwrap_or([0; 8]));
                    for (op, body) in partial_chunk_records(source, pos)? {
                        if let Ok(Record::Message { header, .. }) = mcap::parse_record(op, &body) {
                            salvaged_messages += 1;
                            start = start.max(header.log_time);
                        }
                    }
                    lost_log_time_range = Some((start, end));
                }
            }
            return Ok(Truncation {
                intact_bytes: pos,
                lost_bytes: file_len - pos,
                messages_intact,
                lost_log_time_range,
                salvaged_messages,
            });
        }
        if opcode == mcap::records::op::DATA_END {
            messages_intact = true;
        }
        file.seek_relative(len as i64).map_err(io)?;
        pos = end;
    }
    Ok(Truncation {
        intact_bytes: pos,
        lost_bytes: file_len - pos,
        messages_intact,
        lost_log_time_range: None,
        salvaged_messages: 0,
    })
}

/// Buffer size of the linear reader's file reads.
const READ_BUFFER_BYTES: usize = 1 << 20;

/// Smallest limit on one record or decompressed chunk, whatever the file size. Recorders write
/// chunks of a few MiB (ours 4 MiB) and the largest single RGB-D message is a raw 4K frame of
/// ~25 MB; a compressed chunk may decompress to more than the whole file, so the limit is not
/// just the file length.
const MIN_RECORD_LENGTH_LIMIT_BYTES: u64 = 256 << 20;

/// The longest record (or decompressed chunk) the MCAP readers accept in a file of `file_len`
/// bytes. Without a limit the mcap readers allocate whatever length a corrupt record declares
/// (found by fuzzing: 8e18 bytes from a 2.5 kB file, fuzz/README.md).
fn record_length_limit(file_len: u64) -> usize {
    usize::try_from(file_len.max(MIN_RECORD_LENGTH_LIMIT_BYTES)).unwrap_or(usize::MAX)
}

/// Where an [`McapInput`] reads its bytes, and the name its messages give it.
struct Source {
    /// The file's path, or the name given to a reader.
    path: PathBuf,
    /// `None`: the file at `path`, opened again for each pass (passes may overlap).
    reader: Option<SharedReader>,
}

/// Any seekable byte source an [`McapInput`] can read ([`std::fs::File`],
/// [`std::io::Cursor`] over bytes, ...).
pub trait ReadSeek: Read + Seek + Send {}

impl<T: Read + Seek + Send> ReadSeek for T {}

/// A reader shared by the passes over it; each pass keeps its own position.
type SharedReader = Arc<Mutex<Box<dyn ReadSeek>>>;

/// One pass over a [`Source`].
enum SourceReader {
    File(File),
    Shared { reader: SharedReader, position: u64 },
}

fn poisoned() -> std::io::Error {
    std::io::Error::other("another reader of the same MCAP input panicked")
}

impl Read for SourceReader {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        match self {
            SourceReader::File(f) => f.read(buf),
            SourceReader::Shared { reader, position } => {
                let mut r = reader.lock().map_err(|_| poisoned())?;
                r.seek(SeekFrom::Start(*position))?;
                let n = r.read(buf)?;
                *position += n as u64;
                Ok(n)
            }
        }
    }
}

impl Seek for SourceReader {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        match self {
            SourceReader::File(f) => f.seek(to),
            SourceReader::Shared { reader, position } => {
                let target = match to {
                    SeekFrom::Start(n) => Some(n),
                    SeekFrom::Current(d) => position.checked_add_signed(d),
                    SeekFrom::End(_) => Some(reader.lock().map_err(|_| poisoned())?.seek(to)?),
                };
                *position = target.ok_or_else(|| {
                    std::io::Error::new(std::io::ErrorKind::InvalidInput, "seek before the start")
                })?;
                Ok(*position)
            }
        }
    }
}

impl Source {
    /// Starts a pass at the beginning.
    fn open(&self) -> Result<SourceReader> {
        match &self.reader {
            None => open_file(&self.path).map(SourceReader::File),
            Some(reader) => Ok(SourceReader::Shared {
                reader: Arc::clone(reader),
                position: 0,
            }),
        }
    }

    /// The length in bytes.
    fn len(&self, pass: &mut SourceReader) -> Result<u64> {
        let len = match pass {
            SourceReader::File(f) => f.metadata().map(|m| m.len()),
            SourceReader::Shared { .. } => pass.seek(SeekFrom::End(0)),
        };
        len.map_err(|e| Error::io("cannot stat MCAP file", &self.path, e))
    }
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
    truncation: Option<Truncation>,
    file_len: u64,
}

fn mcap_error(path: &Path, message: impl Into<String>) -> Error {
    Error::Dataset {
        path: path.to_owned(),
        message: message.into(),
    }
}

fn open_file(path: &Path) -> Result<File> {
    // Opening a directory succeeds on Unix; reading it then fails with a vaguer message.
    if path.is_dir() {
        return Err(mcap_error(path, "expected an MCAP file, found a directory"));
    }
    File::open(path).map_err(|e| Error::io("cannot open MCAP file", path, e))
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
        return Err(mcap_error(
            path,
            "not an MCAP file (expected the magic bytes \\x89MCAP0\\r\\n at the start)",
        ));
    }
    let opcode = prefix[MAGIC_BYTES];
    let mut len_bytes = [0u8; 8];
    len_bytes.copy_from_slice(&prefix[MAGIC_BYTES + 1..]);
    let len = u64::from_le_bytes(len_bytes);
    if opcode != mcap::records::op::HEADER || len > MAX_HEADER_BYTES {
        return Err(mcap_error(path, "MCAP file does not start with a header record"));
    }
    let mut body = vec![0u8; len as usize];
    file.read_exact(&mut body)
        .map_err(|e| Error::io("cannot read MCAP header", path, e))?;
    match mcap::parse_record(opcode, &body)? {
        Record::Header(h) => Ok(h.profile),
        _ => Err(mcap_error(path, "MCAP file does not start with a header record")),
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
    /// [`Error::Io`] when the file cannot be read; [`Error::Dataset`] when it is not MCAP;
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
                return Err(mcap_error(
                    self.path(),
                    "metadata or attachment index points outside the file",
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
                    return Err(mcap_error(
                        self.path(),
                        "metadata or attachment index points at another record",
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
                        return Err(self.chunk_error(index, "its index points past the end of the file"));
                    }
                    chunk.resize(header_len + length, 0);
                    file.seek(SeekFrom::Start(start))
                        .and_then(|_| file.read_exact(&mut chunk))
                        .map_err(|e| Error::io("cannot read MCAP chunk", self.path(), e))?;
                    let (header, data) = chunk.split_at(header_len);
                    let expected_crc = match index {
                        Some(index) => {
                            chunk_header_crc(header).map_err(|m| self.chunk_error(Some(index), &m))?
                        }
                        None => 0,
                    };
                    if let Ok(mut c) = crc.lock() {
                        *c = None;
                    }
                    reader
                        .insert_chunk_record_data(offset, data)
                        .map_err(|e| self.chunk_error(index, &e.to_string()))?;
                    let found = if index.is_some_and(|i| i.compression.is_empty()) {
                        Some(crc32fast::hash(data))
                    } else {
                        crc.lock().ok().and_then(|c| *c)
                    };
                    check_crc(expected_crc, found).map_err(|m| self.chunk_error(index, &m))?;
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

/// CRC of the last chunk a [`CheckedDecompressor`] decompressed, shared with the reading loop.
type SharedCrc = Arc<std::sync::Mutex<Option<u32>>>;

/// Decompresses whole zstd or lz4 chunks (the indexed reader hands over a complete chunk and
/// an output buffer of its declared size) and records the CRC-32 of the output, so the
/// chunk's CRC is checked for compressed chunks too: a flipped bit that still decompresses
/// would otherwise go unnoticed.
struct CheckedDecompressor {
    name: &'static str,
    crc: SharedCrc,
}

impl mcap::sans_io::decompressor::Decompressor for CheckedDecompressor {
    fn next_read_size(&self) -> usize {
        0
    }

    fn decompress(
        &mut self,
        src: &[u8],
        dst: &mut [u8],
    ) -> mcap::McapResult<mcap::sans_io::decompressor::DecompressResult> {
        let bad = |e: std::io::Error| mcap::McapError::DecompressionError(format!("{} data: {e}", self.name));
        let wrote = if self.name == "zstd" {
            zstd::bulk::Decompressor::new()
                .and_then(|mut d| d.decompress_to_buffer(src, dst))
                .map_err(bad)?
        } else {
            let mut decoder = lz4::Decoder::new(src).map_err(bad)?;
            decoder.read_exact(dst).map_err(bad)?;
            dst.len()
        };
        if let Ok(mut crc) = self.crc.lock() {
            *crc = Some(crc32fast::hash(&dst[..wrote]));
        }
        Ok(mcap::sans_io::decompressor::DecompressResult {
            consumed: src.len(),
            wrote,
        })
    }

    fn reset(&mut self) -> mcap::McapResult<()> {
        Ok(())
    }

    fn name(&self) -> &'static str {
        self.name
    }
}

/// Byte offset of the uncompressed-data CRC inside a chunk record: opcode, record length,
/// message start and end time, uncompressed size.
const CHUNK_CRC_OFFSET: usize = 1 + 8 + 8 + 8 + 8;

/// Checks a chunk record's header and returns the CRC of its uncompressed data (0 = not
/// computed, per the MCAP specification).
fn chunk_header_crc(header: &[u8]) -> std::result::Result<u32, String> {
    if header.len() < CHUNK_CRC_OFFSET + 4 || header[0] != mcap::records::op::CHUNK {
        return Err("expected a chunk record at the offset its index gives".into());
    }
    let mut crc = [0u8; 4];
    crc.copy_from_slice(&header[CHUNK_CRC_OFFSET..CHUNK_CRC_OFFSET + 4]);
    Ok(u32::from_le_bytes(crc))
}

fn check_crc(expected: u32, found: Option<u32>) -> std::result::Result<(), String> {
    match found {
        Some(found) if expected != 0 && found != expected => Err(format!(
            "CRC mismatch: expected {expected:#010x} from the chunk header, computed {found:#010x} \
             from its data"
        )),
        _ => Ok(()),
    }
}

impl McapInput {
    /// Messages a chunk holds, from its message index records (which follow the chunk, so they
    /// usually survive damage to it); `None` when they cannot be read.
    fn chunk_message_count(&self, index: &mcap::records::ChunkIndex) -> Option<u64> {
        // Message index record: opcode, record length, channel ID (u16), then the byte length of
        // its (log time, offset) pairs of 16 bytes each.
        const PREFIX_BYTES: usize = 1 + 8 + 2 + 4;
        const ENTRY_BYTES: u64 = 16;
        let mut file = self.source.open().ok()?;
        let mut total = 0;
        for offset in index.message_index_offsets.values() {
            let mut prefix = [0u8; PREFIX_BYTES];
            file.seek(SeekFrom::Start(*offset)).ok()?;
            file.read_exact(&mut prefix).ok()?;
            if prefix[0] != mcap::records::op::MESSAGE_INDEX {
                return None;
            }
            let mut len = [0u8; 4];
            len.copy_from_slice(&prefix[11..15]);
            total += u64::from(u32::from_le_bytes(len)) / ENTRY_BYTES;
        }
        Some(total)
    }

    fn chunk_error(&self, index: Option<&mcap::records::ChunkIndex>, what: &str) -> Error {
        let place = match index {
            Some(c) => format!(
                "chunk at byte {}{} (messages logged from {} to {} s, compression {:?})",
                c.chunk_start_offset,
                self.chunk_message_count(c)
                    .map(|n| format!(" holding {n} messages"))
                    .unwrap_or_default(),
                crate::time::format_ns_as_seconds(c.message_start_time, 6),
                crate::time::format_ns_as_seconds(c.message_end_time, 6),
                c.compression
            ),
            None => "a chunk".to_owned(),
        };
        mcap_error(
            self.path(),
            format!(
                "damaged {place}: {what}; the other chunks are intact (`mcap recover` copies them to a \
                 new file)"
            ),
        )
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
