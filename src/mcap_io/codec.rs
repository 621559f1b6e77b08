//! Sans-IO conversion from library types to Foxglove protobuf messages (the
//! `foxglove::messages` structs every writer sends), plus the checks shared with the one
//! decoder of every flavour, [`super::input::decode`]: pinhole K and bounded PNG/JPEG decoding.

use foxglove::messages::{
    CameraCalibration, CompressedImage, FrameTransform, Pose, PoseInFrame, Quaternion, RawImage, Timestamp,
    Vector3,
};
use nalgebra::Isometry3;
use prost::bytes::Bytes;

use crate::error::{DecodeProblem, Error, Mismatch, Result};
use crate::geometry::camera::PinholeIntrinsics;
use crate::geometry::distortion::LensDistortion;
use crate::image_buf::{ImageSize, Mask, Rgb8};
use crate::time::{join_ns, split_ns};

use super::encoding::{ColorEncoding, DepthEncoding};

/// Distortion model written into pinhole calibrations (all coefficients zero).
pub const DISTORTION_MODEL: &str = "plumb_bob";
/// Number of `plumb_bob` coefficients (k1, k2, p1, p2, k3).
const PLUMB_BOB_COEFFICIENTS: usize = 5;

pub use super::encoding::ColorFormat;

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
        encoding: DepthEncoding::U16.as_str().to_owned(),
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
        encoding: ColorEncoding::Mono8.as_str().to_owned(),
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
        encoding: ColorEncoding::Rgb8.as_str().to_owned(),
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

/// Pinhole intrinsics from a row-major 3×3 camera matrix `k`, shared by every calibration
/// decoder.
///
/// # Errors
/// [`Error::BadIntrinsics`] naming `topic` when `k` does not have 9 entries or is not a valid
/// pinhole matrix (positive focal lengths, zero skew, last row 0 0 1).
pub fn intrinsics_from_k(k: &[f64], topic: &str) -> Result<PinholeIntrinsics> {
    let bad = || Error::BadIntrinsics {
        topic: topic.to_owned(),
        k: k.to_vec(),
    };
    if k.len() != 9 {
        return Err(bad());
    }
    let intrinsics = PinholeIntrinsics::new(k[0], k[4], k[2], k[5]);
    if !intrinsics.is_valid() || k[1] != 0.0 || k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0 {
        return Err(bad());
    }
    Ok(intrinsics)
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
    let cannot = |e: ::image::ImageError| {
        Error::decode(
            topic,
            DecodeProblem::Undecodable {
                what: what.to_owned(),
                reason: e.to_string(),
            },
        )
    };
    let (width, height) = reader().into_dimensions().map_err(cannot)?;
    let pixels = u64::from(width) * u64::from(height);
    if pixels == 0 || pixels > MAX_COMPRESSED_IMAGE_PIXELS {
        return Err(Error::decode(
            topic,
            DecodeProblem::Compressed {
                what: what.to_owned(),
                mismatch: Mismatch::new(
                    format!("between 1 and {MAX_COMPRESSED_IMAGE_PIXELS} pixels"),
                    format!("{width}x{height} pixels declared"),
                ),
            },
        ));
    }
    reader().decode().map_err(cannot)
}

#[cfg(test)]
mod tests {
    //! Each encoder against the decoder every command reads with (`input::decode`).
    use super::*;
    use crate::geometry::camera::presets;
    use crate::image_buf::{gray_from_rgb8, DepthMeters, GrayF32};
    use crate::mcap_io::input::decode::{
        decode_calibration, decode_image, decode_poses, depth_from_image_into, gray_from_image_into,
    };
    use crate::mcap_io::input::{ChannelType, Flavor, MessageType};
    use approx::assert_relative_eq;
    use nalgebra::Vector3 as NVector3;
    use prost::Message as _;

    fn protobuf(message: MessageType) -> ChannelType {
        ChannelType {
            flavor: Flavor::FoxgloveProtobuf,
            message,
        }
    }

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
        let back = decode_image(protobuf(MessageType::RawImage), "/d", &msg.encode_to_vec()).unwrap();
        assert_eq!((back.timestamp_ns, back.encoding()), (7, "16UC1"));
        // One unit per metre: the decoded metres are the raw values.
        let mut depth_m = DepthMeters::filled(size, 0.0);
        depth_from_image_into(&back, "/d", 1.0, &mut depth_m).unwrap();
        let raw: Vec<f32> = depth.iter().map(|&d| f32::from(d)).collect();
        assert_eq!(depth_m.as_slice(), raw.as_slice());
    }

    #[test]
    fn mask_round_trips_as_mono8() {
        let mask = Mask::from_fn(ImageSize::new(2, 2), |x, y| if x == y { 255 } else { 0 });
        let msg = mask_image(3, "cam", &mask).unwrap();
        let back = decode_image(protobuf(MessageType::RawImage), "/m", &msg.encode_to_vec()).unwrap();
        let mut gray = GrayF32::filled(ImageSize::new(1, 1), 0.0);
        gray_from_image_into(&back, "/m", &mut gray).unwrap();
        assert_eq!(gray.as_slice(), &[1.0, 0.0, 0.0, 1.0]);
    }

    #[test]
    fn calibration_round_trips() {
        let size = ImageSize::new(640, 480);
        let msg = camera_calibration(5, "cam", &presets::TUM_FR2, size, None).unwrap();
        assert_eq!(msg.p[0], presets::TUM_FR2.fx);
        assert_eq!(msg.p[6], presets::TUM_FR2.cy);
        let back =
            decode_calibration(protobuf(MessageType::Calibration), "/c", &msg.encode_to_vec()).unwrap();
        assert_eq!(back.size, size);
        assert_eq!(back.intrinsics("/c").unwrap(), presets::TUM_FR2);
        assert_eq!(back.distortion("/c").unwrap(), None);
    }

    #[test]
    fn pose_and_transform_round_trip() {
        let iso = Isometry3::new(NVector3::new(1.0, -2.0, 3.5), NVector3::new(0.1, 0.2, -0.3));
        let pose = pose_in_frame(42, "world", &iso).encode_to_vec();
        let tf = frame_transform(42, "world", "cam", &iso).encode_to_vec();
        for (message, bytes) in [
            (MessageType::PoseInFrame, pose),
            (MessageType::FrameTransform, tf),
        ] {
            let back = decode_poses(protobuf(message), "/p", &bytes).unwrap();
            assert_eq!(back.len(), 1);
            assert_eq!(
                (back[0].timestamp_ns, back[0].parent_frame.as_str()),
                (42, "world")
            );
            assert_relative_eq!(
                back[0].parent_from_child.to_homogeneous(),
                iso.to_homogeneous(),
                epsilon = 1e-12
            );
        }
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
        let msg = compressed_image(3, "cam", Bytes::from(png), ColorFormat::Png).encode_to_vec();
        let back = decode_image(protobuf(MessageType::CompressedImage), "/c", &msg).unwrap();
        let mut gray = GrayF32::filled(ImageSize::new(1, 1), 0.0);
        gray_from_image_into(&back, "/c", &mut gray).unwrap();
        assert_eq!(gray, gray_from_rgb8(&rgb));
        let bad = compressed_image(
            3,
            "cam",
            Bytes::from_static(b"\x89PNG\r\n\x1a\nxx"),
            ColorFormat::Png,
        )
        .encode_to_vec();
        let bad = decode_image(protobuf(MessageType::CompressedImage), "/c", &bad).unwrap();
        assert!(gray_from_image_into(&bad, "/c", &mut gray)
            .unwrap_err()
            .to_string()
            .contains("/c"));
    }
}
