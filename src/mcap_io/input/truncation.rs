//! Where a damaged input ends: the record framing walked from the start, and what can be
//! salvaged from an incomplete trailing chunk.

use std::io::{BufReader, Read, Seek, SeekFrom};

use mcap::records::Record;

use super::source::Source;
use crate::error::{Error, Result};

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
pub(super) fn partial_chunk_records(source: &Source, offset: u64) -> Result<Vec<(u8, Vec<u8>)>> {
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
pub(super) fn find_truncation(source: &Source, file_len: u64) -> Result<Truncation> {
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
