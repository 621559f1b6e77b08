//! Per-stage wall time and process CPU time of the occlusion detector alone, on the synthetic
//! dominant-object sequence at 640×480 (the frames of `benches/occlusion.rs`). CPU time is the
//! steadier figure on a shared machine. Run:
//! `cargo run --release --example detector_profile [-- ROUNDS [FRAMES_CACHE [paper]]]`
//! (RAYON_NUM_THREADS=1 for one core; `paper` turns the appearance growth off). With FRAMES_CACHE (a file path) the rendered frames are saved there on the first
//! run and read back afterwards: rendering costs ≈ 35 G instructions, 15× the detector's, which
//! matters under `valgrind --tool=callgrind`.

// A profiling tool: a failing setup is a bug worth a panic.
#![allow(clippy::unwrap_used)]

use std::time::Instant;

use nalgebra::Isometry3;
use occmask::image_buf::{DepthMeters, GrayF32, ImageSize};
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
    let cache = std::env::args()
        .nth(2)
        .filter(|a| !a.is_empty())
        .map(std::path::PathBuf::from);
    let paper = std::env::args().nth(3).is_some_and(|a| a == "paper");
    let frames = match cache.as_deref().and_then(|path| std::fs::read(path).ok()) {
        Some(bytes) => decode_frames(&bytes, size),
        None => {
            let frames: Vec<Frame> = (40..70)
                .map(|i| {
                    let frame = sequence.frame(i);
                    (frame.depth_m, frame.gray, sequence.current_from_previous(i))
                })
                .collect();
            if let Some(path) = &cache {
                std::fs::write(path, encode_frames(&frames)).unwrap();
            }
            frames
        }
    };
    let detector_config = OcclusionConfig {
        appearance_growth: if paper {
            None
        } else {
            OcclusionConfig::default().appearance_growth
        },
        ..OcclusionConfig::default()
    };
    let mut detector = OcclusionDetector::new(size, config.intrinsics(), detector_config).unwrap();
    for (depth, gray, motion) in &frames {
        detector.update_with_gray(depth, Some(gray), motion).unwrap();
    }
    let (mut transport, mut label, mut prune, mut growth, mut updates) = (0u64, 0u64, 0u64, 0u64, 0u64);
    let (mut mask_pixels, mut grown_pixels) = (0usize, 0usize);
    let (cpu0, wall0) = (cpu_seconds(), Instant::now());
    for _ in 0..rounds {
        detector.reset();
        for (depth, gray, motion) in &frames {
            detector.update_with_gray(depth, Some(gray), motion).unwrap();
            let s = detector.stats();
            transport += s.transport_us;
            label += s.label_predict_us;
            prune += s.prune_us;
            growth += s.growth_us;
            mask_pixels += s.mask_pixels;
            grown_pixels += s.grown_pixels;
        }
        updates += frames.len() as u64;
    }
    let (cpu, wall) = (cpu_seconds() - cpu0, wall0.elapsed().as_secs_f64());
    let per = |us: u64| us as f64 / 1000.0 / updates as f64;
    println!(
        "{updates} updates at {size} ({}): wall {:.2} ms/frame, CPU {:.2} ms/frame; stages (wall): \
         transport {:.2}, label+predict {:.2}, mask+prune {:.2}, growth {:.2} ms; mean mask {} px, \
         grown {} px",
        if paper {
            "paper"
        } else {
            "default: appearance growth"
        },
        wall * 1000.0 / updates as f64,
        cpu * 1000.0 / updates as f64,
        per(transport),
        per(label),
        per(prune),
        per(growth),
        mask_pixels / updates.max(1) as usize,
        grown_pixels / updates.max(1) as usize,
    );
}

/// Depth, gray and the camera motion of one frame.
type Frame = (DepthMeters, GrayF32, Isometry3<f64>);

/// Per frame: the motion's translation and unit quaternion (i, j, k, w) as 7 f64 (exact), then the
/// depth and the gray image (f32), all little-endian.
fn encode_frames(frames: &[Frame]) -> Vec<u8> {
    let mut bytes = Vec::new();
    for (depth, gray, motion) in frames {
        let (t, q) = (motion.translation.vector, motion.rotation.coords);
        for v in t.iter().chain(q.iter()) {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        for v in depth.as_slice().iter().chain(gray.as_slice()) {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    bytes
}

fn decode_frames(bytes: &[u8], size: ImageSize) -> Vec<Frame> {
    let frame_bytes = 7 * 8 + 2 * size.area() * 4;
    assert_eq!(bytes.len() % frame_bytes, 0, "frames cache of another size");
    bytes
        .chunks_exact(frame_bytes)
        .map(|frame| {
            let (pose, images) = frame.split_at(7 * 8);
            let (depth, gray) = images.split_at(size.area() * 4);
            let p: Vec<f64> = pose
                .chunks_exact(8)
                .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
                .collect();
            let motion = Isometry3::from_parts(
                nalgebra::Translation3::new(p[0], p[1], p[2]),
                nalgebra::UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(p[6], p[3], p[4], p[5])),
            );
            let floats = |b: &[u8]| -> Vec<f32> {
                b.chunks_exact(4)
                    .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
                    .collect()
            };
            (
                DepthMeters::from_vec(size, floats(depth)).unwrap(),
                GrayF32::from_vec(size, floats(gray)).unwrap(),
                motion,
            )
        })
        .collect()
}
