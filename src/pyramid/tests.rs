//! Tests of the pyramid kernels against their references.

use super::*;
use crate::geometry::camera::presets;

/// [`edge_aware_depth`] with branches: the reference it is tested against.
fn edge_aware_depth_reference(children_m: [f32; 4]) -> f32 {
    let mut nearest = f32::INFINITY;
    for &z in &children_m {
        if z > 0.0 && z < nearest {
            nearest = z;
        }
    }
    if !nearest.is_finite() {
        return 0.0;
    }
    let limit = nearest * (1.0 + DEPTH_EDGE_RELATIVE);
    let (mut sum, mut n) = (0.0f32, 0.0f32);
    for &z in &children_m {
        if z > 0.0 && z <= limit {
            sum += z;
            n += 1.0;
        }
    }
    sum / n
}

/// [`pack_samples_into`] pixel by pixel on one thread, with the border cases in every pixel:
/// the reference it is tested against (the sizes are the caller's to match).
fn pack_samples_reference(gray: &GrayF32, depth_m: &DepthMeters, samples: &mut [TargetSample]) {
    let (w, h) = (gray.width(), gray.height());
    let (g, d) = (gray.as_slice(), depth_m.as_slice());
    // 1 / (distance between the two samples of a difference): ½ inside, 1 on the border, and 0
    // for a one-pixel side (no derivative at all).
    let inv_spacing = |i: usize, n: usize| -> f32 {
        match (i > 0, i + 1 < n) {
            (true, true) => 0.5,
            (false, false) => 0.0,
            _ => 1.0,
        }
    };
    for (y, out) in samples.chunks_exact_mut(w).enumerate() {
        let (up, down) = (y.saturating_sub(1), (y + 1).min(h - 1));
        let inv_dy = inv_spacing(y, h);
        let (g_row, g_up, g_down) = (
            &g[y * w..(y + 1) * w],
            &g[up * w..(up + 1) * w],
            &g[down * w..(down + 1) * w],
        );
        let (d_row, d_up, d_down) = (
            &d[y * w..(y + 1) * w],
            &d[up * w..(up + 1) * w],
            &d[down * w..(down + 1) * w],
        );
        // Depth neighbours outside the image read as invalid.
        let (has_up, has_down) = (y > 0, y + 1 < h);
        for (x, s) in out.iter_mut().enumerate() {
            let (left, right) = (x.saturating_sub(1), (x + 1).min(w - 1));
            let gx = (g_row[right] - g_row[left]) * inv_spacing(x, w);
            let gy = (g_down[x] - g_up[x]) * inv_dy;
            let z = clean_depth(d_row[x]);
            let (zv, zx, zy) = if z > 0.0 {
                let zl = if x > 0 { clean_depth(d_row[left]) } else { 0.0 };
                let zr = if x + 1 < w { clean_depth(d_row[right]) } else { 0.0 };
                let zu = if has_up { clean_depth(d_up[x]) } else { 0.0 };
                let zd = if has_down { clean_depth(d_down[x]) } else { 0.0 };
                let zx = depth_derivative(zl, z, zr);
                let zy = depth_derivative(zu, z, zd);
                // A NaN in either derivative makes the whole depth channel unusable.
                let poison = 0.0 * (zx + zy);
                (z + poison, zx + poison, zy + poison)
            } else {
                (f32::NAN, f32::NAN, f32::NAN)
            };
            *s = TargetSample([g_row[x], gx, gy, zv, zx, zy, 0.0, 0.0]);
        }
    }
}

fn ramp(size: ImageSize) -> (GrayF32, DepthMeters) {
    let gray = GrayF32::from_fn(size, |x, y| (x as f32 * 0.01 + y as f32 * 0.002).fract());
    let depth = DepthMeters::from_fn(size, |x, y| 1.0 + 0.001 * (x + y) as f32);
    (gray, depth)
}

/// The branch-free edge-aware depth against the branching one, bit for bit, over blocks
/// of invalid (0, negative, NaN, infinite), equal, near and far children.
#[test]
fn edge_aware_depth_agrees_with_its_scalar_reference() {
    let values = [
        0.0,
        -1.0,
        f32::NAN,
        f32::INFINITY,
        1.0,
        1.01,
        1.02,
        1.03,
        1.5,
        3.0,
        0.3,
    ];
    for a in values {
        for b in values {
            for c in values {
                for d in values {
                    let children = [a, b, c, d];
                    assert_eq!(
                        edge_aware_depth(children).to_bits(),
                        edge_aware_depth_reference(children).to_bits(),
                        "{children:?}"
                    );
                }
            }
        }
    }
}

/// Every build of the depth downsampling's row kernel the CPU runs against the branching
/// reference, bit for bit, over every block of invalid, near and far children (one block per
/// output pixel).
#[test]
fn every_build_of_the_depth_row_agrees_with_the_reference() {
    let values = [0.0, -1.0, f32::NAN, f32::INFINITY, 1.0, 1.01, 1.03, 1.5, 3.0, 0.3];
    let mut blocks: Vec<[f32; 4]> = Vec::new();
    for a in values {
        for b in values {
            for c in values {
                blocks.extend(values.map(|d| [a, b, c, d]));
            }
        }
    }
    let top: Vec<f32> = blocks.iter().flat_map(|c| [c[0], c[1]]).collect();
    let bottom: Vec<f32> = blocks.iter().flat_map(|c| [c[2], c[3]]).collect();
    let expected: Vec<u32> = blocks
        .iter()
        .map(|&c| edge_aware_depth_reference(c).to_bits())
        .collect();
    for simd in Simd::available() {
        let mut out = vec![7.0f32; blocks.len()];
        downsample_depth_row(simd, &top, &bottom, &mut out);
        let found: Vec<u32> = out.iter().map(|v| v.to_bits()).collect();
        assert_eq!(found, expected, "{simd:?}");
    }
}

/// The depth derivative by its definition, branching: the central difference when both
/// neighbours lie on the centre's surface, the one-sided difference when one does, NaN when
/// neither does; bit for bit over invalid, near, edge and far neighbours.
#[test]
fn depth_derivative_is_central_one_sided_or_nan() {
    let centre = 1.0_f32;
    let on_surface = |z: f32| z > 0.0 && (z - centre).abs() <= DEPTH_EDGE_RELATIVE * centre;
    let neighbours = [0.0, 0.9, 0.95, 0.96, 0.999, 1.0, 1.001, 1.04, 1.05, 1.06, 2.0];
    for prev in neighbours {
        for next in neighbours {
            let expected = match (on_surface(prev), on_surface(next)) {
                (true, true) => ((next - centre) + (centre - prev)) * 0.5,
                (true, false) => centre - prev,
                (false, true) => next - centre,
                (false, false) => f32::NAN,
            };
            assert_eq!(
                depth_derivative(prev, centre, next).to_bits(),
                expected.to_bits(),
                "prev {prev}, next {next}"
            );
        }
    }
}

/// The packed samples against the pixel-by-pixel reference, bit for bit (NaNs included),
/// on thin and odd sizes and on depth with holes, edges, NaN and infinity.
#[test]
fn packed_samples_agree_with_their_scalar_reference() {
    for (width, height) in [(1, 1), (2, 1), (1, 3), (3, 2), (4, 4), (37, 23), (640, 480)] {
        let size = ImageSize::new(width, height);
        let gray = GrayF32::from_fn(size, |x, y| ((x * 13 + y * 7) % 31) as f32 / 31.0);
        let depth = DepthMeters::from_fn(size, |x, y| match (x * 29 + y * 11) % 17 {
            0 => 0.0,
            1 => f32::NAN,
            2 => f32::INFINITY,
            3 => -1.0,
            4 => 4.0, // a depth edge
            k => 1.0 + 0.001 * (x + 2 * y) as f32 + 0.0001 * k as f32,
        });
        let mut fast = vec![TargetSample::default(); size.area()];
        let mut reference = fast.clone();
        pack_samples_into(&gray, &depth, &mut fast).unwrap();
        pack_samples_reference(&gray, &depth, &mut reference);
        let bits =
            |v: &[TargetSample]| -> Vec<u32> { v.iter().flat_map(|s| s.0.map(f32::to_bits)).collect() };
        assert_eq!(bits(&fast), bits(&reference), "{width}x{height}");
    }
}

#[test]
fn level_sizes_crop_odd_sides_and_intrinsics_follow() {
    let size = ImageSize::new(641, 481);
    let p = ImagePyramid::new(size, presets::TUM_FR2, 4, 0).unwrap();
    let expect = [(641, 481), (320, 240), (160, 120), (80, 60)];
    for (l, &(w, h)) in expect.iter().enumerate() {
        let lv = p.level(l).unwrap();
        assert_eq!(lv.size(), ImageSize::new(w, h));
        assert_eq!(lv.samples.len(), w * h);
        assert_eq!(lv.intrinsics, presets::TUM_FR2.at_level(l as u32));
    }
    assert!(p.level(4).is_none());
}

#[test]
fn rejects_bad_parameters() {
    let size = ImageSize::new(640, 480);
    assert!(ImagePyramid::new(size, presets::TUM_FR2, 0, 0).is_err());
    assert!(ImagePyramid::new(size, presets::TUM_FR2, 3, 3).is_err());
    // 640 >> 7 = 5 < MIN_LEVEL_SIDE_PX.
    assert!(ImagePyramid::new(size, presets::TUM_FR2, 8, 0).is_err());
    let bad = PinholeIntrinsics::new(0.0, 1.0, 1.0, 1.0);
    assert!(ImagePyramid::new(size, bad, 3, 0).is_err());
    let mut p = ImagePyramid::new(size, presets::TUM_FR2, 3, 1).unwrap();
    let (g, d) = ramp(ImageSize::new(320, 240));
    assert!(matches!(p.build(&g, &d), Err(Error::SizeMismatch { .. })));
}

#[test]
fn gray_mean_is_preserved_and_constant_stays_constant() {
    let size = ImageSize::new(128, 96);
    let (gray, depth) = ramp(size);
    let mut p = ImagePyramid::new(size, presets::TUM_FR2, 4, 0).unwrap();
    p.build(&gray, &depth).unwrap();
    let mean =
        |img: &GrayF32| img.as_slice().iter().map(|&v| f64::from(v)).sum::<f64>() / img.size().area() as f64;
    for l in 1..4 {
        // Even sizes: every level's mean equals the input mean.
        let m = mean(&p.level(l).unwrap().gray);
        assert!((m - mean(&gray)).abs() < 1e-5, "level {l}: {m}");
    }
    let flat = GrayF32::filled(size, 0.37);
    p.build(&flat, &depth).unwrap();
    for l in 0..4 {
        let lv = p.level(l).unwrap();
        assert!(lv.gray.as_slice().iter().all(|&v| (v - 0.37).abs() < 1e-6));
        assert!(lv
            .samples
            .iter()
            .all(|s| s.0[TargetSample::GRAD_X] == 0.0 && s.0[TargetSample::GRAD_Y] == 0.0));
    }
}

#[test]
fn depth_never_blends_across_an_edge() {
    // Left half at 1 m, right half at 3 m, with an odd boundary so some 2x2 blocks straddle it.
    let size = ImageSize::new(128, 96);
    let depth = DepthMeters::from_fn(size, |x, _| if x < 67 { 1.0 } else { 3.0 });
    let gray = GrayF32::filled(size, 0.5);
    let mut p = ImagePyramid::new(size, presets::TUM_FR2, 4, 0).unwrap();
    p.build(&gray, &depth).unwrap();
    for l in 1..4 {
        for &z in p.level(l).unwrap().depth_m.as_slice() {
            assert!(z == 1.0 || z == 3.0, "level {l}: blended depth {z}");
        }
    }
    assert_eq!(edge_aware_depth([1.0, 1.02, 0.0, 3.0]), 1.01);
    assert_eq!(edge_aware_depth([0.0; 4]), 0.0);
    assert_eq!(edge_aware_depth([0.0, 2.0, 0.0, 0.0]), 2.0);
}

#[test]
fn invalid_depth_stays_invalid_and_gradients_are_nan_there() {
    let size = ImageSize::new(32, 32);
    let depth = DepthMeters::from_fn(size, |x, y| if x < 16 && y < 16 { 0.0 } else { 2.0 });
    let gray = GrayF32::filled(size, 0.5);
    let mut p = ImagePyramid::new(size, presets::TUM_FR2, 2, 0).unwrap();
    p.build(&gray, &depth).unwrap();
    let l1 = p.level(1).unwrap();
    assert_eq!(l1.depth_m.get(3, 3), 0.0);
    assert_eq!(l1.depth_m.get(12, 12), 2.0);
    let s = l1.samples[3 * 16 + 3];
    assert!(s.0[TargetSample::DEPTH].is_nan() && s.0[TargetSample::DEPTH_GRAD_X].is_nan());
    let s = l1.samples[12 * 16 + 12];
    assert_eq!(s.0[TargetSample::DEPTH], 2.0);
    assert_eq!(s.0[TargetSample::DEPTH_GRAD_X], 0.0);
}

#[test]
fn gradients_of_a_linear_ramp_are_exact() {
    let size = ImageSize::new(40, 30);
    let gray = GrayF32::from_fn(size, |x, y| 0.01 * x as f32 + 0.003 * y as f32);
    let depth = DepthMeters::from_fn(size, |x, y| 2.0 + 0.004 * x as f32 - 0.002 * y as f32);
    let mut p = ImagePyramid::new(size, presets::TUM_FR2, 2, 0).unwrap();
    p.build(&gray, &depth).unwrap();
    for l in 0..2 {
        let scale = (1 << l) as f32;
        for s in &p.level(l).unwrap().samples {
            assert!((s.0[TargetSample::GRAD_X] - 0.01 * scale).abs() < 1e-5);
            assert!((s.0[TargetSample::GRAD_Y] - 0.003 * scale).abs() < 1e-5);
            assert!((s.0[TargetSample::DEPTH_GRAD_X] - 0.004 * scale).abs() < 1e-5);
            assert!((s.0[TargetSample::DEPTH_GRAD_Y] + 0.002 * scale).abs() < 1e-5);
        }
    }
}

#[test]
fn skipping_level_zero_gives_identical_coarse_levels() {
    let size = ImageSize::new(128, 96);
    let (gray, depth) = ramp(size);
    let mut full = ImagePyramid::new(size, presets::TUM_FR2, 3, 0).unwrap();
    let mut skip = ImagePyramid::new(size, presets::TUM_FR2, 3, 1).unwrap();
    full.build(&gray, &depth).unwrap();
    skip.build(&gray, &depth).unwrap();
    assert!(skip.level(0).is_none());
    for l in 1..3 {
        let (a, b) = (full.level(l).unwrap(), skip.level(l).unwrap());
        assert_eq!(a.gray, b.gray);
        assert_eq!(a.depth_m, b.depth_m);
    }
}
