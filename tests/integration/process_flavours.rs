//! `process` on in-memory fixtures of every input flavour: same masks and poses whatever the
//! encoding, annotated copies that keep every input record byte for byte, sidecars, the
//! linear fallback, determinism and the error messages users see.

#![allow(clippy::unwrap_used)] // helpers outside #[test] fns: a panic is the failure report

use crate::common::mcap_fixture as process_support;

use std::collections::BTreeMap;
use std::io::Cursor;
use std::path::Path;

use foxglove::messages as fm;
use prost::Message as _;

use occmask::error::{DecodeProblem, ImageKind, McapProblem, TopicRole};
use occmask::mcap_io::annotate::{
    AnnotateOptions, FRAME_CAMERA_ESTIMATED, TOPIC_ACCUMULATION, TOPIC_ANCHOR_PATH, TOPIC_MASK,
    TOPIC_MASK_ANNOTATIONS, TOPIC_ODOMETRY, TOPIC_PATH, TOPIC_POINTS, TOPIC_STATS, TOPIC_TF_FALLBACK,
};
use occmask::mcap_io::input::McapInput;
use occmask::process::{process_file, NoHooks, ProcessConfig, ProcessReport};
use process_support::*;

fn write_input(dir: &Path, flavor: Flavor, spec: &FixtureSpec) -> std::path::PathBuf {
    let path = dir.join(format!("{flavor:?}.mcap"));
    std::fs::write(&path, fixture_bytes(flavor, spec)).unwrap();
    path
}

fn run(path: &Path, config: &ProcessConfig) -> occmask::Result<(Vec<u8>, ProcessReport)> {
    let input = McapInput::open(path)?;
    let (cursor, report) = process_file(
        &input,
        Cursor::new(Vec::new()),
        config,
        &mut test_factory,
        &mut NoHooks,
    )?;
    Ok((cursor.into_inner(), report))
}

/// Messages of the output by topic: (sequence, log_time, publish_time, bytes).
type ByTopic = BTreeMap<String, Vec<(u32, u64, u64, Vec<u8>)>>;

fn by_topic(bytes: &[u8]) -> ByTopic {
    let mut out = ByTopic::new();
    for m in mcap::MessageStream::new(bytes).unwrap() {
        let m = m.unwrap();
        out.entry(m.channel.topic.clone()).or_default().push((
            m.sequence,
            m.log_time,
            m.publish_time,
            m.data.into_owned(),
        ));
    }
    out
}

fn masks(out: &ByTopic) -> Vec<(u64, Vec<u8>)> {
    out[TOPIC_MASK]
        .iter()
        .map(|(_, _, _, d)| {
            let img = fm::RawImage::decode(d.as_slice()).unwrap();
            assert_eq!(img.encoding, "mono8");
            assert_eq!(img.frame_id, FRAME_ID);
            (codec_ns(img.timestamp.as_ref()), img.data.to_vec())
        })
        .collect()
}

fn codec_ns(t: Option<&fm::Timestamp>) -> u64 {
    occmask::mcap_io::codec::timestamp_ns(t)
}

fn poses(out: &ByTopic) -> Vec<(u64, [f64; 7])> {
    out[TOPIC_ODOMETRY]
        .iter()
        .map(|(_, _, _, d)| {
            let p = fm::PoseInFrame::decode(d.as_slice()).unwrap();
            assert_eq!(p.frame_id, "world");
            let pose = p.pose.unwrap();
            let (t, q) = (pose.position.unwrap(), pose.orientation.unwrap());
            (
                codec_ns(p.timestamp.as_ref()),
                [t.x, t.y, t.z, q.x, q.y, q.z, q.w],
            )
        })
        .collect()
}

#[test]
fn every_flavour_gives_identical_masks_and_poses() {
    let dir = tempfile::tempdir().unwrap();
    let spec = FixtureSpec::default();
    let mut results = Vec::new();
    for flavor in ALL_FLAVORS {
        let path = write_input(dir.path(), flavor, &spec);
        let (bytes, report) = run(&path, &ProcessConfig::default()).unwrap();
        assert_eq!(report.frames, spec.frames as u64, "{flavor:?}");
        assert_eq!(
            (report.unpaired_color, report.unpaired_depth),
            (0, 0),
            "{flavor:?}"
        );
        assert_eq!(report.intrinsics, INTRINSICS, "{flavor:?}");
        assert_eq!(report.depth_units_per_meter, DEPTH_UNITS, "{flavor:?}");
        assert_eq!(report.topics.color.topic, COLOR_TOPIC);
        assert_eq!(report.topics.depth.topic, DEPTH_TOPIC);
        let out = by_topic(&bytes);
        let m = masks(&out);
        assert_eq!(m.len(), spec.frames);
        // Stamps are the colour stamps; the moving square is detected from frame 1 on.
        for (i, (t, data)) in m.iter().enumerate() {
            assert_eq!(*t, color_stamp(i));
            let moving = data.iter().filter(|&&v| v == 255).count();
            if i == 0 {
                assert_eq!(moving, 0);
            } else {
                assert!(moving >= 2 * 12, "frame {i}: {moving} moving pixels");
            }
        }
        results.push((flavor, m, poses(&out)));
    }
    for (flavor, m, p) in &results[1..] {
        assert_eq!(m, &results[0].1, "{flavor:?} masks differ from protobuf");
        assert_eq!(p, &results[0].2, "{flavor:?} poses differ from protobuf");
    }
}

#[test]
fn annotated_copy_keeps_every_input_record_byte_identical() {
    let dir = tempfile::tempdir().unwrap();
    for flavor in ALL_FLAVORS {
        let path = write_input(dir.path(), flavor, &FixtureSpec::default());
        let input_bytes = std::fs::read(&path).unwrap();
        let (bytes, report) = run(&path, &ProcessConfig::default()).unwrap();

        // Every input message, with channel ID, sequence, times and bytes, in the output.
        let input_msgs: Vec<_> = mcap::MessageStream::new(&input_bytes)
            .unwrap()
            .map(|m| m.unwrap())
            .collect();
        let output_msgs: Vec<_> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| m.unwrap())
            .collect();
        let key = |m: &mcap::Message| {
            (
                m.channel.id,
                m.channel.topic.clone(),
                m.sequence,
                m.log_time,
                m.publish_time,
                m.data.to_vec(),
            )
        };
        let out_keys: std::collections::BTreeSet<_> = output_msgs.iter().map(key).collect();
        for m in &input_msgs {
            assert!(
                out_keys.contains(&key(m)),
                "{flavor:?}: {} seq {} missing",
                m.channel.topic,
                m.sequence
            );
        }
        let input_ids: std::collections::BTreeSet<u16> = input_msgs.iter().map(|m| m.channel.id).collect();
        let copied = output_msgs
            .iter()
            .filter(|m| input_ids.contains(&m.channel.id))
            .count();
        assert_eq!(copied, input_msgs.len(), "{flavor:?}: extra or duplicated copies");
        assert_eq!(report.copied_messages, input_msgs.len() as u64);

        // Log times never go backwards (doctor --strict-message-order).
        assert!(
            output_msgs.windows(2).all(|w| w[0].log_time <= w[1].log_time),
            "{flavor:?}"
        );

        // Schemas and channels keep their IDs and content; header profile kept.
        let si = mcap::Summary::read(&input_bytes).unwrap().unwrap();
        let so = mcap::Summary::read(&bytes).unwrap().unwrap();
        for (id, c) in &si.channels {
            let o = &so.channels[id];
            assert_eq!(
                (&o.topic, &o.message_encoding, &o.metadata),
                (&c.topic, &c.message_encoding, &c.metadata)
            );
            assert_eq!(
                o.schema.as_ref().map(|s| (s.id, s.name.clone(), s.data.to_vec())),
                c.schema.as_ref().map(|s| (s.id, s.name.clone(), s.data.to_vec()))
            );
        }
        // Metadata and attachments copied (plus our own metadata record).
        let names: Vec<_> = so.metadata_indexes.iter().map(|i| i.name.clone()).collect();
        assert!(names.contains(&"recording".to_owned()) && names.contains(&"occmask.process".to_owned()));
        let att = mcap::read::attachment(&bytes, &so.attachment_indexes[0]).unwrap();
        assert_eq!(
            (
                att.name.as_str(),
                att.media_type.as_str(),
                att.create_time,
                &att.data[..]
            ),
            ("calib.yaml", "application/yaml", 7, &b"fx: 50\n"[..])
        );
        let profile: &[u8] = match flavor {
            Flavor::Ros2 => b"ros2",
            Flavor::Ros1 => b"ros1",
            _ => b"",
        };
        if !profile.is_empty() {
            let header = &bytes[8..];
            assert!(
                header.windows(4).take(64).any(|w| w == profile),
                "{flavor:?} profile not kept"
            );
        }

        // The new channels, one message per frame (path throttled to 1 Hz of data time).
        let out = by_topic(&bytes);
        for topic in [
            TOPIC_MASK,
            TOPIC_MASK_ANNOTATIONS,
            TOPIC_ODOMETRY,
            "/tf",
            TOPIC_STATS,
        ] {
            assert_eq!(out[topic].len(), 12, "{flavor:?} {topic}");
        }
        assert_eq!(
            out[TOPIC_PATH].len(),
            2,
            "12 frames span 0.37 s: the path at the first frame and at the last"
        );
        assert!(!out.contains_key(TOPIC_ACCUMULATION));
        assert!(!out.contains_key(TOPIC_TF_FALLBACK));
        let tf = fm::FrameTransform::decode(out["/tf"][3].3.as_slice()).unwrap();
        assert_eq!(
            (tf.parent_frame_id.as_str(), tf.child_frame_id.as_str()),
            ("world", FRAME_CAMERA_ESTIMATED)
        );
        let stats: serde_json::Value = serde_json::from_slice(&out[TOPIC_STATS][2].3).unwrap();
        assert_eq!(stats["frame_index"], 2);
        assert_eq!(stats["pose_source"], "dvo");
        assert_eq!(stats["timestamp"]["nsec"], color_stamp(2) % 1_000_000_000);
        let ann = fm::ImageAnnotations::decode(out[TOPIC_MASK_ANNOTATIONS][5].3.as_slice()).unwrap();
        assert!(!ann.points.is_empty(), "frame 5 has a moving region");
        assert!(ann.points[0].fill_color.as_ref().unwrap().a < 1.0);
        assert_eq!(codec_ns(ann.timestamp.as_ref()), color_stamp(5));
    }
}

#[test]
fn sidecar_has_only_new_channels_and_accumulation_is_opt_in() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_input(dir.path(), Flavor::Ros2, &FixtureSpec::default());
    let config = ProcessConfig {
        annotate: AnnotateOptions {
            copy_input: false,
            accumulation: true,
            ..Default::default()
        },
        ..Default::default()
    };
    let (bytes, report) = run(&path, &config).unwrap();
    assert_eq!(report.copied_messages, 0);
    let out = by_topic(&bytes);
    let topics: Vec<&str> = out.keys().map(String::as_str).collect();
    // The ROS input has no /tf, so ours is /tf.
    assert_eq!(
        topics,
        vec![
            TOPIC_ACCUMULATION,
            TOPIC_ANCHOR_PATH,
            TOPIC_MASK,
            TOPIC_MASK_ANNOTATIONS,
            TOPIC_ODOMETRY,
            TOPIC_PATH,
            TOPIC_STATS,
            "/tf"
        ]
    );
    let acc = fm::RawImage::decode(out[TOPIC_ACCUMULATION][0].3.as_slice()).unwrap();
    assert_eq!(
        (acc.encoding.as_str(), acc.step, acc.data.len()),
        ("32FC1", 64 * 4, 64 * 48 * 4)
    );
}

/// `--points`: absent by default; with it, one `foxglove.PointCloud` per frame in the estimated
/// camera's frame, every 4th pixel per axis with depth, in the colour image's colours, the
/// moving pixels tinted; nothing else in the output changes.
#[test]
fn point_clouds_are_opt_in_sampled_coloured_and_tinted_where_moving() {
    use occmask::point_cloud::{tint, POINT_STRIDE_BYTES};
    let dir = tempfile::tempdir().unwrap();
    let spec = FixtureSpec::default();
    let stride = 4;
    for flavor in ALL_FLAVORS {
        let path = write_input(dir.path(), flavor, &spec);
        let (plain, _) = run(&path, &ProcessConfig::default()).unwrap();
        let plain = by_topic(&plain);
        assert!(!plain.contains_key(TOPIC_POINTS), "{flavor:?}");
        let config = ProcessConfig {
            annotate: AnnotateOptions {
                points_stride_px: Some(stride),
                ..Default::default()
            },
            ..Default::default()
        };
        let (bytes, report) = run(&path, &config).unwrap();
        let out = by_topic(&bytes);
        // Masks, poses and stats are those of the run without points.
        for topic in [TOPIC_MASK, TOPIC_ODOMETRY, TOPIC_STATS] {
            assert_eq!(out[topic], plain[topic], "{flavor:?} {topic}");
        }
        let clouds = &out[TOPIC_POINTS];
        assert_eq!(clouds.len() as u64, report.frames, "{flavor:?}");
        let k = report.intrinsics;
        let mut tinted = 0;
        for (i, ((_, log_time, _, data), mask)) in clouds.iter().zip(masks(&out)).enumerate() {
            let cloud = fm::PointCloud::decode(data.as_slice()).unwrap();
            let mask_msg = fm::RawImage::decode(out[TOPIC_MASK][i].3.as_slice()).unwrap();
            assert_eq!(*log_time, out[TOPIC_MASK][i].1);
            assert_eq!(cloud.timestamp, mask_msg.timestamp);
            assert_eq!(cloud.frame_id, FRAME_CAMERA_ESTIMATED);
            assert_eq!(cloud.point_stride as usize, POINT_STRIDE_BYTES);
            let fields: Vec<(&str, u32, i32)> = cloud
                .fields
                .iter()
                .map(|f| (f.name.as_str(), f.offset, f.r#type))
                .collect();
            assert_eq!(
                fields,
                [
                    ("x", 0, 7),
                    ("y", 4, 7),
                    ("z", 8, 7),
                    ("red", 12, 1),
                    ("green", 13, 1),
                    ("blue", 14, 1),
                    ("alpha", 15, 1)
                ]
            );
            // Every 4th pixel per axis (16 × 12) but the depth hole in column 0.
            let expected_points = (spec.size.width / stride - 1) * (spec.size.height / stride);
            assert_eq!(
                cloud.data.len(),
                expected_points * POINT_STRIDE_BYTES,
                "{flavor:?} frame {i}"
            );
            for p in cloud.data.chunks_exact(POINT_STRIDE_BYTES) {
                let f = |o: usize| f64::from(f32::from_le_bytes(p[o..o + 4].try_into().unwrap()));
                let (x, y, z) = (f(0), f(4), f(8));
                let u = (x / z * k.fx + k.cx).round() as usize;
                let v = (y / z * k.fy + k.cy).round() as usize;
                assert!(
                    u.is_multiple_of(stride) && v.is_multiple_of(stride) && u > 0,
                    "({u}, {v})"
                );
                assert!((z - f64::from(depth_mm(i, u, v)) / DEPTH_UNITS).abs() < 1e-6);
                let moving = mask.1[v * spec.size.width + u] == 255;
                let color = rgb_pixel(i, u, v);
                let expected = if moving { tint(color) } else { color };
                assert_eq!(
                    &p[12..16],
                    &[expected[0], expected[1], expected[2], 255],
                    "{flavor:?} ({u}, {v})"
                );
                tinted += usize::from(moving);
            }
        }
        // The moving square was sampled and tinted (not vacuously: it is masked in most frames).
        assert!(tinted >= 10, "{flavor:?}: {tinted} tinted points");
    }
}

#[test]
fn linear_fallback_matches_indexed_reading() {
    let dir = tempfile::tempdir().unwrap();
    let indexed = write_input(dir.path(), Flavor::Protobuf, &FixtureSpec::default());
    let linear_path = dir.path().join("linear.mcap");
    let spec = FixtureSpec {
        indexed: false,
        ..Default::default()
    };
    std::fs::write(&linear_path, fixture_bytes(Flavor::Protobuf, &spec)).unwrap();
    assert!(McapInput::open(&indexed).unwrap().is_indexed());
    assert!(!McapInput::open(&linear_path).unwrap().is_indexed());
    let (a, _) = run(&indexed, &ProcessConfig::default()).unwrap();
    let (b, report) = run(&linear_path, &ProcessConfig::default()).unwrap();
    assert_eq!(report.frames, 12);
    let (a, b) = (by_topic(&a), by_topic(&b));
    assert_eq!(masks(&a), masks(&b));
    assert_eq!(poses(&a), poses(&b));
    assert_eq!(a["/diagnostics"], b["/diagnostics"]);
}

#[test]
fn output_bytes_are_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_input(dir.path(), Flavor::Json, &FixtureSpec::default());
    let (a, _) = run(&path, &ProcessConfig::default()).unwrap();
    let (b, _) = run(&path, &ProcessConfig::default()).unwrap();
    assert!(a == b, "two runs differ");
}

#[test]
fn external_poses_are_interpolated_to_frame_times() {
    let dir = tempfile::tempdir().unwrap();
    for flavor in ALL_FLAVORS {
        let path = write_input(dir.path(), flavor, &FixtureSpec::default());
        let config = ProcessConfig {
            processor: occmask::pipeline::ProcessorConfig {
                pose_source: occmask::pipeline::PoseSource::External {
                    camera_from_marker: None,
                },
                ..Default::default()
            },
            topics: occmask::mcap_io::input::detect::TopicOverrides {
                pose: Some(GT_TOPIC.into()),
                ..Default::default()
            },
            start_offset_ns: Some(FRAME_NS), // skip frame 0
            ..Default::default()
        };
        let (bytes, report) = run(&path, &config).unwrap();
        assert_eq!(report.frames, 11, "{flavor:?}");
        assert_eq!(report.outside_time_range, 1);
        for (k, (t, p)) in poses(&by_topic(&bytes)).iter().enumerate() {
            let i = k + 1;
            assert_eq!(*t, color_stamp(i));
            let gt = gt_pose(i);
            let q = gt.rotation;
            let want = [
                gt.translation.x,
                gt.translation.y,
                gt.translation.z,
                q.i,
                q.j,
                q.k,
                q.w,
            ];
            for (a, b) in p.iter().zip(want) {
                assert!((a - b).abs() < 1e-12, "{flavor:?} frame {i}: {p:?} vs {want:?}");
            }
        }
    }
}

#[test]
fn unpaired_frames_are_counted() {
    let dir = tempfile::tempdir().unwrap();
    // Depth 25 ms after colour: beyond the 20 ms tolerance... but within a frame, so each
    // depth is nearest to the next colour (8.3 ms before it).
    let spec = FixtureSpec {
        depth_lag_ns: 25_000_000,
        ..Default::default()
    };
    let path = write_input(dir.path(), Flavor::Protobuf, &spec);
    let (_, report) = run(&path, &ProcessConfig::default()).unwrap();
    assert_eq!(report.frames, 11);
    assert_eq!((report.unpaired_color, report.unpaired_depth), (1, 1));
}

#[test]
fn errors_name_what_to_fix() {
    let dir = tempfile::tempdir().unwrap();
    // Unsupported colour encoding: named, with the supported list.
    let spec = FixtureSpec {
        ros_color_encoding: "nv12",
        ..Default::default()
    };
    let path = write_input(dir.path(), Flavor::Ros2, &spec);
    let err = run(&path, &ProcessConfig::default()).unwrap_err();
    assert!(
        matches!(&err, occmask::Error::Decode {
            topic,
            at: Some(_),
            problem: DecodeProblem::UnsupportedEncoding { image: ImageKind::Color, found, supported },
        } if topic == COLOR_TOPIC && found == "nv12" && supported.contains("bgr8")),
        "{err}"
    );

    // Missing calibration: names the colour topic (the CLI adds --camera).
    let spec = FixtureSpec {
        with_calibration: false,
        ..Default::default()
    };
    let path = write_input(dir.path(), Flavor::Protobuf, &spec);
    let err = run(&path, &ProcessConfig::default()).unwrap_err();
    assert!(
        matches!(&err, occmask::Error::MissingCalibration { color_topic, .. } if color_topic == COLOR_TOPIC),
        "{err}"
    );
    let config = ProcessConfig {
        intrinsics: Some(INTRINSICS),
        ..Default::default()
    };
    assert_eq!(run(&path, &config).unwrap().1.frames, 12);

    // No RGB-D channels: lists topics and schemas.
    let other = dir.path().join("other.mcap");
    let mut w = mcap::Writer::new(std::io::BufWriter::new(std::fs::File::create(&other).unwrap())).unwrap();
    let ch = w.add_channel(0, "/chatter", "json", &BTreeMap::new()).unwrap();
    w.write_to_known_channel(
        &mcap::records::MessageHeader {
            channel_id: ch,
            sequence: 0,
            log_time: 1,
            publish_time: 1,
        },
        b"{}",
    )
    .unwrap();
    w.finish().unwrap();
    drop(w);
    let err = run(&other, &ProcessConfig::default()).unwrap_err();
    assert!(
        matches!(&err, occmask::Error::NoTopic { role: TopicRole::Color, channels, .. } if channels.contains("/chatter (no schema, json)")),
        "{err}"
    );

    // A topic that does not exist.
    let path = write_input(dir.path(), Flavor::Json, &FixtureSpec::default());
    let config = ProcessConfig {
        topics: occmask::mcap_io::input::detect::TopicOverrides {
            depth: Some("/nope".into()),
            ..Default::default()
        },
        ..Default::default()
    };
    let err = run(&path, &config).unwrap_err();
    assert!(
        matches!(&err, occmask::Error::UnknownTopic { role: TopicRole::Depth, topic, channels, .. } if topic == "/nope" && channels.contains(DEPTH_TOPIC)),
        "{err}"
    );

    // Calibration for another image size.
    let config = ProcessConfig {
        topics: occmask::mcap_io::input::detect::TopicOverrides {
            rgb: Some(COLOR_TOPIC.into()),
            ..Default::default()
        },
        ..Default::default()
    };
    let spec = FixtureSpec {
        size: occmask::image_buf::ImageSize::new(32, 48),
        ..Default::default()
    };
    let small = dir.path().join("small.mcap");
    std::fs::write(&small, fixture_bytes(Flavor::Protobuf, &spec)).unwrap();
    assert!(run(&small, &config).is_ok(), "consistent small fixture");

    // Not an MCAP file.
    let junk = dir.path().join("junk.mcap");
    std::fs::write(&junk, b"hello world, definitely not mcap").unwrap();
    let err = run(&junk, &ProcessConfig::default()).unwrap_err();
    assert!(
        matches!(
            &err,
            occmask::Error::BadMcap {
                problem: McapProblem::NoMagic,
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn truncated_recording_is_read_up_to_its_last_complete_record() {
    let dir = tempfile::tempdir().unwrap();
    let full = fixture_bytes(Flavor::Protobuf, &FixtureSpec::default());
    let path = dir.path().join("cut.mcap");
    // A recorder killed mid-write: no summary, no footer, the last chunk incomplete.
    std::fs::write(&path, &full[..full.len() * 7 / 10]).unwrap();
    let input = McapInput::open(&path).unwrap();
    assert!(!input.is_indexed());
    assert!(input.is_truncated());
    let (bytes, report) = run(&path, &ProcessConfig::default()).unwrap();
    assert!(report.input_truncated);
    assert!(report.frames >= 3 && report.frames < 12, "{}", report.frames);
    // Every message that was readable is in the output, unchanged.
    let mut readable = 0;
    input
        .for_each_message(None, None, |m| {
            readable += 1;
            let _ = m;
            Ok(true)
        })
        .unwrap();
    assert_eq!(report.copied_messages, readable);
    assert!(
        mcap::Summary::read(&bytes).unwrap().is_some(),
        "the output is a complete file"
    );
}

/// A sink that fails like a full disk once `limit` bytes are written.
struct FullDisk {
    inner: Cursor<Vec<u8>>,
    limit: usize,
}

impl std::io::Write for FullDisk {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.inner.get_ref().len() + buf.len() > self.limit {
            return Err(std::io::Error::other("no space left on device (test)"));
        }
        self.inner.write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl std::io::Seek for FullDisk {
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        self.inner.seek(pos)
    }
}

#[test]
fn a_write_error_on_the_writer_thread_is_the_error_reported() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_input(dir.path(), Flavor::Protobuf, &FixtureSpec::default());
    let mut config = ProcessConfig::default();
    // Small chunks, so chunks are flushed (and fail) on the writer thread, mid-stream.
    config.annotate.write.chunk_size_bytes = 4096;
    let (full, _) = run(&path, &config).unwrap();
    let input = McapInput::open(&path).unwrap();
    let sink = FullDisk {
        inner: Cursor::new(Vec::new()),
        limit: full.len() / 2,
    };
    let err = process_file(&input, sink, &config, &mut test_factory, &mut NoHooks)
        .err()
        .expect("a full disk must fail the run");
    // The whole chain, as the CLI prints it (`{:#}`).
    let mut chain = err.to_string();
    let mut source = std::error::Error::source(&err);
    while let Some(s) = source {
        chain.push_str(&format!(": {s}"));
        source = s.source();
    }
    assert!(chain.contains("no space left on device"), "{chain}");
    assert!(!chain.contains("writer stopped"), "{chain}");
}

// ---- Depth from another camera, lens distortion (synthetic recordings as drivers write them)

mod geometry {
    use std::io::BufWriter;
    use std::ops::ControlFlow;
    use std::path::{Path, PathBuf};
    use std::sync::{Arc, Mutex};

    use foxglove::messages as fm;
    use occmask::convert::{rig_names, write_synthetic_rig_recording};
    use occmask::geometry::distortion::CameraModel;
    use occmask::image_buf::{DepthMeters, GrayF32, ImageSize, Mask, MASK_SET};
    use occmask::mcap_io::input::McapInput;
    use occmask::mcap_io::ros_out::RosVersion;
    use occmask::mcap_io::McapWriteOptions;
    use occmask::pipeline::{FrameInput, FrameResult, FrameStats, PoseOutcome};
    use occmask::process::rectify::GeometryOptions;
    use occmask::process::{process_file, FrameProcessor, NoHooks, ProcessConfig, ProcessReport};
    use occmask::synthetic::{
        DepthSensorModel, RgbdRig, Scenario, SequenceConfig, SyntheticFrame, SyntheticSequence,
    };

    /// 160×120, ideal depth and noise-free colour, so the images the pipeline receives can be
    /// compared with a direct rendering through the undistorted colour camera.
    fn config() -> SequenceConfig {
        SequenceConfig {
            size: ImageSize::new(160, 120),
            sensor: DepthSensorModel::ideal(),
            rgb_noise_levels: 0.0,
            frame_count: Some(3),
            ..SequenceConfig::default()
        }
    }

    fn recording(dir: &Path, name: &str, rig: &RgbdRig, version: RosVersion) -> PathBuf {
        let sequence = SyntheticSequence::new(Scenario::TwoObjectsCrossing, config());
        let path = dir.join(name);
        let file = BufWriter::new(std::fs::File::create(&path).unwrap());
        write_synthetic_rig_recording(
            &sequence,
            rig,
            version,
            file,
            &McapWriteOptions::default(),
            &mut |_| ControlFlow::Continue(()),
        )
        .unwrap();
        path
    }

    /// A copy of `path` without the channels `drop` names.
    fn without(dir: &Path, path: &Path, drop: &[&str]) -> PathBuf {
        let bytes = std::fs::read(path).unwrap();
        let out = dir.join(format!("without-{}.mcap", drop.len()));
        let mut w = mcap::WriteOptions::new()
            .profile("ros2")
            .create(BufWriter::new(std::fs::File::create(&out).unwrap()))
            .unwrap();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            if !drop.contains(&m.channel.topic.as_str()) {
                w.write(&m).unwrap();
            }
        }
        w.finish().unwrap();
        out
    }

    /// A copy of `path` with the data of every message on `topic` replaced by `data`.
    fn replacing(dir: &Path, path: &Path, topic: &str, data: &[u8], name: &str) -> PathBuf {
        let bytes = std::fs::read(path).unwrap();
        let out = dir.join(name);
        let mut w = mcap::WriteOptions::new()
            .profile("ros2")
            .create(BufWriter::new(std::fs::File::create(&out).unwrap()))
            .unwrap();
        for mut m in mcap::MessageStream::new(&bytes).unwrap().map(Result::unwrap) {
            if m.channel.topic == topic {
                m.data = std::borrow::Cow::Owned(data.to_vec());
            }
            w.write(&m).unwrap();
        }
        w.finish().unwrap();
        out
    }

    /// A transform channel that does not link the two cameras, or that does not decode, is an
    /// error naming the frames looked for and what was found; never a silent identity.
    #[test]
    fn broken_or_undecodable_transforms_are_errors_naming_the_frames() {
        use occmask::mcap_io::ros_out::{encode_transforms, RosTransform};
        let dir = tempfile::tempdir().unwrap();
        let rig = RgbdRig::realsense_like(&config());
        let path = recording(dir.path(), "rs.mcap", &rig, RosVersion::Ros2);
        // The chain stops at camera_link: nothing reaches the depth camera.
        let stump = encode_transforms(
            RosVersion::Ros2,
            0,
            &[RosTransform {
                parent: "camera_link",
                child: rig_names::COLOR_FRAME,
                parent_from_child: nalgebra::Isometry3::identity(),
            }],
        )
        .unwrap();
        let broken = replacing(dir.path(), &path, rig_names::TF_STATIC, &stump, "broken.mcap");
        let err = run(&broken, &ProcessConfig::default()).unwrap_err();
        assert!(matches!(err, occmask::Error::MissingTransform { .. }), "{err}");
        let err = err.to_string();
        assert!(
            err.contains(rig_names::DEPTH_FRAME)
                && err.contains(rig_names::COLOR_FRAME)
                && err.contains(&format!("searched {}", rig_names::TF_STATIC))
                && err.contains("camera_link"),
            "{err}"
        );
        // Bytes that are no TFMessage: the decode error names the channel.
        let garbage = replacing(
            dir.path(),
            &path,
            rig_names::TF_STATIC,
            &[0, 1, 0, 0, 7],
            "garbage.mcap",
        );
        let err = run(&garbage, &ProcessConfig::default()).unwrap_err();
        assert!(
            matches!(&err, occmask::Error::Decode { topic, problem: occmask::error::DecodeProblem::Malformed { .. }, .. }
                if topic == rig_names::TF_STATIC),
            "{err}"
        );
    }

    /// What the pipeline was given for one frame.
    type Frame = (GrayF32, DepthMeters);
    type Seen = Arc<Mutex<Vec<Frame>>>;

    /// Records what the pipeline is given; its mask marks the right quarter of the pipeline's
    /// (undistorted) image, so the published mask shows whether it was mapped back.
    struct Capture(Seen);

    impl FrameProcessor for Capture {
        fn push(&mut self, frame: &FrameInput<'_>) -> occmask::Result<Vec<FrameResult>> {
            self.0
                .lock()
                .unwrap()
                .push((frame.gray.clone(), frame.depth_m.clone()));
            let size = frame.gray.size();
            Ok(vec![FrameResult {
                mask: Mask::from_fn(size, |x, _| if x >= size.width * 3 / 4 { MASK_SET } else { 0 }),
                world_from_camera: nalgebra::Isometry3::identity(),
                accumulation_m: None,
                stats: FrameStats {
                    outcome: PoseOutcome::Tracked,
                    ..FrameStats::default()
                },
            }])
        }
    }

    fn run(path: &Path, config: &ProcessConfig) -> occmask::Result<(Vec<Frame>, ProcessReport, Vec<u8>)> {
        let input = McapInput::open(path)?;
        let seen: Seen = Arc::default();
        let capture = Arc::clone(&seen);
        let mut factory =
            move |_, _, _: &_| Ok(Box::new(Capture(Arc::clone(&capture))) as Box<dyn FrameProcessor>);
        let (out, report) = process_file(
            &input,
            std::io::Cursor::new(Vec::new()),
            config,
            &mut factory,
            &mut NoHooks,
        )?;
        let frames = seen.lock().unwrap().clone();
        Ok((frames, report, out.into_inner()))
    }

    /// Frame 0 as the pipeline should see it: rendered directly through the pinhole camera
    /// the colour camera is undistorted into (colour, and the true depth along its rays).
    fn pinhole_truth(rig: &RgbdRig) -> SyntheticFrame {
        let sequence = SyntheticSequence::new(Scenario::TwoObjectsCrossing, config());
        let mut frame = SyntheticFrame::empty(rig.color.size);
        let pinhole = occmask::registration::inscribed_pinhole(&rig.color);
        sequence.render_camera_into(0, 0.0, &sequence.world_from_camera(0), &pinhole, true, &mut frame);
        frame
    }

    /// Of the pixels the published colour image sees (pinhole pixels whose distorted position
    /// lies in the image): the fraction whose depth is a true depth of its 3×3 neighbourhood
    /// (within 0.5 %: nearest-pixel resampling and splatting move a value by up to a pixel,
    /// but never invent one), and the fraction with any depth.
    fn depth_agreement(rig: &RgbdRig, depth: &DepthMeters, truth: &DepthMeters) -> (f64, f64) {
        let size = truth.size();
        let pinhole = occmask::registration::inscribed_pinhole(&rig.color);
        let (mut seen, mut good, mut valid) = (0.0, 0.0, 0.0);
        for y in 0..size.height {
            for x in 0..size.width {
                let (rx, ry) = pinhole.ray(x as f64, y as f64).unwrap();
                let (u, v) = rig.color.pixel(rx, ry);
                let inside =
                    u >= -0.5 && v >= -0.5 && u <= size.width as f64 - 0.5 && v <= size.height as f64 - 0.5;
                if !inside {
                    continue;
                }
                seen += 1.0;
                let d = depth.get(x, y);
                if d <= 0.0 {
                    continue;
                }
                valid += 1.0;
                let (mut lo, mut hi) = (f32::INFINITY, 0.0f32);
                for ny in y.saturating_sub(1)..(y + 2).min(size.height) {
                    for nx in x.saturating_sub(1)..(x + 2).min(size.width) {
                        lo = lo.min(truth.get(nx, ny));
                        hi = hi.max(truth.get(nx, ny));
                    }
                }
                if d >= lo * 0.995 && d <= hi * 1.005 {
                    good += 1.0;
                }
            }
        }
        (good / seen, valid / seen)
    }

    fn mean_abs_difference(a: &GrayF32, b: &GrayF32) -> f64 {
        let sum: f64 = a
            .as_slice()
            .iter()
            .zip(b.as_slice())
            .map(|(x, y)| f64::from((x - y).abs()))
            .sum();
        sum / a.size().area() as f64
    }

    fn metadata(bytes: &[u8]) -> std::collections::BTreeMap<String, String> {
        let summary = mcap::Summary::read(bytes).unwrap().unwrap();
        summary
            .metadata_indexes
            .iter()
            .map(|i| mcap::read::metadata(bytes, i).unwrap())
            .find(|m| m.name == "occmask.process")
            .unwrap()
            .metadata
    }

    #[test]
    fn depth_from_another_camera_is_registered_and_colour_undistorted() {
        let dir = tempfile::tempdir().unwrap();
        let rig = RgbdRig::realsense_like(&config());
        let truth = pinhole_truth(&rig);
        let sequence = SyntheticSequence::new(Scenario::TwoObjectsCrossing, config());
        let mut distorted = SyntheticFrame::empty(rig.color.size);
        sequence.render_camera_into(
            0,
            0.0,
            &sequence.world_from_camera(0),
            &rig.color,
            true,
            &mut distorted,
        );
        for version in [RosVersion::Ros2, RosVersion::Ros1] {
            let path = recording(dir.path(), &format!("{version:?}.mcap"), &rig, version);
            let (frames, report, bytes) = run(&path, &ProcessConfig::default()).unwrap();
            assert_eq!(report.frames, 3, "{version:?}");
            let (gray, depth) = &frames[0];
            assert_eq!(depth.size(), rig.color.size);
            // Registered depth is the colour camera's: measured 99.92 % of the pixels hold a
            // true depth of their neighbourhood (the rest are holes at disocclusions).
            let (good, valid) = depth_agreement(&rig, depth, &truth.depth_true_m);
            assert!(
                good > 0.99 && valid > 0.99,
                "{version:?}: {good} good, {valid} valid"
            );
            // The undistorted colour image is the pinhole rendering up to resampling: measured
            // mean |difference| 0.020, against 0.069 for the published (distorted) image.
            let undistorted = mean_abs_difference(gray, &truth.gray);
            let raw = mean_abs_difference(&distorted.gray, &truth.gray);
            assert!(undistorted * 2.0 < raw, "{version:?}: {undistorted} vs {raw}");
            let md = metadata(&bytes);
            assert_eq!(md["depth_registration"], "registered");
            assert!(
                md["color_from_depth_source"].contains(rig_names::TF_STATIC),
                "{md:?}"
            );
            assert!(
                md["color_from_depth_source"].contains(rig_names::DEPTH_FRAME),
                "{md:?}"
            );
            assert!(md["color_distortion"].starts_with("plumb_bob"), "{md:?}");
            assert!(report.geometry.describe().contains("registered"));
        }
    }

    #[test]
    fn masks_are_published_in_the_distorted_pixels() {
        let dir = tempfile::tempdir().unwrap();
        let rig = RgbdRig::realsense_like(&config());
        let path = recording(dir.path(), "rs.mcap", &rig, RosVersion::Ros2);
        let (_, _, bytes) = run(&path, &ProcessConfig::default()).unwrap();
        let mask_msg = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| m.unwrap())
            .find(|m| m.channel.topic == occmask::mcap_io::annotate::TOPIC_MASK)
            .unwrap();
        let raw: fm::RawImage = prost::Message::decode(mask_msg.data.as_ref()).unwrap();
        let size = ImageSize::new(raw.width as usize, raw.height as usize);
        let mask = Mask::from_vec(size, raw.data.to_vec()).unwrap();
        let pinhole = occmask::registration::inscribed_pinhole(&rig.color);
        let quarter = rig.color.size.width * 3 / 4;
        let (mut wrong, mut moved) = (0, 0);
        for y in 0..mask.height() {
            for x in 0..mask.width() {
                // The processor marked pinhole columns ≥ 3/4 of the width; a published pixel is
                // set where its ray lands there.
                let (px, py) = rig
                    .color
                    .ray(x as f64, y as f64)
                    .map(|(rx, ry)| pinhole.pixel(rx, ry))
                    .unwrap();
                // Published pixels beyond the pipeline's (magnified) pinhole image are never set.
                let (w, h) = (mask.width() as f64, mask.height() as f64);
                let seen = px >= -0.5 && py >= -0.5 && px <= w - 0.5 && py <= h - 0.5;
                let expected = seen && px.round() >= quarter as f64;
                if (mask.get(x, y) == MASK_SET) != expected {
                    wrong += 1;
                }
                if (mask.get(x, y) == MASK_SET) != (x >= quarter) {
                    moved += 1;
                }
            }
        }
        assert_eq!(wrong, 0);
        // Distortion bends the boundary away from the pinhole column.
        assert!(moved > 0);
    }

    #[test]
    fn depth_registered_to_distorted_colour_is_undistorted_with_it() {
        // A Kinect-style recording: depth registered to the distorted colour pixels, same
        // frame_id and calibration: aligned, undistorted by the colour's table.
        let dir = tempfile::tempdir().unwrap();
        let color = CameraModel {
            distortion: Some(occmask::synthetic::KINECT_LIKE_DISTORTION),
            ..CameraModel::pinhole(config().size, config().intrinsics())
        };
        let rig = RgbdRig {
            color,
            depth: color,
            color_from_depth: nalgebra::Isometry3::identity(),
        };
        let path = recording(dir.path(), "kinect.mcap", &rig, RosVersion::Ros2);
        let (frames, report, bytes) = run(&path, &ProcessConfig::default()).unwrap();
        let truth = pinhole_truth(&rig);
        // Measured: every seen pixel; without undistortion 90 %.
        let (good, _) = depth_agreement(&rig, &frames[0].1, &truth.depth_true_m);
        assert!(good > 0.99, "{good}");
        let md = metadata(&bytes);
        assert_eq!(md["depth_registration"], "aligned");
        assert_eq!(
            md["depth_registration_reason"],
            "same frame_id, size and calibration as colour"
        );
        assert!(!report.geometry.is_identity());
        // --no-undistort: the images go through unchanged.
        let config = ProcessConfig {
            geometry: GeometryOptions {
                no_undistort: true,
                ..Default::default()
            },
            ..Default::default()
        };
        let (frames, report, _) = run(&path, &config).unwrap();
        assert!(report.geometry.is_identity());
        let (good_raw, _) = depth_agreement(&rig, &frames[0].1, &truth.depth_true_m);
        assert!(good_raw < good - 0.05, "{good_raw} vs {good}");
    }

    #[test]
    fn missing_transforms_and_calibrations_are_errors_naming_the_flag() {
        let dir = tempfile::tempdir().unwrap();
        let rig = RgbdRig::realsense_like(&config());
        let path = recording(dir.path(), "rs.mcap", &rig, RosVersion::Ros2);

        let no_tf = without(dir.path(), &path, &[rig_names::TF_STATIC]);
        let err = run(&no_tf, &ProcessConfig::default()).unwrap_err();
        assert!(matches!(err, occmask::Error::MissingTransform { .. }), "{err}");
        let err = err.to_string();
        assert!(
            err.contains(rig_names::DEPTH_FRAME)
                && err.contains(rig_names::COLOR_FRAME)
                && err.contains("no transform channel"),
            "{err}"
        );
        // The flag supplies the transform.
        let config = ProcessConfig {
            geometry: GeometryOptions {
                color_from_depth: Some(rig.color_from_depth),
                ..Default::default()
            },
            ..Default::default()
        };
        let (frames, _, bytes) = run(&no_tf, &config).unwrap();
        assert_eq!(metadata(&bytes)["color_from_depth_source"], "--depth-to-color");
        let (good, _) = depth_agreement(&rig, &frames[0].1, &pinhole_truth(&rig).depth_true_m);
        assert!(good > 0.99, "{good}");

        let no_depth_info = without(dir.path(), &path, &[rig_names::DEPTH_INFO, rig_names::TF_STATIC]);
        let err = run(&no_depth_info, &ProcessConfig::default()).unwrap_err();
        assert!(
            matches!(
                &err,
                occmask::Error::DepthNotRegistered { needed, .. }
                    if **needed == occmask::error::RegistrationNeed::DepthCalibration
            ),
            "{err}"
        );
        let err = err.to_string();
        assert!(
            err.contains(rig_names::DEPTH_IMAGE) && err.contains("212x120"),
            "{err}"
        );

        // --depth-aligned on depth of another size cannot be right.
        let config = ProcessConfig {
            geometry: GeometryOptions {
                depth_aligned: true,
                ..Default::default()
            },
            ..Default::default()
        };
        let err = run(&path, &config).unwrap_err().to_string();
        assert!(
            err.contains("--depth-aligned") && err.contains("212x120"),
            "{err}"
        );
    }
}
