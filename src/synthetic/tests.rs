//! Tests of the synthetic scenes: geometry against the analytic boxes, the sensor model,
//! determinism and the scenario catalogue.

use super::*;

fn small_config() -> SequenceConfig {
    SequenceConfig {
        size: ImageSize::new(320, 240),
        ..SequenceConfig::default()
    }
}

#[test]
fn rendering_is_deterministic_and_seed_dependent() {
    let sequence = SyntheticSequence::new(Scenario::TwoObjectsCrossing, small_config());
    let a = sequence.frame(20);
    let b = sequence.frame(20);
    assert_eq!(a, b);
    let other_seed = SyntheticSequence::new(
        Scenario::TwoObjectsCrossing,
        SequenceConfig {
            seed: 2,
            ..small_config()
        },
    );
    let c = other_seed.frame(20);
    assert_eq!(
        a.depth_true_m, c.depth_true_m,
        "geometry does not depend on the seed"
    );
    assert_ne!(a.rgb, c.rgb, "texture and noise do");
}

#[test]
fn true_depth_matches_analytic_far_wall_and_box() {
    let config = SequenceConfig {
        sensor: DepthSensorModel::ideal(),
        rgb_noise_levels: 0.0,
        ..small_config()
    };
    let (reference, _) = motion_pair(config, &Isometry3::identity(), true);
    let k = config.intrinsics();
    // The box's front face is the plane z = 1.5 m spanning x ∈ [−0.75, 0.25], y ∈ [−0.375, 0.375].
    let (px, py) = (k.cx.round() as usize, k.cy.round() as usize);
    assert!((reference.depth_m.get(px, py) - 1.5).abs() < 1e-3);
    assert_eq!(reference.gt_mask.get(px, py), MASK_SET);
    // A pixel left of the box edge projection sees the far wall at z = 4.5 m... or a side wall.
    let x_edge = k.fx * (-0.75 / 1.5) + k.cx;
    let left = (x_edge - 3.0) as usize;
    let z_left = reference.depth_m.get(left, py) as f64;
    assert!((z_left - 4.5).abs() < 1e-3, "far wall depth {z_left}");
    assert_eq!(reference.gt_mask.get(left, py), 0);
    let inside = (x_edge + 3.0) as usize;
    assert_eq!(reference.gt_mask.get(inside, py), MASK_SET);
    // The mask equals the set of pixels whose ray hits the box front face region.
    let mut mismatches = 0;
    for y in 0..config.size.height {
        for x in 0..config.size.width {
            let u = (x as f64 - k.cx) / k.fx * 1.5;
            let v = (y as f64 - k.cy) / k.fy * 1.5;
            let on_face = (-0.75..=0.25).contains(&u) && (-0.375..=0.375).contains(&v);
            mismatches += usize::from(on_face != (reference.gt_mask.get(x, y) == MASK_SET));
        }
    }
    // Only pixels whose ray grazes the face boundary may disagree (rounding on the edge).
    assert!(
        mismatches <= 4,
        "{mismatches} mask pixels disagree with the analytic box"
    );
}

#[test]
fn motion_pair_second_view_is_consistent_with_the_motion() {
    let config = SequenceConfig {
        sensor: DepthSensorModel::ideal(),
        rgb_noise_levels: 0.0,
        ..small_config()
    };
    let current_from_reference =
        Isometry3::new(Vector3::new(0.03, -0.01, 0.02), Vector3::new(0.01, -0.02, 0.005));
    let (reference, current) = motion_pair(config, &current_from_reference, false);
    let k = config.intrinsics();
    let mut checked = 0;
    let mut worst: f64 = 0.0;
    for y in (10..config.size.height - 10).step_by(7) {
        for x in (10..config.size.width - 10).step_by(7) {
            let z = reference.depth_m.get(x, y) as f64;
            let p = current_from_reference * k.back_project(x as f64, y as f64, z);
            let Some(q) = k.project(&p) else { continue };
            let (qx, qy) = (q.x.round() as usize, q.y.round() as usize);
            if q.x < 0.0 || q.y < 0.0 || qx >= config.size.width || qy >= config.size.height {
                continue;
            }
            // Compare with the bilinear-free nearest pixel: depth changes smoothly on walls.
            let zc = current.depth_m.get(qx, qy) as f64;
            let rel = (zc - p.z).abs() / p.z;
            if rel < 0.05 {
                worst = worst.max(rel);
                checked += 1;
            }
        }
    }
    assert!(checked > 1000, "only {checked} correspondences");
    assert!(worst < 0.02, "worst relative depth disagreement {worst}");
}

#[test]
fn depth_noise_grows_with_z_squared() {
    // A fronto-parallel wall at several distances: measured − true depth over many pixels.
    for &distance in &[1.0, 2.0, 4.0] {
        let config = SequenceConfig {
            sensor: DepthSensorModel {
                disparity_step_px: 0.0,
                dropout_probability: 0.0,
                ..DepthSensorModel::default()
            },
            ..small_config()
        };
        let camera = CameraPath {
            start_m: Vector3::new(0.0, 0.0, 4.5 - distance),
            ..CameraPath::fixed()
        };
        let sequence = SyntheticSequence::custom(config, camera, Vec::new(), 1);
        let frame = sequence.frame(0);
        let (mut n, mut sum, mut sum_sq) = (0.0f64, 0.0f64, 0.0f64);
        let (w, h) = (config.size.width, config.size.height);
        for y in h / 2 - 20..h / 2 + 20 {
            for x in w / 2 - 20..w / 2 + 20 {
                let z = frame.depth_m.get(x, y) as f64;
                assert!(z > 0.0);
                let e = z - frame.depth_true_m.get(x, y) as f64;
                n += 1.0;
                sum += e;
                sum_sq += e * e;
            }
        }
        let mean = sum / n;
        let sigma = (sum_sq / n - mean * mean).sqrt();
        let expected = 1.425e-3 * distance * distance;
        // 1600 samples: the σ estimate is within ±10 % at 3 standard errors (3/√(2·1600) ≈ 7.5 %),
        // plus the 0.2 mm storage quantisation (uniform, σ = 0.058 mm).
        assert!(
            (sigma - expected).abs() < 0.1 * expected + 1e-4,
            "Z = {distance}: σ = {sigma}, expected {expected}"
        );
        assert!(
            mean.abs() < 3.0 * expected / n.sqrt() + 1e-4,
            "Z = {distance}: bias {mean}"
        );
    }
}

#[test]
fn sensor_invalidates_borders_and_depth_edges_and_quantises() {
    let config = small_config();
    let sequence = SyntheticSequence::new(Scenario::DominantObject, config);
    let frame = sequence.frame(60);
    let (w, h) = (config.size.width, config.size.height);
    let border = config.sensor.border_px;
    for x in 0..w {
        assert_eq!(frame.depth_raw.get(x, 0), 0);
        assert_eq!(frame.depth_raw.get(x, h - border), 0);
    }
    let mut edges = 0;
    let mut edges_invalid = 0;
    let mut near_valid = 0;
    for y in border + 1..h - border - 1 {
        for x in border + 1..w - border - 1 {
            let z = frame.depth_true_m.get(x, y);
            let right = frame.depth_true_m.get(x + 1, y);
            if (right - z).abs() > 0.3 {
                // The far side of the edge is invalid, the near side measured.
                let (far, near) = if right > z { (x + 1, x) } else { (x, x + 1) };
                edges += 1;
                edges_invalid += usize::from(frame.depth_raw.get(far, y) == 0);
                near_valid += usize::from(frame.depth_raw.get(near, y) != 0);
            }
            let raw = frame.depth_raw.get(x, y);
            assert_eq!(frame.depth_m.get(x, y), raw as f32 / DEPTH_UNITS_PER_M);
        }
    }
    assert!(
        edges > 50,
        "the dominant object must produce depth edges ({edges})"
    );
    assert_eq!(edges, edges_invalid);
    // Near-side pixels are valid unless they are themselves the far side of another edge or dropped.
    assert!(near_valid as f64 > 0.9 * edges as f64, "{near_valid} of {edges}");
    let valid = frame.depth_raw.as_slice().iter().filter(|&&r| r > 0).count();
    assert!(
        valid as f64 > 0.85 * (w * h) as f64,
        "valid fraction too low: {valid}"
    );
}

#[test]
fn dominant_object_covers_half_of_the_view_for_many_frames() {
    let config = SequenceConfig {
        size: ImageSize::new(160, 120),
        ..SequenceConfig::default()
    };
    let sequence = SyntheticSequence::new(Scenario::DominantObject, config);
    let dominant = (0..sequence.len())
        .filter(|&i| sequence.frame(i).gt_fraction() >= 0.5)
        .count();
    assert!(dominant >= 40, "only {dominant} frames with ≥ 50 % object");
}

#[test]
fn every_scenario_is_well_formed() {
    let config = SequenceConfig {
        size: ImageSize::new(160, 120),
        ..SequenceConfig::default()
    };
    for scenario in Scenario::ALL {
        let sequence = SyntheticSequence::new(scenario, config);
        let with_objects = (0..sequence.len())
            .filter(|&i| sequence.frame(i).gt_fraction() > 0.0)
            .count();
        if scenario == Scenario::StaticScene {
            assert_eq!(with_objects, 0);
        } else {
            assert!(
                with_objects >= sequence.len() / 3,
                "{}: {with_objects} frames",
                scenario.name()
            );
        }
        // The camera moves by a plausible hand-held amount per frame.
        let step = sequence.current_from_previous(10).translation.vector.norm();
        assert!(
            step > 1e-4 && step < 0.03,
            "{}: camera step {step}",
            scenario.name()
        );
    }
}

/// What each failure-class scenario is built to show holds in its ground truth.
#[test]
fn failure_class_scenarios_show_their_class() {
    let config = SequenceConfig {
        size: ImageSize::new(160, 120),
        ..SequenceConfig::default()
    };
    for scenario in Scenario::FAILURE_CLASSES.into_iter().chain(Scenario::HELD_OUT) {
        let name = scenario.name();
        let class = scenario
            .failure_class()
            .expect("every later scenario has a class");
        assert_eq!(Scenario::from_name(name), Some(scenario));
        assert_eq!(
            scenario.is_static(),
            class == FailureClass::StaticControl,
            "{name}"
        );
        let sequence = SyntheticSequence::new(scenario, config);
        let frames: Vec<SyntheticFrame> = (0..sequence.len()).map(|i| sequence.frame(i)).collect();
        let with_objects = frames.iter().filter(|f| f.gt_fraction() > 0.0).count();
        if scenario.is_static() {
            assert_eq!(with_objects, 0, "{name}");
        } else {
            assert!(
                with_objects >= sequence.len() / 2,
                "{name}: {with_objects} frames"
            );
        }
        for f in &frames {
            // The ground truth lies on boxes, and only on boxes that move.
            for (&truth, &object) in f.gt_mask.as_slice().iter().zip(f.object_index.as_slice()) {
                if truth != 0 {
                    assert!(object > 0, "{name}: ground truth on the room");
                    let b = &sequence.boxes[usize::from(object) - 1];
                    assert!(!b.legs.is_empty(), "{name}: ground truth on a static box");
                }
            }
        }
        let step = sequence.current_from_previous(10).translation.vector.norm();
        assert!(step > 1e-4 && step < 0.03, "{name}: camera step {step}");
        let first = frames[0].gt_fraction();
        match scenario {
            Scenario::InViewAtStart
            | Scenario::StopAndGo
            | Scenario::HeldOutInViewAtStart
            | Scenario::HeldOutHeadOnApproach
            | Scenario::HeldOutSlowCart => {
                assert!(first > 0.01, "{name}: moving in view at frame 0 ({first})")
            }
            Scenario::DominantFromStart
            | Scenario::HeldOutDominantFromStart
            | Scenario::HeldOutDominantOnFloor
            | Scenario::HeldOutCloseOnFloor
            | Scenario::HeldOutWideOnFloor => {
                assert!(first > 0.5, "{name}: {first} of frame 0")
            }
            Scenario::RestsThenMovesSlowly | Scenario::HeldOutRestsThenMoves | Scenario::HeadOnApproach => {
                // In view but resting: the first frames have no ground truth, yet the box is seen.
                assert_eq!(first, 0.0, "{name}");
                assert!(frames[0].object_index.as_slice().iter().any(|&o| o > 0), "{name}");
            }
            Scenario::SlidingOnDesk | Scenario::HeldOutSlidingOnFloor => {
                // Enters the view.
                assert_eq!(first, 0.0, "{name}");
            }
            _ => {}
        }
        if class == FailureClass::HeadOnApproach {
            // The box moves along the optical axis of the camera: straight at it.
            let b = &sequence.boxes[0];
            for leg in b.legs.iter().filter(|l| l.velocity_mps.norm() > 0.0) {
                let v = leg.velocity_mps;
                assert!(v.z < 0.0 && v.x == 0.0 && v.y == 0.0, "{name}: {v:?}");
            }
            let centre = frames[0].world_from_objects[0].translation.vector;
            assert!(centre.x.abs() < 0.3 && centre.y.abs() < 0.2, "{name}: {centre:?}");
        }
        if class == FailureClass::NearBackground {
            // A static box or the floor lies right under the sliding box.
            let b = &sequence.boxes[sequence.boxes.len() - 1];
            let bottom = b.world_from_object_start.translation.vector.y + b.half_extents_m.y;
            let support = sequence
                .boxes
                .iter()
                .filter(|s| s.legs.is_empty())
                .map(|s| s.world_from_object_start.translation.vector.y - s.half_extents_m.y)
                .chain([sequence.room.max_m.y])
                .any(|top| (top - bottom).abs() < 1e-9);
            assert!(support, "{name}: nothing under the box");
        }
    }
}

#[test]
fn object_index_names_the_box_seen_first() {
    let config = SequenceConfig {
        size: ImageSize::new(160, 120),
        sensor: DepthSensorModel::ideal(),
        ..SequenceConfig::default()
    };
    let sequence = SyntheticSequence::new(Scenario::SlidingOnDesk, config);
    let frame = sequence.frame(50);
    let count = |k: u8| frame.object_index.as_slice().iter().filter(|&&o| o == k).count();
    // The desk (box 1) fills much of the view, the sliding box (box 2) some of it, and the
    // sliding box is exactly the ground truth.
    assert!(count(1) > frame.object_index.size().area() / 3);
    assert!(count(2) > 100);
    let truth = frame.gt_mask.as_slice().iter().filter(|&&m| m != 0).count();
    assert_eq!(truth, count(2));
}

#[test]
fn texture_has_strong_gradients() {
    let config = small_config();
    let frame = SyntheticSequence::new(Scenario::StaticScene, config).frame(0);
    let (w, h) = (config.size.width, config.size.height);
    let mut strong = 0;
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let gx = 0.5 * (frame.gray.get(x + 1, y) - frame.gray.get(x - 1, y));
            strong += usize::from(gx.abs() > 0.02);
        }
    }
    assert!(
        strong as f64 > 0.2 * (w * h) as f64,
        "only {strong} pixels with |∂I/∂x| > 0.02"
    );
}
