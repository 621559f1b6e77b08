"""Reads an `occmask process` output with the official Python readers.

usage: python process_validate.py FILE FRAMES

Decodes every message: protobuf channels with mcap-protobuf-support, ROS 2 cdr channels with
mcap-ros2-support, ROS 1 channels with mcap-ros1-support, json channels with json.loads. Checks: summary present; log times
non-decreasing; FRAMES messages on /occmask/mask, /occmask/mask_annotations, /occmask/odometry
and /occmask/stats; masks mono8 0/255 with the colour frame; annotations with translucent fill
and the mask's stamp; unit quaternions; stats fields of schemas/occmask.FrameStats.json;
/occmask/points, when present: FRAMES point clouds at the masks' stamps with float32 x/y/z and
uint8 red/green/blue/alpha fields inside the stride, finite points in front of the camera.
Prints one JSON line with per-topic counts; exits 1 on any failure.
"""

import json
import math
import struct
import sys

from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
from mcap_ros1.decoder import DecoderFactory as Ros1DecoderFactory
from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory


def fail(msg):
    print(f"FAIL: {msg}", file=sys.stderr)
    sys.exit(1)


def ns(ts):
    return ts.seconds * 1_000_000_000 + ts.nanos


def main():
    path, frames = sys.argv[1], int(sys.argv[2])
    factories = [ProtobufDecoderFactory(), Ros2DecoderFactory(), Ros1DecoderFactory()]
    decoders = {}
    counts = {}
    mask_stamps = []
    annotation_stamps = []
    cloud_stamps = []
    last = 0
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is None:
            fail("no summary section")
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            topic = channel.topic
            counts[topic] = counts.get(topic, 0) + 1
            if message.log_time < last:
                fail(f"{topic}: log time {message.log_time} before {last}")
            last = message.log_time
            if channel.message_encoding == "json":
                decoded = json.loads(message.data)
            else:
                key = channel.id
                if key not in decoders:
                    for factory in factories:
                        d = factory.decoder_for(channel.message_encoding, schema)
                        if d is not None:
                            decoders[key] = d
                            break
                    else:
                        fail(f"{topic}: no decoder for {channel.message_encoding}")
                decoded = decoders[key](message.data)
            if topic == "/occmask/mask":
                if decoded.encoding != "mono8" or set(decoded.data) - {0, 255}:
                    fail("mask not mono8 0/255")
                if len(decoded.data) != decoded.width * decoded.height:
                    fail("mask size")
                mask_stamps.append(ns(decoded.timestamp))
            elif topic == "/occmask/mask_annotations":
                annotation_stamps.append(ns(decoded.timestamp))
                for p in decoded.points:
                    if p.type != 2 or not (0 < p.fill_color.a < 1) or len(p.points) < 3:
                        fail("annotation polygon")
            elif topic == "/occmask/points":
                cloud_stamps.append(ns(decoded.timestamp))
                stride = decoded.point_stride
                fields = {f.name: (f.offset, f.type) for f in decoded.fields}
                float32, uint8 = 7, 1
                for name, kind in (("x", float32), ("y", float32), ("z", float32), ("red", uint8),
                                   ("green", uint8), ("blue", uint8), ("alpha", uint8)):
                    offset, found = fields.get(name, (None, None))
                    size = 4 if kind == float32 else 1
                    if found != kind or offset + size > stride:
                        fail(f"point field {name}: {fields.get(name)}")
                if stride <= 0 or len(decoded.data) % stride:
                    fail(f"point data {len(decoded.data)} bytes, stride {stride}")
                for o in range(0, len(decoded.data), stride):
                    x, y, z = (struct.unpack_from("<f", decoded.data, o + fields[n][0])[0] for n in "xyz")
                    if not all(math.isfinite(v) for v in (x, y, z)) or z <= 0:
                        fail(f"point ({x}, {y}, {z})")
            elif topic == "/occmask/odometry":
                q = decoded.pose.orientation
                if abs(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1) > 1e-9 or decoded.frame_id != "world":
                    fail("odometry pose")
            elif topic == "/occmask/stats":
                for key in ("timestamp", "frame_index", "pose_source", "dvo_status", "dvo_iterations",
                            "dvo_cost", "pose_fallback", "consecutive_failures", "detector_reset",
                            "valid_depth_fraction", "moving_fraction", "moving_pixels", "decode_ms", "process_ms"):
                    if key not in decoded:
                        fail(f"stats without {key}")
                for key in ("dvo_cost", "valid_depth_fraction", "moving_fraction", "decode_ms", "process_ms"):
                    if not isinstance(decoded[key], (int, float)) or not math.isfinite(decoded[key]):
                        fail(f"stats {key} = {decoded[key]!r} is not a finite number")
        stats = summary.statistics
        if stats is not None and stats.message_count != sum(counts.values()):
            fail(f"statistics say {stats.message_count} messages, read {sum(counts.values())}")
    for topic in ("/occmask/mask", "/occmask/mask_annotations", "/occmask/odometry", "/occmask/stats"):
        if counts.get(topic, 0) != frames:
            fail(f"{topic}: expected {frames} messages, found {counts.get(topic, 0)}")
    if mask_stamps != annotation_stamps:
        fail("annotation stamps differ from mask stamps")
    if "/occmask/points" in counts and cloud_stamps != mask_stamps:
        fail("point cloud stamps differ from mask stamps")
    print(json.dumps(counts, sort_keys=True))


if __name__ == "__main__":
    main()
