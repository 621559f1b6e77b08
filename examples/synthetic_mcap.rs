//! Writes synthetic RGB-D scenarios (src/synthetic.rs: exact ground-truth masks and poses) as
//! MCAP files, so `occmask process` + `occmask eval` can be scored on sequences with moving
//! objects and exact ground-truth masks (no real sequence here has them).
//!
//! usage: cargo run --release --example synthetic_mcap -- OUT_DIR [--rig RIG] [--ros1|--ros2]
//!        [--frames N] [--seed N] [--sensor kinect|ideal|unquantised] [SCENARIO...]
//!
//! Without `--rig`, files are `occmask convert`'s layout (Foxglove protobuf, 640×480,
//! registered pinhole). With `--rig`, files are ROS 2 recordings (or ROS 1 with `--ros1`) laid
//! out as the RealSense wrapper publishes them (`convert::rig_names`):
//! - `registered`: one pinhole camera for colour and depth (the reference);
//! - `distorted`: colour with Kinect-class lens distortion, depth registered to those
//!   distorted pixels (as a Kinect's registered depth is);
//! - `realsense`: colour 640×480 with that distortion, depth 848×480 from its own camera
//!   15 mm away, the transform on `/tf_static`;
//! - `realsense-pinhole`: the same with a pinhole colour camera (registration alone);
//! - `reference`: `registered` through the pinhole camera the distorted colour is undistorted
//!   into (`registration::inscribed_pinhole`): what `process` should see of the other rigs.
//!
//! `--sensor`: the depth sensor model (default `kinect`, `synthetic::DepthSensorModel`);
//! `ideal` has no noise and no invalid pixels, `unquantised` the Kinect's noise and invalid
//! pixels without disparity quantisation (which depends on the depth camera's focal length,
//! so two rigs differ in it).
//!
//! Files are OUT_DIR/<scenario>[-<rig>[-ros1]].mcap (default: every scenario).

use std::io::BufWriter;
use std::ops::ControlFlow;

use anyhow::{bail, Context};
use occmask::convert::{write_synthetic_rig_recording, write_synthetic_sequence};
use occmask::geometry::distortion::CameraModel;
use occmask::mcap_io::ros_out::RosVersion;
use occmask::mcap_io::McapWriteOptions;
use occmask::synthetic::{
    DepthSensorModel, RgbdRig, Scenario, SequenceConfig, SyntheticSequence, KINECT_LIKE_DISTORTION,
};

const USAGE: &str = "usage: cargo run --release --example synthetic_mcap -- OUT_DIR [--rig RIG] \
                     [--ros1|--ros2] [--frames N] [--seed N] [--sensor kinect|ideal|unquantised] \
                     [SCENARIO...]";

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let out_dir = match args.next() {
        Some(arg) if arg == "-h" || arg == "--help" => {
            println!("{USAGE}");
            return Ok(());
        }
        Some(arg) if !arg.starts_with('-') => std::path::PathBuf::from(arg),
        _ => bail!("{USAGE}"),
    };
    let (mut rig_name, mut version, mut frames, mut wanted) = (None, RosVersion::Ros2, None, Vec::new());
    let mut sensor = DepthSensorModel::default();
    let mut seed = SequenceConfig::default().seed;
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--rig" => {
                rig_name = Some(
                    args.next()
                        .context("--rig needs registered, distorted or realsense")?,
                )
            }
            "--ros1" => version = RosVersion::Ros1,
            "--ros2" => version = RosVersion::Ros2,
            "--frames" => frames = Some(args.next().context("--frames N")?.parse::<usize>()?),
            "--seed" => seed = args.next().context("--seed N")?.parse::<u64>()?,
            "--sensor" => {
                sensor = match args.next().as_deref() {
                    Some("kinect") => DepthSensorModel::default(),
                    Some("ideal") => DepthSensorModel::ideal(),
                    Some("unquantised") => DepthSensorModel {
                        disparity_step_px: 0.0,
                        ..DepthSensorModel::default()
                    },
                    other => bail!("--sensor kinect|ideal|unquantised, found {other:?}"),
                }
            }
            flag if flag.starts_with('-') => bail!("unknown option {flag:?}; {USAGE}"),
            name => {
                if !Scenario::EVERY.iter().any(|s| s.name() == name) {
                    let names: Vec<&str> = Scenario::EVERY.iter().map(|s| s.name()).collect();
                    bail!("unknown scenario {name:?}: one of {}", names.join(", "));
                }
                wanted.push(arg)
            }
        }
    }
    std::fs::create_dir_all(&out_dir)?;
    let config = SequenceConfig {
        frame_count: frames,
        sensor,
        seed,
        ..SequenceConfig::default()
    };
    let rig = match rig_name.as_deref() {
        None => None,
        Some("registered") => Some(RgbdRig::registered(&config)),
        Some("realsense") => Some(RgbdRig::realsense_like(&config)),
        Some("reference") => {
            let distorted = CameraModel {
                distortion: Some(KINECT_LIKE_DISTORTION),
                ..CameraModel::pinhole(config.size, config.intrinsics())
            };
            let pinhole = occmask::registration::inscribed_pinhole(&distorted);
            Some(RgbdRig {
                color: pinhole,
                depth: pinhole,
                color_from_depth: nalgebra::Isometry3::identity(),
            })
        }
        Some("realsense-pinhole") => Some(RgbdRig {
            color: CameraModel::pinhole(config.size, config.intrinsics()),
            ..RgbdRig::realsense_like(&config)
        }),
        Some("distorted") => {
            let color = CameraModel {
                distortion: Some(KINECT_LIKE_DISTORTION),
                ..CameraModel::pinhole(config.size, config.intrinsics())
            };
            Some(RgbdRig {
                color,
                depth: color,
                color_from_depth: nalgebra::Isometry3::identity(),
            })
        }
        Some(other) => {
            bail!("unknown rig {other:?}: registered, distorted, realsense, realsense-pinhole or reference")
        }
    };
    for scenario in Scenario::EVERY {
        if !wanted.is_empty() && !wanted.iter().any(|w| w == scenario.name()) {
            continue;
        }
        let sequence = SyntheticSequence::new(scenario, config);
        let suffix = match (&rig_name, version) {
            (None, _) => String::new(),
            (Some(r), RosVersion::Ros2) => format!("-{r}"),
            (Some(r), RosVersion::Ros1) => format!("-{r}-ros1"),
        };
        let path = out_dir.join(format!("{}{suffix}.mcap", scenario.name()));
        let file = BufWriter::new(std::fs::File::create(&path)?);
        let mut done = |_| ControlFlow::Continue(());
        match &rig {
            None => drop(write_synthetic_sequence(
                &sequence,
                file,
                &McapWriteOptions::default(),
                &mut done,
            )?),
            Some(rig) => drop(write_synthetic_rig_recording(
                &sequence,
                rig,
                version,
                file,
                &McapWriteOptions::default(),
                &mut done,
            )?),
        }
        println!("{} ({} frames)", path.display(), sequence.len());
    }
    Ok(())
}
