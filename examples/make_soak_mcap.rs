//! Writes a long RGB-D MCAP for the soak benchmark (tools/soak.sh): the frames of an
//! occmask-converted file (e.g. TUM fr2_desk) replayed forwards and backwards (ping-pong, so
//! the camera motion stays continuous) with fresh 30 Hz timestamps, for exactly FRAMES frames.
//!
//! To keep a 30-minute recording (54 000 VGA frames) on disk, each source frame is re-encoded
//! once, as a robot would record it: colour as JPEG (quality 90, `foxglove.CompressedImage`
//! `jpeg`) and depth as 16-bit PNG in the ROS `compressed_depth_image_transport` layout
//! (`16UC1; compressedDepth png`), ≈ 0.2 MB per frame instead of 1.1 MB raw. Calibration
//! messages are copied. The pixels `occmask process` decodes are the source's, except for the
//! JPEG loss in colour.
//!
//! usage: cargo run --release --example make_soak_mcap -- IN.mcap OUT.mcap FRAMES

use std::collections::BTreeMap;
use std::io::BufWriter;

use anyhow::Context as _;
use foxglove::messages as fm;
use prost::Message as _;

use occmask::mcap_io::input::McapInput;

/// 30 Hz, as the Kinect.
const FRAME_NS: u64 = 33_333_333;
/// JPEG quality of the colour images (a typical recorder setting).
const JPEG_QUALITY: u8 = 90;
/// `compressed_depth_image_transport` header: format enum (i32) + two f32 quantisation
/// parameters, unused for 16UC1.
const COMPRESSED_DEPTH_HEADER: [u8; 12] = [0; 12];

struct SourceFrame {
    color_jpeg: Vec<u8>,
    color_frame_id: String,
    depth_png: Vec<u8>,
    depth_frame_id: String,
    calibration: Vec<u8>,
}

fn png_from_depth(raw: &fm::RawImage) -> anyhow::Result<Vec<u8>> {
    anyhow::ensure!(
        raw.encoding == "16UC1",
        "depth encoding {} (expected 16UC1)",
        raw.encoding
    );
    let (w, h, step) = (raw.width as usize, raw.height as usize, raw.step as usize);
    let mut pixels = Vec::with_capacity(w * h);
    for y in 0..h {
        let row = raw
            .data
            .get(y * step..y * step + 2 * w)
            .context("short depth image")?;
        pixels.extend(row.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])));
    }
    let img = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(raw.width, raw.height, pixels)
        .context("depth size")?;
    let mut out = std::io::Cursor::new(COMPRESSED_DEPTH_HEADER.to_vec());
    out.set_position(COMPRESSED_DEPTH_HEADER.len() as u64);
    img.write_to(&mut out, image::ImageFormat::Png)?;
    Ok(out.into_inner())
}

fn jpeg_from_color(data: &[u8], format: &str) -> anyhow::Result<Vec<u8>> {
    let rgb = image::load_from_memory(data)
        .with_context(|| format!("colour {format}"))?
        .to_rgb8();
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, JPEG_QUALITY).encode_image(&rgb)?;
    Ok(out)
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    anyhow::ensure!(args.len() == 4, "usage: make_soak_mcap IN.mcap OUT.mcap FRAMES");
    let total_frames: u64 = args[3].parse()?;
    let input = McapInput::open(std::path::Path::new(&args[1]))?;
    let (color_topic, depth_topic, calib_topic) = (
        "/camera/rgb/image",
        "/camera/depth/image",
        "/camera/rgb/camera_info",
    );
    let names = vec![
        color_topic.to_owned(),
        depth_topic.to_owned(),
        calib_topic.to_owned(),
    ];
    let mut streams: BTreeMap<String, Vec<Vec<u8>>> = BTreeMap::new();
    input.for_each_message(Some(&names), None, |m| {
        let topic = input.channels()[&m.header.channel_id].topic.clone();
        streams.entry(topic).or_default().push(m.data);
        Ok(true)
    })?;
    let count = names
        .iter()
        .map(|t| streams.get(t).map_or(0, Vec::len))
        .min()
        .unwrap_or(0);
    anyhow::ensure!(
        count >= 2,
        "need colour, depth and calibration messages in {}",
        args[1]
    );
    let mut frames = Vec::with_capacity(count);
    let sources = streams[color_topic]
        .iter()
        .zip(&streams[depth_topic])
        .zip(&streams[calib_topic])
        .take(count);
    for ((color, depth), calibration) in sources {
        let color = fm::CompressedImage::decode(color.as_slice())
            .context("colour must be a foxglove.CompressedImage (as `occmask convert tum` writes it)")?;
        let depth =
            fm::RawImage::decode(depth.as_slice()).context("depth must be a foxglove.RawImage 16UC1")?;
        frames.push(SourceFrame {
            color_jpeg: jpeg_from_color(&color.data, &color.format)?,
            color_frame_id: color.frame_id,
            depth_png: png_from_depth(&depth)?,
            depth_frame_id: depth.frame_id,
            calibration: calibration.clone(),
        });
    }

    let out = BufWriter::with_capacity(8 << 20, std::fs::File::create(&args[2])?);
    let mut w = mcap::WriteOptions::new()
        .compression(None) // JPEG and PNG do not compress further
        .chunk_size(Some(8 << 20))
        .library("make_soak_mcap")
        .create(out)?;
    let mut ids = BTreeMap::new();
    let image_schema = w.add_schema(
        "foxglove.CompressedImage",
        "protobuf",
        &input
            .schemas()
            .values()
            .find(|s| s.name == "foxglove.CompressedImage")
            .context("no CompressedImage schema in the input")?
            .data,
    )?;
    for c in input.channels().values().filter(|c| names.contains(&c.topic)) {
        let schema = if c.topic == calib_topic {
            let s = &input.schemas()[&c.schema_id];
            w.add_schema(&s.name, &s.encoding, &s.data)?
        } else {
            image_schema
        };
        ids.insert(
            c.topic.clone(),
            w.add_channel(schema, &c.topic, &c.message_encoding, &c.metadata)?,
        );
    }
    let t0 = 1_600_000_000_000_000_000u64;
    let period = 2 * (frames.len() - 1);
    let mut written = 0u64;
    for k in 0..total_frames {
        let phase = k as usize % period;
        let f = &frames[if phase < frames.len() {
            phase
        } else {
            period - phase
        }];
        let t = t0 + k * FRAME_NS;
        let stamp = Some(occmask::mcap_io::codec::timestamp(t));
        let color = fm::CompressedImage {
            timestamp: stamp,
            frame_id: f.color_frame_id.clone(),
            data: f.color_jpeg.clone().into(),
            format: "jpeg".into(),
        }
        .encode_to_vec();
        let depth = fm::CompressedImage {
            timestamp: stamp,
            frame_id: f.depth_frame_id.clone(),
            data: f.depth_png.clone().into(),
            format: "16UC1; compressedDepth png".into(),
        }
        .encode_to_vec();
        let mut calibration = fm::CameraCalibration::decode(f.calibration.as_slice())?;
        calibration.timestamp = stamp;
        let calibration = calibration.encode_to_vec();
        for (topic, bytes) in [
            (color_topic, &color),
            (calib_topic, &calibration),
            (depth_topic, &depth),
        ] {
            w.write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: ids[topic],
                    sequence: k as u32,
                    log_time: t,
                    publish_time: t,
                },
                bytes,
            )?;
            written += bytes.len() as u64;
        }
    }
    w.finish()?;
    println!(
        "{total_frames} frames ({:.1} min at 30 Hz) from {} source frames, {written} message bytes",
        total_frames as f64 * FRAME_NS as f64 / 60e9,
        frames.len()
    );
    Ok(())
}
