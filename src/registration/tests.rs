//! Tests of the remap tables and of depth registration, each optimised kernel against its scalar reference.

use super::depth::{ceil_f32, whole_to_index};
use super::*;
use crate::geometry::camera::PinholeIntrinsics;
use crate::geometry::distortion::{presets, LensDistortion};
use nalgebra::{Translation3, UnitQuaternion, Vector3};

fn realsense_like() -> (CameraModel, CameraModel, Isometry3<f64>) {
    let depth = CameraModel {
        size: ImageSize::new(212, 120),
        intrinsics: PinholeIntrinsics::new(106.0, 106.0, 105.7, 59.6),
        distortion: Some(LensDistortion::plumb_bob(-0.02, 0.01, 0.0, 0.0, 0.0)),
    };
    let color = CameraModel::pinhole(
        ImageSize::new(160, 120),
        PinholeIntrinsics::new(131.0, 131.0, 79.5, 59.5),
    );
    let color_from_depth = Isometry3::from_parts(
        Translation3::new(0.015, 0.0002, -0.0004),
        UnitQuaternion::from_euler_angles(0.004, -0.003, 0.002),
    );
    (depth, color, color_from_depth)
}

/// Depth of the plane n·p = offset seen by `camera` (exact ray–plane intersection).
fn plane_depth(
    camera: &CameraModel,
    normal: Vector3<f64>,
    offset: f64,
    camera_from_world: &Isometry3<f64>,
) -> DepthMeters {
    let world_from_camera = camera_from_world.inverse();
    DepthMeters::from_fn(camera.size, |u, v| {
        let Some((x, y)) = camera.ray(u as f64, v as f64) else {
            return 0.0;
        };
        let o = world_from_camera.translation.vector;
        let dir = world_from_camera.rotation * Vector3::new(x, y, 1.0);
        let s = (offset - normal.dot(&o)) / normal.dot(&dir);
        if s > 0.0 {
            s as f32
        } else {
            0.0
        }
    })
}

#[test]
fn registering_a_plane_gives_the_plane_seen_from_colour() {
    // The law "register, then project back = identity" on a slanted plane: the registered
    // depth at every covered colour pixel is that pixel's own ray hitting the plane.
    let (depth_camera, color_camera, color_from_depth) = realsense_like();
    let normal = Vector3::new(0.2, -0.1, 1.0).normalize();
    let offset = 2.0;
    // World = colour camera.
    let depth_from_color = color_from_depth.inverse();
    let depth = plane_depth(&depth_camera, normal, offset, &depth_from_color);
    let expected = plane_depth(&color_camera, normal, offset, &Isometry3::identity());
    let mut registration =
        DepthRegistration::new(&depth_camera, &color_camera, &color_from_depth, 2).unwrap();
    let mut registered = DepthMeters::filled(color_camera.size, -1.0);
    registration.register_into(&depth, &mut registered).unwrap();
    let mut covered = 0;
    let mut worst = 0.0f32;
    for (r, e) in registered.as_slice().iter().zip(expected.as_slice()) {
        if *r > 0.0 {
            covered += 1;
            worst = worst.max((r - e).abs() / e);
        }
    }
    // The depth camera is wider than the colour camera: everything is covered, and each
    // value is the depth of a point within the depth pixel's footprint, never an
    // interpolation: 0.18 % of the depth at worst on this slant (bound 0.5 %).
    assert_eq!(covered, color_camera.size.area(), "holes on a plane");
    assert!(worst < 5e-3, "worst relative depth error {worst}");
}

#[test]
fn nearer_surfaces_win_and_disocclusions_stay_holes() {
    // A near box in front of a far wall: the colour camera, 15 mm to the side, sees wall
    // that the depth camera cannot: those pixels must stay 0, not take either depth.
    let (depth_camera, color_camera, _) = realsense_like();
    let color_from_depth = Isometry3::translation(-0.05, 0.0, 0.0);
    let depth = DepthMeters::from_fn(depth_camera.size, |u, v| {
        if (90..120).contains(&u) && (40..80).contains(&v) {
            0.5
        } else {
            3.0
        }
    });
    let mut registration =
        DepthRegistration::new(&depth_camera, &color_camera, &color_from_depth, 2).unwrap();
    let mut registered = DepthMeters::filled(color_camera.size, -1.0);
    registration.register_into(&depth, &mut registered).unwrap();
    let row = registered.row(60);
    let values: Vec<f32> = row.to_vec();
    let holes = values.iter().filter(|&&z| z == 0.0).count();
    // Parallax of the box against the wall: 131 px · 0.05 m · (1/0.5 − 1/3) m⁻¹ ≈ 10.9 px.
    assert!((9..=12).contains(&holes), "{holes} holes in {values:?}");
    assert!(values
        .iter()
        .all(|&z| z == 0.0 || (z - 0.5).abs() < 0.01 || (z - 3.0).abs() < 0.03));
    // The box keeps its depth where both see it.
    assert!(values.iter().filter(|&&z| (z - 0.5).abs() < 0.01).count() > 10);
}

#[test]
fn parallel_registration_matches_the_reference_bit_for_bit() {
    let (depth_camera, color_camera, color_from_depth) = realsense_like();
    let depth = DepthMeters::from_fn(depth_camera.size, |u, v| {
        // Noisy steps, holes and NaN-free garbage values the kernel must skip.
        let base = 1.0 + ((u * 7 + v * 13) % 17) as f32 * 0.13;
        if (u + 3 * v) % 11 == 0 {
            0.0
        } else if (u * v) % 29 == 1 {
            -1.0
        } else {
            base
        }
    });
    let pool = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap();
    let mut reference = DepthMeters::filled(color_camera.size, -2.0);
    for bands in [3, 1] {
        let mut registration =
            DepthRegistration::new(&depth_camera, &color_camera, &color_from_depth, bands).unwrap();
        assert_eq!(registration.bands.len(), bands);
        let mut fast = DepthMeters::filled(color_camera.size, -1.0);
        pool.install(|| registration.register_into(&depth, &mut fast))
            .unwrap();
        registration.register_reference(&depth, &mut reference).unwrap();
        assert_eq!(fast, reference, "{bands} bands");
        assert!(fast.as_slice().iter().any(|&z| z > 0.0));
    }
}

#[test]
fn remaps_match_their_references_and_check_sizes() {
    let camera = CameraModel {
        size: ImageSize::new(96, 64),
        intrinsics: PinholeIntrinsics::new(80.0, 80.0, 47.5, 31.5),
        distortion: Some(presets::TUM_FR1),
    };
    let bilinear = undistortion_map(&camera, &inscribed_pinhole(&camera)).unwrap();
    let nearest = NearestMap::from_fn(camera.size, camera.size, |u, v| {
        Some((u * 0.9 + 3.0, v * 1.1 - 2.0))
    })
    .unwrap();
    let gray = GrayF32::from_fn(camera.size, |x, y| ((x * 3 + y * 5) % 23) as f32 / 23.0);
    let mut a = GrayF32::filled(camera.size, 0.0);
    let mut b = GrayF32::filled(camera.size, 1.0);
    bilinear.apply_into(&gray, &mut a).unwrap();
    bilinear.apply_serial(&gray, &mut b).unwrap();
    assert_eq!(a, b);
    let depth = DepthMeters::from_fn(camera.size, |x, y| (x + y) as f32 * 0.01);
    let mut c = DepthMeters::filled(camera.size, 5.0);
    let mut d = DepthMeters::filled(camera.size, 6.0);
    nearest.apply_into(&depth, &mut c).unwrap();
    nearest.apply_serial(&depth, &mut d).unwrap();
    assert_eq!(c, d);
    bilinear.apply_depth_into(&depth, &mut c).unwrap();
    bilinear.apply_depth_serial(&depth, &mut d).unwrap();
    assert_eq!(c, d);
    let wrong = GrayF32::filled(ImageSize::new(10, 10), 0.0);
    assert!(matches!(
        bilinear.apply_into(&wrong, &mut a),
        Err(Error::SizeMismatch { .. })
    ));
    assert!(BilinearMap::from_fn(ImageSize::new(1, 5), camera.size, |u, v| Some((u, v))).is_err());
}

#[test]
fn undistorting_then_distorting_a_mask_returns_it() {
    // undistort ∘ distort ≈ identity on images: a blob mapped to the pinhole image and
    // back covers the same pixels, except a few outline pixels where the two
    // nearest-pixel roundings disagree.
    let camera = CameraModel {
        size: ImageSize::new(160, 120),
        intrinsics: PinholeIntrinsics::new(131.0, 131.0, 79.5, 59.5),
        distortion: Some(presets::TUM_FR1),
    };
    let pinhole = camera.intrinsics;
    let to_pinhole = NearestMap::from_fn(camera.size, camera.size, |u, v| {
        Some(camera.pixel((u - pinhole.cx) / pinhole.fx, (v - pinhole.cy) / pinhole.fy))
    })
    .unwrap();
    let back = distortion_map(&camera, &camera.undistorted()).unwrap();
    let blob = Image::from_fn(camera.size, |x, y| {
        let (dx, dy) = (x as f64 - 110.0, y as f64 - 30.0);
        u8::from(dx * dx + dy * dy < 400.0) * 255
    });
    let mut pinhole = Image::filled(camera.size, 0u8);
    let mut round_trip = Image::filled(camera.size, 0u8);
    to_pinhole.apply_into(&blob, &mut pinhole).unwrap();
    back.apply_into(&pinhole, &mut round_trip).unwrap();
    let set = blob.as_slice().iter().filter(|&&m| m != 0).count();
    let differ = blob
        .as_slice()
        .iter()
        .zip(round_trip.as_slice())
        .filter(|(a, b)| a != b)
        .count();
    assert!(set > 1000);
    // Measured: 8 of 1245 pixels; the bound allows 3×.
    assert!(differ * 50 < set, "{differ} of {set} pixels changed");
    // The distortion is not a no-op: the pinhole blob sits elsewhere.
    assert!(pinhole.as_slice() != blob.as_slice());
    assert!(back.covered_fraction() > 0.99);
}

#[test]
fn whole_numbers_become_indices() {
    for i in [0usize, 1, 2, 639, 640, 1 << 22, (1 << 23) - 1] {
        assert_eq!(whole_to_index(i as f32), i);
    }
}

#[test]
fn arithmetic_ceil_matches_ceil() {
    for x in [
        -2.5f32, -1.0, -0.3, -0.0, 0.0, 0.2, 0.5, 1.0, 1.0001, 2.5, 639.5, 639.99997, 1e6, 4194303.5,
    ] {
        assert_eq!(ceil_f32(x), x.ceil(), "{x}");
    }
    assert!(ceil_f32(f32::NAN).is_nan());
    assert!((ceil_f32(1e20) - 1e20).abs() <= 1e20 * 1e-6);
}

#[test]
fn the_inscribed_pinhole_image_has_data_everywhere() {
    let camera = CameraModel {
        size: ImageSize::new(160, 120),
        intrinsics: PinholeIntrinsics::new(131.0, 131.0, 79.5, 59.5),
        distortion: Some(presets::TUM_FR1),
    };
    // With K, the corners lack data (the lens pushes them out by ≈ 4.5 px here).
    let same_k = undistortion_map(&camera, &camera.undistorted()).unwrap();
    assert!(same_k.covered_fraction() < 0.97, "{}", same_k.covered_fraction());
    let inscribed = inscribed_pinhole(&camera);
    let scale = inscribed.intrinsics.fx / camera.intrinsics.fx;
    assert!(scale > 1.0 && scale < 1.1, "{scale}");
    assert_eq!(inscribed.intrinsics.cx, camera.intrinsics.cx);
    assert!((inscribed.intrinsics.fy / camera.intrinsics.fy - scale).abs() < 1e-12);
    assert_eq!(
        undistortion_map(&camera, &inscribed).unwrap().covered_fraction(),
        1.0
    );
    // The smallest such scale: 1 % less leaves pixels without data.
    let smaller = CameraModel::pinhole(
        camera.size,
        PinholeIntrinsics::new(131.0 * (scale - 0.01), 131.0 * (scale - 0.01), 79.5, 59.5),
    );
    assert!(undistortion_map(&camera, &smaller).unwrap().covered_fraction() < 1.0);
    // Barrel distortion: the pinhole image with K lies inside the recorded one.
    let barrel = CameraModel {
        distortion: Some(LensDistortion::plumb_bob(-0.2, 0.0, 0.0, 0.0, 0.0)),
        ..camera
    };
    assert_eq!(inscribed_pinhole(&barrel), barrel.undistorted());
}

#[test]
fn depth_is_interpolated_on_a_surface_but_never_across_an_edge() {
    let size = ImageSize::new(6, 4);
    // A slanted plane (2 % per pixel) left of x = 3, a surface 1 m behind it on the right,
    // and a hole at (1, 3).
    let depth = DepthMeters::from_fn(size, |x, y| match (x, y) {
        (1, 3) => 0.0,
        (x, _) if x < 3 => 2.0 * (1.0 + 0.02 * x as f32),
        _ => 3.0,
    });
    let half = BilinearMap::from_fn(size, size, |u, v| Some((u + 0.5, v + 0.25))).unwrap();
    let mut out = DepthMeters::filled(size, -1.0);
    half.apply_depth_into(&depth, &mut out).unwrap();
    // On the plane: interpolated, halfway between columns 0 and 1.
    assert!((out.get(0, 0) - 2.0 * 1.01).abs() < 1e-6, "{}", out.get(0, 0));
    // Straddling the edge (columns 2 and 3): one of the two depths, never between.
    let edge = out.get(2, 0);
    assert!(edge == depth.get(2, 0) || edge == 3.0, "{edge}");
    // Next to the hole: the nearest neighbour, not an average with 0.
    let near_hole = out.get(0, 2);
    assert!(near_hole == depth.get(1, 3) || near_hole == depth.get(0, 2) || near_hole == depth.get(1, 2));
    assert!(out.get(0, 2) == 0.0 || out.get(0, 2) >= 2.0);
}

#[test]
fn bilinear_map_of_the_identity_copies_and_interpolates() {
    let size = ImageSize::new(8, 6);
    let gray = GrayF32::from_fn(size, |x, y| (x + 10 * y) as f32);
    let identity = BilinearMap::from_fn(size, size, |u, v| Some((u, v))).unwrap();
    let mut out = GrayF32::filled(size, 0.0);
    identity.apply_into(&gray, &mut out).unwrap();
    assert_eq!(out, gray);
    let shifted = BilinearMap::from_fn(size, size, |u, v| Some((u + 0.25, v + 0.5))).unwrap();
    shifted.apply_into(&gray, &mut out).unwrap();
    assert!((out.get(2, 2) - (2.25 + 25.0)).abs() < 1e-5);
    // Outside positions clamp to the border.
    assert_eq!(out.get(7, 5), gray.get(7, 5));
}
