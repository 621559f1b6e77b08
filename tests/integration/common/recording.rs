//! Reading back what occmask wrote, through the library's one MCAP reader
//! ([`occmask::mcap_io::input::McapInput`]); messages are decoded by the tests themselves
//! (protobuf with `prost`), so fields can be compared bit for bit.

use std::path::Path;

use occmask::mcap_io::input::{ExtraRecord, McapInput};

/// One stored message.
#[derive(Debug, Clone)]
pub struct Message {
    /// Its channel's topic.
    pub topic: String,
    /// Its channel's schema name.
    pub schema_name: String,
    /// MCAP log time, nanoseconds.
    pub log_time_ns: u64,
    /// The serialised message.
    pub data: Vec<u8>,
}

impl Message {
    /// The message decoded as protobuf `T`.
    pub fn decode<T: prost::Message + Default>(&self) -> T {
        T::decode(self.data.as_slice())
            .unwrap_or_else(|e| panic!("{}: not a protobuf {}: {e}", self.topic, self.schema_name))
    }
}

/// Opens `path` with the library's reader.
pub fn open(path: &Path) -> McapInput {
    McapInput::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Every message of `input`, in log-time order.
pub fn messages(input: &McapInput) -> Vec<Message> {
    let mut out = Vec::new();
    input
        .for_each_message(None, None, |m| {
            let channel = &input.channels()[&m.header.channel_id];
            out.push(Message {
                topic: channel.topic.clone(),
                schema_name: channel.schema_name.clone(),
                log_time_ns: m.header.log_time,
                data: m.data,
            });
            Ok(true)
        })
        .unwrap();
    out
}

/// The metadata records of `input`, in file order.
pub fn metadata(input: &McapInput) -> Vec<mcap::records::Metadata> {
    input
        .extras()
        .unwrap()
        .into_iter()
        .filter_map(|e| match e {
            ExtraRecord::Metadata(m) => Some(m),
            ExtraRecord::Attachment { .. } => None,
        })
        .collect()
}

/// The attachments of `input` as (name, bytes), in file order.
pub fn attachments(input: &McapInput) -> Vec<(String, Vec<u8>)> {
    input
        .extras()
        .unwrap()
        .into_iter()
        .filter_map(|e| match e {
            ExtraRecord::Attachment { name, data, .. } => Some((name, data)),
            ExtraRecord::Metadata(_) => None,
        })
        .collect()
}
