//! The Foxglove layout in the repository: valid JSON, every panel of the tree configured, and
//! every topic it shows is one that `convert` or `process` writes; and `process` outputs that
//! Foxglove's MCAP reader opens with the right timeline.
//!
//! The deeper check, reading a processed file with Foxglove's own libraries and checking what
//! each panel of the layout needs, is tools/foxglove_check (node); screenshots of the layout in
//! Foxglove Studio are in foxglove/screenshots/.

#![allow(clippy::unwrap_used)] // helpers outside #[test] fns: a panic is the failure report

use crate::common::mcap_fixture as process_support;

use std::io::Cursor;

use occmask::mcap_io::annotate::{
    AnnotateOptions, METADATA_PROCESS, TOPIC_ANCHOR_PATH, TOPIC_MASK, TOPIC_MASK_ANNOTATIONS, TOPIC_ODOMETRY,
    TOPIC_PATH, TOPIC_POINTS, TOPIC_STATS,
};
use occmask::mcap_io::input::McapInput;
use occmask::mcap_io::{
    TOPIC_COLOR_CAMERA_INFO, TOPIC_COLOR_IMAGE, TOPIC_DEPTH_CAMERA_INFO, TOPIC_DEPTH_IMAGE,
    TOPIC_GROUNDTRUTH_POSE, TOPIC_TF,
};
use occmask::process::{process_file, NoHooks, ProcessConfig};
use process_support::{fixture_bytes, test_factory, FixtureSpec, ALL_FLAVORS};
use serde_json::Value;

fn panel_ids(node: &Value, out: &mut Vec<String>) {
    match node {
        Value::String(id) => out.push(id.clone()),
        Value::Object(o) => {
            for key in ["first", "second"] {
                panel_ids(&o[key], out);
            }
        }
        other => panic!("unexpected layout node {other}"),
    }
}

#[test]
fn layout_panels_show_topics_we_write() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/foxglove/occmask-layout.json");
    let layout: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let configs = layout["configById"].as_object().unwrap();
    let mut ids = Vec::new();
    panel_ids(&layout["layout"], &mut ids);
    assert_eq!(ids.len(), configs.len());
    for id in &ids {
        assert!(configs.contains_key(id), "{id} has no config");
    }
    let known = [
        TOPIC_COLOR_IMAGE,
        TOPIC_COLOR_CAMERA_INFO,
        TOPIC_DEPTH_IMAGE,
        TOPIC_DEPTH_CAMERA_INFO,
        TOPIC_GROUNDTRUTH_POSE,
        TOPIC_TF,
        TOPIC_MASK,
        TOPIC_MASK_ANNOTATIONS,
        TOPIC_ODOMETRY,
        TOPIC_PATH,
        TOPIC_ANCHOR_PATH,
        TOPIC_POINTS,
        TOPIC_STATS,
    ];
    let mut shown = Vec::new();
    for config in configs.values() {
        if let Some(mode) = config.get("imageMode") {
            for key in ["imageTopic", "calibrationTopic"] {
                if let Some(t) = mode.get(key) {
                    shown.push(t.as_str().unwrap().to_owned());
                }
            }
            if let Some(a) = mode.get("annotations") {
                shown.extend(a.as_object().unwrap().keys().cloned());
            }
        }
        if let Some(topics) = config.get("topics").and_then(Value::as_object) {
            shown.extend(topics.keys().cloned());
        }
        if let Some(paths) = config.get("paths").and_then(Value::as_array) {
            for p in paths {
                let v = p["value"].as_str().unwrap();
                shown.push(v.split('.').next().unwrap().to_owned());
            }
        }
    }
    assert!(shown.len() >= 10, "{shown:?}");
    for topic in &shown {
        assert!(
            known.contains(&topic.as_str()),
            "layout shows unknown topic {topic}"
        );
    }
    // Depth gets a colour map with a range for TUM units (6 m at 5000 units/m: the 99th
    // percentile of valid depth is 5.7 m on tum_fr2_desk_50, 4.6 m in the demo).
    let depth = &configs["Image!occmask-depth"]["imageMode"];
    assert_eq!(depth["colorMap"], "turbo");
    assert_eq!(depth["maxValue"], 30000);
    // The 3D panel shows the points in their own colours (the moving ones tinted) beside both
    // trajectories. The colour field is set too: without one, Foxglove picks the field and the
    // colour mode itself on the first message (Studio 1.48: a colour map of x).
    let scene = &configs["3D!occmask-scene"]["topics"];
    assert_eq!(scene[TOPIC_POINTS]["colorMode"], "rgba-fields");
    assert_eq!(scene[TOPIC_POINTS]["colorField"], "red");
    for topic in [
        TOPIC_PATH,
        TOPIC_ANCHOR_PATH,
        TOPIC_ODOMETRY,
        TOPIC_GROUNDTRUTH_POSE,
    ] {
        assert_eq!(scene[topic]["visible"], true, "{topic}");
    }
}

/// Foxglove and Lichtblick take a file's time range from its chunk indexes (the smallest
/// `message_start_time`, `McapIndexedIterableSource.initialize`), and `@mcap/core` before 2025
/// (Foxglove Studio 1.x, older Lichtblick) throws "Chunks without message indexes are not
/// currently supported" on a chunk without messages. A chunk holding only schemas and channels
/// has times (0, 0): the timeline then starts in 1970 and the file does not play. `process` used
/// to close such chunks by writing metadata before the first message.
#[test]
fn process_outputs_have_no_message_less_chunks_and_start_at_the_first_message() {
    for flavor in ALL_FLAVORS {
        for copy_input in [true, false] {
            let input_bytes = fixture_bytes(flavor, &FixtureSpec::default());
            let dir = tempfile::tempdir().unwrap();
            let input_path = dir.path().join("in.mcap");
            std::fs::write(&input_path, &input_bytes).unwrap();
            let input = McapInput::open(&input_path).unwrap();
            let config = ProcessConfig {
                annotate: AnnotateOptions {
                    copy_input,
                    ..Default::default()
                },
                ..Default::default()
            };
            let (sink, _) = process_file(
                &input,
                Cursor::new(Vec::new()),
                &config,
                &mut test_factory,
                &mut NoHooks,
            )
            .unwrap();
            let out = sink.into_inner();
            let summary = mcap::Summary::read(&out).unwrap().unwrap();
            let stats = summary.stats.as_ref().unwrap();
            let case = format!("{flavor:?}, copy_input {copy_input}");
            assert!(!summary.chunk_indexes.is_empty(), "{case}");
            for chunk in &summary.chunk_indexes {
                assert!(
                    !chunk.message_index_offsets.is_empty() && chunk.message_index_length > 0,
                    "{case}: chunk at {} holds no message",
                    chunk.chunk_start_offset
                );
            }
            let timeline_start = summary.chunk_indexes.iter().map(|c| c.message_start_time).min();
            let timeline_end = summary.chunk_indexes.iter().map(|c| c.message_end_time).max();
            assert_eq!(timeline_start, Some(stats.message_start_time), "{case}");
            assert_eq!(timeline_end, Some(stats.message_end_time), "{case}");
            // The metadata (and, in a copy, the input's attachment) are still all there.
            let names: Vec<&str> = summary.metadata_indexes.iter().map(|i| i.name.as_str()).collect();
            assert!(names.contains(&METADATA_PROCESS), "{case}: {names:?}");
            assert_eq!(names.contains(&"recording"), copy_input, "{case}: {names:?}");
            assert_eq!(
                summary.attachment_indexes.len(),
                usize::from(copy_input),
                "{case}"
            );
        }
    }
}
