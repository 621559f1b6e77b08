//! Per-stage wall time and process CPU time of the occlusion detector alone, on the synthetic
//! dominant-object sequence at 640×480 (the frames of `benches/occlusion.rs`). CPU time is the
//! steadier figure on a shared machine. Run:
//! `cargo run --release --example detector_profile [-- ROUNDS [FRAMES_CACHE]]` (RAYON_NUM_THREADS=1
//! for one core). With FRAMES_CACHE (a file path) the rendered frames are saved there on the first
//! run and read back afterwards: rendering costs ≈ 35 G instructions, 15× the detector's, which
//! matters under `valgrind --tool=callgrind`.

// A profiling tool: a failing setup is a bug worth a panic.
#![allow(clippy::unwrap_used)]

use std::time::Instant;

use nalgebra::Isometry3;
use occmask::image_buf::{DepthMeters, ImageSize};
use occmask::occlusion::{OcclusionConfig, OcclusionDetector};
use occmask::synthetic::{Scenario, SequenceConfig, SyntheticSequence};

/// Process CPU time (user + system, all threads) in seconds.
fn cpu_seconds() -> f64 {
    #[cfg(unix)]
    {
        // SAFETY: getrusage writes into the zeroed struct we own.
        let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
        unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut usage) };
        let seconds = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
        seconds(usage.ru_utime) + seconds(usage.ru_stime)
    }
    #[cfg(not(unix))]
    {
        0.0
    }
}

fn main() {
    let rounds: usize = std::env::args().nth(1).map_or(20, |s| s.parse().unwrap());
    let size = ImageSize::new(640, 480);
    let config = SequenceConfig {
        size,
        ..SequenceConfig::default()
    };
    let sequence = SyntheticSequence::new(Scenario::DominantObject, config);
    let cache = std::env::args().nth(2).map(std::path::PathBuf::from);
    let frames = match cache.as_deref().and_then(|path| std::fs::read(path).ok()) {
        Some(bytes) => decode_frames(&bytes, size),
        None => {
            let frames: Vec<(DepthMeters, Isometry3<f64>)> = (40..70)
                .map(|i| (sequence.frame(i).depth_m, sequence.current_from_previous(i)))
                .collect();
            if let Some(path) = &cache {
                std::fs::write(path, encode_frames(&frames)).unwrap();
            }
            frames
        }
    };
    let mut detector = OcclusionDetector::new(size, config.intrinsics(), OcclusionConfig::default()).unwrap();
    for (depth, motion) in &frames {
        detector.update(depth, motion).unwrap();
    }
    let (mut transport, mut label, mut prune, mut updates) = (0u64, 0u64, 0u64, 0u64);
    let (cpu0, wall0) = (cpu_seconds(), Instant::now());
    for _ in 0..rounds {
        detector.reset();
        for (depth, motion) in &frames {
            detector.update(depth, motion).unwrap();
            let s = detector.stats();
            transport += s.transport_us;
            label += s.label_predict_us;
            prune += s.prune_us;
        }
        updates += frames.len() as u64;
    }
    let (cpu, wall) = (cpu_seconds() - cpu0, wall0.elapsed().as_secs_f64());
    let per = |us: u64| us as f64 / 1000.0 / updates as f64;
    println!(
        "{updates} updates at {size}: wall {:.2} ms/frame, CPU {:.2} ms/frame; stages (wall): transport {:.2}, label+predict {:.2}, mask+prune {:.2} ms",
        wall * 1000.0 / updates as f64,
        cpu * 1000.0 / updates as f64,
        per(transport),
        per(label),
        per(prune)
    );
}

/// Per frame: the motion's translation and unit quaternion (i, j, k, w) as 7 f64 (exact), then the
/// depth (f32), all little-endian.
fn encode_frames(frames: &[(DepthMeters, Isometry3<f64>)]) -> Vec<u8> {
    let mut bytes = Vec::new();
    for (depth, motion) in frames {
        let (t, q) = (motion.translation.vector, motion.rotation.coords);
        for v in t.iter().chain(q.iter()) {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        for v in depth.as_slice() {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    bytes
}

fn decode_frames(bytes: &[u8], size: ImageSize) -> Vec<(DepthMeters, Isometry3<f64>)> {
    let frame_bytes = 7 * 8 + size.area() * 4;
    assert_eq!(bytes.len() % frame_bytes, 0, "frames cache of another size");
    bytes
        .chunks_exact(frame_bytes)
        .map(|frame| {
            let (pose, depth) = frame.split_at(7 * 8);
            let p: Vec<f64> = pose
                .chunks_exact(8)
                .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
                .collect();
            let motion = Isometry3::from_parts(
                nalgebra::Translation3::new(p[0], p[1], p[2]),
                nalgebra::UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(p[6], p[3], p[4], p[5])),
            );
            let depth: Vec<f32> = depth
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
                .collect();
            (DepthMeters::from_vec(size, depth).unwrap(), motion)
        })
        .collect()
}
