//! Pixel codecs of the field: RVL depth compression (`compressedDepth rvl`), packed YUV 4:2:2
//! and Bayer mosaics, and the grey of interleaved colour. Every decoder checks declared sizes
//! against the data before writing and fails with a message instead of reading past the end.

use crate::mcap_io::encoding::BayerFilter;
use crate::simd::{simd_kernel, Simd};

/// Bytes of the header `compressed_depth_image_transport` writes before an RVL stream: the
/// image's width and height as little-endian `u32`.
pub const RVL_SIZE_HEADER_BYTES: usize = 8;
/// An RVL stream is at most this many times smaller than the image it holds, in pixels per
/// byte: the bound `compressed_depth_image_transport` itself applies to reject corrupt sizes
/// (its best compression ratio is 4:1 in bytes; it allows 10:1).
pub const RVL_MAX_PIXELS_PER_BYTE: u64 = 5;
/// Nibbles of one RVL variable-length value: 3 payload bits each, so 11 cover 32 bits.
const RVL_MAX_NIBBLES: u32 = 11;

/// Reads the nibbles of an RVL stream: little-endian 32-bit words, most significant nibble
/// first.
struct Nibbles<'a> {
    data: &'a [u8],
    word: u32,
    left: u32,
}

impl Nibbles<'_> {
    fn next(&mut self) -> Result<u32, String> {
        if self.left == 0 {
            let Some((word, rest)) = self.data.split_first_chunk::<4>() else {
                return Err("RVL stream ends inside a value".into());
            };
            self.word = u32::from_le_bytes(*word);
            self.data = rest;
            self.left = 8;
        }
        let nibble = self.word >> 28;
        self.word <<= 4;
        self.left -= 1;
        Ok(nibble)
    }

    /// One variable-length value: 3 bits per nibble, least significant first, while the
    /// nibble's high bit says more follow.
    fn value(&mut self) -> Result<u32, String> {
        let mut value = 0u32;
        for k in 0..RVL_MAX_NIBBLES {
            let nibble = self.next()?;
            value |= (nibble & 0x7).checked_shl(3 * k).unwrap_or(0);
            if nibble & 0x8 == 0 {
                return Ok(value);
            }
        }
        Err("RVL value longer than 32 bits".into())
    }
}

/// Decodes an RVL stream (Wilson, "Fast Lossless Depth Image Compression", ISS 2017, as
/// `compressed_depth_image_transport` writes it: runs of zeros and of non-zero values, the
/// latter as zig-zag deltas) into `out` (one value per pixel).
///
/// # Errors
/// A message when the stream ends early, a run overruns the image or a value is malformed.
pub fn decode_rvl(data: &[u8], out: &mut [u16]) -> Result<(), String> {
    let mut nibbles = Nibbles {
        data,
        word: 0,
        left: 0,
    };
    let mut previous = 0u16;
    let mut at = 0usize;
    let pixels = out.len();
    let run = |n: u32, at: usize| -> Result<usize, String> {
        at.checked_add(n as usize)
            .filter(|&end| end <= pixels)
            .ok_or_else(|| format!("RVL run of {n} values at pixel {at} overruns the {pixels} pixels"))
    };
    while at < pixels {
        let zeros_end = run(nibbles.value()?, at)?;
        out[at..zeros_end].fill(0);
        at = zeros_end;
        let values_end = run(nibbles.value()?, at)?;
        for o in &mut out[at..values_end] {
            let zigzag = nibbles.value()?;
            // Zig-zag: 2|d| for d ≥ 0, 2|d| − 1 for d < 0; values are 16-bit, deltas wrap.
            let delta = ((zigzag >> 1) as i32) ^ -((zigzag & 1) as i32);
            previous = previous.wrapping_add(delta as u16);
            *o = previous;
        }
        at = values_end;
    }
    Ok(())
}

/// Encodes `values` as RVL (the inverse of [`decode_rvl`], for fixtures and round trips).
pub fn encode_rvl(values: &[u16]) -> Vec<u8> {
    struct Writer {
        out: Vec<u8>,
        word: u32,
        nibbles: u32,
    }
    impl Writer {
        fn value(&mut self, mut v: u32) {
            loop {
                let mut nibble = v & 0x7;
                v >>= 3;
                if v != 0 {
                    nibble |= 0x8;
                }
                self.word = (self.word << 4) | nibble;
                self.nibbles += 1;
                if self.nibbles == 8 {
                    self.out.extend_from_slice(&self.word.to_le_bytes());
                    self.word = 0;
                    self.nibbles = 0;
                }
                if v == 0 {
                    return;
                }
            }
        }
    }
    let mut w = Writer {
        out: Vec::new(),
        word: 0,
        nibbles: 0,
    };
    let mut previous = 0u16;
    let mut i = 0;
    while i < values.len() {
        let zeros = values[i..].iter().take_while(|&&v| v == 0).count();
        i += zeros;
        let nonzeros = values[i..].iter().take_while(|&&v| v != 0).count();
        w.value(zeros as u32);
        w.value(nonzeros as u32);
        for &v in &values[i..i + nonzeros] {
            let delta = i32::from(v) - i32::from(previous);
            w.value(((delta << 1) ^ (delta >> 31)) as u32);
            previous = v;
        }
        i += nonzeros;
    }
    if w.nibbles > 0 {
        let word = w.word << (4 * (8 - w.nibbles));
        w.out.extend_from_slice(&word.to_le_bytes());
    }
    w.out
}

/// Byte offset of pixel `x`'s luma in a packed YUV 4:2:2 row: `uyvy` (ROS `yuv422`) stores
/// U Y V Y, `yuyv` (ROS `yuv422_yuy2`) Y U Y V.
pub fn yuv422_luma_offset(x: usize, uyvy: bool) -> usize {
    2 * x + usize::from(uyvy)
}

/// Grey in [0, 1] from BT.601 video-range luma (16 = black, 235 = white), as the RGB a
/// standard YUV→RGB conversion gives would have.
#[inline]
pub fn gray_from_video_luma(y: u8) -> f32 {
    /// Black level and range of 8-bit BT.601 video-range luma.
    const BLACK: f32 = 16.0;
    const RANGE: f32 = 219.0;
    ((f32::from(y) - BLACK) / RANGE).clamp(0.0, 1.0)
}

/// Byte offsets of the U and V samples shared by pixel `x` in a packed YUV 4:2:2 row (see
/// [`yuv422_luma_offset`]).
pub fn yuv422_chroma_offsets(x: usize, uyvy: bool) -> (usize, usize) {
    let pair = 4 * (x / 2);
    if uyvy {
        (pair, pair + 2)
    } else {
        (pair + 1, pair + 3)
    }
}

/// Chroma of no colour (U = V = 128).
pub const NEUTRAL_CHROMA: u8 = 128;

/// RGB from BT.601 video-range YUV (the standard conversion: luma 16–235, chroma 16–240
/// around 128).
#[inline]
pub fn rgb_from_video_yuv(y: u8, u: u8, v: u8) -> [u8; 3] {
    let c = 1.164 * (f32::from(y) - 16.0);
    let (d, e) = (f32::from(u) - 128.0, f32::from(v) - 128.0);
    let channel = |value: f32| value.round().clamp(0.0, 255.0) as u8;
    [
        channel(c + 1.596 * e),
        channel(c - 0.392 * d - 0.813 * e),
        channel(c + 2.017 * d),
    ]
}

/// The colour filter of a Bayer mosaic: the channel (0 = R, 1 = G, 2 = B) of the top-left
/// 2×2 cell's four pixels in row order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BayerPattern([u8; 4]);

impl From<BayerFilter> for BayerPattern {
    fn from(filter: BayerFilter) -> Self {
        Self(match filter {
            BayerFilter::Rggb => [0, 1, 1, 2],
            BayerFilter::Bggr => [2, 1, 1, 0],
            BayerFilter::Gbrg => [1, 2, 0, 1],
            BayerFilter::Grbg => [1, 0, 2, 1],
        })
    }
}

impl BayerPattern {
    fn channel(self, x: usize, y: usize) -> usize {
        usize::from(self.0[(y % 2) * 2 + x % 2])
    }
}

/// Bilinear demosaicing of one pixel: its own channel is its own sample; each other channel
/// is the mean of that channel's samples in the 3×3 neighbourhood (its 2 or 4 nearest; the
/// image border repeated).
///
/// `rows` are the mosaic's rows (at least `width` bytes each).
pub fn demosaic_pixel(rows: &[&[u8]], pattern: BayerPattern, x: usize, y: usize) -> [u8; 3] {
    let (width, height) = (rows[0].len(), rows.len());
    let own = pattern.channel(x, y);
    let mut sum = [0u32; 3];
    let mut count = [0u32; 3];
    for dy in [-1isize, 0, 1] {
        let ny = (y as isize + dy).clamp(0, height as isize - 1) as usize;
        for dx in [-1isize, 0, 1] {
            let nx = (x as isize + dx).clamp(0, width as isize - 1) as usize;
            let c = pattern.channel(nx, ny);
            sum[c] += u32::from(rows[ny][nx]);
            count[c] += 1;
        }
    }
    let mut rgb = [0u8; 3];
    for c in 0..3 {
        rgb[c] = if c == own {
            rows[y][x]
        } else {
            // A 1-pixel-wide image has neighbours of only two channels: the own value then.
            (sum[c] + count[c] / 2)
                .checked_div(count[c])
                .map_or(rows[y][x], |v| v as u8)
        };
    }
    rgb
}

/// Grey from interleaved 8-bit pixels (`bpp` bytes each, red, green and blue at `offsets`):
/// `out[i] = wr·r + wg·g + wb·b` with `weights` = (wr, wg, wb), summed in that order.
/// `data` holds at least `out.len()` pixels. The common layouts (RGB, RGBA, BGR, BGRA) run in
/// a loop the compiler vectorises (AVX2 when the CPU has it: 5× a per-pixel loop on VGA), with
/// the same bits as [`gray_from_interleaved_reference`].
pub fn gray_from_interleaved(
    out: &mut [f32],
    data: &[u8],
    bpp: usize,
    offsets: [usize; 3],
    weights: [f32; 3],
) {
    let simd = Simd::detect();
    match (bpp, offsets) {
        (3, [0, 1, 2]) => weighted::<3, 0, 1, 2>(simd, out, data, weights),
        (4, [0, 1, 2]) => weighted::<4, 0, 1, 2>(simd, out, data, weights),
        (3, [2, 1, 0]) => weighted::<3, 2, 1, 0>(simd, out, data, weights),
        (4, [2, 1, 0]) => weighted::<4, 2, 1, 0>(simd, out, data, weights),
        _ => gray_from_interleaved_reference(out, data, bpp, offsets, weights),
    }
}

/// [`gray_from_interleaved`] one pixel at a time, for any layout.
pub fn gray_from_interleaved_reference(
    out: &mut [f32],
    data: &[u8],
    bpp: usize,
    [r, g, b]: [usize; 3],
    [wr, wg, wb]: [f32; 3],
) {
    for (o, px) in out.iter_mut().zip(data.chunks_exact(bpp)) {
        *o = wr * f32::from(px[r]) + wg * f32::from(px[g]) + wb * f32::from(px[b]);
    }
}

simd_kernel!(
    weighted,
    weighted_avx2,
    weighted_generic<const BPP: usize, const R: usize, const G: usize, const B: usize>,
    (out: &mut [f32], data: &[u8], weights: [f32; 3])
);

/// The reference's arithmetic with the layout known at compile time.
#[inline(always)]
fn weighted_generic<const BPP: usize, const R: usize, const G: usize, const B: usize>(
    out: &mut [f32],
    data: &[u8],
    [wr, wg, wb]: [f32; 3],
) {
    for (o, px) in out.iter_mut().zip(data.chunks_exact(BPP)) {
        *o = wr * f32::from(px[R]) + wg * f32::from(px[G]) + wb * f32::from(px[B]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The vectorised grey agrees with the per-pixel reference bit for bit, for every
    /// specialised layout and one that is not (offsets in another order), on varied bytes and
    /// on lengths that leave a remainder after any vector width.
    #[test]
    fn interleaved_gray_matches_the_reference() {
        let weights = [0.299_f32 / 255.0, 0.587 / 255.0, 0.114 / 255.0];
        for (bpp, offsets) in [
            (3, [0, 1, 2]),
            (4, [0, 1, 2]),
            (3, [2, 1, 0]),
            (4, [2, 1, 0]),
            (3, [1, 0, 2]),
        ] {
            for pixels in [1, 7, 33, 256 * 3 + 5] {
                let data: Vec<u8> = (0..pixels * bpp).map(|i| (i * 89 + i / 7) as u8).collect();
                let (mut fast, mut reference) = (vec![f32::NAN; pixels], vec![0.0; pixels]);
                gray_from_interleaved(&mut fast, &data, bpp, offsets, weights);
                gray_from_interleaved_reference(&mut reference, &data, bpp, offsets, weights);
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(
                    bits(&fast),
                    bits(&reference),
                    "bpp {bpp}, offsets {offsets:?}, {pixels} px"
                );
            }
        }
    }

    #[test]
    fn rvl_round_trips_runs_deltas_and_extremes() {
        let values: Vec<u16> = [
            0, 0, 0, 1500, 1501, 1499, 0, 65535, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 42,
        ]
        .into_iter()
        .chain((0..1000).map(|i| {
            if i % 7 == 0 {
                0
            } else {
                800 + (i * 37 % 300) as u16
            }
        }))
        .collect();
        let encoded = encode_rvl(&values);
        let mut decoded = vec![9u16; values.len()];
        decode_rvl(&encoded, &mut decoded).unwrap();
        assert_eq!(decoded, values);
        // A stream of known bytes: 3 zeros, 1 value 5 (zig-zag 10 = 0o12: nibbles 0xA, 0x1),
        // padded to a word: nibbles 3, 1, A, 1 then zeros.
        let word: u32 = 0x31A1_0000;
        let mut one = vec![7u16; 4];
        decode_rvl(&word.to_le_bytes(), &mut one).unwrap();
        assert_eq!(one, [0, 0, 0, 5]);
    }

    #[test]
    fn corrupt_rvl_streams_are_errors() {
        let encoded = encode_rvl(&[100, 200, 0, 300]);
        let mut out = vec![0u16; 4];
        for len in 0..encoded.len() {
            // Truncated streams must fail or stop cleanly, never read past the end.
            let _ = decode_rvl(&encoded[..len], &mut out);
        }
        assert!(decode_rvl(&[], &mut out).is_err());
        // A run longer than the image (3 zeros into 2 pixels).
        let mut small = vec![0u16; 2];
        let zeros = encode_rvl(&[0, 0, 0, 5]);
        assert!(decode_rvl(&zeros, &mut small).unwrap_err().contains("overruns"));
        // All continuation bits: a value longer than 32 bits.
        assert!(decode_rvl(&[0xff; 16], &mut out).unwrap_err().contains("32 bits"));
    }

    #[test]
    fn demosaicing_a_uniform_colour_returns_it() {
        // A uniform colour (r, g, b) mosaicked with each pattern demosaics back to (r, g, b)
        // everywhere, borders included.
        let (r, g, b) = (200u8, 120u8, 40u8);
        for encoding in [
            BayerFilter::Rggb,
            BayerFilter::Bggr,
            BayerFilter::Gbrg,
            BayerFilter::Grbg,
        ] {
            let pattern = BayerPattern::from(encoding);
            let mosaic: Vec<Vec<u8>> = (0..5)
                .map(|y| (0..6).map(|x| [r, g, b][pattern.channel(x, y)]).collect())
                .collect();
            let rows: Vec<&[u8]> = mosaic.iter().map(Vec::as_slice).collect();
            for y in 0..5 {
                for x in 0..6 {
                    assert_eq!(
                        demosaic_pixel(&rows, pattern, x, y),
                        [r, g, b],
                        "{encoding:?} ({x},{y})"
                    );
                }
            }
        }
    }

    #[test]
    fn yuv_luma_offsets_and_levels() {
        assert_eq!(yuv422_luma_offset(0, true), 1);
        assert_eq!(yuv422_luma_offset(3, true), 7);
        assert_eq!(yuv422_luma_offset(3, false), 6);
        assert_eq!(gray_from_video_luma(16), 0.0);
        assert_eq!(gray_from_video_luma(235), 1.0);
        assert_eq!(gray_from_video_luma(255), 1.0);
        assert!((gray_from_video_luma(125) - 0.5).abs() < 0.01);
    }
}
