"""Reads an occmask MCAP file with the official Python `mcap` reader and decodes every
message with the protobuf schemas embedded in the file (mcap-protobuf-support).

usage: python validate_mcap.py FILE [TOPIC=COUNT ...]

Checks: summary present; every message decodes; log times non-decreasing; message timestamp
== log time; per-topic counts as given; image fields consistent (16UC1 step/size, mono8
0/255, CompressedImage format png|jpeg with the right magic bytes); calibrations are 3x3
pinhole matrices. Prints one JSON line with per-topic counts; exits 1 on any failure.
"""

import json
import sys

from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory


def fail(msg):
    print(f"FAIL: {msg}", file=sys.stderr)
    sys.exit(1)


def stamp_ns(ts):
    return ts.seconds * 1_000_000_000 + ts.nanos


def main():
    path = sys.argv[1]
    expected = dict(arg.rsplit("=", 1) for arg in sys.argv[2:])
    counts = {}
    last = 0
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        if summary is None:
            fail("no summary section")
        for schema, channel, message, proto in reader.iter_decoded_messages(log_time_order=False):
            topic = channel.topic
            counts[topic] = counts.get(topic, 0) + 1
            if message.log_time < last:
                fail(f"{topic}: log time {message.log_time} before {last}")
            last = message.log_time
            if stamp_ns(proto.timestamp) != message.log_time:
                fail(f"{topic}: timestamp {stamp_ns(proto.timestamp)} != log time {message.log_time}")
            name = schema.name
            if name == "foxglove.CompressedImage":
                magic = {"png": b"\x89PNG", "jpeg": b"\xff\xd8\xff"}.get(proto.format)
                if magic is None or not proto.data.startswith(magic):
                    fail(f"{topic}: format {proto.format!r} does not match the data")
            elif name == "foxglove.RawImage":
                bpp = {"16UC1": 2, "mono8": 1, "rgb8": 3}.get(proto.encoding)
                if bpp is None:
                    fail(f"{topic}: unexpected encoding {proto.encoding!r}")
                if proto.step != proto.width * bpp or len(proto.data) != proto.step * proto.height:
                    fail(f"{topic}: {proto.width}x{proto.height} step {proto.step} data {len(proto.data)}")
                if proto.encoding == "mono8" and set(proto.data) - {0, 255}:
                    fail(f"{topic}: mask values other than 0/255")
                if proto.encoding == "16UC1" and "depth_units_per_meter" not in channel.metadata:
                    fail(f"{topic}: no depth_units_per_meter channel metadata")
            elif name == "foxglove.CameraCalibration":
                k = list(proto.K)
                if len(k) != 9 or k[0] <= 0 or k[4] <= 0 or k[8] != 1.0 or len(proto.P) != 12:
                    fail(f"{topic}: bad K {k}")
            elif name == "foxglove.PoseInFrame":
                q = proto.pose.orientation
                if abs(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1.0) > 1e-9:
                    fail(f"{topic}: non-unit quaternion")
            elif name == "foxglove.FrameTransform":
                if not proto.parent_frame_id or not proto.child_frame_id:
                    fail(f"{topic}: empty frame ids")
            else:
                fail(f"{topic}: unexpected schema {name}")
        stats = summary.statistics
        if stats is not None and stats.message_count != sum(counts.values()):
            fail(f"statistics say {stats.message_count} messages, read {sum(counts.values())}")
    for topic, n in expected.items():
        if counts.get(topic, 0) != int(n):
            fail(f"{topic}: expected {n} messages, found {counts.get(topic, 0)}")
    print(json.dumps(counts, sort_keys=True))


if __name__ == "__main__":
    main()
