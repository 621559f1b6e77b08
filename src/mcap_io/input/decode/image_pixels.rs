//! Pixel conversion of a decoded image message into the pipeline's buffers: grey, RGB and
//! depth in metres, for every raw encoding ([`ColorEncoding`], [`DepthEncoding`]), PNG/JPEG
//! and the compressed-depth formats. A new colour encoding's conversion goes here; depth
//! values become metres in [`DepthEncoding`] and [`CompressedDepthFormat`] themselves, so a new
//! depth encoding does not touch this file.

use super::*;

/// Header bytes `compressed_depth_image_transport` puts before the PNG of a 16-bit depth
/// image (format enum + two float quantisation parameters).
pub(super) const COMPRESSED_DEPTH_HEADER_BYTES: usize = 12;

/// Checks row step and data length of a raw image; returns its size.
pub(super) fn raw_rows(
    topic: &str,
    width: u32,
    height: u32,
    step: u32,
    bpp: usize,
    len: usize,
) -> Result<ImageSize> {
    let size = ImageSize::new(width as usize, height as usize);
    if size.area() == 0 {
        // A 0×N image would pass the length checks with no data and loop over N empty rows.
        return Err(Error::decode(topic, DecodeProblem::EmptyImage { size }));
    }
    let row_bytes = size.width * bpp;
    let step = step as usize;
    if step < row_bytes {
        return Err(Error::decode(
            topic,
            DecodeProblem::RowStep {
                size,
                step,
                row_bytes,
            },
        ));
    }
    let needed = step * (size.height - 1) + row_bytes;
    // The data is `height` rows of `step` bytes; writers that trim the last row's padding are
    // accepted too. Anything else means width, height, step or encoding disagree with the data
    // (e.g. 32-bit float depth declared as 16UC1).
    let full = step * size.height;
    if len != needed && len != full {
        return Err(Error::decode(
            topic,
            DecodeProblem::ImageLength {
                size,
                step,
                bytes_per_pixel: bpp,
                needed,
                full,
                found: len,
            },
        ));
    }
    Ok(size)
}

pub(super) fn resize_for<T: Copy + Default>(image: &mut crate::image_buf::Image<T>, size: ImageSize) {
    if image.size() != size {
        *image = crate::image_buf::Image::filled(size, T::default());
    }
}

/// Decodes a colour (or grey) image into `gray` (0..1, BT.601 luma, the same weights as
/// [`crate::image_buf::gray_from_rgb8`]), resizing `gray` when the size differs.
///
/// # Errors
/// [`Error::Decode`] naming `topic` for unsupported encodings (listing the supported ones),
/// short buffers or undecodable PNG/JPEG.
pub fn gray_from_image_into(msg: &ImageMsg, topic: &str, gray: &mut GrayF32) -> Result<()> {
    let [wr, wg, wb] = LUMA_WEIGHTS_BT601.map(|w| w / 255.0);
    match &msg.payload {
        ImagePayload::Raw {
            width,
            height,
            encoding,
            step,
            data,
            ..
        } => {
            let (color, size) = raw_color(topic, *width, *height, encoding, *step, data)?;
            let bpp = color.bytes_per_pixel();
            resize_for(gray, size);
            let step = *step as usize;
            let row = |y: usize| &data[y * step..y * step + size.width * bpp];
            // Offsets of r, g, b in an interleaved pixel.
            let rgb_offsets = match color {
                ColorEncoding::Uyvy | ColorEncoding::Yuyv => {
                    // Packed 4:2:2: two bytes per pixel, the luma is the grey.
                    let uyvy = color == ColorEncoding::Uyvy;
                    for y in 0..size.height {
                        let row = row(y);
                        for (x, out) in gray.row_mut(y).iter_mut().enumerate() {
                            *out = pixels::gray_from_video_luma(row[pixels::yuv422_luma_offset(x, uyvy)]);
                        }
                    }
                    return Ok(());
                }
                ColorEncoding::Bayer8(filter) => {
                    let pattern = pixels::BayerPattern::from(filter);
                    let rows: Vec<&[u8]> = (0..size.height).map(row).collect();
                    for y in 0..size.height {
                        for (x, out) in gray.row_mut(y).iter_mut().enumerate() {
                            let [pr, pg, pb] = pixels::demosaic_pixel(&rows, pattern, x, y);
                            *out = wr * f32::from(pr) + wg * f32::from(pg) + wb * f32::from(pb);
                        }
                    }
                    return Ok(());
                }
                interleaved => interleaved_rgb_offsets(interleaved).unwrap_or([0, 0, 0]),
            };
            for y in 0..size.height {
                if bpp == 1 {
                    for (out, &v) in gray.row_mut(y).iter_mut().zip(row(y)) {
                        *out = f32::from(v) / 255.0;
                    }
                } else {
                    pixels::gray_from_interleaved(gray.row_mut(y), row(y), bpp, rgb_offsets, [wr, wg, wb]);
                }
            }
            Ok(())
        }
        ImagePayload::Compressed { format, data } => {
            let image_format = color_image_format(topic, format)?;
            let decoded = decode_compressed_pixels(data, image_format, topic, &format!("{format} image"))?;
            let size = ImageSize::new(decoded.width() as usize, decoded.height() as usize);
            resize_for(gray, size);
            if decoded.color().channel_count() <= 2 {
                let luma = decoded.into_luma8();
                for (out, v) in gray.as_mut_slice().iter_mut().zip(luma.as_raw()) {
                    *out = f32::from(*v) / 255.0;
                }
            } else {
                let rgb = decoded.into_rgb8();
                pixels::gray_from_interleaved(gray.as_mut_slice(), rgb.as_raw(), 3, [0, 1, 2], [wr, wg, wb]);
            }
            Ok(())
        }
    }
}

/// A raw colour image's encoding and size, checked against its row length and bytes.
pub(super) fn raw_color(
    topic: &str,
    width: u32,
    height: u32,
    encoding: &str,
    step: u32,
    data: &[u8],
) -> Result<(ColorEncoding, ImageSize)> {
    let color: ColorEncoding = encoding
        .parse()
        .map_err(|_| unsupported(topic, ImageKind::Color, encoding, SUPPORTED_COLOR_ENCODINGS))?;
    let size = raw_rows(topic, width, height, step, color.bytes_per_pixel(), data.len())?;
    Ok((color, size))
}

/// The PNG or JPEG format of a compressed colour image's `format` string.
pub(super) fn color_image_format(topic: &str, format: &str) -> Result<image::ImageFormat> {
    ColorFormat::from_transport_format(format)
        .map(ColorFormat::image_format)
        .ok_or_else(|| unsupported(topic, ImageKind::Color, format, SUPPORTED_COLOR_ENCODINGS))
}

/// Offsets of red, green and blue in an interleaved pixel of `color` (`None` for the packed
/// and mosaic encodings); grey images use their one channel three times.
pub(super) fn interleaved_rgb_offsets(color: ColorEncoding) -> Option<[usize; 3]> {
    match color {
        ColorEncoding::Rgb8 | ColorEncoding::Rgba8 => Some([0, 1, 2]),
        ColorEncoding::Bgr8 | ColorEncoding::Bgra8 => Some([2, 1, 0]),
        ColorEncoding::Mono8 => Some([0, 0, 0]),
        ColorEncoding::Uyvy | ColorEncoding::Yuyv | ColorEncoding::Bayer8(_) => None,
    }
}

/// Decodes a colour (or grey) image into `rgb` (grey repeated in the three channels; YUV
/// 4:2:2 through BT.601; Bayer mosaics demosaiced as for grey), resizing `rgb` when the size
/// differs. The same encodings as [`gray_from_image_into`].
///
/// # Errors
/// As [`gray_from_image_into`].
pub fn rgb_from_image_into(msg: &ImageMsg, topic: &str, rgb: &mut Rgb8) -> Result<()> {
    match &msg.payload {
        ImagePayload::Raw {
            width,
            height,
            encoding,
            step,
            data,
            ..
        } => {
            let (color, size) = raw_color(topic, *width, *height, encoding, *step, data)?;
            let yuv = match color {
                ColorEncoding::Uyvy => Some(true),
                ColorEncoding::Yuyv => Some(false),
                _ => None,
            };
            let bayer = match color {
                ColorEncoding::Bayer8(filter) => Some(pixels::BayerPattern::from(filter)),
                _ => None,
            };
            let bpp = color.bytes_per_pixel();
            let [r, g, b] = interleaved_rgb_offsets(color).unwrap_or([0, 0, 0]);
            resize_for(rgb, size);
            let step = *step as usize;
            let rows: Vec<&[u8]> = (0..size.height)
                .map(|y| &data[y * step..y * step + size.width * bpp])
                .collect();
            for (y, row) in rows.iter().enumerate() {
                for (x, out) in rgb.row_mut(y).iter_mut().enumerate() {
                    *out = match (yuv, bayer) {
                        (Some(uyvy), _) => {
                            let (u, v) = pixels::yuv422_chroma_offsets(x, uyvy);
                            // The last pixel of an odd-width row has no complete pair: its
                            // missing chroma is neutral (grey at its luma).
                            let chroma = |i: usize| row.get(i).copied().unwrap_or(pixels::NEUTRAL_CHROMA);
                            pixels::rgb_from_video_yuv(
                                row[pixels::yuv422_luma_offset(x, uyvy)],
                                chroma(u),
                                chroma(v),
                            )
                        }
                        (None, Some(pattern)) => pixels::demosaic_pixel(&rows, pattern, x, y),
                        (None, None) => {
                            let px = &row[x * bpp..x * bpp + bpp];
                            [px[r], px[g], px[b]]
                        }
                    };
                }
            }
            Ok(())
        }
        ImagePayload::Compressed { format, data } => {
            let image_format = color_image_format(topic, format)?;
            let decoded = decode_compressed_pixels(data, image_format, topic, &format!("{format} image"))?;
            let size = ImageSize::new(decoded.width() as usize, decoded.height() as usize);
            resize_for(rgb, size);
            let decoded = decoded.into_rgb8();
            for (out, px) in rgb
                .as_mut_slice()
                .iter_mut()
                .zip(decoded.as_raw().chunks_exact(3))
            {
                *out = [px[0], px[1], px[2]];
            }
            Ok(())
        }
    }
}

/// Decodes a depth image into metres (0 = invalid), resizing `depth_m` when needed.
/// `units_per_meter` scales 16-bit encodings; `32FC1` is metres already (NaN, ±inf and
/// negative values become 0).
///
/// # Errors
/// [`Error::Decode`] naming `topic` for unsupported encodings (listing the supported ones),
/// short buffers or an undecodable compressedDepth PNG.
pub fn depth_from_image_into(
    msg: &ImageMsg,
    topic: &str,
    units_per_meter: f64,
    depth_m: &mut DepthMeters,
) -> Result<()> {
    match &msg.payload {
        ImagePayload::Raw {
            width,
            height,
            encoding,
            step,
            big_endian,
            data,
        } => {
            let depth_encoding: DepthEncoding = encoding
                .parse()
                .map_err(|_| unsupported(topic, ImageKind::Depth, encoding, SUPPORTED_DEPTH_ENCODINGS))?;
            let bpp = depth_encoding.bytes_per_pixel();
            let size = raw_rows(topic, *width, *height, *step, bpp, data.len())?;
            resize_for(depth_m, size);
            let step = *step as usize;
            let row_bytes = size.width * bpp;
            let rows = (0..size.height).map(|y| &data[y * step..y * step + row_bytes]);
            depth_encoding.metres_from_rows(
                rows.zip(depth_m.as_mut_slice().chunks_exact_mut(size.width)),
                *big_endian,
                depth_encoding.metres_per_unit(units_per_meter),
            );
            Ok(())
        }
        ImagePayload::Compressed { format, data } => {
            let compressed: CompressedDepthFormat = format
                .parse()
                .map_err(|_| unsupported(topic, ImageKind::Depth, format, SUPPORTED_DEPTH_ENCODINGS))?;
            let Some((header, payload)) = data.split_at_checked(COMPRESSED_DEPTH_HEADER_BYTES) else {
                return Err(compressed_error(
                    topic,
                    format,
                    format!("a {COMPRESSED_DEPTH_HEADER_BYTES}-byte header and the compressed image"),
                    format!("{} bytes", data.len()),
                ));
            };
            let (size, values) = if compressed.codec == DepthCodec::Rvl {
                rvl_values(payload, topic, format)?
            } else {
                let what = format!("{format} depth PNG");
                let decoded =
                    decode_compressed_pixels(payload, image::ImageFormat::Png, topic, &what)?.into_luma16();
                let size = ImageSize::new(decoded.width() as usize, decoded.height() as usize);
                (size, decoded.into_raw())
            };
            resize_for(depth_m, size);
            // The header is the format enum, then the two inverse-depth parameters.
            let param = |i: usize| {
                let at = 4 + 4 * i;
                f32::from_le_bytes([header[at], header[at + 1], header[at + 2], header[at + 3]])
            };
            compressed.metres_from_values(
                &values,
                [param(0), param(1)],
                compressed.depth.metres_per_unit(units_per_meter),
                depth_m.as_mut_slice(),
            );
            Ok(())
        }
    }
}

/// The image size and values of a `compressedDepth rvl` payload (after the config header):
/// width and height (`u32` each), then the RVL stream.
pub(super) fn rvl_values(payload: &[u8], topic: &str, format: &str) -> Result<(ImageSize, Vec<u16>)> {
    let Some((dims, stream)) = payload.split_at_checked(pixels::RVL_SIZE_HEADER_BYTES) else {
        return Err(compressed_error(
            topic,
            format,
            format!(
                "the {}-byte RVL size and the stream",
                pixels::RVL_SIZE_HEADER_BYTES
            ),
            format!("{} bytes after the header", payload.len()),
        ));
    };
    let dim = |at: usize| u32::from_le_bytes([dims[at], dims[at + 1], dims[at + 2], dims[at + 3]]);
    let size = ImageSize::new(dim(0) as usize, dim(4) as usize);
    let pixels_declared = size.area() as u64;
    let most = (stream.len() as u64)
        .saturating_mul(pixels::RVL_MAX_PIXELS_PER_BYTE)
        .min(crate::mcap_io::codec::MAX_COMPRESSED_IMAGE_PIXELS);
    if pixels_declared == 0 || pixels_declared > most {
        return Err(compressed_error(
            topic,
            format,
            format!(
                "at least one pixel and at most {most} (5 pixels per byte, {} in all)",
                crate::mcap_io::codec::MAX_COMPRESSED_IMAGE_PIXELS
            ),
            format!("an RVL image of {size} from {} bytes", stream.len()),
        ));
    }
    let mut values = vec![0u16; size.area()];
    pixels::decode_rvl(stream, &mut values).map_err(|reason| {
        Error::decode(
            topic,
            DecodeProblem::Undecodable {
                what: format.to_owned(),
                reason,
            },
        )
    })?;
    Ok((size, values))
}

/// [`Error::Decode`] for a compressed image whose header or declared size is not what `format`
/// allows.
fn compressed_error(
    topic: &str,
    format: &str,
    expected: impl Into<String>,
    found: impl Into<String>,
) -> Error {
    Error::decode(
        topic,
        DecodeProblem::Compressed {
            what: format.to_owned(),
            mismatch: Mismatch::new(expected, found),
        },
    )
}
