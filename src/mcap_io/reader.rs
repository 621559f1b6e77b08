//! [`McapFileReader`]: reads files occmask wrote back into Foxglove messages.
//!
//! The file is memory-mapped; messages are streamed chunk by chunk in file order (which is
//! log-time order for our files) and decoded by their channel's schema name.

use std::collections::BTreeMap;
use std::fs::File;
use std::path::{Path, PathBuf};

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
        let stream = mcap::MessageStream::new(&self.map)?;
        Ok(stream.map(|m| {
            let m = m?;
            let schema_name = m.channel.schema.as_ref().map(|s| s.name.as_str()).unwrap_or("");
            let message = codec::decode(schema_name, &m.channel.topic, &m.data)?;
            Ok(ReadMessage {
                topic: m.channel.topic.clone(),
                log_time_ns: m.log_time,
                sequence: m.sequence,
                message,
            })
        }))
    }
}
