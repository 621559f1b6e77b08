use super::super::components::NEIGHBOURS_8;
use super::*;
use crate::image_buf::MASK_SET;
use crate::xorshift::XorShift64;

/// The detector's end of frame: keeps `gray` and hands `mask` over as the previous mask.
fn remember_frame(state: &mut AppearanceGrowth, gray: &GrayF32, mask: &Mask) {
    state.remember(Some(gray));
    state.keep_mask(&mut mask.clone());
}

/// The growth written plainly (the reference of [`AppearanceGrowth::grow`]): seeds by
/// testing each mask pixel's 8 neighbours, breadth-first rings with bounds checks and a
/// separate "decided" image; same rules, same order.
fn grow_reference(
    state: &AppearanceGrowth,
    frame: &GrowthFrame,
    mask: &mut Mask,
    accumulation_m: &mut DepthMeters,
) -> usize {
    let growth = frame.growth;
    let (width, height) = (state.width, state.height);
    if !state.previous_valid || growth.max_rings == 0 {
        return 0;
    }
    let (mut ray_x, mut ray_y) = (vec![0.0; width], vec![0.0; height]);
    fill_ray_tables(frame.intrinsics, &mut ray_x, &mut ray_y);
    let evidence = Evidence::new(
        frame,
        (&ray_x, &ray_y),
        (&state.previous_gray, &state.previous_mask),
    );
    let interior = |x: isize, y: isize| x >= 1 && y >= 1 && x < width as isize - 1 && y < height as isize - 1;
    let set = |mask: &Mask, x: isize, y: isize| mask.get(x as usize, y as usize) != 0;
    let mut frontier = Vec::new();
    for y in 1..height - 1 {
        for x in 1..width - 1 {
            let (xi, yi) = (x as isize, y as isize);
            let on_boundary =
                set(mask, xi, yi) && NEIGHBOURS_8.iter().any(|&(dx, dy)| !set(mask, xi + dx, yi + dy));
            if on_boundary && evidence.may_seed(x, y) {
                frontier.push((x, y));
            }
        }
    }
    let mut decided = vec![false; width * height];
    let mut grown = 0;
    for _ in 0..growth.max_rings {
        let mut next = Vec::new();
        for &(fx, fy) in &frontier {
            let zf = frame.depth_m.get(fx, fy);
            if zf <= 0.0 {
                continue;
            }
            for &(dx, dy) in &NEIGHBOURS_8 {
                let (nx, ny) = (fx as isize + dx, fy as isize + dy);
                if !interior(nx, ny) || set(mask, nx, ny) || decided[ny as usize * width + nx as usize] {
                    continue;
                }
                let (nx, ny) = (nx as usize, ny as usize);
                let zn = frame.depth_m.get(nx, ny);
                if zn <= 0.0 || (zn - zf).abs() > growth.depth_tolerance * zf {
                    continue;
                }
                decided[ny * width + nx] = true;
                if evidence.changed(nx, ny) {
                    mask.set(nx, ny, MASK_SET);
                    let af = accumulation_m.get(fx, fy);
                    accumulation_m.set(nx, ny, evidence.grown_accumulation(frame.config, af, zf, zn));
                    next.push((nx, ny));
                }
            }
        }
        grown += next.len();
        if next.is_empty() {
            break;
        }
        frontier = next;
    }
    grown
}

const SIZE: ImageSize = ImageSize::new(160, 120);
/// The box: [40, 100) × [30, 90) at 2 m in front of a wall at 3 m.
const BOX_X: std::ops::Range<usize> = 40..100;
const BOX_Y: std::ops::Range<usize> = 30..90;
/// Object pixels already detected: the box's right 6 columns (a swept strip).
const SEED_X: std::ops::Range<usize> = 94..100;

fn intrinsics() -> PinholeIntrinsics {
    PinholeIntrinsics::new(131.25, 131.25, 79.5, 59.5)
}

/// The fixed test scenes' camera: default detector config, the test intrinsics, no motion.
struct StillCamera {
    config: OcclusionConfig,
    intrinsics: PinholeIntrinsics,
    motion: Isometry3<f64>,
}

impl StillCamera {
    fn new() -> Self {
        Self {
            config: OcclusionConfig::default(),
            intrinsics: intrinsics(),
            motion: Isometry3::identity(),
        }
    }

    /// A frame of depth `depth_m` and gray image `gray` grown with `growth`.
    fn frame<'a>(
        &'a self,
        growth: &'a AppearanceGrowthConfig,
        depth_m: &'a DepthMeters,
        gray: &'a GrayF32,
    ) -> GrowthFrame<'a> {
        GrowthFrame {
            growth,
            config: &self.config,
            intrinsics: &self.intrinsics,
            previous_from_current: &self.motion,
            depth_m,
            gray,
        }
    }
}

fn in_box(x: usize, y: usize) -> bool {
    BOX_X.contains(&x) && BOX_Y.contains(&y)
}

fn depth() -> DepthMeters {
    Image::from_fn(SIZE, |x, y| if in_box(x, y) { 2.0 } else { 3.0 })
}

/// Vertical stripes 2 px wide, shifted by `phase_px`: a 2 px shift inverts every pixel.
fn stripes(x: usize, phase_px: usize) -> f32 {
    0.3 + 0.4 * (((x + phase_px) / 2) % 2) as f32
}

/// A static textured scene whose box texture is misregistered by 1 px between the frames.
fn misregistered_pair() -> (GrayF32, GrayF32) {
    let previous = Image::from_fn(SIZE, |x, _| stripes(x, 0));
    let current = Image::from_fn(SIZE, |x, y| stripes(x, usize::from(in_box(x, y))));
    (previous, current)
}

/// Box and wall textured (2 px stripes); a moved texture puts the box's (or the wall's)
/// bright part where its dark part was: every pixel changes by at least 0.3, and no
/// previous pixel nearby matches it.
fn moved_pair(box_moved: bool, wall_moved: bool) -> (GrayF32, GrayF32) {
    let texture = |x: usize, y: usize, moved: bool| {
        let base = if in_box(x, y) { 0.1 } else { 0.3 };
        base + 0.1 * ((x / 2) % 2) as f32 + if moved { 0.4 } else { 0.0 }
    };
    let previous = Image::from_fn(SIZE, |x, y| texture(x, y, false));
    let current = Image::from_fn(SIZE, |x, y| {
        texture(x, y, if in_box(x, y) { box_moved } else { wall_moved })
    });
    (previous, current)
}

/// Runs one growth step from the seed strip with A = 1 m on it; returns the mask, A and
/// the count.
fn grow(previous: &GrayF32, current: &GrayF32, growth: AppearanceGrowthConfig) -> (Mask, DepthMeters, usize) {
    let seed = |x: usize, y: usize| SEED_X.contains(&x) && BOX_Y.contains(&y);
    let mut mask = Image::from_fn(SIZE, |x, y| if seed(x, y) { MASK_SET } else { 0 });
    let mut accumulation = Image::from_fn(SIZE, |x, y| if seed(x, y) { 1.0 } else { 0.0 });
    let mask_pixels = SEED_X.len() * BOX_Y.len();
    let mut state = AppearanceGrowth::new(SIZE);
    // The strip was already detected in the previous frame (the growth's seeds).
    remember_frame(&mut state, previous, &mask);
    let counts = state.grow(
        &StillCamera::new().frame(&growth, &depth(), current),
        &mut mask,
        &mut accumulation,
        mask_pixels,
    );
    let set = mask.as_slice().iter().filter(|&&m| m != 0).count();
    assert_eq!(set, mask_pixels + counts.grown);
    (mask, accumulation, counts.grown)
}

fn unbounded() -> AppearanceGrowthConfig {
    AppearanceGrowthConfig {
        max_rings: 1000,
        ..AppearanceGrowthConfig::default()
    }
}

/// A random scene: depth steps between a few planes (with holes), random textures, masks
/// of random rectangles with speckle holes touching the image border, a previous mask
/// that overlaps them, and a small camera motion.
struct Scene {
    size: ImageSize,
    depth: DepthMeters,
    previous_gray: GrayF32,
    gray: GrayF32,
    previous_mask: Mask,
    mask: Mask,
    accumulation: DepthMeters,
    motion: Isometry3<f64>,
}

fn random_scene(seed: u64) -> Scene {
    let mut random = XorShift64::new(seed | 1);
    // Odd sizes: the seed scan's 8-pixel words end in a partial word.
    let size = ImageSize::new(
        61 + (random.next_u64() % 40) as usize,
        37 + (random.next_u64() % 30) as usize,
    );
    let planes: Vec<f32> = (0..3).map(|_| 1.0 + 3.0 * random.unit_f32()).collect();
    let split = (random.next_u64() % size.width as u64) as usize;
    let depth = Image::from_fn(size, |x, y| {
        let plane = usize::from(x >= split) + usize::from(y % 17 < 5);
        let slope = 0.002 * x as f32;
        if (x * 7 + y * 13) % 29 == 0 {
            0.0
        } else {
            planes[plane] + slope
        }
    });
    let previous_gray = Image::from_fn(size, |_, _| random.unit_f32());
    // Half the pixels keep their previous value, the others change (texture moved).
    let gray = Image::from_fn(size, |x, y| {
        if random.next_u64().is_multiple_of(2) {
            previous_gray.get(x, y)
        } else {
            random.unit_f32()
        }
    });
    let mut mask: Mask = Image::filled(size, 0);
    for _ in 0..4 {
        let (x0, y0) = (
            random.next_u64() as usize % size.width,
            random.next_u64() as usize % size.height,
        );
        let (w, h) = (
            1 + random.next_u64() as usize % 25,
            1 + random.next_u64() as usize % 20,
        );
        for y in y0..(y0 + h).min(size.height) {
            for x in x0..(x0 + w).min(size.width) {
                if !random.next_u64().is_multiple_of(11) {
                    mask.set(x, y, MASK_SET);
                }
            }
        }
    }
    let previous_mask = Image::from_fn(size, |x, y| {
        if x > 0 && mask.get(x - 1, y) != 0 || random.next_u64().is_multiple_of(5) {
            MASK_SET
        } else {
            0
        }
    });
    let accumulation = Image::from_fn(size, |x, y| {
        if mask.get(x, y) != 0 {
            0.2 + random.unit_f32()
        } else {
            0.0
        }
    });
    let motion = Isometry3::new(
        nalgebra::Vector3::new(0.01 * f64::from(random.unit_f32()), -0.005, 0.02),
        nalgebra::Vector3::new(0.0, 0.01 * f64::from(random.unit_f32()), 0.003),
    );
    Scene {
        size,
        depth,
        previous_gray,
        gray,
        previous_mask,
        mask,
        accumulation,
        motion,
    }
}

#[test]
fn growth_matches_the_plain_reference_on_random_scenes() {
    let config = OcclusionConfig::default();
    let growths = [
        AppearanceGrowthConfig::default(),
        unbounded(),
        AppearanceGrowthConfig {
            max_rings: 2,
            photometric_search_radius_px: 0,
            ..AppearanceGrowthConfig::default()
        },
        AppearanceGrowthConfig {
            persistent_seeds_only: false,
            inherit_accumulation: false,
            depth_tolerance: 0.5,
            ..unbounded()
        },
    ];
    let mut total_grown = 0;
    for seed in 0..40u64 {
        let scene = random_scene(0x9E37_79B9_7F4A_7C15 ^ seed);
        let intrinsics = PinholeIntrinsics::new(60.0, 60.0, scene.size.width as f64 / 2.0, 25.0);
        for growth in &growths {
            let mut state = AppearanceGrowth::new(scene.size);
            remember_frame(&mut state, &scene.previous_gray, &scene.previous_mask);
            let mask_pixels = scene.mask.as_slice().iter().filter(|&&m| m != 0).count();
            let frame = GrowthFrame {
                growth,
                config: &config,
                intrinsics: &intrinsics,
                previous_from_current: &scene.motion,
                depth_m: &scene.depth,
                gray: &scene.gray,
            };
            let (mut mask, mut accumulation) = (scene.mask.clone(), scene.accumulation.clone());
            let counts = state.grow(&frame, &mut mask, &mut accumulation, mask_pixels);
            let (mut expected_mask, mut expected_accumulation) =
                (scene.mask.clone(), scene.accumulation.clone());
            let expected_grown =
                grow_reference(&state, &frame, &mut expected_mask, &mut expected_accumulation);
            assert_eq!(counts.grown, expected_grown, "seed {seed}, {growth:?}");
            assert!(mask == expected_mask, "seed {seed}, {growth:?}: masks differ");
            assert!(
                accumulation == expected_accumulation,
                "seed {seed}, {growth:?}: accumulations differ"
            );
            total_grown += counts.grown;
        }
    }
    // The scenes exercise the growth (not a comparison of two empty results).
    assert!(total_grown > 2000, "{total_grown}");
}

#[test]
fn remember_keeps_the_gray_image_whether_or_not_the_growth_staged_it() {
    let (previous, current) = moved_pair(true, false);
    let seeds = Image::from_fn(SIZE, |x, y| if in_box(x, y) && x >= 94 { MASK_SET } else { 0 });
    let mut state = AppearanceGrowth::new(SIZE);
    remember_frame(&mut state, &previous, &seeds);
    assert!(state.previous_gray == previous, "copied without a growth");
    let (mut mask, mut accumulation) = (seeds.clone(), Image::filled(SIZE, 1.0f32));
    let counts = state.grow(
        &StillCamera::new().frame(&unbounded(), &depth(), &current),
        &mut mask,
        &mut accumulation,
        360,
    );
    assert!(counts.grown > 0);
    remember_frame(&mut state, &current, &mask);
    assert!(state.previous_gray == current, "swapped in after a growth");
    assert!(state.previous_mask == mask);
    // The next frame without a growth (no objects) copies again.
    remember_frame(&mut state, &previous, &Image::filled(SIZE, 0));
    assert!(
        state.previous_gray == previous,
        "copied after the staged image was used"
    );
}

#[test]
fn grows_over_a_moved_texture_and_stops_at_the_depth_edge() {
    // The wall's texture changes too (as if it were misregistered): only depth stops growth.
    let (previous, current) = moved_pair(true, true);
    let (mask, accumulation, grown) = grow(&previous, &current, unbounded());
    assert_eq!(grown, BOX_X.len() * BOX_Y.len() - SEED_X.len() * BOX_Y.len());
    for y in 0..SIZE.height {
        for x in 0..SIZE.width {
            assert_eq!(mask.get(x, y) != 0, in_box(x, y), "pixel ({x}, {y})");
            if in_box(x, y) {
                // Same depth as the seed: its accumulation, carried over unchanged.
                assert_eq!(accumulation.get(x, y), 1.0, "pixel ({x}, {y})");
            } else {
                assert_eq!(accumulation.get(x, y), 0.0);
            }
        }
    }
}

#[test]
fn a_static_texture_misregistered_by_a_pixel_is_not_grown_into() {
    // The box's texture shifted by 1 px only (gray and depth not quite registered): with
    // the default 1 px search every pixel finds its own value nearby; the bilinear sample
    // alone sees half the pixels change.
    let (previous, current) = misregistered_pair();
    let (_, _, grown) = grow(&previous, &current, unbounded());
    assert_eq!(grown, 0);
    let point = AppearanceGrowthConfig {
        photometric_search_radius_px: 0,
        ..unbounded()
    };
    let (_, _, grown) = grow(&previous, &current, point);
    assert!(grown > 0);
}

#[test]
fn a_component_new_in_this_frame_is_not_grown() {
    let (previous, current) = moved_pair(true, false);
    let seed = |x: usize, y: usize| SEED_X.contains(&x) && BOX_Y.contains(&y);
    let run = |growth: AppearanceGrowthConfig| {
        let mut mask = Image::from_fn(SIZE, |x, y| if seed(x, y) { MASK_SET } else { 0 });
        let mut accumulation = Image::from_fn(SIZE, |x, y| if seed(x, y) { 1.0 } else { 0.0 });
        let mut state = AppearanceGrowth::new(SIZE);
        // Nothing was detected in the previous frame.
        remember_frame(&mut state, &previous, &Image::filled(SIZE, 0));
        state
            .grow(
                &StillCamera::new().frame(&growth, &depth(), &current),
                &mut mask,
                &mut accumulation,
                SEED_X.len() * BOX_Y.len(),
            )
            .grown
    };
    assert_eq!(run(unbounded()), 0);
    let any_seed = AppearanceGrowthConfig {
        persistent_seeds_only: false,
        ..unbounded()
    };
    assert_eq!(run(any_seed), (BOX_X.len() - SEED_X.len()) * BOX_Y.len());
}

#[test]
fn does_not_grow_without_a_photometric_change() {
    // A static scene: nothing changed (same texture phase in both images).
    let (previous, current) = moved_pair(false, false);
    let (_, _, grown) = grow(&previous, &current, unbounded());
    assert_eq!(grown, 0);
    // A change below the threshold: sensor noise, not motion.
    let noisy = Image::from_fn(SIZE, |x, y| {
        previous.get(x, y) + if (x + y) % 2 == 0 { 0.03 } else { -0.03 }
    });
    let (_, _, grown) = grow(&previous, &noisy, unbounded());
    assert_eq!(grown, 0);
}

#[test]
fn growth_per_frame_is_bounded_by_the_ring_count() {
    let (previous, current) = moved_pair(true, false);
    let rings = 5;
    let bounded = AppearanceGrowthConfig {
        max_rings: rings,
        ..AppearanceGrowthConfig::default()
    };
    let (mask, _, grown) = grow(&previous, &current, bounded);
    // 5 columns left of the strip (the strip spans the box's full height).
    assert_eq!(grown, rings * BOX_Y.len());
    for y in 0..SIZE.height {
        for x in 0..SIZE.width {
            let expected = in_box(x, y) && x >= SEED_X.start - rings;
            assert_eq!(mask.get(x, y) != 0, expected, "pixel ({x}, {y})");
        }
    }
}

#[test]
fn grown_accumulation_follows_the_depth_and_stays_above_tau_alpha() {
    // A slanted box face (depth rising 1 mm per column towards the left): the accumulation
    // moves with the depth like Eq. 10's prediction; a seed with A barely above τ_α gives its
    // neighbours at least τ_α · (1 + margin).
    let config = OcclusionConfig::default();
    let growth = unbounded();
    let slanted = Image::from_fn(SIZE, |x, y| {
        if in_box(x, y) {
            2.0 + 0.001 * (BOX_X.end - x) as f32
        } else {
            3.0
        }
    });
    let (previous, current) = moved_pair(true, false);
    for seed_a in [1.0f32, 0.31] {
        let seed = |x: usize, y: usize| SEED_X.contains(&x) && BOX_Y.contains(&y);
        let mut mask = Image::from_fn(SIZE, |x, y| if seed(x, y) { MASK_SET } else { 0 });
        let mut accumulation = Image::from_fn(SIZE, |x, y| if seed(x, y) { seed_a } else { 0.0 });
        let mut state = AppearanceGrowth::new(SIZE);
        remember_frame(&mut state, &previous, &mask);
        let counts = state.grow(
            &StillCamera::new().frame(&growth, &slanted, &current),
            &mut mask,
            &mut accumulation,
            SEED_X.len() * BOX_Y.len(),
        );
        assert_eq!(counts.grown, (SEED_X.start - BOX_X.start) * BOX_Y.len());
        for x in BOX_X.start..SEED_X.start {
            let z = slanted.get(x, 60);
            let floor = config.threshold(config.alpha, z) * (1.0 + growth.accumulation_margin);
            let carried = seed_a + slanted.get(SEED_X.start, 60) - z;
            let expected = carried.max(floor);
            assert!(
                (accumulation.get(x, 60) - expected).abs() < 1e-4,
                "seed A {seed_a}, x {x}: {} vs {expected}",
                accumulation.get(x, 60)
            );
        }
    }
}

#[test]
fn bad_parameters_are_rejected_by_name() {
    for (name, bad) in [
        (
            "appearance_growth.photometric_threshold",
            AppearanceGrowthConfig {
                photometric_threshold: f32::NAN,
                ..AppearanceGrowthConfig::default()
            },
        ),
        (
            "appearance_growth.depth_tolerance",
            AppearanceGrowthConfig {
                depth_tolerance: -0.1,
                ..AppearanceGrowthConfig::default()
            },
        ),
        (
            "appearance_growth.accumulation_margin",
            AppearanceGrowthConfig {
                accumulation_margin: f32::INFINITY,
                ..AppearanceGrowthConfig::default()
            },
        ),
    ] {
        let config = OcclusionConfig {
            appearance_growth: Some(bad),
            ..OcclusionConfig::default()
        };
        match config.validate() {
            Err(crate::error::Error::InvalidParameter { name: found, .. }) => assert_eq!(found, name),
            other => panic!("{name}: {other:?}"),
        }
    }
    assert!(OcclusionConfig::default().validate().is_ok());
}

#[test]
fn nothing_happens_without_a_previous_image_or_objects() {
    let (_, current) = moved_pair(true, false);
    let mut state = AppearanceGrowth::new(SIZE);
    let mut mask = Image::from_fn(SIZE, |x, y| if in_box(x, y) && x >= 94 { MASK_SET } else { 0 });
    let mut accumulation = Image::filled(SIZE, 0.0f32);
    let run = |state: &mut AppearanceGrowth, mask: &mut Mask, accumulation: &mut DepthMeters, pixels| {
        state
            .grow(
                &StillCamera::new().frame(&unbounded(), &depth(), &current),
                mask,
                accumulation,
                pixels,
            )
            .grown
    };
    assert_eq!(
        run(&mut state, &mut mask, &mut accumulation, 360),
        0,
        "no previous image"
    );
    let seeds = mask.clone();
    remember_frame(&mut state, &current, &seeds);
    state.invalidate();
    assert_eq!(
        run(&mut state, &mut mask, &mut accumulation, 360),
        0,
        "after a reset"
    );
    remember_frame(&mut state, &current, &seeds);
    let mut empty = Image::filled(SIZE, 0u8);
    assert_eq!(run(&mut state, &mut empty, &mut accumulation, 0), 0, "no objects");
}
