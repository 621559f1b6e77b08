//! In-memory RGB-D MCAP fixtures in four flavours (Foxglove protobuf, Foxglove JSON, ROS 2
//! CDR, ROS 1) with the same pixels, stamps, calibration and poses, plus a deterministic
//! [`FrameProcessor`] whose outputs depend on every decoded pixel, so equal outputs across
//! flavours mean equal decoding.
#![allow(clippy::unwrap_used)] // test helpers: a panic is the failure report

use std::collections::BTreeMap;
use std::io::{Cursor, Seek, Write};

use foxglove::messages as fm;
use foxglove::Encode;
use mcap::records::MessageHeader;
use nalgebra::{Isometry3, Vector3};
use occmask::geometry::camera::PinholeIntrinsics;
use occmask::geometry::distortion::CameraModel;
use occmask::image_buf::{DepthMeters, GrayF32, ImageSize, Mask, MASK_SET};
use occmask::mcap_io::codec;
use occmask::mcap_io::input::{json, ros1, ros2};
use occmask::mcap_io::ros_out::{self, RosImage, RosVersion};
use occmask::pipeline::{DvoSummary, FrameInput, FrameResult, FrameStats, PoseOutcome};
use occmask::process::FrameProcessor;
use occmask::Result;
use prost::Message as _;

/// Fixture flavours.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flavor {
    /// rgb8 RawImage colour, 16UC1 depth, protobuf.
    Protobuf,
    /// PNG CompressedImage colour, 16UC1 depth, JSON.
    Json,
    /// bgr8 Image colour, 16UC1 depth (mm), CDR with the ros2 profile.
    Ros2,
    /// The same as ROS 1 messages (ros1 profile), written by `occmask::mcap_io::ros_out`.
    Ros1,
}

pub const ALL_FLAVORS: [Flavor; 4] = [Flavor::Protobuf, Flavor::Json, Flavor::Ros2, Flavor::Ros1];

/// Shape of a fixture sequence.
#[derive(Debug, Clone, Copy)]
pub struct FixtureSpec {
    pub size: ImageSize,
    pub frames: usize,
    /// Depth stamps lag colour by this much (pairing must still match them).
    pub depth_lag_ns: u64,
    /// Write the summary's chunk indexes (false = linear fallback).
    pub indexed: bool,
    /// Colour image encoding for the ROS flavour (`bgr8`, `rgb8`; others are written as
    /// `bgr8` bytes under that name, for unsupported-encoding errors).
    pub ros_color_encoding: &'static str,
    /// Calibration messages.
    pub with_calibration: bool,
    /// Ground-truth poses only from this frame on (a pose stream that starts late)...
    pub first_ground_truth_frame: usize,
    /// ...and before this one (a pose stream that ends early).
    pub ground_truth_end_frame: usize,
    /// Ground-truth poses are logged this long after the frame they are stamped with.
    pub ground_truth_delay_ns: u64,
}

impl Default for FixtureSpec {
    fn default() -> Self {
        Self {
            size: ImageSize::new(64, 48),
            frames: 12,
            depth_lag_ns: 3_000_000,
            indexed: true,
            ros_color_encoding: "bgr8",
            with_calibration: true,
            first_ground_truth_frame: 0,
            ground_truth_end_frame: usize::MAX,
            ground_truth_delay_ns: 0,
        }
    }
}

pub const T0_NS: u64 = 1_700_000_000_000_000_000;
pub const FRAME_NS: u64 = 33_333_333;
pub const COLOR_TOPIC: &str = "/camera/color/image";
pub const DEPTH_TOPIC: &str = "/camera/depth/image";
pub const INFO_TOPIC: &str = "/camera/color/camera_info";
pub const GT_TOPIC: &str = "/groundtruth/pose";
pub const OTHER_TOPIC: &str = "/diagnostics";
/// Ground-truth masks (protobuf flavour only): the moving square.
pub const GT_MASK_TOPIC: &str = "/groundtruth/mask";
pub const FRAME_ID: &str = "camera_color_optical_frame";
pub const INTRINSICS: PinholeIntrinsics = PinholeIntrinsics {
    fx: 50.0,
    fy: 50.0,
    cx: 31.5,
    cy: 23.5,
};
pub const DEPTH_UNITS: f64 = 1000.0;

/// True inside the moving square of frame `i` (12×12 px, moving right by 2 px per frame).
pub fn square(i: usize, x: usize, y: usize) -> bool {
    let sx = 8 + 2 * i;
    x >= sx && x < sx + 12 && (14..26).contains(&y)
}

/// Colour of frame `i`: a gradient with a bright square moving right by 2 px per frame.
pub fn rgb_pixel(i: usize, x: usize, y: usize) -> [u8; 3] {
    if square(i, x, y) {
        [250, 240, 30]
    } else {
        [(3 * x) as u8, (4 * y) as u8, ((x + y) * 2) as u8]
    }
}

/// Depth of frame `i` in millimetres: 3 m wall, the square at 1.5 m, a hole column.
pub fn depth_mm(i: usize, x: usize, y: usize) -> u16 {
    if x == 0 {
        0
    } else if square(i, x, y) {
        1500
    } else {
        3000 + (y as u16) * 4
    }
}

/// Ground-truth pose of frame `i`: a slow translation and yaw.
pub fn gt_pose(i: usize) -> Isometry3<f64> {
    Isometry3::new(
        Vector3::new(0.01 * i as f64, 0.002 * i as f64, 0.0),
        Vector3::new(0.0, 0.003 * i as f64, 0.0),
    )
}

pub fn color_stamp(i: usize) -> u64 {
    T0_NS + i as u64 * FRAME_NS
}

fn jtime(ns: u64) -> json::Time {
    json::Time {
        sec: ns / 1_000_000_000,
        nsec: ns % 1_000_000_000,
    }
}

fn rtime(ns: u64) -> ros2::Time {
    ros2::Time {
        sec: (ns / 1_000_000_000) as i32,
        nanosec: (ns % 1_000_000_000) as u32,
    }
}

fn png_bytes(size: ImageSize, i: usize) -> Vec<u8> {
    let mut img = image::RgbImage::new(size.width as u32, size.height as u32);
    for (x, y, p) in img.enumerate_pixels_mut() {
        *p = image::Rgb(rgb_pixel(i, x as usize, y as usize));
    }
    let mut out = Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

struct Channels {
    gt_mask: Option<u16>,
    color: u16,
    depth: u16,
    info: u16,
    gt: u16,
    other: u16,
}

fn register<W: Write + Seek>(w: &mut mcap::Writer<W>, flavor: Flavor, spec: &FixtureSpec) -> Channels {
    let mut depth_meta = BTreeMap::new();
    let json_schema = |name: &str| format!(r#"{{"title":"{name}","type":"object"}}"#);
    let mut add = |topic: &str, schema: (&str, &str, Vec<u8>), enc: &str, meta: &BTreeMap<String, String>| {
        let sid = w.add_schema(schema.0, schema.1, &schema.2).unwrap();
        w.add_channel(sid, topic, enc, meta).unwrap()
    };
    let none = BTreeMap::new();
    let other = add(OTHER_TOPIC, ("", "", Vec::new()), "json", &none);
    let ids = match flavor {
        Flavor::Protobuf | Flavor::Json => {
            depth_meta.insert("depth_units_per_meter".to_owned(), DEPTH_UNITS.to_string());
            let schema = |s: foxglove::Schema| {
                if flavor == Flavor::Protobuf {
                    (s.name.clone(), s.encoding.clone(), s.data.to_vec())
                } else {
                    (
                        s.name.clone(),
                        "jsonschema".to_owned(),
                        json_schema(&s.name).into_bytes(),
                    )
                }
            };
            let enc = if flavor == Flavor::Protobuf {
                "protobuf"
            } else {
                "json"
            };
            let color_schema = if flavor == Flavor::Protobuf {
                schema(fm::RawImage::get_schema().unwrap())
            } else {
                schema(fm::CompressedImage::get_schema().unwrap())
            };
            let raw = schema(fm::RawImage::get_schema().unwrap());
            let cal = schema(fm::CameraCalibration::get_schema().unwrap());
            let pose = schema(fm::PoseInFrame::get_schema().unwrap());
            let mut a = |t: &str, s: &(String, String, Vec<u8>), m: &BTreeMap<String, String>| {
                add(t, (s.0.as_str(), s.1.as_str(), s.2.clone()), enc, m)
            };
            let color = a(COLOR_TOPIC, &color_schema, &none);
            let depth = a(DEPTH_TOPIC, &raw, &depth_meta);
            let info = if spec.with_calibration {
                a(INFO_TOPIC, &cal, &none)
            } else {
                0
            };
            let gt = a(GT_TOPIC, &pose, &none);
            (color, depth, info, gt)
        }
        Flavor::Ros2 => {
            let qos = BTreeMap::from([("offered_qos_profiles".to_owned(), String::new())]);
            let s = |name: &str, text: String| (name.to_owned(), "ros2msg".to_owned(), text.into_bytes());
            let mut a = |t: &str, s: (String, String, Vec<u8>)| {
                add(t, (s.0.as_str(), s.1.as_str(), s.2), "cdr", &qos)
            };
            let color = a(COLOR_TOPIC, s(ros2::names::IMAGE, ros2::schema_text::image()));
            let depth = a(DEPTH_TOPIC, s(ros2::names::IMAGE, ros2::schema_text::image()));
            let info = if spec.with_calibration {
                a(
                    INFO_TOPIC,
                    s(ros2::names::CAMERA_INFO, ros2::schema_text::camera_info()),
                )
            } else {
                0
            };
            let gt = a(
                GT_TOPIC,
                s(ros2::names::POSE_STAMPED, ros2::schema_text::pose_stamped()),
            );
            (color, depth, info, gt)
        }
        Flavor::Ros1 => {
            let s = |name: &str, text: String| (name.to_owned(), "ros1msg".to_owned(), text.into_bytes());
            let mut a = |t: &str, s: (String, String, Vec<u8>)| {
                add(t, (s.0.as_str(), s.1.as_str(), s.2), "ros1", &none)
            };
            let color = a(COLOR_TOPIC, s(ros1::names::IMAGE, ros1::schema_text::image()));
            let depth = a(DEPTH_TOPIC, s(ros1::names::IMAGE, ros1::schema_text::image()));
            let info = if spec.with_calibration {
                a(
                    INFO_TOPIC,
                    s(ros1::names::CAMERA_INFO, ros1::schema_text::camera_info()),
                )
            } else {
                0
            };
            let gt = a(
                GT_TOPIC,
                s(ros1::names::POSE_STAMPED, ros1::schema_text::pose_stamped()),
            );
            (color, depth, info, gt)
        }
    };
    let gt_mask = (flavor == Flavor::Protobuf).then(|| {
        let s = fm::RawImage::get_schema().unwrap();
        let sid = w.add_schema(&s.name, &s.encoding, &s.data).unwrap();
        w.add_channel(sid, GT_MASK_TOPIC, "protobuf", &BTreeMap::new())
            .unwrap()
    });
    Channels {
        gt_mask,
        color: ids.0,
        depth: ids.1,
        info: ids.2,
        gt: ids.3,
        other,
    }
}

fn cdr<T: serde::Serialize>(msg: &T) -> Vec<u8> {
    cdr::serialize::<_, _, cdr::CdrLe>(msg, cdr::Infinite).unwrap()
}

fn color_msg(flavor: Flavor, spec: &FixtureSpec, i: usize, stamp: u64) -> Vec<u8> {
    let size = spec.size;
    match flavor {
        Flavor::Protobuf => {
            let rgb = occmask::image_buf::Rgb8::from_fn(size, |x, y| rgb_pixel(i, x, y));
            codec::rgb8_image(stamp, FRAME_ID, &rgb).unwrap().encode_to_vec()
        }
        Flavor::Json => serde_json::to_vec(&json::CompressedImage {
            timestamp: jtime(stamp),
            frame_id: FRAME_ID.into(),
            data: json::Base64Bytes(png_bytes(size, i)),
            format: "png".into(),
        })
        .unwrap(),
        Flavor::Ros2 | Flavor::Ros1 => {
            let enc = spec.ros_color_encoding;
            let bpp = 3;
            let mut data = Vec::with_capacity(size.area() * bpp);
            for y in 0..size.height {
                for x in 0..size.width {
                    let [r, g, b] = rgb_pixel(i, x, y);
                    match enc {
                        "rgb8" => data.extend_from_slice(&[r, g, b]),
                        _ => data.extend_from_slice(&[b, g, r]),
                    }
                }
            }
            if flavor == Flavor::Ros1 {
                return ros1_image(i, enc, size, bpp, stamp, &data);
            }
            cdr(&ros2::Image {
                header: ros2::Header {
                    stamp: rtime(stamp),
                    frame_id: FRAME_ID.into(),
                },
                height: size.height as u32,
                width: size.width as u32,
                encoding: enc.into(),
                is_bigendian: 0,
                step: (size.width * bpp) as u32,
                data,
            })
        }
    }
}

/// A ROS 1 `sensor_msgs/Image` (header sequence number = frame index, as a publisher counts).
fn ros1_image(i: usize, encoding: &str, size: ImageSize, bpp: usize, stamp: u64, data: &[u8]) -> Vec<u8> {
    let image = RosImage {
        frame_id: FRAME_ID,
        encoding,
        size,
        step: size.width * bpp,
        data,
    };
    ros_out::encode_image(RosVersion::Ros1, i as u32, stamp, &image).unwrap()
}

fn depth_msg(flavor: Flavor, size: ImageSize, i: usize, stamp: u64) -> Vec<u8> {
    let mut data = Vec::with_capacity(size.area() * 2);
    for y in 0..size.height {
        for x in 0..size.width {
            data.extend_from_slice(&depth_mm(i, x, y).to_le_bytes());
        }
    }
    match flavor {
        Flavor::Protobuf => fm::RawImage {
            timestamp: Some(codec::timestamp(stamp)),
            frame_id: FRAME_ID.into(),
            width: size.width as u32,
            height: size.height as u32,
            encoding: "16UC1".into(),
            step: (size.width * 2) as u32,
            data: data.into(),
        }
        .encode_to_vec(),
        Flavor::Json => serde_json::to_vec(&json::RawImage {
            timestamp: jtime(stamp),
            frame_id: FRAME_ID.into(),
            width: size.width as u32,
            height: size.height as u32,
            encoding: "16UC1".into(),
            step: (size.width * 2) as u32,
            data: json::Base64Bytes(data),
        })
        .unwrap(),
        Flavor::Ros2 => cdr(&ros2::Image {
            header: ros2::Header {
                stamp: rtime(stamp),
                frame_id: FRAME_ID.into(),
            },
            height: size.height as u32,
            width: size.width as u32,
            encoding: "16UC1".into(),
            is_bigendian: 0,
            step: (size.width * 2) as u32,
            data,
        }),
        Flavor::Ros1 => ros1_image(i, "16UC1", size, 2, stamp, &data),
    }
}

fn info_msg(flavor: Flavor, size: ImageSize, stamp: u64) -> Vec<u8> {
    let cal = codec::camera_calibration(stamp, FRAME_ID, &INTRINSICS, size, None).unwrap();
    match flavor {
        Flavor::Ros1 => {
            let camera = CameraModel::pinhole(size, INTRINSICS);
            ros_out::encode_camera_info(RosVersion::Ros1, 0, stamp, FRAME_ID, &camera).unwrap()
        }
        Flavor::Protobuf => cal.encode_to_vec(),
        Flavor::Json => serde_json::to_vec(&json::CameraCalibration {
            timestamp: jtime(stamp),
            frame_id: FRAME_ID.into(),
            width: cal.width,
            height: cal.height,
            distortion_model: cal.distortion_model.clone(),
            d: cal.d.clone(),
            k: cal.k.clone(),
            r: cal.r.clone(),
            p: cal.p.clone(),
        })
        .unwrap(),
        Flavor::Ros2 => {
            let mut k = [0.0; 9];
            k.copy_from_slice(&cal.k);
            let mut r = [0.0; 9];
            r.copy_from_slice(&cal.r);
            let mut p = [0.0; 12];
            p.copy_from_slice(&cal.p);
            cdr(&ros2::CameraInfo {
                header: ros2::Header {
                    stamp: rtime(stamp),
                    frame_id: FRAME_ID.into(),
                },
                height: cal.height,
                width: cal.width,
                distortion_model: cal.distortion_model.clone(),
                d: cal.d.clone(),
                k,
                r,
                p,
                ..Default::default()
            })
        }
    }
}

fn pose_msg(flavor: Flavor, stamp: u64, iso: &Isometry3<f64>) -> Vec<u8> {
    let t = iso.translation.vector;
    let q = iso.rotation;
    match flavor {
        Flavor::Ros1 => ros_out::encode_pose(RosVersion::Ros1, 0, stamp, "world", iso).unwrap(),
        Flavor::Protobuf => codec::pose_in_frame(stamp, "world", iso).encode_to_vec(),
        Flavor::Json => serde_json::to_vec(&json::PoseInFrame {
            timestamp: jtime(stamp),
            frame_id: "world".into(),
            pose: json::Pose {
                position: json::Vector3 {
                    x: t.x,
                    y: t.y,
                    z: t.z,
                },
                orientation: json::Quaternion {
                    x: q.i,
                    y: q.j,
                    z: q.k,
                    w: q.w,
                },
            },
        })
        .unwrap(),
        Flavor::Ros2 => cdr(&ros2::PoseStamped {
            header: ros2::Header {
                stamp: rtime(stamp),
                frame_id: "world".into(),
            },
            pose: ros2::Pose {
                position: ros2::Point {
                    x: t.x,
                    y: t.y,
                    z: t.z,
                },
                orientation: ros2::Quaternion {
                    x: q.i,
                    y: q.j,
                    z: q.k,
                    w: q.w,
                },
            },
        }),
    }
}

/// Writes a fixture file into `sink`. Messages are in log-time order; the recorder's log time
/// is the stamp plus 1 ms of "transport" delay, so log time and stamp differ as in real bags.
pub fn write_fixture<W: Write + Seek>(sink: W, flavor: Flavor, spec: &FixtureSpec) -> W {
    const TRANSPORT_NS: u64 = 1_000_000;
    let mut options = mcap::WriteOptions::new()
        .library("fixture")
        .chunk_size(Some(256 * 1024))
        .compression(Some(mcap::Compression::Lz4));
    if flavor == Flavor::Ros2 {
        options = options.profile("ros2");
    }
    if flavor == Flavor::Ros1 {
        options = options.profile("ros1");
    }
    if !spec.indexed {
        options = options.emit_chunk_indexes(false).emit_message_indexes(false);
    }
    let mut w = options.create(sink).unwrap();
    let ch = register(&mut w, flavor, spec);
    w.write_metadata(&mcap::records::Metadata {
        name: "recording".into(),
        metadata: BTreeMap::from([("robot".to_owned(), "fixture-bot".to_owned())]),
    })
    .unwrap();
    w.attach(&mcap::Attachment {
        log_time: T0_NS,
        create_time: 7,
        name: "calib.yaml".into(),
        media_type: "application/yaml".into(),
        data: std::borrow::Cow::Borrowed(b"fx: 50\n"),
    })
    .unwrap();
    let mut seq: BTreeMap<u16, u32> = BTreeMap::new();
    let mut msgs: Vec<(u64, u16, Vec<u8>)> = Vec::new();
    for i in 0..spec.frames {
        let tc = color_stamp(i);
        let td = tc + spec.depth_lag_ns;
        msgs.push((tc + TRANSPORT_NS, ch.color, color_msg(flavor, spec, i, tc)));
        msgs.push((td + TRANSPORT_NS, ch.depth, depth_msg(flavor, spec.size, i, td)));
        if spec.with_calibration {
            msgs.push((tc + TRANSPORT_NS, ch.info, info_msg(flavor, spec.size, tc)));
        }
        if (spec.first_ground_truth_frame..spec.ground_truth_end_frame).contains(&i) {
            let logged = tc + TRANSPORT_NS + spec.ground_truth_delay_ns;
            msgs.push((logged, ch.gt, pose_msg(flavor, tc, &gt_pose(i))));
        }
        if let Some(id) = ch.gt_mask {
            let mask = Mask::from_fn(spec.size, |x, y| if square(i, x, y) { MASK_SET } else { 0 });
            let msg = codec::mask_image(tc, FRAME_ID, &mask).unwrap();
            msgs.push((tc + TRANSPORT_NS, id, msg.encode_to_vec()));
        }
        msgs.push((
            tc + 2 * TRANSPORT_NS,
            ch.other,
            format!("{{\"i\":{i}}}").into_bytes(),
        ));
    }
    msgs.sort_by_key(|m| m.0);
    for (log_time, channel_id, data) in msgs {
        let s = seq.entry(channel_id).or_insert(100);
        w.write_to_known_channel(
            &MessageHeader {
                channel_id,
                sequence: *s,
                log_time,
                publish_time: log_time - 500,
            },
            &data,
        )
        .unwrap();
        *s += 1;
    }
    w.finish().unwrap();
    w.into_inner()
}

/// Fixture bytes.
pub fn fixture_bytes(flavor: Flavor, spec: &FixtureSpec) -> Vec<u8> {
    write_fixture(Cursor::new(Vec::new()), flavor, spec).into_inner()
}

/// A processor whose outputs depend on every pixel: mask = pixels whose gray changed by more
/// than 0.1 since the previous frame (and have depth); pose = external, else a translation
/// built from the mean gray, mean depth and frame count.
pub struct TestProcessor {
    previous: Option<GrayF32>,
    count: u32,
    pub intrinsics: PinholeIntrinsics,
}

impl FrameProcessor for TestProcessor {
    fn push(&mut self, frame: &FrameInput<'_>) -> Result<Vec<FrameResult>> {
        self.process(frame).map(|result| vec![result])
    }
}

impl TestProcessor {
    fn process(&mut self, frame: &FrameInput<'_>) -> Result<FrameResult> {
        let size = frame.gray.size();
        let mask = match &self.previous {
            Some(prev) => Mask::from_fn(size, |x, y| {
                let changed = (frame.gray.get(x, y) - prev.get(x, y)).abs() > 0.1;
                if changed && frame.depth_m.get(x, y) > 0.0 {
                    MASK_SET
                } else {
                    0
                }
            }),
            None => Mask::filled(size, 0),
        };
        let mean = |v: &[f32]| v.iter().map(|&x| f64::from(x)).sum::<f64>() / v.len() as f64;
        let pose = frame.world_from_marker.copied().unwrap_or_else(|| {
            Isometry3::translation(
                mean(frame.gray.as_slice()),
                mean(frame.depth_m.as_slice()),
                f64::from(self.count),
            )
        });
        self.previous = Some(frame.gray.clone());
        self.count += 1;
        let mut iterations_per_level = [0; occmask::dvo::MAX_DVO_LEVELS];
        iterations_per_level[0] = self.count;
        Ok(FrameResult {
            mask,
            world_from_camera: pose,
            accumulation_m: Some(occmask::image_buf::Image::filled(size, self.count as f32)),
            stats: FrameStats {
                outcome: if frame.world_from_marker.is_some() {
                    PoseOutcome::External
                } else {
                    PoseOutcome::Tracked
                },
                dvo: Some(DvoSummary {
                    status: occmask::dvo::DvoStatus::Converged,
                    iterations_per_level,
                    final_cost: 0.5,
                    pixels_used: 0,
                    reference_pixels: 0,
                }),
                ..FrameStats::default()
            },
        })
    }
}

/// A factory for [`TestProcessor`].
pub fn test_factory(
    intrinsics: PinholeIntrinsics,
    _size: ImageSize,
    _config: &occmask::pipeline::ProcessorConfig,
) -> Result<Box<dyn FrameProcessor>> {
    Ok(Box::new(TestProcessor {
        previous: None,
        count: 0,
        intrinsics,
    }))
}

/// Keeps `DepthMeters` in the public imports used by some test crates.
pub type Depth = DepthMeters;
