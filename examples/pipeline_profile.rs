//! Where the closed loop's time goes: the `Processor` (DVO closed loop + detector) on the frames
//! of `benches/pipeline.rs` (synthetic dominant-object sequence, frames 40–70, 640×480), then
//! DVO level by level (points, LM iterations, stop reason, time) on the same pairs with the
//! same ignore masks, and on the consecutive pairs of the TUM fr2_desk excerpt in `fixtures/` for
//! comparison. Run:
//! `cargo run --release --example pipeline_profile [-- ROUNDS]` (RAYON_NUM_THREADS=1 for one core).

// A profiling tool: a failing setup is a bug worth a panic.
#![allow(clippy::unwrap_used)]

#[path = "../tests/integration/common/tum.rs"]
mod tum;

#[path = "../tests/integration/common/data.rs"]
mod data;

use std::time::Instant;

use nalgebra::Isometry3;
use occmask::dvo::bench_api::{self as kernels, LmSchedule};
use occmask::dvo::{DvoConfig, DvoEstimator, LevelStop};
use occmask::geometry::camera::presets;
use occmask::geometry::PinholeIntrinsics;
use occmask::image_buf::{DepthMeters, GrayF32, ImageSize, Mask};
use occmask::pipeline::{FrameInput, PoseSource, Processor, ProcessorConfig};
use occmask::pyramid::ImagePyramid;
use occmask::synthetic::{Scenario, SequenceConfig, SyntheticSequence};

/// Process CPU time (user + system, all threads) in seconds.
fn cpu_seconds() -> f64 {
    // SAFETY: getrusage writes into the zeroed struct we own.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut usage) };
    let seconds = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    seconds(usage.ru_utime) + seconds(usage.ru_stime)
}

#[derive(Default, Clone, Copy)]
struct LevelTotals {
    pairs: u32,
    points: u64,
    iterations: u64,
    max_iterations_hit: u32,
    lambda_overflow: u32,
    us: f64,
    /// Fastest single normal-equation pass seen.
    min_pass_us: f64,
}

/// DVO level by level on `pairs` (reference, current, ignore mask on the reference).
fn per_level(
    name: &str,
    size: ImageSize,
    k: PinholeIntrinsics,
    pairs: &[(usize, usize, Option<Mask>)],
    frames: &[(GrayF32, DepthMeters)],
    rounds: usize,
) {
    let cfg = DvoConfig::default();
    let mut estimator = DvoEstimator::new(size, cfg).unwrap();
    let cfg = *estimator.config();
    let mut reference = ImagePyramid::new(size, k, cfg.levels, cfg.finest_level).unwrap();
    let mut current = reference.clone();
    let mut totals = [LevelTotals::default(); 8];
    let (mut build_us, mut prepare_us) = (0.0, 0.0);
    for _ in 0..rounds {
        for (r, c, mask) in pairs {
            reference.build(&frames[*r].0, &frames[*r].1).unwrap();
            let t = Instant::now();
            current.build(&frames[*c].0, &frames[*c].1).unwrap();
            build_us += t.elapsed().as_secs_f64() * 1e6;
            let t = Instant::now();
            estimator.prepare_reference(&reference, mask.as_ref()).unwrap();
            prepare_us += t.elapsed().as_secs_f64() * 1e6;
            let mut pose = Isometry3::identity();
            for l in (cfg.finest_level..cfg.levels).rev() {
                let lv = current.level(l).unwrap();
                let target = kernels::TargetView {
                    samples: &lv.samples,
                    size: lv.size(),
                    intrinsics: lv.intrinsics,
                };
                let cost = cfg.cost_at_level(l);
                let schedule = LmSchedule {
                    lambda_initial: cfg.lm_lambda_initial,
                    lambda_up: cfg.lm_lambda_up,
                    lambda_down: cfg.lm_lambda_down,
                    lambda_max: cfg.lm_lambda_max,
                    max_iterations: cfg.max_iterations_per_level,
                    step_tolerance: cfg.step_tolerance * f64::from(1u32 << (l - cfg.finest_level)),
                };
                let points = estimator.reference_points(l);
                let t = Instant::now();
                let mut level_pose = pose;
                let res = kernels::optimize_level(
                    points,
                    lv.size().width,
                    &target,
                    &cost,
                    &schedule,
                    None,
                    &mut level_pose,
                );
                let tot = &mut totals[l];
                tot.us += t.elapsed().as_secs_f64() * 1e6;
                tot.pairs += 1;
                tot.points += points.len() as u64;
                if let Ok(res) = res {
                    tot.iterations += res.iterations as u64;
                    match res.stop {
                        LevelStop::MaxIterations => tot.max_iterations_hit += 1,
                        LevelStop::LambdaOverflow => tot.lambda_overflow += 1,
                        LevelStop::SmallStep => {}
                    }
                    pose = level_pose;
                }
                // Load-robust kernel figure: the fastest of a few normal-equation passes.
                let points = estimator.reference_points(l);
                for _ in 0..3 {
                    let t = Instant::now();
                    std::hint::black_box(kernels::accumulate_normal_equations(
                        points,
                        lv.size().width,
                        &target,
                        &pose,
                        &cost,
                    ));
                    let us = t.elapsed().as_secs_f64() * 1e6;
                    let tot = &mut totals[l];
                    tot.min_pass_us = if tot.min_pass_us == 0.0 {
                        us
                    } else {
                        tot.min_pass_us.min(us)
                    };
                }
            }
        }
    }
    let n = (pairs.len() * rounds) as f64;
    println!(
        "{name}: {} pairs; pyramid build {:.2} ms, prepare_reference {:.2} ms per pair",
        pairs.len(),
        build_us / n / 1e3,
        prepare_us / n / 1e3
    );
    for l in (cfg.finest_level..cfg.levels).rev() {
        let t = &totals[l];
        let p = f64::from(t.pairs);
        println!(
            "  level {l}: {:>7.0} points, {:>5.2} iterations (max hit {}, λ overflow {}), {:.2} ms per pair, {:.3} ms per iteration, fastest pass {:.3} ms",
            t.points as f64 / p,
            t.iterations as f64 / p,
            t.max_iterations_hit,
            t.lambda_overflow,
            t.us / p / 1e3,
            t.us / (t.iterations.max(1) as f64) / 1e3,
            t.min_pass_us / 1e3,
        );
    }
}

fn main() {
    let rounds: usize = std::env::args().nth(1).map_or(3, |s| s.parse().unwrap());
    let size = ImageSize::new(640, 480);
    let config = SequenceConfig {
        size,
        ..SequenceConfig::default()
    };
    let sequence = SyntheticSequence::new(Scenario::DominantObject, config);
    let synthetic: Vec<_> = (40..70).map(|i| sequence.frame(i)).collect();
    let processor_config = ProcessorConfig {
        pose_source: PoseSource::DvoClosedLoop,
        ..ProcessorConfig::default()
    };
    let mut processor = Processor::new(size, config.intrinsics(), processor_config).unwrap();
    let mut masks: Vec<Option<Mask>> = vec![None; synthetic.len()];
    let (mut pose_us, mut detector_us, mut n) = (0u64, 0u64, 0u64);
    let mut iterations = [0u64; 8];
    let (cpu0, wall0) = (cpu_seconds(), Instant::now());
    for _ in 0..rounds {
        processor.reset();
        for (k, f) in synthetic.iter().enumerate() {
            let out = processor
                .process(&FrameInput {
                    timestamp_ns: f.timestamp_ns,
                    gray: &f.gray,
                    depth_m: &f.depth_m,
                    world_from_marker: Some(&f.world_from_camera),
                    ignore_in_previous: None,
                })
                .unwrap();
            masks[k] = Some(out.mask.clone());
            if let Some(d) = out.stats.dvo {
                pose_us += out.stats.pose_us;
                detector_us += out.stats.detector_us;
                n += 1;
                for (t, i) in iterations.iter_mut().zip(d.iterations_per_level) {
                    *t += u64::from(i);
                }
            }
        }
    }
    let frames = (rounds * synthetic.len()) as f64;
    println!(
        "closed loop, {} frames: wall {:.2} ms/frame, CPU {:.2} ms/frame; DVO (pyramid + estimate) {:.2} ms, detector {:.2} ms; iterations per level {:?}",
        rounds * synthetic.len(),
        wall0.elapsed().as_secs_f64() * 1e3 / frames,
        (cpu_seconds() - cpu0) * 1e3 / frames,
        pose_us as f64 / n as f64 / 1e3,
        detector_us as f64 / n as f64 / 1e3,
        iterations.map(|i| (i as f64 / n as f64 * 10.0).round() / 10.0),
    );
    let frames: Vec<(GrayF32, DepthMeters)> = synthetic
        .iter()
        .map(|f| (f.gray.clone(), f.depth_m.clone()))
        .collect();
    let pairs: Vec<_> = (1..frames.len())
        .map(|k| (k - 1, k, masks[k - 1].clone()))
        .collect();
    per_level(
        "synthetic dominant object, closed-loop masks",
        size,
        config.intrinsics(),
        &pairs,
        &frames,
        rounds,
    );
    let unmasked: Vec<_> = (1..frames.len()).map(|k| (k - 1, k, None)).collect();
    per_level(
        "synthetic dominant object, no mask",
        size,
        config.intrinsics(),
        &unmasked,
        &frames,
        rounds,
    );
    if let Ok(sequence) = tum::TumSequence::load(&data::tum_fixture()) {
        let tum_frames: Vec<_> = (0..sequence.pairs.len())
            .map(|i| {
                let frame = sequence.frame(i).unwrap();
                (frame.gray, frame.depth_m)
            })
            .collect();
        let pairs: Vec<_> = (1..tum_frames.len()).map(|k| (k - 1, k, None)).collect();
        per_level(
            "tum_fr2_desk_10 (fixtures/)",
            size,
            presets::TUM_FR2,
            &pairs,
            &tum_frames,
            rounds,
        );
    }
}
