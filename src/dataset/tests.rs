//! Tests of the list and pose parsers, pairing, the camera presets and image decoding.

use super::*;

fn refs(times_ms: &[u64]) -> Vec<ImageRef> {
    times_ms
        .iter()
        .map(|&t| ImageRef {
            timestamp_ns: t * 1_000_000,
            path: PathBuf::new(),
        })
        .collect()
}

#[test]
fn associate_is_one_to_one_nearest_within_gap() {
    // colour at 0, 33, 66, 100; depth at 5, 30, 90 (66 has no depth within 20 ms once 90 is
    // taken by 100? |90-66| = 24 > 20 anyway).
    let a = associate(&refs(&[0, 33, 66, 100]), &refs(&[5, 30, 90, 300]), 20_000_000);
    assert_eq!(
        a.pairs,
        vec![
            FramePair { color: 0, depth: 0 },
            FramePair { color: 1, depth: 1 },
            FramePair { color: 3, depth: 2 }
        ]
    );
    assert_eq!(a.unpaired_color, vec![2]);
    assert_eq!(a.unpaired_depth, vec![3]);
}

#[test]
fn associate_gives_a_contested_depth_to_the_closer_colour() {
    let a = associate(&refs(&[0, 12]), &refs(&[10]), 20_000_000);
    assert_eq!(a.pairs, vec![FramePair { color: 1, depth: 0 }]);
    assert_eq!(a.unpaired_color, vec![0]);
    assert_eq!(nearest_gap_ns(&refs(&[0, 12]), &refs(&[10])), Some(2_000_000));
}

fn write_image(dir: &Path, name: &str, image: image::DynamicImage, format: image::ImageFormat) -> PathBuf {
    let path = dir.join(name);
    image.save_with_format(&path, format).unwrap();
    path
}

#[test]
fn jpeg_colour_checks_end_marker_and_tolerates_padding() {
    let dir = tempfile::tempdir().unwrap();
    let img = image::DynamicImage::ImageRgb8(image::RgbImage::from_pixel(16, 8, image::Rgb([10, 200, 30])));
    let path = write_image(dir.path(), "a.jpg", img, image::ImageFormat::Jpeg);
    let c = read_color(&path).unwrap();
    assert_eq!((c.format, c.size), (ColorFormat::Jpeg, ImageSize::new(16, 8)));
    let mut bytes = std::fs::read(&path).unwrap();
    bytes.extend_from_slice(&[0, 0, 0]);
    std::fs::write(&path, &bytes).unwrap();
    assert!(read_color(&path).is_ok(), "zero padding after EOI is accepted");
    std::fs::write(&path, &bytes[..bytes.len() - 10]).unwrap();
    let err = read_color(&path).unwrap_err().to_string();
    assert!(err.contains("truncated JPEG") && err.contains("a.jpg"), "{err}");
}

#[test]
fn depth_must_be_16_bit_grey() {
    let dir = tempfile::tempdir().unwrap();
    let d16 = image::DynamicImage::ImageLuma16(image::ImageBuffer::from_fn(3, 2, |x, y| {
        image::Luma([(x * 1000 + y * 7) as u16])
    }));
    let path = write_image(dir.path(), "d.png", d16, image::ImageFormat::Png);
    let d = read_depth(&path).unwrap();
    assert_eq!(d.size, ImageSize::new(3, 2));
    assert_eq!(d.data, vec![0, 1000, 2000, 7, 1007, 2007]);
    let rgb16 = image::DynamicImage::ImageRgb16(image::ImageBuffer::new(3, 2));
    let path = write_image(dir.path(), "c.png", rgb16, image::ImageFormat::Png);
    let err = read_depth(&path).unwrap_err().to_string();
    assert!(err.contains("found Rgb16") && !err.contains("8-bit"), "{err}");
}

#[test]
fn mask_thresholds_white() {
    let dir = tempfile::tempdir().unwrap();
    let gray = image::DynamicImage::ImageLuma8(image::GrayImage::from_fn(4, 1, |x, _| {
        image::Luma([[0u8, 100, 128, 255][x as usize]])
    }));
    let path = write_image(dir.path(), "m.png", gray, image::ImageFormat::Png);
    assert_eq!(read_mask(&path).unwrap().as_slice(), &[0, 0, MASK_SET, MASK_SET]);
}

/// The preset is the inverse of the dataset module's marker-to-camera transform.
#[test]
fn bonn_marker_preset_is_the_dataset_conversion() {
    use nalgebra::{Quaternion, Translation3, UnitQuaternion};
    let [x, y, z, qx, qy, qz, qw] = camera_from_marker_preset("Bonn").unwrap();
    let preset = nalgebra::Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_quaternion(Quaternion::new(qw, qx, qy, qz)),
    );
    let expected = bonn::marker_from_camera().inverse();
    assert!((preset.to_homogeneous() - expected.to_homogeneous()).norm() < 1e-12);
    assert!(camera_from_marker_preset("tum").is_none());
}

#[test]
fn camera_names() {
    assert_eq!(
        camera_from_folder_name("rgbd_dataset_freiburg2_desk"),
        Some("fr2")
    );
    assert_eq!(camera_from_folder_name("tum_fr3_walking"), Some("fr3"));
    assert_eq!(camera_from_folder_name("office"), None);
    assert_eq!(camera_from_folder_name("frame1"), None);
    assert_eq!(parse_camera("fr1").unwrap().intrinsics, presets::TUM_FR1);
    assert_eq!(parse_camera("fr1").unwrap().distortion, None);
    assert_eq!(
        parse_camera("500,501,320.5,240").unwrap(),
        CameraSpec::pinhole(PinholeIntrinsics::new(500.0, 501.0, 320.5, 240.0))
    );
    let bonn = parse_camera("Bonn").unwrap();
    assert_eq!(bonn.intrinsics, presets::BONN);
    assert_eq!(
        bonn.distortion.map(|d| d.to_ros()),
        Some(("plumb_bob", vec![0.039903, -0.099343, -0.000730, -0.000144, 0.0]))
    );
    assert_eq!(
        parse_camera("542.822841,542.576870,315.593520,237.756098,0.039903,-0.099343,-0.000730,-0.000144,0")
            .unwrap(),
        bonn
    );
    let rational = parse_camera("500,500,320,240,0.1,0.2,0,0,0.3,0.4,0.5,0.6").unwrap();
    assert_eq!(rational.distortion.map(|d| d.k6), Some(0.6));
    for bad in [
        "fr4",
        "1,2,3",
        "a,b,c,d",
        "-5,5,1,1",
        "500,500,320,240,0.1",
        "500,500,320,240,nan,0,0,0",
    ] {
        assert!(parse_camera(bad).is_err(), "{bad}");
    }
}
