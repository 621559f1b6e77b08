//! [`McapFileReader`]: reads files occmask wrote back into Foxglove messages.
//!
//! The file is memory-mapped; messages are streamed chunk by chunk in file order (which is
//! log-time order for our files) and decoded by their channel's schema name.

use std::collections::BTreeMap;
use std::fs::File;
use std::path::{Path, PathBuf};

use mcap::records::Record;
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use crate::error::{Error, Result};

use super::codec::{self, Decoded};

/// An attachment read from the file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReadAttachment {
    /// File name as stored.
    pub name: String,
    /// Media type such as `text/plain`.
    pub media_type: String,
    /// Log time, nanoseconds.
    pub log_time_ns: u64,
    /// The bytes.
    pub data: Vec<u8>,
}

/// A channel of the file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelInfo {
    /// Channel ID.
    pub id: u16,
    /// Topic name.
    pub topic: String,
    /// Schema name (`foxglove.RawImage`, ...), empty without a schema.
    pub schema_name: String,
    /// Message encoding (`protobuf`).
    pub message_encoding: String,
    /// Channel metadata (e.g. [`super::DEPTH_UNITS_KEY`]).
    pub metadata: BTreeMap<String, String>,
}

/// One decoded message.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadMessage {
    /// Topic name.
    pub topic: String,
    /// MCAP log time, nanoseconds.
    pub log_time_ns: u64,
    /// Per-channel sequence number.
    pub sequence: u32,
    /// The decoded message.
    pub message: Decoded,
}

/// A memory-mapped MCAP file with its summary.
pub struct McapFileReader {
    path: PathBuf,
    map: memmap2::Mmap,
    summary: mcap::Summary,
}

impl McapFileReader {
    /// Opens `path` and reads its summary.
    ///
    /// # Errors
    /// [`Error::Io`] when the file cannot be opened or mapped; [`Error::Mcap`] when it is not
    /// an MCAP file; [`Error::Dataset`] when it has no summary (an unfinished recording: run
    /// `pymcap-cli recover` on it first).
    pub fn open(path: &Path) -> Result<Self> {
        let file = File::open(path).map_err(|e| Error::io("cannot open MCAP file", path, e))?;
        // SAFETY: the map is read-only; as with any mmap, the file must not be truncated by
        // another process while we read it.
        let map =
            unsafe { memmap2::Mmap::map(&file) }.map_err(|e| Error::io("cannot map MCAP file", path, e))?;
        let summary = mcap::Summary::read(&map)?.ok_or_else(|| Error::Dataset {
            path: path.to_owned(),
            message: "MCAP file has no summary section (unfinished or unindexed); \
                      repair it with `pymcap-cli recover` first"
                .into(),
        })?;
        Ok(Self {
            path: path.to_owned(),
            map,
            summary,
        })
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The MCAP summary (statistics, channels, schemas, indexes).
    pub fn summary(&self) -> &mcap::Summary {
        &self.summary
    }

    /// Channels sorted by ID.
    pub fn channels(&self) -> Vec<ChannelInfo> {
        let mut out: Vec<ChannelInfo> = self
            .summary
            .channels
            .values()
            .map(|c| ChannelInfo {
                id: c.id,
                topic: c.topic.clone(),
                schema_name: c.schema.as_ref().map(|s| s.name.clone()).unwrap_or_default(),
                message_encoding: c.message_encoding.clone(),
                metadata: c.metadata.clone(),
            })
            .collect();
        out.sort_by_key(|c| c.id);
        out
    }

    /// Metadata records in file order.
    ///
    /// # Errors
    /// [`Error::Mcap`] on a corrupt index or record.
    pub fn metadata(&self) -> Result<Vec<mcap::records::Metadata>> {
        let mut indexes = self.summary.metadata_indexes.clone();
        indexes.sort_by_key(|i| i.offset);
        indexes
            .iter()
            .map(|i| mcap::read::metadata(&self.map, i).map_err(Error::from))
            .collect()
    }

    /// Attachments in file order.
    ///
    /// # Errors
    /// [`Error::Mcap`] on a corrupt index or record.
    pub fn attachments(&self) -> Result<Vec<ReadAttachment>> {
        let mut indexes = self.summary.attachment_indexes.clone();
        indexes.sort_by_key(|i| i.offset);
        indexes
            .iter()
            .map(|i| {
                let a = mcap::read::attachment(&self.map, i)?;
                Ok(ReadAttachment {
                    name: a.name,
                    media_type: a.media_type,
                    log_time_ns: a.log_time,
                    data: a.data.into_owned(),
                })
            })
            .collect()
    }

    /// Decoded messages in file order (log-time order for files occmask wrote).
    ///
    /// # Errors
    /// Each item is [`Error::Mcap`] for a corrupt record or [`Error::Decode`] for a message
    /// that does not match its schema.
    pub fn messages(&self) -> Result<impl Iterator<Item = Result<ReadMessage>> + '_> {
        // The sans-IO reader with a record-length limit: `mcap::MessageStream` (mcap 0.26)
        // decompresses chunks without one, and a corrupt record length inside a chunk made it
        // panic with "capacity overflow" (found by fuzzing, fuzz/README.md).
        let reader = LinearReader::new_with_options(
            LinearReaderOptions::default().with_record_length_limit(self.map.len()),
        );
        Ok(Messages {
            data: &self.map,
            pos: 0,
            reader,
            schemas: BTreeMap::new(),
            channels: BTreeMap::new(),
            done: false,
        })
    }
}

/// Streaming iterator behind [`McapFileReader::messages`].
struct Messages<'a> {
    data: &'a [u8],
    /// Bytes of `data` already handed to `reader`.
    pos: usize,
    reader: LinearReader,
    /// Schema ID → schema name.
    schemas: BTreeMap<u16, String>,
    /// Channel ID → (topic, schema ID).
    channels: BTreeMap<u16, (String, u16)>,
    done: bool,
}

impl Iterator for Messages<'_> {
    type Item = Result<ReadMessage>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            let event = match self.reader.next_event()? {
                Ok(event) => event,
                Err(e) => {
                    self.done = true;
                    return Some(Err(e.into()));
                }
            };
            let record = match event {
                LinearReadEvent::ReadRequest(n) => {
                    let n = n.min(self.data.len() - self.pos);
                    self.reader
                        .insert(n)
                        .copy_from_slice(&self.data[self.pos..self.pos + n]);
                    self.reader.notify_read(n);
                    self.pos += n;
                    continue;
                }
                LinearReadEvent::Record { data, opcode } => mcap::parse_record(opcode, data),
            };
            let message = match record {
                Ok(Record::Schema { header, .. }) => {
                    self.schemas.insert(header.id, header.name);
                    continue;
                }
                Ok(Record::Channel(c)) => {
                    self.channels.insert(c.id, (c.topic, c.schema_id));
                    continue;
                }
                Ok(Record::Message { header, data }) => {
                    let Some((topic, schema_id)) = self.channels.get(&header.channel_id) else {
                        return Some(Err(mcap::McapError::UnknownChannel(
                            header.sequence,
                            header.channel_id,
                        )
                        .into()));
                    };
                    let schema_name = self.schemas.get(schema_id).map_or("", String::as_str);
                    codec::decode(schema_name, topic, &data).map(|message| ReadMessage {
                        topic: topic.clone(),
                        log_time_ns: header.log_time,
                        sequence: header.sequence,
                        message,
                    })
                }
                Ok(_) => continue,
                Err(e) => Err(e.into()),
            };
            return Some(message);
        }
        None
    }
}
