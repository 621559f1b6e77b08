//! Chunk integrity: whole-chunk decompression with a CRC-32 of the output, the CRC in a chunk
//! record's header, and the error that says which chunk is damaged and what it held.

use std::io::{Read, Seek, SeekFrom};
use std::sync::Arc;

use super::McapInput;
use crate::error::{ChunkDamage, ChunkPlace, Error, McapProblem};

/// CRC of the last chunk a [`CheckedDecompressor`] decompressed, shared with the reading loop.
pub(super) type SharedCrc = Arc<std::sync::Mutex<Option<u32>>>;

/// Decompresses whole zstd or lz4 chunks (the indexed reader hands over a complete chunk and
/// an output buffer of its declared size) and records the CRC-32 of the output, so the
/// chunk's CRC is checked for compressed chunks too: a flipped bit that still decompresses
/// would otherwise go unnoticed.
pub(super) struct CheckedDecompressor {
    pub(super) name: &'static str,
    pub(super) crc: SharedCrc,
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
pub(super) fn chunk_header_crc(header: &[u8]) -> std::result::Result<u32, ChunkDamage> {
    if header.len() < CHUNK_CRC_OFFSET + 4 || header[0] != mcap::records::op::CHUNK {
        return Err(ChunkDamage::NotAChunk);
    }
    let mut crc = [0u8; 4];
    crc.copy_from_slice(&header[CHUNK_CRC_OFFSET..CHUNK_CRC_OFFSET + 4]);
    Ok(u32::from_le_bytes(crc))
}

pub(super) fn check_crc(expected: u32, found: Option<u32>) -> std::result::Result<(), ChunkDamage> {
    match found {
        Some(computed) if expected != 0 && computed != expected => {
            Err(ChunkDamage::CrcMismatch { expected, computed })
        }
        _ => Ok(()),
    }
}

impl McapInput {
    /// Messages a chunk holds, from its message index records (which follow the chunk, so they
    /// usually survive damage to it); `None` when they cannot be read.
    pub(super) fn chunk_message_count(&self, index: &mcap::records::ChunkIndex) -> Option<u64> {
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

    pub(super) fn chunk_error(
        &self,
        index: Option<&mcap::records::ChunkIndex>,
        damage: ChunkDamage,
    ) -> Error {
        let chunk = index.map(|c| {
            Box::new(ChunkPlace {
                start_offset: c.chunk_start_offset,
                messages: self.chunk_message_count(c),
                message_start_time_ns: c.message_start_time,
                message_end_time_ns: c.message_end_time,
                compression: c.compression.clone(),
            })
        });
        Error::bad_mcap(self.path(), McapProblem::DamagedChunk { chunk, damage })
    }
}
