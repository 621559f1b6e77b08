//! Writes a large RGB-D MCAP for the `process` memory benchmark (tools/bench_process.sh) by
//! replaying the colour/depth/calibration messages of an occmask-converted file forwards and
//! backwards (so the camera motion stays continuous) with new timestamps, uncompressed, until
//! the file reaches the requested size.
//!
//! usage: cargo run --release --example make_big_rgbd_mcap -- IN.mcap OUT.mcap MIN_BYTES

use std::collections::BTreeMap;
use std::io::BufWriter;

use foxglove::messages as fm;
use prost::Message as _;

use occmask::mcap_io::input::McapInput;

/// 30 Hz, as the Kinect.
const FRAME_NS: u64 = 33_333_333;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    anyhow::ensure!(
        args.len() == 4,
        "usage: make_big_rgbd_mcap IN.mcap OUT.mcap MIN_BYTES"
    );
    let min_bytes: u64 = args[3].parse()?;
    let input = McapInput::open(std::path::Path::new(&args[1]))?;
    let topics = [
        "/camera/rgb/image",
        "/camera/depth/image",
        "/camera/rgb/camera_info",
    ];
    // Colour, depth and colour calibration messages in time order; a converted file holds pairs
    // only, so the k-th messages of the three topics form frame k.
    let mut streams: BTreeMap<&str, Vec<(String, Vec<u8>)>> = BTreeMap::new();
    let names: Vec<String> = topics.iter().map(|s| s.to_string()).collect();
    input.for_each_message(Some(&names), None, |m| {
        let channel = &input.channels()[&m.header.channel_id];
        let topic = topics
            .iter()
            .find(|t| **t == channel.topic)
            .copied()
            .unwrap_or_default();
        let key = format!("{}|{}", channel.topic, channel.schema_name);
        streams.entry(topic).or_default().push((key, m.data));
        Ok(true)
    })?;
    let count = streams.values().map(Vec::len).min().unwrap_or(0);
    anyhow::ensure!(
        streams.len() == 3 && count >= 2,
        "need colour, depth and calibration messages in {}",
        args[1]
    );
    let frames: Vec<Vec<(String, Vec<u8>)>> = (0..count)
        .map(|k| topics.iter().map(|t| streams[t][k].clone()).collect())
        .collect();

    let out = BufWriter::with_capacity(8 << 20, std::fs::File::create(&args[2])?);
    let mut w = mcap::WriteOptions::new()
        .compression(None)
        .chunk_size(Some(8 << 20))
        .library("make_big_rgbd_mcap")
        .create(out)?;
    let mut ids = BTreeMap::new();
    for c in input
        .channels()
        .values()
        .filter(|c| topics.contains(&c.topic.as_str()))
    {
        let s = &input.schemas()[&c.schema_id];
        let sid = w.add_schema(&s.name, &s.encoding, &s.data)?;
        ids.insert(
            c.topic.clone(),
            w.add_channel(sid, &c.topic, &c.message_encoding, &c.metadata)?,
        );
    }
    let t0 = 1_600_000_000_000_000_000u64;
    let (mut written, mut k, mut seq) = (0u64, 0usize, 0u32);
    let period = 2 * (frames.len() - 1);
    while written < min_bytes {
        let phase = k % period;
        let index = if phase < frames.len() {
            phase
        } else {
            period - phase
        };
        let t = t0 + k as u64 * FRAME_NS;
        let stamp = Some(occmask::mcap_io::codec::timestamp(t));
        for (topic, data) in &frames[index] {
            let (topic, schema) = topic.split_once('|').unwrap_or_default();
            let bytes = match schema {
                "foxglove.CompressedImage" => {
                    let mut m = fm::CompressedImage::decode(data.as_slice())?;
                    m.timestamp = stamp;
                    m.encode_to_vec()
                }
                "foxglove.RawImage" => {
                    let mut m = fm::RawImage::decode(data.as_slice())?;
                    m.timestamp = stamp;
                    m.encode_to_vec()
                }
                _ => {
                    let mut m = fm::CameraCalibration::decode(data.as_slice())?;
                    m.timestamp = stamp;
                    m.encode_to_vec()
                }
            };
            w.write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: ids[topic],
                    sequence: seq,
                    log_time: t,
                    publish_time: t,
                },
                &bytes,
            )?;
            written += bytes.len() as u64;
        }
        seq += 1;
        k += 1;
    }
    w.finish()?;
    println!("{} frames, {} message bytes", k, written);
    Ok(())
}
