//! `process` on in-memory fixtures of every input flavour: same masks and poses whatever the
//! encoding, annotated copies that keep every input record byte for byte, sidecars, the
//! linear fallback, determinism and the error messages users see.

#![allow(clippy::unwrap_used)] // helpers outside #[test] fns: a panic is the failure report

mod process_support;

use std::collections::BTreeMap;
use std::io::Cursor;
use std::path::Path;

use foxglove::messages as fm;
use prost::Message as _;

use occmask::mcap_io::annotate::{
    AnnotateOptions, FRAME_CAMERA_ESTIMATED, TOPIC_ACCUMULATION, TOPIC_MASK, TOPIC_MASK_ANNOTATIONS,
    TOPIC_ODOMETRY, TOPIC_PATH, TOPIC_STATS, TOPIC_TF_FALLBACK,
};
use occmask::mcap_io::input::McapInput;
use occmask::process::{process_file, NoHooks, PoseMode, ProcessConfig, ProcessReport};
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
        if flavor == Flavor::Ros2 {
            let header = &bytes[8..];
            assert!(
                header.windows(4).take(64).any(|w| w == b"ros2"),
                "ros2 profile not kept"
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
            1,
            "12 frames span 0.37 s: one path message"
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
            pose_mode: PoseMode::External,
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
        ros_color_encoding: "yuv422",
        ..Default::default()
    };
    let path = write_input(dir.path(), Flavor::Ros2, &spec);
    let err = run(&path, &ProcessConfig::default()).unwrap_err().to_string();
    assert!(
        err.contains("yuv422") && err.contains("bgr8") && err.contains(COLOR_TOPIC),
        "{err}"
    );

    // Missing calibration: names --camera.
    let spec = FixtureSpec {
        with_calibration: false,
        ..Default::default()
    };
    let path = write_input(dir.path(), Flavor::Protobuf, &spec);
    let err = run(&path, &ProcessConfig::default()).unwrap_err().to_string();
    assert!(err.contains("--camera") && err.contains(COLOR_TOPIC), "{err}");
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
    let err = run(&other, &ProcessConfig::default()).unwrap_err().to_string();
    assert!(
        err.contains("/chatter (no schema, json)") && err.contains("--rgb-topic"),
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
    let err = run(&path, &config).unwrap_err().to_string();
    assert!(
        err.contains("--depth-topic /nope") && err.contains(DEPTH_TOPIC),
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
    let err = run(&junk, &ProcessConfig::default()).unwrap_err().to_string();
    assert!(err.contains("not an MCAP file"), "{err}");
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
