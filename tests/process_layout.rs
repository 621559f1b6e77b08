//! The Foxglove layout in the repository: valid JSON, every panel of the tree configured, and
//! every topic it shows is one that `convert` or `process` writes.

#![allow(clippy::unwrap_used)] // helpers outside #[test] fns: a panic is the failure report

use occmask::mcap_io::annotate::{
    TOPIC_MASK, TOPIC_MASK_ANNOTATIONS, TOPIC_ODOMETRY, TOPIC_PATH, TOPIC_STATS,
};
use occmask::mcap_io::{
    TOPIC_COLOR_CAMERA_INFO, TOPIC_COLOR_IMAGE, TOPIC_DEPTH_CAMERA_INFO, TOPIC_DEPTH_IMAGE,
    TOPIC_GROUNDTRUTH_POSE, TOPIC_TF,
};
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
    // Depth gets a colour map with a range for TUM units (4 m at 5000 units/m).
    let depth = &configs["Image!occmask-depth"]["imageMode"];
    assert_eq!(depth["colorMap"], "turbo");
    assert_eq!(depth["maxValue"], 20000);
}
