//! Reading a dataset's image files: colour kept compressed with its integrity checked, 16-bit
//! depth, masks, and a colour/depth pair decoded for the pipeline.

use super::*;

/// A compressed colour image, read but not decoded.
#[derive(Debug, Clone)]
pub struct ColorImage {
    /// The file's bytes, unchanged.
    pub bytes: Bytes,
    /// PNG or JPEG, from the magic bytes.
    pub format: ColorFormat,
    /// Size from the image header.
    pub size: ImageSize,
}

fn bad_image(path: &Path, expected: impl Into<String>, found: impl Into<String>) -> Error {
    Error::BadImage {
        path: path.to_owned(),
        expected: expected.into(),
        found: found.into(),
    }
}

/// PNG files end with an empty `IEND` chunk: length 0, type, CRC.
const PNG_TRAILER: [u8; 12] = [0, 0, 0, 0, b'I', b'E', b'N', b'D', 0xAE, 0x42, 0x60, 0x82];
/// JPEG end-of-image marker.
const JPEG_EOI: [u8; 2] = [0xFF, 0xD9];

/// Reads a colour image's bytes and checks them without decoding the pixels: PNG or JPEG
/// magic, a readable header (size), and the end marker (`IEND` / `EOI`), which catches
/// truncated files. Trailing padding after a JPEG's `EOI` (some cameras add zeros) is allowed.
///
/// # Errors
/// [`Error::Io`] if unreadable, [`Error::BadImage`] for anything else.
pub fn read_color(path: &Path) -> Result<ColorImage> {
    let bytes = std::fs::read(path).map_err(|e| Error::io("cannot read colour image", path, e))?;
    let format = ColorFormat::from_magic(&bytes)
        .ok_or_else(|| bad_image(path, "a PNG or JPEG colour image", "neither signature"))?;
    let complete = match format {
        ColorFormat::Png => bytes.ends_with(&PNG_TRAILER),
        ColorFormat::Jpeg => {
            let trimmed = bytes
                .iter()
                .rposition(|&b| b != 0)
                .map_or(&bytes[..0], |i| &bytes[..=i]);
            trimmed.ends_with(&JPEG_EOI)
        }
    };
    if !complete {
        let format = format.as_str().to_uppercase();
        return Err(bad_image(
            path,
            format!("a complete {format} colour image"),
            format!(
                "a truncated {format} colour image: the end marker is missing ({} bytes)",
                bytes.len()
            ),
        ));
    }
    let image_format = match format {
        ColorFormat::Png => image::ImageFormat::Png,
        ColorFormat::Jpeg => image::ImageFormat::Jpeg,
    };
    let (width, height) = image::ImageReader::with_format(std::io::Cursor::new(&bytes), image_format)
        .into_dimensions()
        .map_err(|e| bad_image(path, "a readable colour image header", e.to_string()))?;
    Ok(ColorImage {
        bytes: Bytes::from(bytes),
        format,
        size: ImageSize::new(width as usize, height as usize),
    })
}

/// A decoded depth image in raw sensor units.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DepthImage {
    /// Image size.
    pub size: ImageSize,
    /// Raw units, row-major; 0 = no measurement.
    pub data: Vec<u16>,
}

/// Decodes a 16-bit single-channel PNG depth image.
///
/// # Errors
/// [`Error::Io`] if unreadable; [`Error::BadImage`] for a corrupt or truncated PNG or any
/// pixel format other than 16-bit grey (8-bit depth has lost its precision; convert it
/// from the sensor's original data instead).
pub fn read_depth(path: &Path) -> Result<DepthImage> {
    let bytes = std::fs::read(path).map_err(|e| Error::io("cannot read depth image", path, e))?;
    if ColorFormat::from_magic(&bytes) != Some(ColorFormat::Png) {
        return Err(bad_image(path, "a 16-bit PNG depth image", "no PNG signature"));
    }
    let image = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png).map_err(|e| {
        bad_image(
            path,
            "a 16-bit PNG depth image",
            format!("a corrupt or truncated depth PNG: {e}"),
        )
    })?;
    let size = ImageSize::new(image.width() as usize, image.height() as usize);
    match image {
        image::DynamicImage::ImageLuma16(buffer) => Ok(DepthImage {
            size,
            data: buffer.into_raw(),
        }),
        other => Err(bad_image(
            path,
            "a 16-bit single-channel depth PNG",
            format!(
                "{:?}{}",
                other.color(),
                if other.color().bytes_per_pixel() == 1 {
                    " (8-bit depth cannot hold sensor depth; use the original 16-bit PNGs)"
                } else {
                    ""
                }
            ),
        )),
    }
}

/// A colour/depth pair of a dataset decoded for the pipeline.
#[derive(Debug, Clone)]
pub struct DecodedPair {
    /// The colour image's time (the frame's time).
    pub timestamp_ns: u64,
    /// The depth image's time.
    pub depth_timestamp_ns: u64,
    /// Gray in [0, 1] (BT.601 luma of the colour image).
    pub gray: GrayF32,
    /// Depth in metres, 0 = no measurement.
    pub depth_m: DepthMeters,
}

/// Decodes pair `pair` of `sequence` (colour PNG/JPEG to gray, 16-bit depth PNG to metres
/// with `depth_units_per_meter`).
///
/// # Errors
/// [`Error::Io`] / [`Error::BadImage`] for unreadable images, [`Error::SizeMismatch`] when
/// colour and depth differ in size.
pub fn decode_pair(sequence: &Sequence, pair: &FramePair, depth_units_per_meter: f64) -> Result<DecodedPair> {
    let color = &sequence.color[pair.color];
    let depth = &sequence.depth[pair.depth];
    let bytes =
        std::fs::read(&color.path).map_err(|e| Error::io("cannot read colour image", &color.path, e))?;
    let rgb = image::load_from_memory(&bytes)
        .map_err(|e| bad_image(&color.path, "a decodable colour image", e.to_string()))?
        .to_rgb8();
    let size = ImageSize::new(rgb.width() as usize, rgb.height() as usize);
    let rgb = Rgb8::from_vec(size, rgb.pixels().map(|p| p.0).collect())?;
    let raw = read_depth(&depth.path)?;
    if raw.size != size {
        return Err(Error::SizeMismatch {
            what: format!(
                "depth {} vs colour {}",
                depth.path.display(),
                color.path.display()
            ),
            expected: size,
            found: raw.size,
        });
    }
    let mut depth_m = DepthMeters::filled(size, 0.0);
    depth_m_from_u16_into(&raw.data, depth_units_per_meter as f32, &mut depth_m)?;
    Ok(DecodedPair {
        timestamp_ns: color.timestamp_ns,
        depth_timestamp_ns: depth.timestamp_ns,
        gray: gray_from_rgb8(&rgb),
        depth_m,
    })
}

/// Grey level at or above which a mask pixel counts as set ("white = moving object").
const MASK_THRESHOLD: u8 = 128;

/// Decodes a ground-truth mask PNG (grey or colour; white = moving object) into a [`Mask`]
/// of 0 / [`MASK_SET`].
///
/// # Errors
/// [`Error::Io`] if unreadable; [`Error::BadImage`] for a corrupt image.
pub fn read_mask(path: &Path) -> Result<Mask> {
    let bytes = std::fs::read(path).map_err(|e| Error::io("cannot read mask image", path, e))?;
    let image = image::load_from_memory(&bytes)
        .map_err(|e| bad_image(path, "a mask image", format!("a corrupt one: {e}")))?;
    let gray = image.into_luma8();
    let size = ImageSize::new(gray.width() as usize, gray.height() as usize);
    let data = gray
        .into_raw()
        .into_iter()
        .map(|v| if v >= MASK_THRESHOLD { MASK_SET } else { 0 })
        .collect();
    Mask::from_vec(size, data)
}
