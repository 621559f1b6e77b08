//! Writes the seed corpora of the cargo-fuzz targets (fuzz/README.md): valid
//! messages of every decoded type, produced by occmask's own writers and serde structs, so
//! the fuzzer starts from meaningful inputs instead of random bytes.
//!
//! `cargo run --example fuzz_seeds -- fuzz/corpus` writes `fuzz/corpus/<target>/seed-*`.
//! The input layout (a selector byte, then the message) is the one of fuzz/src/lib.rs.

use std::collections::BTreeMap;
use std::io::Cursor;
use std::path::Path;

use anyhow::{Context, Result};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use occmask::convert::write_synthetic_rig_recording;
use occmask::geometry::camera::presets;
use occmask::geometry::distortion::CameraModel;
use occmask::image_buf::{ImageSize, Mask, Rgb8, MASK_SET};
use occmask::mcap_io::codec::{self, ColorFormat};
use occmask::mcap_io::input::{json, pixels, ros2};
use occmask::mcap_io::ros_out::{self, RosImage, RosTransform, RosVersion};
use occmask::mcap_io::{Compression, McapWriteOptions, RgbdMcapWriter};
use occmask::synthetic::{RgbdRig, Scenario, SequenceConfig, SyntheticSequence};
use occmask::trajectory::{to_tum_text, tum_line, StampedPose};
use prost::bytes::Bytes;
use prost::Message as _;

/// Tiny images keep every fuzz execution fast.
const SIZE: ImageSize = ImageSize { width: 4, height: 3 };
const STAMP_NS: u64 = 1_305_031_102_175_304_000;

fn rgb() -> Rgb8 {
    Rgb8::from_fn(SIZE, |x, y| [(40 * x) as u8, (60 * y) as u8, 200])
}

fn depth_u16() -> Vec<u16> {
    (0..SIZE.area() as u16).map(|i| 5000 + 100 * i).collect()
}

fn png(rgb: &Rgb8) -> Result<Vec<u8>> {
    let flat: Vec<u8> = rgb.as_slice().iter().flatten().copied().collect();
    let buf = image::RgbImage::from_raw(SIZE.width as u32, SIZE.height as u32, flat).context("rgb buffer")?;
    let mut out = Cursor::new(Vec::new());
    buf.write_to(&mut out, image::ImageFormat::Png)?;
    Ok(out.into_inner())
}

fn jpeg(rgb: &Rgb8) -> Result<Vec<u8>> {
    let flat: Vec<u8> = rgb.as_slice().iter().flatten().copied().collect();
    let buf = image::RgbImage::from_raw(SIZE.width as u32, SIZE.height as u32, flat).context("rgb buffer")?;
    let mut out = Cursor::new(Vec::new());
    buf.write_to(&mut out, image::ImageFormat::Jpeg)?;
    Ok(out.into_inner())
}

/// `16UC1; compressedDepth png`: a 12-byte configuration header, then a 16-bit PNG.
fn compressed_depth() -> Result<Vec<u8>> {
    let buf = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(
        SIZE.width as u32,
        SIZE.height as u32,
        depth_u16(),
    )
    .context("depth buffer")?;
    let mut out = Cursor::new(vec![0u8; 12]);
    out.set_position(12);
    buf.write_to(&mut out, image::ImageFormat::Png)?;
    Ok(out.into_inner())
}

fn pose(i: u64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.1 * i as f64, -0.2, 1.5),
        UnitQuaternion::from_euler_angles(0.01 * i as f64, 0.2, -0.3),
    )
}

fn with_selector(selector: u8, msg: &[u8]) -> Vec<u8> {
    let mut out = vec![selector];
    out.extend_from_slice(msg);
    out
}

fn cdr<T: serde::Serialize>(msg: &T) -> Result<Vec<u8>> {
    Ok(cdr::serialize::<_, _, cdr::CdrLe>(msg, cdr::Infinite)?)
}

fn json_time() -> json::Time {
    json::Time {
        sec: STAMP_NS / 1_000_000_000,
        nsec: STAMP_NS % 1_000_000_000,
    }
}

fn ros_header() -> ros2::Header {
    ros2::Header {
        stamp: ros2::Time {
            sec: (STAMP_NS / 1_000_000_000) as i32,
            nanosec: (STAMP_NS % 1_000_000_000) as u32,
        },
        frame_id: "camera_optical".into(),
    }
}

fn ros_transform(iso: &Isometry3<f64>) -> ros2::Transform {
    let (t, q) = (iso.translation.vector, iso.rotation.coords);
    ros2::Transform {
        translation: ros2::Point {
            x: t.x,
            y: t.y,
            z: t.z,
        },
        rotation: ros2::Quaternion {
            x: q.x,
            y: q.y,
            z: q.z,
            w: q.w,
        },
    }
}

fn json_transform(iso: &Isometry3<f64>, child: &str) -> json::FrameTransform {
    let (t, q) = (iso.translation.vector, iso.rotation.coords);
    json::FrameTransform {
        timestamp: json_time(),
        parent_frame_id: "world".into(),
        child_frame_id: child.into(),
        translation: json::Vector3 {
            x: t.x,
            y: t.y,
            z: t.z,
        },
        rotation: json::Quaternion {
            x: q.x,
            y: q.y,
            z: q.z,
            w: q.w,
        },
    }
}

fn write(dir: &Path, target: &str, name: &str, bytes: &[u8]) -> Result<()> {
    let dir = dir.join(target);
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let path = dir.join(format!("seed-{name}"));
    std::fs::write(&path, bytes).with_context(|| format!("cannot write {}", path.display()))
}

fn proto_seeds(out: &Path) -> Result<()> {
    let depth = codec::depth_u16_image(STAMP_NS, "cam", &depth_u16(), SIZE)?;
    let mut depth_padded = depth.clone();
    depth_padded.step += 4;
    let mut data = Vec::new();
    for row in depth.data.chunks(depth.step as usize) {
        data.extend_from_slice(row);
        data.extend_from_slice(&[0; 4]);
    }
    depth_padded.data = data.into();
    let rgb8 = codec::rgb8_image(STAMP_NS, "cam", &rgb())?;
    let mask = codec::mask_image(
        STAMP_NS,
        "cam",
        &Mask::from_fn(SIZE, |x, _| if x > 1 { MASK_SET } else { 0 }),
    )?;
    write(
        out,
        "proto_image",
        "raw-16uc1",
        &with_selector(0, &depth.encode_to_vec()),
    )?;
    write(
        out,
        "proto_image",
        "raw-16uc1-padded",
        &with_selector(0, &depth_padded.encode_to_vec()),
    )?;
    write(
        out,
        "proto_image",
        "raw-rgb8",
        &with_selector(0, &rgb8.encode_to_vec()),
    )?;
    write(
        out,
        "proto_image",
        "raw-mono8",
        &with_selector(0, &mask.encode_to_vec()),
    )?;
    let png_msg = codec::compressed_image(STAMP_NS, "cam", Bytes::from(png(&rgb())?), ColorFormat::Png);
    let jpeg_msg = codec::compressed_image(STAMP_NS, "cam", Bytes::from(jpeg(&rgb())?), ColorFormat::Jpeg);
    let mut depth_png = png_msg.clone();
    depth_png.format = "16UC1; compressedDepth png".into();
    depth_png.data = Bytes::from(compressed_depth()?);
    write(
        out,
        "proto_image",
        "png",
        &with_selector(1, &png_msg.encode_to_vec()),
    )?;
    write(
        out,
        "proto_image",
        "jpeg",
        &with_selector(1, &jpeg_msg.encode_to_vec()),
    )?;
    write(
        out,
        "proto_image",
        "compressed-depth",
        &with_selector(1, &depth_png.encode_to_vec()),
    )?;
    let calibration = codec::camera_calibration(STAMP_NS, "cam", &presets::TUM_FR2, SIZE, None)?;
    write(out, "proto_calibration", "fr2", &calibration.encode_to_vec())?;
    Ok(())
}

fn json_seeds(out: &Path) -> Result<()> {
    let raw = json::RawImage {
        timestamp: json_time(),
        frame_id: "cam".into(),
        width: SIZE.width as u32,
        height: SIZE.height as u32,
        encoding: "16UC1".into(),
        step: 2 * SIZE.width as u32,
        data: json::Base64Bytes(depth_u16().iter().flat_map(|v| v.to_le_bytes()).collect()),
    };
    let rgb_raw = json::RawImage {
        encoding: "bgra8".into(),
        step: 4 * SIZE.width as u32,
        data: json::Base64Bytes(vec![90; 4 * SIZE.area()]),
        ..raw.clone()
    };
    let compressed = json::CompressedImage {
        timestamp: json_time(),
        frame_id: "cam".into(),
        data: json::Base64Bytes(png(&rgb())?),
        format: "png".into(),
    };
    let k = presets::TUM_FR2.k_row_major().to_vec();
    let calibration = json::CameraCalibration {
        timestamp: json_time(),
        frame_id: "cam".into(),
        width: SIZE.width as u32,
        height: SIZE.height as u32,
        distortion_model: "plumb_bob".into(),
        d: vec![0.0; 5],
        k,
        r: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: vec![0.0; 12],
    };
    write(
        out,
        "json_messages",
        "raw-16uc1",
        &with_selector(0, &serde_json::to_vec(&raw)?),
    )?;
    write(
        out,
        "json_messages",
        "raw-bgra8",
        &with_selector(0, &serde_json::to_vec(&rgb_raw)?),
    )?;
    write(
        out,
        "json_messages",
        "png",
        &with_selector(1, &serde_json::to_vec(&compressed)?),
    )?;
    write(
        out,
        "json_messages",
        "calibration",
        &with_selector(2, &serde_json::to_vec(&calibration)?),
    )?;
    Ok(())
}

fn ros2_seeds(out: &Path) -> Result<()> {
    let depth = ros2::Image {
        header: ros_header(),
        height: SIZE.height as u32,
        width: SIZE.width as u32,
        encoding: "16UC1".into(),
        is_bigendian: 0,
        step: 2 * SIZE.width as u32,
        data: depth_u16().iter().flat_map(|v| v.to_le_bytes()).collect(),
    };
    let metres = ros2::Image {
        encoding: "32FC1".into(),
        is_bigendian: 1,
        step: 4 * SIZE.width as u32,
        data: (0..SIZE.area())
            .flat_map(|i| (1.0 + i as f32 * 0.1).to_be_bytes())
            .collect(),
        ..depth.clone()
    };
    let colour = ros2::Image {
        encoding: "rgb8".into(),
        step: 3 * SIZE.width as u32,
        data: rgb().as_slice().iter().flatten().copied().collect(),
        ..depth.clone()
    };
    let compressed = ros2::CompressedImage {
        header: ros_header(),
        format: "rgb8; jpeg compressed bgr8".into(),
        data: jpeg(&rgb())?,
    };
    let compressed_depth = ros2::CompressedImage {
        header: ros_header(),
        format: "16UC1; compressedDepth png".into(),
        data: self::compressed_depth()?,
    };
    write(out, "ros2_image", "16uc1", &with_selector(0, &cdr(&depth)?))?;
    write(out, "ros2_image", "32fc1-be", &with_selector(0, &cdr(&metres)?))?;
    write(out, "ros2_image", "rgb8", &with_selector(0, &cdr(&colour)?))?;
    write(out, "ros2_image", "jpeg", &with_selector(1, &cdr(&compressed)?))?;
    write(
        out,
        "ros2_image",
        "compressed-depth",
        &with_selector(1, &cdr(&compressed_depth)?),
    )?;
    let mut k = [0.0; 9];
    k.copy_from_slice(&presets::TUM_FR2.k_row_major());
    let info = ros2::CameraInfo {
        header: ros_header(),
        height: SIZE.height as u32,
        width: SIZE.width as u32,
        distortion_model: "plumb_bob".into(),
        d: vec![0.0; 5],
        k,
        ..Default::default()
    };
    write(out, "ros2_camera_info", "fr2", &cdr(&info)?)?;
    Ok(())
}

fn pose_seeds(out: &Path) -> Result<()> {
    let iso = pose(1);
    // Selector = flavour (0 protobuf, 1 JSON, 2 CDR) + 3 × type (0 pose, 1 transform, 2 list).
    let proto_pose = codec::pose_in_frame(STAMP_NS, "world", &iso);
    let proto_tf = codec::frame_transform(STAMP_NS, "world", "camera", &iso);
    let proto_tfs = foxglove::messages::FrameTransforms {
        transforms: vec![
            proto_tf.clone(),
            codec::frame_transform(STAMP_NS, "camera", "optical", &pose(2)),
        ],
    };
    write(
        out,
        "poses",
        "proto-pose",
        &with_selector(0, &proto_pose.encode_to_vec()),
    )?;
    write(
        out,
        "poses",
        "proto-tf",
        &with_selector(3, &proto_tf.encode_to_vec()),
    )?;
    write(
        out,
        "poses",
        "proto-tfs",
        &with_selector(6, &proto_tfs.encode_to_vec()),
    )?;
    let (t, q) = (iso.translation.vector, iso.rotation.coords);
    let json_pose = json::PoseInFrame {
        timestamp: json_time(),
        frame_id: "world".into(),
        pose: json::Pose {
            position: json::Vector3 {
                x: t.x,
                y: t.y,
                z: t.z,
            },
            orientation: json::Quaternion {
                x: q.x,
                y: q.y,
                z: q.z,
                w: q.w,
            },
        },
    };
    let json_tfs = json::FrameTransforms {
        transforms: vec![
            json_transform(&iso, "camera"),
            json_transform(&pose(2), "optical"),
        ],
    };
    write(
        out,
        "poses",
        "json-pose",
        &with_selector(1, &serde_json::to_vec(&json_pose)?),
    )?;
    write(
        out,
        "poses",
        "json-tf",
        &with_selector(4, &serde_json::to_vec(&json_transform(&iso, "camera"))?),
    )?;
    write(
        out,
        "poses",
        "json-tfs",
        &with_selector(7, &serde_json::to_vec(&json_tfs)?),
    )?;
    let ros_pose = ros2::PoseStamped {
        header: ros_header(),
        pose: ros2::Pose {
            position: ros_transform(&iso).translation,
            orientation: ros_transform(&iso).rotation,
        },
    };
    let ros_tf = |iso: &Isometry3<f64>, child: &str| ros2::TransformStamped {
        header: ros_header(),
        child_frame_id: child.into(),
        transform: ros_transform(iso),
    };
    let ros_tfs = ros2::TfMessage {
        transforms: vec![ros_tf(&iso, "camera"), ros_tf(&pose(2), "optical")],
    };
    write(out, "poses", "cdr-pose", &with_selector(2, &cdr(&ros_pose)?))?;
    write(
        out,
        "poses",
        "cdr-tf",
        &with_selector(5, &cdr(&ros_tf(&iso, "camera"))?),
    )?;
    write(out, "poses", "cdr-tfs", &with_selector(8, &cdr(&ros_tfs)?))?;
    Ok(())
}

fn text_seeds(out: &Path) -> Result<()> {
    // Selector: 0 image list, 1 ground truth, 2 --camera, 3 seconds, 4 TUM line, 5 association.
    let list = "# color images\n# file: 'rgbd_dataset_freiburg2_desk.bag'\n# timestamp filename\n\
                1311868164.363181 rgb/1311868164.363181.png\n1311868164.399454 rgb/1311868164.399454.png\n";
    let poses: Vec<StampedPose> = (0..3)
        .map(|i| StampedPose {
            timestamp_ns: STAMP_NS + i * 33_000_000,
            world_from_camera: pose(i),
        })
        .collect();
    let gt = format!(
        "# ground truth trajectory\n# timestamp tx ty tz qx qy qz qw\n{}",
        to_tum_text(&poses)
    );
    write(
        out,
        "text_parsers",
        "image-list",
        &with_selector(0, list.as_bytes()),
    )?;
    write(
        out,
        "text_parsers",
        "groundtruth",
        &with_selector(1, gt.as_bytes()),
    )?;
    write(out, "text_parsers", "camera-preset", &with_selector(2, b"fr2"))?;
    write(
        out,
        "text_parsers",
        "camera-numbers",
        &with_selector(2, b"520.9,521.0,325.1,249.7"),
    )?;
    write(
        out,
        "text_parsers",
        "seconds",
        &with_selector(3, b"1311868164.363181"),
    )?;
    write(
        out,
        "text_parsers",
        "tum-line",
        &with_selector(4, tum_line(&poses[1]).as_bytes()),
    )?;
    let association = "1.0 rgb/1.0.png 1.005 depth/1.005.png\n1.1 rgb/1.1.png 1.105 depth/1.105.png\n";
    write(
        out,
        "text_parsers",
        "association",
        &with_selector(5, association.as_bytes()),
    )?;
    Ok(())
}

/// A small indexed protobuf file from [`RgbdMcapWriter`] with every channel kind.
fn protobuf_file(compression: Compression) -> Result<Vec<u8>> {
    let options = McapWriteOptions {
        compression,
        compression_threads: 0,
        ..McapWriteOptions::default()
    };
    let mut w = RgbdMcapWriter::new(Cursor::new(Vec::new()), &options)?;
    let png = Bytes::from(png(&rgb())?);
    for i in 0..3u64 {
        let t = STAMP_NS + i * 33_000_000;
        w.write_camera_info("/camera/color/camera_info", t, &presets::TUM_FR2, SIZE, None)?;
        w.write_color_compressed("/camera/color/image", t, png.clone(), ColorFormat::Png)?;
        w.write_depth_u16("/camera/depth/image", t, &depth_u16(), SIZE, 5000.0)?;
        w.write_pose("/groundtruth/pose", t, &pose(i))?;
        w.write_tf(t, "world", "camera", &pose(i))?;
    }
    w.write_metadata(
        "occmask",
        BTreeMap::from([("dataset".to_owned(), "fuzz".to_owned())]),
    )?;
    w.attach("groundtruth.txt", "text/plain", STAMP_NS, b"# empty\n")?;
    Ok(w.finish()?.into_inner())
}

/// A small ROS 2 (CDR) file written with the mcap crate directly.
fn ros2_file() -> Result<Vec<u8>> {
    let mut w = mcap::WriteOptions::new()
        .compression(None)
        .profile("ros2")
        .create(Cursor::new(Vec::new()))?;
    let schema = |w: &mut mcap::Writer<Cursor<Vec<u8>>>, name: &str| w.add_schema(name, "ros2msg", b"");
    let image_schema = schema(&mut w, ros2::names::IMAGE)?;
    let info_schema = schema(&mut w, ros2::names::CAMERA_INFO)?;
    let color = w.add_channel(image_schema, "/camera/color/image_raw", "cdr", &BTreeMap::new())?;
    let depth = w.add_channel(image_schema, "/camera/depth/image_raw", "cdr", &BTreeMap::new())?;
    let info = w.add_channel(info_schema, "/camera/color/camera_info", "cdr", &BTreeMap::new())?;
    let header = ros_header();
    let colour_msg = ros2::Image {
        header: header.clone(),
        height: SIZE.height as u32,
        width: SIZE.width as u32,
        encoding: "rgb8".into(),
        is_bigendian: 0,
        step: 3 * SIZE.width as u32,
        data: rgb().as_slice().iter().flatten().copied().collect(),
    };
    let depth_msg = ros2::Image {
        encoding: "16UC1".into(),
        step: 2 * SIZE.width as u32,
        data: depth_u16().iter().flat_map(|v| v.to_le_bytes()).collect(),
        ..colour_msg.clone()
    };
    let mut k = [0.0; 9];
    k.copy_from_slice(&presets::TUM_FR2.k_row_major());
    let info_msg = ros2::CameraInfo {
        header,
        height: SIZE.height as u32,
        width: SIZE.width as u32,
        k,
        ..Default::default()
    };
    for (i, (channel, bytes)) in [
        (info, cdr(&info_msg)?),
        (color, cdr(&colour_msg)?),
        (depth, cdr(&depth_msg)?),
    ]
    .into_iter()
    .enumerate()
    {
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: i as u32,
            log_time: STAMP_NS,
            publish_time: STAMP_NS,
        };
        w.write_to_known_channel(&header, &bytes)?;
    }
    w.finish()?;
    Ok(w.into_inner().into_inner())
}

fn file_seeds(out: &Path) -> Result<()> {
    write(
        out,
        "mcap_file",
        "protobuf-zstd.mcap",
        &protobuf_file(Compression::Zstd)?,
    )?;
    write(
        out,
        "mcap_file",
        "protobuf-lz4.mcap",
        &protobuf_file(Compression::Lz4)?,
    )?;
    let plain = protobuf_file(Compression::None)?;
    write(out, "mcap_file", "protobuf-none.mcap", &plain)?;
    // Without its summary and footer: the linear-scan path.
    write(
        out,
        "mcap_file",
        "protobuf-truncated.mcap",
        &plain[..plain.len() * 3 / 4],
    )?;
    write(out, "mcap_file", "ros2.mcap", &ros2_file()?)?;
    // A ROS 1 recording of the synthetic RealSense-like rig: depth from another camera,
    // distorted colour, /tf_static (what `process` registers and undistorts).
    let config = SequenceConfig {
        size: SIZE,
        frame_count: Some(2),
        ..SequenceConfig::default()
    };
    let sequence = SyntheticSequence::new(Scenario::SmallObjectCrossing, config);
    let rig = write_synthetic_rig_recording(
        &sequence,
        &RgbdRig::realsense_like(&config),
        RosVersion::Ros1,
        Cursor::new(Vec::new()),
        &McapWriteOptions::default(),
        &mut |_| std::ops::ControlFlow::Continue(()),
    )?;
    write(out, "mcap_file", "ros1-rig.mcap", &rig.into_inner())?;
    Ok(())
}

/// ROS 1 messages (selector % 6 as in `ros1_messages`) from `ros_out`'s encoders.
fn ros1_seeds(out: &Path) -> Result<()> {
    let v = RosVersion::Ros1;
    let rgb: Vec<u8> = rgb().as_slice().iter().flatten().copied().collect();
    let image = |encoding, step, data| RosImage {
        frame_id: "camera_optical",
        encoding,
        size: SIZE,
        step,
        data,
    };
    let depth: Vec<u8> = depth_u16().iter().flat_map(|d| d.to_le_bytes()).collect();
    let target = "ros1_messages";
    let encoded = ros_out::encode_image(v, 3, STAMP_NS, &image("rgb8", SIZE.width * 3, &rgb))?;
    write(out, target, "image-rgb8", &with_selector(0, &encoded))?;
    let encoded = ros_out::encode_image(v, 3, STAMP_NS, &image("16UC1", SIZE.width * 2, &depth))?;
    write(out, target, "image-16uc1", &with_selector(0, &encoded))?;
    let camera = CameraModel {
        distortion: Some(occmask::geometry::distortion::presets::BONN),
        ..CameraModel::pinhole(SIZE, presets::BONN)
    };
    let encoded = ros_out::encode_camera_info(v, 3, STAMP_NS, "camera_optical", &camera)?;
    write(out, target, "camera-info-plumb-bob", &with_selector(2, &encoded))?;
    let encoded = ros_out::encode_pose(v, 3, STAMP_NS, "world", &pose(1))?;
    write(out, target, "pose-stamped", &with_selector(3, &encoded))?;
    let tf = [RosTransform {
        parent: "camera_link",
        child: "camera_depth_frame",
        parent_from_child: pose(2),
    }];
    let encoded = ros_out::encode_transforms(v, STAMP_NS, &tf)?;
    write(out, target, "tf-message", &with_selector(5, &encoded))?;
    Ok(())
}

/// `field_pixels` inputs: selector (encoding), width, height, step padding, spare, data.
fn field_pixel_seeds(out: &Path) -> Result<()> {
    let (w, h) = (SIZE.width as u8, SIZE.height as u8);
    let packed: Vec<u8> = (0..SIZE.area() * 2).map(|i| (16 + 13 * i) as u8).collect();
    let mosaic: Vec<u8> = (0..SIZE.area()).map(|i| (40 + 17 * i) as u8).collect();
    for (selector, name, data) in [
        (0u8, "uyvy", &packed),
        (1, "yuyv", &packed),
        (2, "bayer-rggb", &mosaic),
    ] {
        let mut seed = vec![selector, w, h, 0, 0];
        seed.extend_from_slice(data);
        write(out, "field_pixels", name, &seed)?;
    }
    // compressedDepth rvl: the 12-byte header (format, two quantisation floats), then width,
    // height and the RVL stream; the selector's first four bytes are part of the header here.
    let mut rvl = vec![6u8];
    rvl.extend_from_slice(&[0; 4]);
    rvl.extend_from_slice(&3000f32.to_le_bytes());
    rvl.extend_from_slice(&(-0.5f32).to_le_bytes());
    rvl.extend_from_slice(&(SIZE.width as u32).to_le_bytes());
    rvl.extend_from_slice(&(SIZE.height as u32).to_le_bytes());
    rvl.extend(pixels::encode_rvl(&depth_u16()));
    write(out, "field_pixels", "rvl-16uc1", &rvl)?;
    rvl[0] = 7;
    write(out, "field_pixels", "rvl-32fc1", &rvl)?;
    Ok(())
}

fn main() -> Result<()> {
    let out = std::env::args_os()
        .nth(1)
        .context("usage: fuzz_seeds OUT_DIR (e.g. fuzz/corpus)")?;
    let out = Path::new(&out);
    proto_seeds(out)?;
    json_seeds(out)?;
    ros2_seeds(out)?;
    pose_seeds(out)?;
    text_seeds(out)?;
    file_seeds(out)?;
    ros1_seeds(out)?;
    field_pixel_seeds(out)?;
    println!("seeds written under {}", out.display());
    Ok(())
}
