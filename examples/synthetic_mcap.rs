//! Writes synthetic RGB-D scenarios (src/synthetic.rs: exact ground-truth masks and poses) as
//! MCAP files in `occmask convert`'s layout, so `occmask process` + `occmask eval` can be scored
//! on sequences with moving objects (no real one is available; see ../shared/data/INDEX.txt).
//!
//! usage: cargo run --release --example synthetic_mcap -- OUT_DIR [SCENARIO...]
//! (default: every scenario; files are OUT_DIR/<scenario>.mcap, 640×480)

use std::collections::BTreeMap;
use std::io::BufWriter;

use occmask::mcap_io::{
    McapWriteOptions, RgbdMcapWriter, FRAME_CAMERA_GROUNDTRUTH, FRAME_WORLD, TOPIC_COLOR_CAMERA_INFO,
    TOPIC_COLOR_IMAGE, TOPIC_DEPTH_CAMERA_INFO, TOPIC_DEPTH_IMAGE, TOPIC_GROUNDTRUTH_MASK,
    TOPIC_GROUNDTRUTH_POSE,
};
use occmask::synthetic::{Scenario, SequenceConfig, SyntheticSequence, DEPTH_UNITS_PER_M};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out_dir = std::path::PathBuf::from(
        args.first()
            .ok_or_else(|| anyhow::anyhow!("usage: OUT_DIR [SCENARIO...]"))?,
    );
    std::fs::create_dir_all(&out_dir)?;
    let wanted: Vec<&String> = args[1..].iter().collect();
    for scenario in Scenario::ALL {
        if !wanted.is_empty() && !wanted.iter().any(|w| w.as_str() == scenario.name()) {
            continue;
        }
        let config = SequenceConfig::default();
        let sequence = SyntheticSequence::new(scenario, config);
        let path = out_dir.join(format!("{}.mcap", scenario.name()));
        let file = BufWriter::new(std::fs::File::create(&path)?);
        let mut w = RgbdMcapWriter::new(file, &McapWriteOptions::default())?;
        let mut frame = sequence.frame(0);
        for i in 0..sequence.len() {
            sequence.render_into(i, &mut frame);
            let t = frame.timestamp_ns;
            let size = frame.rgb.size();
            w.write_pose(TOPIC_GROUNDTRUTH_POSE, t, &frame.world_from_camera)?;
            w.write_tf(t, FRAME_WORLD, FRAME_CAMERA_GROUNDTRUTH, &frame.world_from_camera)?;
            w.write_color_raw(TOPIC_COLOR_IMAGE, t, &frame.rgb)?;
            w.write_camera_info(TOPIC_COLOR_CAMERA_INFO, t, &frame.intrinsics, size)?;
            w.write_depth_u16(
                TOPIC_DEPTH_IMAGE,
                t,
                frame.depth_raw.as_slice(),
                size,
                f64::from(DEPTH_UNITS_PER_M),
            )?;
            w.write_camera_info(TOPIC_DEPTH_CAMERA_INFO, t, &frame.intrinsics, size)?;
            w.write_mask(TOPIC_GROUNDTRUTH_MASK, t, &frame.gt_mask)?;
        }
        w.write_metadata(
            "occmask.synthetic",
            BTreeMap::from([("scenario".to_owned(), scenario.name().to_owned())]),
        )?;
        w.finish()?;
        println!("{} ({} frames)", path.display(), sequence.len());
    }
    Ok(())
}
