//! Fuzz harness: one function per target, each feeding arbitrary bytes through the same
//! library calls the CLI makes on untrusted input. Errors are the expected outcome for most
//! inputs; the harness only fails on panics, aborts (huge allocations), hangs and a few
//! round-trip properties that must hold for every accepted input.
//!
//! The first byte of a message target's input selects the message flavour/type (so one corpus
//! covers all variants); the rest is the message. `tests/integration/fuzz_regressions.rs` in the main crate
//! includes this file with `#[path]` and replays the committed regressions and corpus through
//! the very same functions, so the fuzz findings stay tested in a plain `cargo test`.

use std::path::Path;

use occmask::dataset;
use occmask::geometry::distortion::CameraModel;
use occmask::image_buf::{DepthMeters, GrayF32, ImageSize, Rgb8};
use occmask::mcap_io::input::decode::{
    decode_calibration, decode_image, decode_poses, depth_from_image_into, gray_from_image_into,
    rgb_from_image_into, CalibrationMsg, ImageMsg, ImagePayload,
};
use occmask::mcap_io::input::detect::{describe_channels, detect_topics, TopicOverrides};
use occmask::mcap_io::input::{ChannelType, Flavor, McapInput, MessageType};
use occmask::point_cloud::{PointGrid, POINT_STRIDE_BYTES};
use occmask::registration;
use occmask::time::{format_ns_as_seconds, parse_seconds_to_ns};
use occmask::trajectory::{parse_tum_line, tum_line};

/// Topic named in decode errors.
const TOPIC: &str = "/fuzz";
/// Depth scale passed to the depth conversion (TUM's 16-bit millimetre-ish scale).
const UNITS_PER_METER: f64 = 5000.0;
/// Messages of a whole file visited per input (keeps each execution short).
const MAX_MESSAGES_PER_FILE: usize = 64;

/// Splits the selector byte from the message.
fn split(data: &[u8]) -> Option<(u8, &[u8])> {
    data.split_first().map(|(s, rest)| (*s, rest))
}

fn channel(flavor: Flavor, message: MessageType) -> ChannelType {
    ChannelType { flavor, message }
}

/// The grey conversion (the pipeline's) and the RGB one (`process --points`): both take the same
/// messages, at the same size.
fn colour_conversions(msg: &ImageMsg) {
    let mut gray = GrayF32::filled(ImageSize::new(1, 1), 0.0);
    let gray_ok = gray_from_image_into(msg, TOPIC, &mut gray).is_ok();
    if gray_ok {
        assert!(
            gray.as_slice().iter().all(|v| (0.0..=1.0).contains(v)),
            "gray outside 0..1"
        );
    }
    let mut rgb = Rgb8::filled(ImageSize::new(1, 1), [0; 3]);
    let rgb_ok = rgb_from_image_into(msg, TOPIC, &mut rgb).is_ok();
    assert_eq!(
        gray_ok, rgb_ok,
        "grey and RGB decoding disagree on accepting the image"
    );
    if gray_ok {
        assert_eq!(gray.size(), rgb.size(), "grey and RGB sizes differ");
    }
}

/// Decodes an image and runs both pixel conversions (what `process` does per frame).
fn image_and_pixels(ct: ChannelType, data: &[u8]) {
    let Ok(msg) = decode_image(ct, TOPIC, data) else {
        return;
    };
    let _ = msg.is_depth();
    colour_conversions(&msg);
    let mut depth = DepthMeters::filled(ImageSize::new(1, 1), 0.0);
    if depth_from_image_into(&msg, TOPIC, UNITS_PER_METER, &mut depth).is_ok() {
        assert!(
            depth.as_slice().iter().all(|v| v.is_finite() && *v >= 0.0),
            "depth must be finite and non-negative (0 = invalid)"
        );
    }
}

/// Foxglove protobuf `RawImage` / `CompressedImage` (selector bit 0), decoded by the process
/// input decoder and the convert/eval codec, then converted to grey and depth.
pub fn proto_image(data: &[u8]) {
    let Some((selector, msg)) = split(data) else {
        return;
    };
    let message = if selector & 1 == 0 {
        MessageType::RawImage
    } else {
        MessageType::CompressedImage
    };
    image_and_pixels(channel(Flavor::FoxgloveProtobuf, message), msg);
}

/// Images at most this many pixels wide and tall are built from fuzzed calibrations (keeps
/// each execution short; the tables' cost is linear in the pixels).
const MAX_FUZZ_SIDE: usize = 48;

/// A decoded calibration through K validation, the distortion model and, for small images,
/// the undistortion tables `process` builds from it (Newton inversion of arbitrary
/// coefficients must stay finite or be refused, never panic or hang).
fn calibration_checks(c: &CalibrationMsg) {
    if let Ok(k) = c.intrinsics(TOPIC) {
        assert!(k.is_valid(), "accepted intrinsics must be valid: {k:?}");
    }
    let Ok(camera) = c.camera_model(TOPIC) else {
        return;
    };
    let size = ImageSize::new(
        camera.size.width.clamp(2, MAX_FUZZ_SIDE),
        camera.size.height.clamp(2, MAX_FUZZ_SIDE),
    );
    let camera = CameraModel { size, ..camera };
    let pinhole = registration::inscribed_pinhole(&camera);
    assert!(pinhole.intrinsics.is_valid(), "{pinhole:?}");
    if let (Ok(to_pinhole), Ok(back)) = (
        registration::undistortion_map(&camera, &pinhole),
        registration::distortion_map(&camera, &pinhole),
    ) {
        let gray = GrayF32::from_fn(size, |x, y| ((x + y) % 7) as f32 / 7.0);
        let mut out = GrayF32::filled(size, 0.0);
        if to_pinhole.apply_into(&gray, &mut out).is_ok() {
            assert!(
                out.as_slice().iter().all(|v| (0.0..=1.0).contains(v)),
                "remapped gray outside 0..1"
            );
        }
        let mask = occmask::image_buf::Mask::filled(size, 255);
        let mut published = occmask::image_buf::Mask::filled(size, 0);
        let _ = back.apply_into(&mask, &mut published);
        // `--points`: the samples of the pinhole view, coloured through this lens.
        if let Ok(grid) = PointGrid::new(&pinhole, Some(&camera), 3) {
            let (mut colors, mut depth, mut points) = (Vec::new(), Vec::new(), Vec::new());
            let rgb = Rgb8::filled(size, [9, 8, 7]);
            let depth_m = DepthMeters::filled(size, 1.5);
            if grid.sample_colors_into(&rgb, &mut colors).is_ok()
                && grid.sample_depth_into(&depth_m, &mut depth).is_ok()
            {
                let n = grid.write_points(&depth, &colors, &mask, &mut points);
                assert!(
                    n.is_ok_and(|n| n <= grid.samples() && points.len() == n * POINT_STRIDE_BYTES),
                    "point cloud"
                );
            }
        }
    }
    // Registration from this camera into a fixed pinhole one, 2 cm away.
    let target = CameraModel::pinhole(
        size,
        occmask::geometry::PinholeIntrinsics::new(40.0, 40.0, 23.5, 23.5),
    );
    let color_from_depth = nalgebra::Isometry3::translation(0.02, 0.0, 0.0);
    if let Ok(mut r) = registration::DepthRegistration::new(&camera, &target, &color_from_depth, 1) {
        let depth = DepthMeters::from_fn(size, |x, y| 0.5 + ((x * 3 + y) % 11) as f32 * 0.3);
        let mut out = DepthMeters::filled(size, 0.0);
        if r.register_into(&depth, &mut out).is_ok() {
            assert!(
                out.as_slice().iter().all(|v| v.is_finite() && *v >= 0.0),
                "registered depth"
            );
        }
    }
}

/// Foxglove protobuf `CameraCalibration` through both decoders and the K validation.
pub fn proto_calibration(data: &[u8]) {
    let ct = channel(Flavor::FoxgloveProtobuf, MessageType::Calibration);
    if let Ok(c) = decode_calibration(ct, TOPIC, data) {
        calibration_checks(&c);
    }
}

/// Foxglove JSON `RawImage` / `CompressedImage` / `CameraCalibration` (selector % 3).
pub fn json_messages(data: &[u8]) {
    let Some((selector, msg)) = split(data) else {
        return;
    };
    match selector % 3 {
        0 => image_and_pixels(channel(Flavor::FoxgloveJson, MessageType::RawImage), msg),
        1 => image_and_pixels(channel(Flavor::FoxgloveJson, MessageType::CompressedImage), msg),
        _ => {
            let ct = channel(Flavor::FoxgloveJson, MessageType::Calibration);
            if let Ok(c) = decode_calibration(ct, TOPIC, msg) {
                calibration_checks(&c);
            }
        }
    }
}

/// ROS 2 CDR `sensor_msgs/msg/Image` / `CompressedImage` (selector bit 0).
pub fn ros2_image(data: &[u8]) {
    let Some((selector, msg)) = split(data) else {
        return;
    };
    let message = if selector & 1 == 0 {
        MessageType::RawImage
    } else {
        MessageType::CompressedImage
    };
    image_and_pixels(channel(Flavor::Ros2Cdr, message), msg);
}

/// ROS 2 CDR `sensor_msgs/msg/CameraInfo`.
pub fn ros2_camera_info(data: &[u8]) {
    let ct = channel(Flavor::Ros2Cdr, MessageType::Calibration);
    if let Ok(c) = decode_calibration(ct, TOPIC, data) {
        calibration_checks(&c);
    }
}

/// ROS 1 messages (selector % 6): `Image`, `CompressedImage` (through both pixel
/// conversions), `CameraInfo` (through the calibration checks), `PoseStamped`,
/// `TransformStamped`, `TFMessage`.
pub fn ros1_messages(data: &[u8]) {
    let Some((selector, msg)) = split(data) else {
        return;
    };
    let ct = |message| channel(Flavor::Ros1, message);
    match selector % 6 {
        0 => image_and_pixels(ct(MessageType::RawImage), msg),
        1 => image_and_pixels(ct(MessageType::CompressedImage), msg),
        2 => {
            if let Ok(c) = decode_calibration(ct(MessageType::Calibration), TOPIC, msg) {
                calibration_checks(&c);
            }
        }
        k => {
            let message = [
                MessageType::PoseInFrame,
                MessageType::FrameTransform,
                MessageType::FrameTransforms,
            ][usize::from(k - 3)];
            if let Ok(samples) = decode_poses(ct(message), TOPIC, msg) {
                for s in samples {
                    assert!(s
                        .parent_from_child
                        .translation
                        .vector
                        .iter()
                        .all(|v| v.is_finite()));
                }
            }
        }
    }
}

/// Encodings of the field decoded straight from the pixel bytes: the selector picks the
/// encoding (packed YUV 4:2:2 both orders, the four 8-bit Bayer patterns, compressedDepth
/// RVL 16UC1 / 32FC1, compressedDepth PNG 32FC1), the next four bytes width, height (the
/// low byte each; `step` = the natural row size plus the third byte's low two bits) and the
/// rest are the data; both pixel conversions run.
pub fn field_pixels(data: &[u8]) {
    const RAW: [&str; 6] = [
        "yuv422",
        "yuv422_yuy2",
        "bayer_rggb8",
        "bayer_bggr8",
        "bayer_gbrg8",
        "bayer_grbg8",
    ];
    const COMPRESSED: [&str; 3] = [
        "16UC1; compressedDepth rvl",
        "32FC1; compressedDepth rvl",
        "32FC1; compressedDepth png",
    ];
    let Some((&selector, rest)) = data.split_first() else {
        return;
    };
    let Some((dims, bytes)) = rest.split_first_chunk::<4>() else {
        return;
    };
    let choice = usize::from(selector) % (RAW.len() + COMPRESSED.len());
    let payload = match RAW.get(choice) {
        Some(encoding) => {
            let (width, height) = (u32::from(dims[0]), u32::from(dims[1]));
            let bpp = if choice < 2 { 2 } else { 1 };
            ImagePayload::Raw {
                width,
                height,
                encoding: (*encoding).to_owned(),
                step: width * bpp + u32::from(dims[2] & 3),
                big_endian: false,
                data: bytes.to_vec(),
            }
        }
        None => ImagePayload::Compressed {
            format: COMPRESSED[choice - RAW.len()].to_owned(),
            data: rest.to_vec(),
        },
    };
    let msg = ImageMsg {
        timestamp_ns: 1,
        frame_id: "cam".into(),
        payload,
    };
    colour_conversions(&msg);
    let mut depth = DepthMeters::filled(ImageSize::new(1, 1), 0.0);
    if depth_from_image_into(&msg, TOPIC, UNITS_PER_METER, &mut depth).is_ok() {
        assert!(
            depth.as_slice().iter().all(|v| v.is_finite() && *v >= 0.0),
            "depth"
        );
    }
}

/// Every pose decoder: 3 flavours × PoseInFrame / FrameTransform / FrameTransforms
/// (selector % 9), plus the convert/eval codec's PoseInFrame and FrameTransform.
pub fn poses(data: &[u8]) {
    let Some((selector, msg)) = split(data) else {
        return;
    };
    let flavor = match selector % 3 {
        0 => Flavor::FoxgloveProtobuf,
        1 => Flavor::FoxgloveJson,
        _ => Flavor::Ros2Cdr,
    };
    let message = match (selector / 3) % 3 {
        0 => MessageType::PoseInFrame,
        1 => MessageType::FrameTransform,
        _ => MessageType::FrameTransforms,
    };
    if let Ok(samples) = decode_poses(channel(flavor, message), TOPIC, msg) {
        for s in samples {
            let iso = s.parent_from_child;
            assert!(
                iso.translation.vector.iter().all(|v| v.is_finite())
                    && iso.rotation.coords.iter().all(|v| v.is_finite()),
                "accepted poses must be finite"
            );
        }
    }
}

/// The TUM/LARR text parsers (selector % 6): image lists, ground-truth trajectories, `--camera`,
/// times in seconds, single TUM lines and LARR `association.txt`. Accepted times and poses
/// must survive a format/parse round trip with the exact same nanoseconds.
pub fn text_parsers(data: &[u8]) {
    let Some((selector, bytes)) = split(data) else {
        return;
    };
    let text = String::from_utf8_lossy(bytes);
    let source = Path::new("fuzz.txt");
    let root = Path::new("/nonexistent-occmask-fuzz-root");
    match selector % 6 {
        0 => {
            let _ = dataset::parse_image_list(&text, source, root);
        }
        1 => {
            if let Ok(poses) = dataset::parse_groundtruth(&text, source) {
                for p in &poses {
                    let back = parse_tum_line(&tum_line(p)).expect("tum_line output must parse");
                    assert_eq!(back.timestamp_ns, p.timestamp_ns);
                }
            }
        }
        2 => {
            if let Ok(k) = dataset::parse_camera(&text) {
                assert!(k.intrinsics.is_valid());
            }
        }
        3 => {
            if let Ok(ns) = parse_seconds_to_ns(&text) {
                let formatted = format_ns_as_seconds(ns, 0);
                assert_eq!(parse_seconds_to_ns(&formatted), Ok(ns), "{formatted}");
            }
        }
        4 => {
            if let Ok(p) = parse_tum_line(&text) {
                let back = parse_tum_line(&tum_line(&p)).expect("tum_line output must parse");
                assert_eq!(back.timestamp_ns, p.timestamp_ns);
            }
        }
        _ => {
            // Colour frames at 1.0, 1.1, ... s and depth frames 5 ms later, as a LARR listing.
            let frames = |offset_ns: u64| -> Vec<dataset::ImageRef> {
                (0..8u64)
                    .map(|i| dataset::ImageRef {
                        timestamp_ns: 1_000_000_000 + i * 100_000_000 + offset_ns,
                        path: root.join(format!("{i}.png")),
                    })
                    .collect()
            };
            let _ = dataset::larr::parse_association(&text, source, &frames(0), &frames(5_000_000));
        }
    }
}

/// A whole MCAP file, opened from memory by the one MCAP reader (`McapInput`, indexed or
/// linear; a file on disk takes the same path after opening): channels described and detected,
/// the first message of every supported channel decoded and a bounded number of messages
/// visited.
pub fn mcap_file(data: &[u8]) {
    if let Ok(input) = McapInput::from_bytes(data, Path::new("fuzz.mcap")) {
        let _ = describe_channels(&input);
        let _ = detect_topics(&input, &TopicOverrides::default());
        let _ = input.extras();
        for channel in input.channels().values() {
            let Some(ct) = channel.channel_type else {
                continue;
            };
            let Ok(Some(first)) = input.first_message(channel.id) else {
                continue;
            };
            if ct.is_image() {
                image_and_pixels(ct, &first.data);
            } else if ct.is_pose() {
                let _ = decode_poses(ct, TOPIC, &first.data);
            } else if let Ok(c) = decode_calibration(ct, TOPIC, &first.data) {
                calibration_checks(&c);
            }
        }
        let mut visited = 0;
        let _ = input.for_each_message(None, None, |_| {
            visited += 1;
            Ok(visited < MAX_MESSAGES_PER_FILE)
        });
    }
}
