//! Round trip: convert the TUM fr2_desk excerpt in fixtures/ with the binary, read it back with the
//! library's reader (`McapInput`, messages decoded here with `prost`), and compare with the
//! source files decoded independently (the `image` crate, the text files): every colour byte,
//! depth pixel, timestamp and pose.

#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns: a panic is the failure report

use crate::common;

use std::collections::BTreeMap;
use std::path::Path;

use common::recording::{self, Message};
use common::*;
use foxglove::messages as fm;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use occmask::geometry::camera::presets;
use occmask::geometry::PinholeIntrinsics;
use occmask::mcap_io::codec::timestamp_ns;
use occmask::mcap_io::*;
use occmask::trajectory::parse_tum_line;

/// `(timestamp_ns, path)` of a TUM list file, read by the library's list reader.
fn list(dir: &Path, name: &str) -> Vec<(u64, std::path::PathBuf)> {
    occmask::dataset::read_image_list(&dir.join(name), dir)
        .unwrap()
        .into_iter()
        .map(|image| (image.timestamp_ns, image.path))
        .collect()
}

#[test]
fn tum_fr2_desk_round_trips_exactly() {
    let src = tum_fixture();
    let tmp = tempfile::tempdir().unwrap();
    let out_path = tmp.path().join("desk.mcap");
    let out = convert("tum", &src, &out_path, &["-q"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));

    let rgb = list(&src, "rgb.txt");
    let depth = list(&src, "depth.txt");
    let gt_text = std::fs::read_to_string(src.join("groundtruth.txt")).unwrap();
    let gt_lines: Vec<&str> = gt_text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .collect();
    assert_eq!(
        (rgb.len(), depth.len(), gt_lines.len()),
        (TUM_FIXTURE_FRAMES, TUM_FIXTURE_FRAMES, 154)
    );

    let input = recording::open(&out_path);
    let channels: Vec<_> = input.channels().values().collect();
    let topics: Vec<(&str, &str)> = channels
        .iter()
        .map(|c| (c.topic.as_str(), c.schema_name.as_str()))
        .collect();
    assert_eq!(
        topics,
        vec![
            (TOPIC_COLOR_IMAGE, SCHEMA_COMPRESSED_IMAGE),
            (TOPIC_COLOR_CAMERA_INFO, SCHEMA_CAMERA_CALIBRATION),
            (TOPIC_DEPTH_IMAGE, SCHEMA_RAW_IMAGE),
            (TOPIC_DEPTH_CAMERA_INFO, SCHEMA_CAMERA_CALIBRATION),
            (TOPIC_GROUNDTRUTH_POSE, SCHEMA_POSE_IN_FRAME),
            (TOPIC_TF, SCHEMA_FRAME_TRANSFORM),
        ]
    );
    assert_eq!(
        channels[2].metadata.get(DEPTH_UNITS_KEY).map(String::as_str),
        Some("5000")
    );

    let mut by_topic: BTreeMap<String, Vec<Message>> = BTreeMap::new();
    let mut last_log_time = 0;
    for m in recording::messages(&input) {
        assert!(
            m.log_time_ns >= last_log_time,
            "messages must be in log-time order"
        );
        last_log_time = m.log_time_ns;
        by_topic.entry(m.topic.clone()).or_default().push(m);
    }

    // Colour: the original PNG bytes, at the listed time, with one calibration each.
    let colour = &by_topic[TOPIC_COLOR_IMAGE];
    assert_eq!(colour.len(), rgb.len());
    for (m, (t, path)) in colour.iter().zip(&rgb) {
        assert_eq!(m.schema_name, SCHEMA_COMPRESSED_IMAGE);
        let img: fm::CompressedImage = m.decode();
        assert_eq!(m.log_time_ns, *t);
        assert_eq!(timestamp_ns(img.timestamp.as_ref()), *t);
        assert_eq!(img.format, "png");
        assert_eq!(img.frame_id, FRAME_CAMERA_OPTICAL);
        assert!(
            img.data.as_ref() == std::fs::read(path).unwrap().as_slice(),
            "{}",
            path.display()
        );
    }
    for (topic, stamps) in [(TOPIC_COLOR_CAMERA_INFO, &rgb), (TOPIC_DEPTH_CAMERA_INFO, &depth)] {
        let infos = &by_topic[topic];
        assert_eq!(infos.len(), stamps.len());
        for (m, (t, _)) in infos.iter().zip(stamps) {
            assert_eq!(m.schema_name, SCHEMA_CAMERA_CALIBRATION, "{topic}");
            let cal: fm::CameraCalibration = m.decode();
            assert_eq!(m.log_time_ns, *t);
            assert_eq!(timestamp_ns(cal.timestamp.as_ref()), *t);
            let k = &cal.k;
            assert_eq!(
                (
                    PinholeIntrinsics::new(k[0], k[4], k[2], k[5]),
                    cal.width,
                    cal.height
                ),
                (presets::TUM_FR2, 640, 480)
            );
        }
    }

    // Depth: every pixel equal to the PNG decoded by the `image` crate.
    let depth_msgs = &by_topic[TOPIC_DEPTH_IMAGE];
    assert_eq!(depth_msgs.len(), depth.len());
    for (m, (t, path)) in depth_msgs.iter().zip(&depth) {
        assert_eq!(m.schema_name, SCHEMA_RAW_IMAGE);
        let raw: fm::RawImage = m.decode();
        assert_eq!(m.log_time_ns, *t);
        assert_eq!(raw.encoding, "16UC1");
        let expected = image::open(path).unwrap().into_luma16();
        assert_eq!(
            (raw.width, raw.height, raw.step),
            (expected.width(), expected.height(), 2 * expected.width())
        );
        let pixels: Vec<u16> = raw
            .data
            .chunks_exact(2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
            .collect();
        assert!(
            pixels == expected.into_raw(),
            "depth pixels differ: {}",
            path.display()
        );
    }

    // Ground truth: every sample at its own time; positions bit-identical to the text,
    // orientation equal to the text's quaternion normalised (the file rounds to 4 decimals).
    for topic in [TOPIC_GROUNDTRUTH_POSE, TOPIC_TF] {
        let msgs = &by_topic[topic];
        assert_eq!(msgs.len(), gt_lines.len());
        for (m, line) in msgs.iter().zip(&gt_lines) {
            let fields: Vec<f64> = line
                .split_whitespace()
                .skip(1)
                .map(|f| f.parse().unwrap())
                .collect();
            let expected = parse_tum_line(line).unwrap();
            // Raw protobuf fields, compared bit for bit.
            let (stamp, position, orientation) = match m.schema_name.as_str() {
                SCHEMA_POSE_IN_FRAME => {
                    let p: fm::PoseInFrame = m.decode();
                    assert_eq!(p.frame_id, FRAME_WORLD);
                    let pose = p.pose.as_ref().unwrap();
                    (
                        timestamp_ns(p.timestamp.as_ref()),
                        pose.position.unwrap(),
                        pose.orientation.unwrap(),
                    )
                }
                SCHEMA_FRAME_TRANSFORM => {
                    let tf: fm::FrameTransform = m.decode();
                    assert_eq!(
                        (tf.parent_frame_id.as_str(), tf.child_frame_id.as_str()),
                        (FRAME_WORLD, FRAME_CAMERA_GROUNDTRUTH)
                    );
                    (
                        timestamp_ns(tf.timestamp.as_ref()),
                        tf.translation.unwrap(),
                        tf.rotation.unwrap(),
                    )
                }
                other => panic!("unexpected schema {other:?}"),
            };
            assert_eq!(
                (m.log_time_ns, stamp),
                (expected.timestamp_ns, expected.timestamp_ns)
            );
            assert_eq!(
                [position.x, position.y, position.z],
                [fields[0], fields[1], fields[2]]
            );
            let e = expected.world_from_camera.rotation;
            let q = [orientation.x, orientation.y, orientation.z, orientation.w];
            assert_eq!(q, [e.i, e.j, e.k, e.w]);
            let iso = Isometry3::from_parts(
                Translation3::new(position.x, position.y, position.z),
                UnitQuaternion::from_quaternion(Quaternion::new(q[3], q[0], q[1], q[2])),
            );
            assert!(
                (iso.to_homogeneous() - expected.world_from_camera.to_homogeneous())
                    .abs()
                    .max()
                    < 1e-12
            );
            // ...and within the file's rounding of the raw quaternion.
            for (got, raw) in q.iter().zip(&fields[3..7]) {
                assert!((got - raw).abs() < 2e-4, "{got} vs {raw}");
            }
        }
    }

    // Metadata and attachments.
    let metadata = recording::metadata(&input);
    assert_eq!(metadata.len(), 1);
    let md = &metadata[0].metadata;
    assert_eq!(metadata[0].name, METADATA_CONVERT);
    assert_eq!(md["dataset_kind"], "tum");
    assert_eq!(md["sequence_name"], "tum_fr2_desk_10");
    assert_eq!(md["intrinsics_source"], "folder name (fr2)");
    assert_eq!(md["pairs"], TUM_FIXTURE_FRAMES.to_string());
    assert!(md["command_line"].contains("convert tum"));
    let attachments = recording::attachments(&input);
    let names: Vec<&str> = attachments.iter().map(|(name, _)| name.as_str()).collect();
    assert_eq!(
        names,
        vec![
            "occmask_association.txt",
            "rgb.txt",
            "depth.txt",
            "groundtruth.txt"
        ]
    );
    assert_eq!(attachments[3].1, gt_text.as_bytes());
    assert_eq!(
        attachments[0].1.iter().filter(|&&b| b == b'\n').count(),
        TUM_FIXTURE_FRAMES + 1
    );
}
