//! Runs the DVO tracker over a TUM RGB-D folder and prints, per consecutive frame pair, the
//! time, the estimated motion, the ground-truth motion and the relative pose error, as CSV
//! (stdout or `--csv FILE`), plus the chained trajectory in TUM format (`--tum FILE`).
//!
//! ```sh
//! cargo run --release --example dvo_tum -- fixtures/tum_fr2_desk_10 --csv /tmp/ours.csv
//! cargo run --release --example dvo_tum -- DIR --finest 0 --profile release --tum /tmp/traj.txt
//! ```
//! Frames are decoded before timing starts; "ms" is the wall time of `DvoTracker::track` (pyramid
//! of the new frame + estimate), on the TUM fr2 intrinsics. The summary line on stderr also
//! gives the process CPU time per pair (all threads), which stays meaningful on a loaded machine.

#[path = "../tests/integration/common/tum.rs"]
mod tum;

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use occmask::dvo::{DvoConfig, DvoTracker};
use occmask::geometry::camera::presets;
use occmask::trajectory::{chain, to_tum_text, StampedPose};

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let mut dir = None;
    let mut csv_path: Option<PathBuf> = None;
    let mut tum_path: Option<PathBuf> = None;
    let mut config = DvoConfig::paper();
    while let Some(a) = args.next() {
        match a.as_str() {
            "--csv" => csv_path = args.next().map(PathBuf::from),
            "--tum" => tum_path = args.next().map(PathBuf::from),
            "--finest" => config.finest_level = args.next().unwrap_or_default().parse()?,
            "--max-iterations" => {
                config.max_iterations_per_level = args.next().unwrap_or_default().parse()?
            }
            "--step-tolerance" => config.step_tolerance = args.next().unwrap_or_default().parse()?,
            "--min-gradient" => config.min_gradient_per_px = args.next().unwrap_or_default().parse()?,
            "--lambda0" => config.lm_lambda_initial = args.next().unwrap_or_default().parse()?,
            "--init-previous" => config.init_from_previous_motion = true,
            "--profile" => {
                let p = args.next().unwrap_or_default();
                let finest = config.finest_level;
                config = match p.as_str() {
                    "paper" => DvoConfig::paper(),
                    "release" => DvoConfig::release(),
                    other => anyhow::bail!("--profile expects paper or release, found {other:?}"),
                };
                config.finest_level = finest;
            }
            _ if dir.is_none() => dir = Some(PathBuf::from(a)),
            other => anyhow::bail!("unexpected argument {other:?}"),
        }
    }
    let dir = dir.ok_or_else(|| {
        anyhow::anyhow!("usage: dvo_tum DIR [--csv F] [--tum F] [--finest N] [--profile paper|release]")
    })?;
    let sequence = tum::TumSequence::load(&dir)?;
    let gt = sequence.groundtruth();
    let frames = (0..sequence.pairs.len())
        .map(|i| sequence.frame(i))
        .collect::<Result<Vec<_>, _>>()?;
    let size = frames
        .first()
        .map(|f| f.gray.size())
        .ok_or_else(|| anyhow::anyhow!("no frames"))?;
    let mut tracker = DvoTracker::new(size, presets::TUM_FR2, config)?;
    let mut csv = String::from(
        "pair,t_ref_ns,t_cur_ns,ms,status,iterations,pixels_used,est_tx,est_ty,est_tz,est_qx,est_qy,est_qz,est_qw,\
         gt_tx,gt_ty,gt_tz,gt_qx,gt_qy,gt_qz,gt_qw,err_trans_mm,err_rot_deg\n",
    );
    let mut poses = vec![StampedPose {
        timestamp_ns: frames[0].timestamp_ns,
        world_from_camera: nalgebra::Isometry3::identity(),
    }];
    let (mut errs_t, mut errs_r, mut times) = (Vec::new(), Vec::new(), Vec::new());
    let cpu_start = process_cpu_s();
    for (i, frame) in frames.iter().enumerate() {
        let start = Instant::now();
        let est = tracker.track(&frame.gray, &frame.depth_m, None, None)?;
        let ms = start.elapsed().as_secs_f64() * 1e3;
        let Some(est) = est else { continue };
        times.push(ms);
        if std::env::var_os("DVO_DEBUG").is_some() {
            eprintln!(
                "pair {} iters {:?} stops {:?}",
                i - 1,
                est.iterations_per_level,
                est.stop_per_level
            );
        }
        let (t_ref, t_cur) = (frames[i - 1].timestamp_ns, frames[i].timestamp_ns);
        let last = poses[poses.len() - 1].world_from_camera;
        poses.push(StampedPose {
            timestamp_ns: t_cur,
            world_from_camera: chain(&last, &est.current_from_reference),
        });
        let m = est.current_from_reference;
        let q = m.rotation;
        let status = if est.is_converged() {
            "converged".to_string()
        } else {
            format!("{:?}", est.status).replace(',', ";")
        };
        write!(
            csv,
            "{},{t_ref},{t_cur},{ms:.3},{status},{},{},{:.9},{:.9},{:.9},{:.9},{:.9},{:.9},{:.9}",
            i - 1,
            est.total_iterations(),
            est.pixels_used,
            m.translation.x,
            m.translation.y,
            m.translation.z,
            q.i,
            q.j,
            q.k,
            q.w
        )?;
        match tum::gt_motion(gt, t_ref, t_cur) {
            Some(g) => {
                let (et, er) = tum::rpe(&m, &g);
                errs_t.push(et);
                errs_r.push(er);
                let gq = g.rotation;
                writeln!(
                    csv,
                    ",{:.9},{:.9},{:.9},{:.9},{:.9},{:.9},{:.9},{et:.4},{er:.5}",
                    g.translation.x, g.translation.y, g.translation.z, gq.i, gq.j, gq.k, gq.w
                )?;
            }
            None => writeln!(csv, ",,,,,,,,,")?,
        }
    }
    let cpu_ms_per_pair = (process_cpu_s() - cpu_start) * 1e3 / times.len().max(1) as f64;
    match &csv_path {
        Some(p) => std::fs::write(p, &csv)?,
        None => print!("{csv}"),
    }
    if let Some(p) = &tum_path {
        std::fs::write(p, to_tum_text(&poses))?;
    }
    let mean_ms = times.iter().sum::<f64>() / times.len().max(1) as f64;
    eprintln!(
        "pairs {}  RPE RMSE trans {:.2} mm  rot {:.3} deg  mean {:.2} ms/pair wall, {:.2} ms/pair CPU (finest level {})",
        errs_t.len(),
        tum::rms(errs_t.iter().copied()),
        tum::rms(errs_r.iter().copied()),
        mean_ms,
        cpu_ms_per_pair,
        config.finest_level
    );
    Ok(())
}

/// CPU time of this process (all threads) in seconds, from /proc/self/stat (Linux; NaN
/// elsewhere). Unlike wall time it does not grow when other jobs share the machine.
fn process_cpu_s() -> f64 {
    const CLOCK_TICKS_PER_S: f64 = 100.0; // USER_HZ on Linux
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return f64::NAN;
    };
    // Fields after the ")" that closes the command name: utime is the 12th, stime the 13th.
    let fields: Vec<&str> = stat.rsplit(')').next().unwrap_or("").split_whitespace().collect();
    let tick = |i: usize| {
        fields
            .get(i)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(f64::NAN)
    };
    (tick(11) + tick(12)) / CLOCK_TICKS_PER_S
}
