//! Tests of message decoding for every flavour and of the pixel conversions.

use super::image_pixels::COMPRESSED_DEPTH_HEADER_BYTES;
use super::*;

fn raw(encoding: &str, width: u32, bpp: u32, data: Vec<u8>) -> ImageMsg {
    ImageMsg {
        timestamp_ns: 1,
        frame_id: "cam".into(),
        payload: ImagePayload::Raw {
            width,
            height: 1,
            encoding: encoding.into(),
            step: width * bpp,
            big_endian: false,
            data,
        },
    }
}

#[test]
fn colour_orders_give_the_same_gray() {
    let rgb = raw("rgb8", 2, 3, vec![10, 200, 30, 255, 0, 128]);
    let bgr = raw("bgr8", 2, 3, vec![30, 200, 10, 128, 0, 255]);
    let bgra = raw("bgra8", 2, 4, vec![30, 200, 10, 9, 128, 0, 255, 9]);
    let mut a = GrayF32::filled(ImageSize::new(1, 1), 0.0);
    let mut b = a.clone();
    let mut c = a.clone();
    gray_from_image_into(&rgb, "/c", &mut a).unwrap();
    gray_from_image_into(&bgr, "/c", &mut b).unwrap();
    gray_from_image_into(&bgra, "/c", &mut c).unwrap();
    assert_eq!(a, b);
    assert_eq!(a, c);
    let reference =
        crate::image_buf::gray_from_rgb8(&crate::image_buf::Rgb8::from_fn(ImageSize::new(2, 1), |x, _| {
            if x == 0 {
                [10, 200, 30]
            } else {
                [255, 0, 128]
            }
        }));
    assert_eq!(a, reference);
}

#[test]
fn rgb_decoding_agrees_with_the_grey_one_in_every_encoding() {
    let mut rgb = Rgb8::filled(ImageSize::new(1, 1), [0; 3]);
    for msg in [
        raw("rgb8", 2, 3, vec![10, 200, 30, 255, 0, 128]),
        raw("bgr8", 2, 3, vec![30, 200, 10, 128, 0, 255]),
        raw("bgra8", 2, 4, vec![30, 200, 10, 9, 128, 0, 255, 9]),
    ] {
        rgb_from_image_into(&msg, "/c", &mut rgb).unwrap();
        assert_eq!(rgb.as_slice(), &[[10, 200, 30], [255, 0, 128]]);
    }
    rgb_from_image_into(&raw("mono8", 2, 1, vec![7, 250]), "/c", &mut rgb).unwrap();
    assert_eq!(rgb.as_slice(), &[[7; 3], [250; 3]]);
    // UYVY: grey (chroma 128) decodes to grey with the luma's video-range level, red to red.
    rgb_from_image_into(&raw("uyvy", 2, 2, vec![128, 235, 128, 16]), "/c", &mut rgb).unwrap();
    assert_eq!(rgb.as_slice(), &[[255; 3], [0; 3]]);
    rgb_from_image_into(&raw("yuyv", 2, 2, vec![82, 90, 82, 240]), "/c", &mut rgb).unwrap();
    assert!(
        rgb.as_slice()
            .iter()
            .all(|&[r, g, b]| r > 240 && g < 10 && b < 10),
        "{rgb:?}"
    );
    // Every encoding the grey decoder takes, the colour one takes; the same errors.
    let mut gray = GrayF32::filled(ImageSize::new(1, 1), 0.0);
    for encoding in ["bayer_rggb8", "rgba8", "8UC3", "nv12"] {
        let msg = raw(encoding, 2, 1, vec![50, 60, 70, 80, 90, 100, 110, 120]);
        assert_eq!(
            gray_from_image_into(&msg, "/c", &mut gray).is_ok(),
            rgb_from_image_into(&msg, "/c", &mut rgb).is_ok(),
            "{encoding}"
        );
    }
    assert!(rgb_from_image_into(&raw("rgb8", 2, 3, vec![0; 5]), "/c", &mut rgb).is_err());
    // An odd width: the last pixel's pair is cut short (a fuzzing finding: it indexed past
    // the row); its chroma is neutral.
    rgb_from_image_into(
        &raw("uyvy", 3, 2, vec![128, 235, 128, 235, 128, 235]),
        "/c",
        &mut rgb,
    )
    .unwrap();
    assert_eq!(rgb.as_slice()[2], [255; 3]);
}

#[test]
fn depth_encodings_agree_in_metres() {
    let mm: Vec<u8> = [1500u16, 0].iter().flat_map(|v| v.to_le_bytes()).collect();
    let m: Vec<u8> = [1.5f32, f32::NAN].iter().flat_map(|v| v.to_le_bytes()).collect();
    let mut a = DepthMeters::filled(ImageSize::new(2, 1), 9.0);
    let mut b = a.clone();
    depth_from_image_into(&raw("16UC1", 2, 2, mm), "/d", 1000.0, &mut a).unwrap();
    depth_from_image_into(&raw("32FC1", 2, 4, m), "/d", 1000.0, &mut b).unwrap();
    let mut reference = DepthMeters::filled(ImageSize::new(2, 1), 0.0);
    crate::image_buf::depth_m_from_u16_into(&[1500, 0], 1000.0, &mut reference).unwrap();
    assert_eq!(
        a, reference,
        "16UC1 must match the dataset reader's scaling exactly"
    );
    assert!((a.get(0, 0) - 1.5).abs() < 1e-6 && a.get(1, 0) == 0.0);
    assert_eq!(b.as_slice(), &[1.5, 0.0]);
}

#[test]
fn packed_yuv_and_bayer_colour_give_the_gray_of_the_same_colour() {
    // A uniform colour: BT.601 video-range Y of (200, 120, 40) is 16 + 219 · luma.
    let (r, g, b) = (200u8, 120u8, 40u8);
    let rgb = raw("rgb8", 4, 3, [r, g, b].repeat(4));
    let mut expected = GrayF32::filled(ImageSize::new(1, 1), 0.0);
    gray_from_image_into(&rgb, "/c", &mut expected).unwrap();
    let luma = 16.0 + 219.0 * expected.get(0, 0);
    let y = luma.round() as u8;
    let mut gray = GrayF32::filled(ImageSize::new(1, 1), 0.0);
    for (encoding, quad) in [("yuv422", [128, y, 128, y]), ("yuv422_yuy2", [y, 128, y, 128])] {
        gray_from_image_into(&raw(encoding, 4, 2, quad.repeat(2)), "/c", &mut gray).unwrap();
        assert!(
            gray.as_slice()
                .iter()
                .all(|v| (v - expected.get(0, 0)).abs() < 0.5 / 219.0),
            "{encoding}"
        );
    }
    // Bayer RGGB mosaic of the colour, 4×4: demosaiced to the colour everywhere.
    let mosaic: Vec<u8> = (0..16)
        .map(|i| match ((i / 4) % 2, i % 2) {
            (0, 0) => r,
            (1, 1) => b,
            _ => g,
        })
        .collect();
    let msg = ImageMsg {
        payload: ImagePayload::Raw {
            width: 4,
            height: 4,
            encoding: "bayer_rggb8".into(),
            step: 4,
            big_endian: false,
            data: mosaic,
        },
        ..raw("bayer_rggb8", 4, 1, vec![])
    };
    gray_from_image_into(&msg, "/c", &mut gray).unwrap();
    assert_eq!(gray.size(), ImageSize::new(4, 4));
    assert!(gray
        .as_slice()
        .iter()
        .all(|v| (v - expected.get(0, 0)).abs() < 1e-6));
}

fn compressed_depth(format: &str, header: [f32; 2], payload: Vec<u8>) -> ImageMsg {
    let mut data = vec![0u8; 4];
    data.extend_from_slice(&header[0].to_le_bytes());
    data.extend_from_slice(&header[1].to_le_bytes());
    data.extend(payload);
    ImageMsg {
        timestamp_ns: 1,
        frame_id: "cam".into(),
        payload: ImagePayload::Compressed {
            format: format.into(),
            data,
        },
    }
}

#[test]
fn compressed_depth_rvl_and_inverse_depth_decode() {
    let values: Vec<u16> = vec![1500, 0, 1502, 1498, 0, 0];
    let mut payload = Vec::new();
    payload.extend_from_slice(&3u32.to_le_bytes());
    payload.extend_from_slice(&2u32.to_le_bytes());
    payload.extend(pixels::encode_rvl(&values));
    let msg = compressed_depth("16UC1; compressedDepth rvl", [0.0, 0.0], payload.clone());
    assert!(msg.is_depth());
    let mut d = DepthMeters::filled(ImageSize::new(1, 1), 9.0);
    depth_from_image_into(&msg, "/d", 1000.0, &mut d).unwrap();
    let mut reference = DepthMeters::filled(ImageSize::new(3, 2), 0.0);
    crate::image_buf::depth_m_from_u16_into(&values, 1000.0, &mut reference).unwrap();
    assert_eq!(d, reference);
    // 32FC1: quantised inverse depth, depth = a / (q − b); q = 0 is invalid.
    let msg = compressed_depth("32FC1; compressedDepth rvl", [3000.0, -0.5], payload);
    depth_from_image_into(&msg, "/d", 1000.0, &mut d).unwrap();
    assert!((d.get(0, 0) - 3000.0 / 1500.5).abs() < 1e-5 && d.get(1, 0) == 0.0);
    // A size the stream cannot hold is refused before allocating.
    let mut huge = Vec::new();
    huge.extend_from_slice(&100_000u32.to_le_bytes());
    huge.extend_from_slice(&100_000u32.to_le_bytes());
    huge.extend_from_slice(&[0; 8]);
    let err = depth_from_image_into(
        &compressed_depth("16UC1; compressedDepth rvl", [0.0; 2], huge),
        "/d",
        1.0,
        &mut d,
    )
    .unwrap_err();
    assert!(
        matches!(&err, Error::Decode { topic, problem: DecodeProblem::Compressed { mismatch, .. }, .. }
            if topic == "/d" && mismatch.found.contains("100000x100000")),
        "{err}"
    );
    let short = compressed_depth("16UC1; compressedDepth rvl", [0.0; 2], vec![1, 2]);
    let err = depth_from_image_into(&short, "/d", 1.0, &mut d).unwrap_err();
    assert!(
        matches!(&err, Error::Decode { problem: DecodeProblem::Compressed { what, .. }, .. }
            if what == "16UC1; compressedDepth rvl"),
        "{err}"
    );
}

#[test]
fn compressed_depth_png_skips_its_config_header() {
    let raw = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(2, 1, vec![1500, 0]).unwrap();
    let mut png = std::io::Cursor::new(Vec::new());
    raw.write_to(&mut png, image::ImageFormat::Png).unwrap();
    let mut data = vec![0u8; COMPRESSED_DEPTH_HEADER_BYTES];
    data.extend_from_slice(png.get_ref());
    let msg = ImageMsg {
        timestamp_ns: 1,
        frame_id: "cam".into(),
        payload: ImagePayload::Compressed {
            format: "16UC1; compressedDepth png".into(),
            data,
        },
    };
    assert!(msg.is_depth());
    let mut d = DepthMeters::filled(ImageSize::new(1, 1), 9.0);
    depth_from_image_into(&msg, "/d", 1000.0, &mut d).unwrap();
    let mut reference = DepthMeters::filled(ImageSize::new(2, 1), 0.0);
    crate::image_buf::depth_m_from_u16_into(&[1500, 0], 1000.0, &mut reference).unwrap();
    assert_eq!(d, reference);
}

/// `32FC1; compressedDepth png` (compressed_depth_image_transport's float depth): a 16-bit
/// PNG of quantised inverse depth q = a / d + b, with ROS's defaults (quantisation 100,
/// 10 m range: a = 100 · 101, b = 1 − a / 10); q = 0 marks invalid depth.
#[test]
fn compressed_depth_png_32fc1_is_inverse_depth() {
    let a = 100.0f32 * 101.0;
    let b = 1.0 - a / 10.0;
    let depth_m = [0.6f32, 1.5, 4.25, 9.5, f32::NAN, 0.0];
    let q: Vec<u16> = depth_m
        .iter()
        .map(|&d| {
            if d.is_finite() && d > 0.0 {
                (a / d + b).round() as u16
            } else {
                0
            }
        })
        .collect();
    let png_image = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(3, 2, q).unwrap();
    let mut png = std::io::Cursor::new(Vec::new());
    png_image.write_to(&mut png, image::ImageFormat::Png).unwrap();
    let msg = compressed_depth("32FC1; compressedDepth png", [a, b], png.into_inner());
    assert!(msg.is_depth());
    let mut d = DepthMeters::filled(ImageSize::new(1, 1), 9.0);
    // Metres already: the units flag does not scale float depth.
    depth_from_image_into(&msg, "/d", 5000.0, &mut d).unwrap();
    assert_eq!(d.size(), ImageSize::new(3, 2));
    for (i, (&got, &want)) in d.as_slice().iter().zip(&depth_m).enumerate() {
        if want.is_finite() && want > 0.0 {
            // Half a quantisation step of inverse depth: d² / (2a), 4.5 mm at 9.5 m.
            let bound = want * want / (2.0 * a) + 1e-6;
            assert!(
                (got - want).abs() <= bound,
                "pixel {i}: {got} vs {want} (bound {bound})"
            );
        } else {
            assert_eq!(got, 0.0, "pixel {i}");
        }
    }
    // The 16-bit reading of the same bytes is raw units, not inverse depth.
    let mut raw_units = DepthMeters::filled(ImageSize::new(1, 1), 0.0);
    let as_16 = ImageMsg {
        payload: match &msg.payload {
            ImagePayload::Compressed { data, .. } => ImagePayload::Compressed {
                format: "16UC1; compressedDepth png".into(),
                data: data.clone(),
            },
            ImagePayload::Raw { .. } => unreachable!(),
        },
        ..msg.clone()
    };
    depth_from_image_into(&as_16, "/d", 1000.0, &mut raw_units).unwrap();
    assert!((raw_units.get(1, 0) - d.get(1, 0)).abs() > 1.0);
}

#[test]
fn unsupported_encodings_are_named() {
    let mut g = GrayF32::filled(ImageSize::new(1, 1), 0.0);
    let err = gray_from_image_into(&raw("nv12", 2, 2, vec![0; 4]), "/c", &mut g).unwrap_err();
    assert!(
        matches!(&err, Error::Decode {
            topic,
            problem: DecodeProblem::UnsupportedEncoding { image: ImageKind::Color, found, supported },
            ..
        } if topic == "/c" && found == "nv12" && supported.contains("rgb8")),
        "{err}"
    );
    let mut d = DepthMeters::filled(ImageSize::new(1, 1), 0.0);
    let err = depth_from_image_into(&raw("8UC1", 2, 1, vec![0; 2]), "/d", 1.0, &mut d).unwrap_err();
    assert!(
        matches!(&err, Error::Decode {
            problem: DecodeProblem::UnsupportedEncoding { image: ImageKind::Depth, found, supported },
            ..
        } if found == "8UC1" && supported.contains("32FC1")),
        "{err}"
    );
}

#[test]
fn zero_sized_raw_images_are_rejected_before_any_row_loop() {
    // 0 × u32::MAX passed every length check with no data and then looped over 4 billion
    // empty rows (fuzz/regressions/*/slow-zero-width-4g-rows).
    let msg = ImageMsg {
        timestamp_ns: 1,
        frame_id: "cam".into(),
        payload: ImagePayload::Raw {
            width: 0,
            height: u32::MAX,
            encoding: "mono8".into(),
            step: 0,
            big_endian: false,
            data: Vec::new(),
        },
    };
    let mut g = GrayF32::filled(ImageSize::new(1, 1), 0.0);
    let err = gray_from_image_into(&msg, "/c", &mut g).unwrap_err();
    assert!(
        matches!(&err, Error::Decode { topic, problem: DecodeProblem::EmptyImage { size }, .. }
            if topic == "/c" && *size == ImageSize::new(0, u32::MAX as usize)),
        "{err}"
    );
}

#[test]
fn compressed_images_declaring_huge_sizes_are_rejected_before_decoding() {
    // A PNG header declaring 20000×20000 made the decoder allocate 400 MB for a 60-byte
    // message before failing on the missing pixel data.
    let header = |w: u32, h: u32| {
        let buf = image::GrayImage::new(1, 1);
        let mut png = std::io::Cursor::new(Vec::new());
        buf.write_to(&mut png, image::ImageFormat::Png).unwrap();
        let mut png = png.into_inner();
        // IHDR data starts after the signature (8), length (4) and type (4).
        png[16..20].copy_from_slice(&w.to_be_bytes());
        png[20..24].copy_from_slice(&h.to_be_bytes());
        let crc = crc32(&png[12..29]);
        png[29..33].copy_from_slice(&crc.to_be_bytes());
        png
    };
    let msg = |data| ImageMsg {
        timestamp_ns: 1,
        frame_id: "cam".into(),
        payload: ImagePayload::Compressed {
            format: "png".into(),
            data,
        },
    };
    let mut g = GrayF32::filled(ImageSize::new(1, 1), 0.0);
    let err = gray_from_image_into(&msg(header(20_000, 20_000)), "/c", &mut g).unwrap_err();
    assert!(
        matches!(&err, Error::Decode { topic, problem: DecodeProblem::Compressed { mismatch, .. }, .. }
            if topic == "/c" && mismatch.found.contains("20000x20000")),
        "{err}"
    );
    // The same header with the real 1×1 size still decodes.
    gray_from_image_into(&msg(header(1, 1)), "/c", &mut g).unwrap();
    assert_eq!(g.size(), ImageSize::new(1, 1));
}

/// CRC-32 (PNG chunk checksum), bitwise.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

#[test]
fn ros2_image_decodes_from_cdr() {
    let msg = ros2::Image {
        header: ros2::Header {
            stamp: ros2::Time {
                sec: 12,
                nanosec: 345,
            },
            frame_id: "cam".into(),
        },
        height: 1,
        width: 2,
        encoding: "16UC1".into(),
        is_bigendian: 0,
        step: 4,
        data: vec![1, 0, 2, 0],
    };
    let bytes = cdr::serialize::<_, _, cdr::CdrLe>(&msg, cdr::Infinite).unwrap();
    assert_eq!(&bytes[..4], &[0, 1, 0, 0]);
    let ct = ChannelType::classify(ros2::names::IMAGE, "cdr").unwrap();
    let img = decode_image(ct, "/d", &bytes).unwrap();
    assert_eq!(img.timestamp_ns, 12_000_000_345);
    assert!(img.is_depth());
    let mut d = DepthMeters::filled(ImageSize::new(1, 1), 0.0);
    depth_from_image_into(&img, "/d", 1.0, &mut d).unwrap();
    assert_eq!(d.as_slice(), &[1.0, 2.0]);
}

#[test]
fn json_stamps_beyond_u64_nanoseconds_are_errors_not_wrapped() {
    let ct = ChannelType::classify("foxglove.PoseInFrame", "json").unwrap();
    let text = br#"{"timestamp":{"sec":18446744073709551615,"nsec":0},"frame_id":"w",
        "pose":{"position":{"x":0,"y":0,"z":0},"orientation":{"x":0,"y":0,"z":0,"w":1}}}"#;
    let err = decode_poses(ct, "/p", text).unwrap_err();
    assert!(
        matches!(&err, Error::Decode { topic, problem: DecodeProblem::Value(m), .. }
            if topic == "/p" && m.found.contains("18446744073709551615")),
        "{err}"
    );
}

#[test]
fn json_calibration_uses_upper_case_fields() {
    let text = br#"{"timestamp":{"sec":1,"nsec":2},"frame_id":"c","width":4,"height":3,
        "distortion_model":"plumb_bob","D":[],"K":[500,0,2,0,501,1.5,0,0,1],"R":[],"P":[]}"#;
    let ct = ChannelType::classify("foxglove.CameraCalibration", "json").unwrap();
    let c = decode_calibration(ct, "/ci", text).unwrap();
    assert_eq!(c.timestamp_ns, 1_000_000_002);
    let k = c.intrinsics("/ci").unwrap();
    assert_eq!((k.fx, k.fy, k.cx, k.cy), (500.0, 501.0, 2.0, 1.5));
    let zero = CalibrationMsg { k: vec![0.0; 9], ..c };
    let error = zero.intrinsics("/ci").unwrap_err();
    assert!(error.to_string().contains("uncalibrated"), "{error}");
    assert!(matches!(error, Error::BadIntrinsics { ref topic, .. } if topic == "/ci"));
}

#[test]
fn tf_message_yields_every_transform() {
    let tf = |child: &str, x: f64| ros2::TransformStamped {
        header: ros2::Header {
            stamp: ros2::Time { sec: 1, nanosec: 0 },
            frame_id: "world".into(),
        },
        child_frame_id: child.into(),
        transform: ros2::Transform {
            translation: ros2::Point { x, y: 0.0, z: 0.0 },
            rotation: ros2::Quaternion {
                w: 1.0,
                ..Default::default()
            },
        },
    };
    let msg = ros2::TfMessage {
        transforms: vec![tf("a", 1.0), tf("b", 2.0)],
    };
    let bytes = cdr::serialize::<_, _, cdr::CdrLe>(&msg, cdr::Infinite).unwrap();
    let ct = ChannelType::classify(ros2::names::TF_MESSAGE, "cdr").unwrap();
    let poses = decode_poses(ct, "/tf", &bytes).unwrap();
    assert_eq!(poses.len(), 2);
    assert_eq!(poses[1].child_frame.as_deref(), Some("b"));
    assert_eq!(poses[1].parent_from_child.translation.vector.x, 2.0);
}

#[test]
fn truncated_raw_images_are_image_length_errors() {
    // 16UC1 declared, 8-bit data: half the bytes a 2×1 image needs.
    let mut d = DepthMeters::filled(ImageSize::new(1, 1), 0.0);
    let err = depth_from_image_into(&raw("16UC1", 2, 2, vec![0; 2]), "/d", 1.0, &mut d).unwrap_err();
    assert!(
        matches!(
            &err,
            Error::Decode {
                problem: DecodeProblem::ImageLength {
                    needed: 4,
                    found: 2,
                    bytes_per_pixel: 2,
                    ..
                },
                ..
            }
        ),
        "{err}"
    );
    assert_eq!(
        err.to_string(),
        "topic /d: image 2x1 with step 4 and 2 bytes per pixel needs 4 bytes, found 2 (width, height, \
         step or encoding disagree with the data)"
    );
}
