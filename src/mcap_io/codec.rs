//! Sans-IO conversion between library types and Foxglove protobuf messages.
//!
//! Encoding builds the `foxglove::messages` structs; decoding checks every field a later
//! stage relies on (encoding, size, step, buffer length) and reports what it expected and
//! what it found, naming the topic.

use foxglove::messages::{
    CameraCalibration, CompressedImage, FrameTransform, Pose, PoseInFrame, Quaternion, RawImage, Timestamp,
    Vector3,
};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use prost::bytes::Bytes;

use crate::error::{Error, Result};
use crate::geometry::camera::PinholeIntrinsics;
use crate::geometry::distortion::LensDistortion;
use crate::image_buf::{ImageSize, Mask, Rgb8};
use crate::time::{join_ns, split_ns};
use crate::trajectory::StampedPose;

use super::{
    ENCODING_16UC1, ENCODING_MONO8, ENCODING_RGB8, SCHEMA_CAMERA_CALIBRATION, SCHEMA_COMPRESSED_IMAGE,
    SCHEMA_FRAME_TRANSFORM, SCHEMA_POSE_IN_FRAME, SCHEMA_RAW_IMAGE,
};

/// Distortion model written into pinhole calibrations (all coefficients zero).
pub const DISTORTION_MODEL: &str = "plumb_bob";
/// Number of `plumb_bob` coefficients (k1, k2, p1, p2, k3).
const PLUMB_BOB_COEFFICIENTS: usize = 5;

/// The container format of a compressed colour image, recognised by its magic bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColorFormat {
    /// PNG (`\x89PNG\r\n\x1a\n`).
    Png,
    /// JPEG (`FF D8 FF`).
    Jpeg,
}

impl ColorFormat {
    /// The `CompressedImage.format` string Foxglove expects.
    pub fn as_str(self) -> &'static str {
        match self {
            ColorFormat::Png => "png",
            ColorFormat::Jpeg => "jpeg",
        }
    }

    /// Recognises the format from the first bytes of a file; `None` for anything else.
    pub fn from_magic(bytes: &[u8]) -> Option<Self> {
        if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
            Some(ColorFormat::Png)
        } else if bytes.starts_with(&[0xFF, 0xD8, 0xFF]) {
            Some(ColorFormat::Jpeg)
        } else {
            None
        }
    }

    /// Parses a `CompressedImage.format` string (`png`, `jpeg`, `jpg`; case-insensitive).
    pub fn parse(format: &str) -> Option<Self> {
        match format.to_ascii_lowercase().as_str() {
            "png" => Some(ColorFormat::Png),
            "jpeg" | "jpg" => Some(ColorFormat::Jpeg),
            _ => None,
        }
    }
}

/// Foxglove timestamp for integer nanoseconds (seconds saturate in 2106).
pub fn timestamp(timestamp_ns: u64) -> Timestamp {
    let (sec, nsec) = split_ns(timestamp_ns);
    Timestamp::new_checked(sec, nsec).unwrap_or(Timestamp::MAX)
}

/// Integer nanoseconds of a Foxglove timestamp; a missing timestamp is 0.
pub fn timestamp_ns(stamp: Option<&Timestamp>) -> u64 {
    stamp.map_or(0, |t| join_ns(u64::from(t.sec()), t.nsec()))
}

fn dimension(value: usize, what: &str) -> Result<u32> {
    u32::try_from(value).map_err(|_| Error::InvalidParameter {
        name: "image size",
        value: format!("{what} {value}"),
        expected: "at most 4294967295".into(),
    })
}

/// A `CompressedImage` holding `data` unchanged.
pub fn compressed_image(
    timestamp_ns: u64,
    frame_id: &str,
    data: Bytes,
    format: ColorFormat,
) -> CompressedImage {
    CompressedImage {
        timestamp: Some(timestamp(timestamp_ns)),
        frame_id: frame_id.to_owned(),
        data,
        format: format.as_str().to_owned(),
    }
}

/// A `16UC1` `RawImage` (little-endian) of raw depth units.
///
/// # Errors
/// [`Error::BufferLength`] when `depth.len()` is not `size.area()`.
pub fn depth_u16_image(
    timestamp_ns: u64,
    frame_id: &str,
    depth: &[u16],
    size: ImageSize,
) -> Result<RawImage> {
    check_len(depth.len(), size)?;
    let mut data = Vec::with_capacity(depth.len() * 2);
    for v in depth {
        data.extend_from_slice(&v.to_le_bytes());
    }
    Ok(RawImage {
        timestamp: Some(timestamp(timestamp_ns)),
        frame_id: frame_id.to_owned(),
        width: dimension(size.width, "width")?,
        height: dimension(size.height, "height")?,
        encoding: ENCODING_16UC1.to_owned(),
        step: dimension(size.width * 2, "row step")?,
        data: Bytes::from(data),
    })
}

/// A `mono8` `RawImage` of a mask (0 or [`crate::image_buf::MASK_SET`]).
///
/// # Errors
/// [`Error::InvalidParameter`] for images wider or taller than `u32::MAX`.
pub fn mask_image(timestamp_ns: u64, frame_id: &str, mask: &Mask) -> Result<RawImage> {
    Ok(RawImage {
        timestamp: Some(timestamp(timestamp_ns)),
        frame_id: frame_id.to_owned(),
        width: dimension(mask.width(), "width")?,
        height: dimension(mask.height(), "height")?,
        encoding: ENCODING_MONO8.to_owned(),
        step: dimension(mask.width(), "row step")?,
        data: Bytes::copy_from_slice(mask.as_slice()),
    })
}

/// An `rgb8` `RawImage`.
///
/// # Errors
/// [`Error::InvalidParameter`] for images wider or taller than `u32::MAX`.
pub fn rgb8_image(timestamp_ns: u64, frame_id: &str, rgb: &Rgb8) -> Result<RawImage> {
    let data: Vec<u8> = rgb.as_slice().iter().flatten().copied().collect();
    Ok(RawImage {
        timestamp: Some(timestamp(timestamp_ns)),
        frame_id: frame_id.to_owned(),
        width: dimension(rgb.width(), "width")?,
        height: dimension(rgb.height(), "height")?,
        encoding: ENCODING_RGB8.to_owned(),
        step: dimension(rgb.width() * 3, "row step")?,
        data: Bytes::from(data),
    })
}

/// A `CameraCalibration`: `plumb_bob` with zero coefficients without `distortion` (else the
/// distortion's own model and coefficients), identity rectification, P = [K | 0].
///
/// # Errors
/// [`Error::InvalidParameter`] for images wider or taller than `u32::MAX`.
pub fn camera_calibration(
    timestamp_ns: u64,
    frame_id: &str,
    intrinsics: &PinholeIntrinsics,
    size: ImageSize,
    distortion: Option<&LensDistortion>,
) -> Result<CameraCalibration> {
    let PinholeIntrinsics { fx, fy, cx, cy } = *intrinsics;
    let (distortion_model, d) = match distortion {
        Some(lens) => lens.to_ros(),
        None => (DISTORTION_MODEL, vec![0.0; PLUMB_BOB_COEFFICIENTS]),
    };
    Ok(CameraCalibration {
        timestamp: Some(timestamp(timestamp_ns)),
        frame_id: frame_id.to_owned(),
        width: dimension(size.width, "width")?,
        height: dimension(size.height, "height")?,
        distortion_model: distortion_model.to_owned(),
        d,
        k: intrinsics.k_row_major().to_vec(),
        r: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: vec![fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
    })
}

fn pose(transform: &Isometry3<f64>) -> Pose {
    let t = transform.translation.vector;
    let q = transform.rotation;
    Pose {
        position: Some(Vector3 {
            x: t.x,
            y: t.y,
            z: t.z,
        }),
        orientation: Some(Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        }),
    }
}

/// A `PoseInFrame`: the pose of some body in `frame_id` (e.g. `world_from_camera` in `world`).
pub fn pose_in_frame(timestamp_ns: u64, frame_id: &str, frame_from_body: &Isometry3<f64>) -> PoseInFrame {
    PoseInFrame {
        timestamp: Some(timestamp(timestamp_ns)),
        frame_id: frame_id.to_owned(),
        pose: Some(pose(frame_from_body)),
    }
}

/// A `FrameTransform` placing `child` in `parent` (`parent_from_child`).
pub fn frame_transform(
    timestamp_ns: u64,
    parent: &str,
    child: &str,
    parent_from_child: &Isometry3<f64>,
) -> FrameTransform {
    let Pose {
        position,
        orientation,
    } = pose(parent_from_child);
    FrameTransform {
        timestamp: Some(timestamp(timestamp_ns)),
        parent_frame_id: parent.to_owned(),
        child_frame_id: child.to_owned(),
        translation: position,
        rotation: orientation,
    }
}

fn check_len(len: usize, size: ImageSize) -> Result<()> {
    if len != size.area() {
        return Err(Error::BufferLength {
            expected: size.area(),
            found: len,
            size,
        });
    }
    Ok(())
}

fn decode_error(topic: &str, message: impl Into<String>) -> Error {
    Error::Decode {
        topic: topic.to_owned(),
        message: message.into(),
    }
}

/// Checks a `RawImage`'s encoding, step and data length for `bytes_per_pixel`; returns its size.
fn check_raw(image: &RawImage, topic: &str, encodings: &[&str], bytes_per_pixel: usize) -> Result<ImageSize> {
    if !encodings.contains(&image.encoding.as_str()) {
        return Err(decode_error(
            topic,
            format!(
                "expected RawImage encoding {}, found {:?}",
                encodings.join(" or "),
                image.encoding
            ),
        ));
    }
    let size = ImageSize::new(image.width as usize, image.height as usize);
    if size.area() == 0 {
        return Err(decode_error(
            topic,
            format!("RawImage is {size}: expected at least one pixel"),
        ));
    }
    // u64 arithmetic: u32 width, height and step cannot overflow it, whatever a file claims.
    let row_bytes = u64::from(image.width) * bytes_per_pixel as u64;
    let step = u64::from(image.step);
    if step < row_bytes {
        return Err(decode_error(
            topic,
            format!(
                "RawImage step {step} is shorter than a {}-pixel row of {row_bytes} bytes",
                size.width
            ),
        ));
    }
    let needed = match image.height {
        0 => 0,
        h => step * u64::from(h - 1) + row_bytes,
    };
    if (image.data.len() as u64) < needed {
        return Err(decode_error(
            topic,
            format!(
                "RawImage {size} with step {step} needs {needed} bytes, found {}",
                image.data.len()
            ),
        ));
    }
    Ok(size)
}

/// Raw depth units from a `16UC1`/`mono16` `RawImage` (little-endian).
///
/// # Errors
/// [`Error::Decode`] naming `topic` when the encoding, step or length is wrong.
pub fn depth_u16_from_raw(image: &RawImage, topic: &str) -> Result<(ImageSize, Vec<u16>)> {
    let size = check_raw(image, topic, &[ENCODING_16UC1, "mono16"], 2)?;
    let step = image.step as usize;
    let mut out = Vec::with_capacity(size.area());
    for y in 0..size.height {
        let row = &image.data[y * step..y * step + size.width * 2];
        out.extend(row.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])));
    }
    Ok((size, out))
}

/// A mask from a `mono8`/`8UC1` `RawImage`.
///
/// # Errors
/// [`Error::Decode`] naming `topic` when the encoding, step or length is wrong.
pub fn mask_from_raw(image: &RawImage, topic: &str) -> Result<Mask> {
    let size = check_raw(image, topic, &[ENCODING_MONO8, "8UC1"], 1)?;
    let step = image.step as usize;
    Ok(Mask::from_fn(size, |x, y| image.data[y * step + x]))
}

/// An `Rgb8` image from an `rgb8` `RawImage`.
///
/// # Errors
/// [`Error::Decode`] naming `topic` when the encoding, step or length is wrong.
pub fn rgb8_from_raw(image: &RawImage, topic: &str) -> Result<Rgb8> {
    let size = check_raw(image, topic, &[ENCODING_RGB8], 3)?;
    let step = image.step as usize;
    Ok(Rgb8::from_fn(size, |x, y| {
        let i = y * step + 3 * x;
        [image.data[i], image.data[i + 1], image.data[i + 2]]
    }))
}

/// Pinhole intrinsics from a row-major 3×3 camera matrix `k`, shared by every calibration
/// decoder. `hint` is appended to the error (e.g. which flag supplies intrinsics instead).
///
/// # Errors
/// [`Error::Decode`] naming `topic` when `k` does not have 9 entries or is not a valid
/// pinhole matrix (positive focal lengths, zero skew, last row 0 0 1).
pub fn intrinsics_from_k(k: &[f64], topic: &str, hint: &str) -> Result<PinholeIntrinsics> {
    if k.len() != 9 {
        return Err(decode_error(
            topic,
            format!("expected a 3x3 K (9 numbers), found {} numbers", k.len()),
        ));
    }
    let intrinsics = PinholeIntrinsics::new(k[0], k[4], k[2], k[5]);
    if !intrinsics.is_valid() || k[1] != 0.0 || k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0 {
        return Err(decode_error(
            topic,
            format!("expected a pinhole K [fx 0 cx; 0 fy cy; 0 0 1] with fx, fy > 0, found {k:?}{hint}"),
        ));
    }
    Ok(intrinsics)
}

/// Pinhole intrinsics and image size from a `CameraCalibration` (distortion is ignored).
///
/// # Errors
/// [`Error::Decode`] naming `topic` when `K` does not have 9 entries or is not a valid
/// pinhole matrix (positive focal lengths, zero skew, last row 0 0 1).
pub fn intrinsics_from_calibration(
    calibration: &CameraCalibration,
    topic: &str,
) -> Result<(PinholeIntrinsics, ImageSize)> {
    let intrinsics = intrinsics_from_k(&calibration.k, topic, "")?;
    Ok((
        intrinsics,
        ImageSize::new(calibration.width as usize, calibration.height as usize),
    ))
}

/// The isometry of a Foxglove pose (`frame_from_body`).
///
/// # Errors
/// [`Error::Decode`] naming `topic` when the position or orientation is missing or the
/// orientation is not a finite, non-zero quaternion.
pub fn isometry_from_parts(
    position: Option<&Vector3>,
    orientation: Option<&Quaternion>,
    topic: &str,
) -> Result<Isometry3<f64>> {
    let (Some(p), Some(q)) = (position, orientation) else {
        return Err(decode_error(
            topic,
            "expected a position and an orientation, found a missing field",
        ));
    };
    let quaternion = nalgebra::Quaternion::new(q.w, q.x, q.y, q.z);
    let norm = quaternion.norm();
    if !norm.is_finite() || norm == 0.0 || ![p.x, p.y, p.z].iter().all(|v| v.is_finite()) {
        return Err(decode_error(
            topic,
            format!("expected a finite position and unit quaternion, found {p:?} {q:?}"),
        ));
    }
    Ok(Isometry3::from_parts(
        Translation3::new(p.x, p.y, p.z),
        UnitQuaternion::from_quaternion(quaternion),
    ))
}

/// Largest PNG/JPEG occmask decodes, in pixels (2^25: 8K UHD, 7680×4320, fits). A compressed
/// image declares its size in a few header bytes, so without this bound a tiny corrupt message
/// could make the decoder allocate hundreds of megabytes (and the f32 grey image four times as
/// much).
pub const MAX_COMPRESSED_IMAGE_PIXELS: u64 = 1 << 25;

/// Decodes PNG or JPEG bytes after checking the size their header declares against
/// [`MAX_COMPRESSED_IMAGE_PIXELS`]. `what` names the image in errors (e.g. `"png image"`).
///
/// # Errors
/// [`Error::Decode`] naming `topic` for undecodable bytes, an empty image or one larger than
/// [`MAX_COMPRESSED_IMAGE_PIXELS`].
pub fn decode_compressed_pixels(
    data: &[u8],
    format: ::image::ImageFormat,
    topic: &str,
    what: &str,
) -> Result<::image::DynamicImage> {
    let reader = || ::image::ImageReader::with_format(std::io::Cursor::new(data), format);
    let cannot = |e: ::image::ImageError| decode_error(topic, format!("cannot decode {what}: {e}"));
    let (width, height) = reader().into_dimensions().map_err(cannot)?;
    let pixels = u64::from(width) * u64::from(height);
    if pixels == 0 || pixels > MAX_COMPRESSED_IMAGE_PIXELS {
        return Err(decode_error(
            topic,
            format!(
                "{what} declares {width}x{height} pixels: expected between 1 and \
                 {MAX_COMPRESSED_IMAGE_PIXELS} pixels"
            ),
        ));
    }
    reader().decode().map_err(cannot)
}

/// Decodes a `CompressedImage` (PNG or JPEG) into `rgb8` pixels (grey or RGBA inputs are
/// converted).
///
/// # Errors
/// [`Error::Decode`] naming `topic` for an unknown format or undecodable bytes.
pub fn rgb8_from_compressed(image: &CompressedImage, topic: &str) -> Result<Rgb8> {
    let format = ColorFormat::parse(&image.format)
        .or_else(|| ColorFormat::from_magic(&image.data))
        .ok_or_else(|| {
            decode_error(
                topic,
                format!("expected format png or jpeg, found {:?}", image.format),
            )
        })?;
    let image_format = match format {
        ColorFormat::Png => ::image::ImageFormat::Png,
        ColorFormat::Jpeg => ::image::ImageFormat::Jpeg,
    };
    let what = format!("{} image", format.as_str());
    let decoded = decode_compressed_pixels(&image.data, image_format, topic, &what)?.into_rgb8();
    let size = ImageSize::new(decoded.width() as usize, decoded.height() as usize);
    let pixels = decoded
        .into_raw()
        .chunks_exact(3)
        .map(|p| [p[0], p[1], p[2]])
        .collect();
    Rgb8::from_vec(size, pixels)
}

/// A [`StampedPose`] (`world_from_camera` at the message timestamp) from a `PoseInFrame`.
///
/// # Errors
/// [`Error::Decode`] naming `topic` for a missing or invalid pose.
pub fn stamped_pose_from(pose: &PoseInFrame, topic: &str) -> Result<StampedPose> {
    let p = pose
        .pose
        .as_ref()
        .ok_or_else(|| decode_error(topic, "expected a pose, found none"))?;
    Ok(StampedPose {
        timestamp_ns: timestamp_ns(pose.timestamp.as_ref()),
        world_from_camera: isometry_from_parts(p.position.as_ref(), p.orientation.as_ref(), topic)?,
    })
}

/// A decoded message of one of the schemas occmask writes.
#[derive(Debug, Clone, PartialEq)]
pub enum Decoded {
    /// `foxglove.CompressedImage`.
    CompressedImage(CompressedImage),
    /// `foxglove.RawImage`.
    RawImage(RawImage),
    /// `foxglove.CameraCalibration`.
    CameraCalibration(CameraCalibration),
    /// `foxglove.PoseInFrame`.
    PoseInFrame(PoseInFrame),
    /// `foxglove.FrameTransform`.
    FrameTransform(FrameTransform),
}

fn decode_as<T: prost::Message + Default>(data: &[u8], topic: &str, schema: &str) -> Result<T> {
    T::decode(data).map_err(|e| decode_error(topic, format!("expected a protobuf {schema}: {e}")))
}

/// Decodes a protobuf message by its schema name.
///
/// # Errors
/// [`Error::Decode`] for an unknown schema or bytes that are not a valid message.
pub fn decode(schema_name: &str, topic: &str, data: &[u8]) -> Result<Decoded> {
    Ok(match schema_name {
        SCHEMA_COMPRESSED_IMAGE => Decoded::CompressedImage(decode_as(data, topic, schema_name)?),
        SCHEMA_RAW_IMAGE => Decoded::RawImage(decode_as(data, topic, schema_name)?),
        SCHEMA_CAMERA_CALIBRATION => Decoded::CameraCalibration(decode_as(data, topic, schema_name)?),
        SCHEMA_POSE_IN_FRAME => Decoded::PoseInFrame(decode_as(data, topic, schema_name)?),
        SCHEMA_FRAME_TRANSFORM => Decoded::FrameTransform(decode_as(data, topic, schema_name)?),
        other => {
            return Err(decode_error(
                topic,
                format!(
                    "expected one of the schemas {SCHEMA_COMPRESSED_IMAGE}, {SCHEMA_RAW_IMAGE}, \
                     {SCHEMA_CAMERA_CALIBRATION}, {SCHEMA_POSE_IN_FRAME}, {SCHEMA_FRAME_TRANSFORM}, \
                     found {other:?}"
                ),
            ))
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::camera::presets;
    use approx::assert_relative_eq;
    use nalgebra::Vector3 as NVector3;
    use prost::Message as _;

    #[test]
    fn timestamps_round_trip_exactly() {
        for ns in [0u64, 1, 999_999_999, 1_311_868_164_363_181_000] {
            assert_eq!(timestamp_ns(Some(&timestamp(ns))), ns);
        }
    }

    #[test]
    fn depth_round_trips_through_protobuf() {
        let size = ImageSize::new(3, 2);
        let depth = vec![0u16, 1, 255, 256, 65535, 5000];
        let msg = depth_u16_image(7, "cam", &depth, size).unwrap();
        assert_eq!(msg.step, 6);
        let bytes = msg.encode_to_vec();
        let Decoded::RawImage(back) = decode(SCHEMA_RAW_IMAGE, "/d", &bytes).unwrap() else {
            panic!("wrong variant")
        };
        assert_eq!(depth_u16_from_raw(&back, "/d").unwrap(), (size, depth));
    }

    #[test]
    fn raw_image_with_padded_step_decodes_rows() {
        let mut msg = mask_image(
            0,
            "cam",
            &Mask::from_fn(ImageSize::new(2, 2), |x, y| (x + 2 * y) as u8),
        )
        .unwrap();
        msg.step = 3;
        msg.data = Bytes::from_static(&[0, 1, 99, 2, 3]);
        assert_eq!(mask_from_raw(&msg, "/m").unwrap().as_slice(), &[0, 1, 2, 3]);
    }

    #[test]
    fn short_raw_image_is_a_decode_error_naming_the_topic() {
        let mut msg = depth_u16_image(0, "cam", &[1, 2, 3, 4], ImageSize::new(2, 2)).unwrap();
        msg.data = msg.data.slice(0..6);
        let err = depth_u16_from_raw(&msg, "/camera/depth/image")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("/camera/depth/image") && err.contains("needs 8 bytes, found 6"),
            "{err}"
        );
        msg.encoding = "32FC1".into();
        let err = depth_u16_from_raw(&msg, "/d").unwrap_err().to_string();
        assert!(err.contains("16UC1") && err.contains("32FC1"), "{err}");
    }

    #[test]
    fn absurd_claimed_sizes_are_errors_not_overflows() {
        let mut msg = depth_u16_image(0, "cam", &[1, 2], ImageSize::new(2, 1)).unwrap();
        (msg.width, msg.height, msg.step) = (u32::MAX, u32::MAX, u32::MAX);
        let err = depth_u16_from_raw(&msg, "/d").unwrap_err().to_string();
        assert!(err.contains("shorter than"), "{err}");
        msg.width = 1;
        let err = depth_u16_from_raw(&msg, "/d").unwrap_err().to_string();
        assert!(err.contains("found 4"), "{err}");
    }

    #[test]
    fn calibration_round_trips() {
        let size = ImageSize::new(640, 480);
        let msg = camera_calibration(5, "cam", &presets::TUM_FR2, size, None).unwrap();
        assert_eq!(msg.p[0], presets::TUM_FR2.fx);
        assert_eq!(msg.p[6], presets::TUM_FR2.cy);
        assert_eq!(
            intrinsics_from_calibration(&msg, "/c").unwrap(),
            (presets::TUM_FR2, size)
        );
    }

    #[test]
    fn pose_round_trips() {
        let iso = Isometry3::new(NVector3::new(1.0, -2.0, 3.5), NVector3::new(0.1, 0.2, -0.3));
        let msg = pose_in_frame(1, "world", &iso);
        let p = msg.pose.as_ref().unwrap();
        let back = isometry_from_parts(p.position.as_ref(), p.orientation.as_ref(), "/p").unwrap();
        assert_relative_eq!(back.to_homogeneous(), iso.to_homogeneous(), epsilon = 1e-12);
        let tf = frame_transform(1, "world", "cam", &iso);
        let back = isometry_from_parts(tf.translation.as_ref(), tf.rotation.as_ref(), "/tf").unwrap();
        assert_relative_eq!(back.to_homogeneous(), iso.to_homogeneous(), epsilon = 1e-12);
    }

    #[test]
    fn compressed_png_decodes_to_the_same_pixels() {
        let size = ImageSize::new(4, 3);
        let rgb = Rgb8::from_fn(size, |x, y| [x as u8 * 60, y as u8 * 80, 7]);
        let flat: Vec<u8> = rgb.as_slice().iter().flatten().copied().collect();
        let mut png = Vec::new();
        ::image::RgbImage::from_raw(4, 3, flat)
            .unwrap()
            .write_to(&mut std::io::Cursor::new(&mut png), ::image::ImageFormat::Png)
            .unwrap();
        let msg = compressed_image(3, "cam", Bytes::from(png), ColorFormat::Png);
        assert_eq!(rgb8_from_compressed(&msg, "/c").unwrap(), rgb);
        let bad = compressed_image(
            3,
            "cam",
            Bytes::from_static(b"\x89PNG\r\n\x1a\nxx"),
            ColorFormat::Png,
        );
        assert!(rgb8_from_compressed(&bad, "/c")
            .unwrap_err()
            .to_string()
            .contains("/c"));
    }

    #[test]
    fn stamped_pose_round_trips() {
        let iso = Isometry3::new(NVector3::new(0.5, 0.0, -1.0), NVector3::new(0.0, 0.3, 0.0));
        let back = stamped_pose_from(&pose_in_frame(42, "world", &iso), "/p").unwrap();
        assert_eq!(back.timestamp_ns, 42);
        assert_relative_eq!(
            back.world_from_camera.to_homogeneous(),
            iso.to_homogeneous(),
            epsilon = 1e-12
        );
    }

    #[test]
    fn color_format_from_magic() {
        assert_eq!(
            ColorFormat::from_magic(b"\x89PNG\r\n\x1a\nrest"),
            Some(ColorFormat::Png)
        );
        assert_eq!(
            ColorFormat::from_magic(&[0xFF, 0xD8, 0xFF, 0xE0]),
            Some(ColorFormat::Jpeg)
        );
        assert_eq!(ColorFormat::from_magic(b"GIF89a"), None);
        assert_eq!(ColorFormat::parse("JPG"), Some(ColorFormat::Jpeg));
    }

    #[test]
    fn unknown_schema_is_rejected() {
        let err = decode("foo.Bar", "/x", &[]).unwrap_err().to_string();
        assert!(err.contains("foo.Bar"), "{err}");
    }
}
