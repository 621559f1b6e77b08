"""Decodes a ROS recording written by occmask (occmask::mcap_io::ros_out: ROS 1 `ros1` or
ROS 2 `cdr` messages) with the official Python readers (mcap-ros1-support,
mcap-ros2-support), independently of occmask's own decoders.

usage: python validate_ros_recording.py FILE

Checks: summary present; every message decodes with the schema embedded in the file; image
step * height == len(data); CameraInfo K is a 3x3 pinhole matrix. Prints one JSON line with
what occmask's test compares against its own view of the file: per-topic counts, image
encodings, sizes and frame ids, the calibrations (model, D, K, size) and the /tf_static edges
(parent, child, translation, rotation xyzw). Exits 1 on any failure.
"""

import json
import sys

from mcap.reader import make_reader
from mcap_ros1.decoder import DecoderFactory as Ros1DecoderFactory
from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory


def fail(msg):
    print(f"FAIL: {msg}", file=sys.stderr)
    sys.exit(1)


def field(msg, *names):
    """ROS 1 CameraInfo has D/K, ROS 2 d/k."""
    for name in names:
        if hasattr(msg, name):
            return getattr(msg, name)
    fail(f"message has none of {names}")


def main():
    path = sys.argv[1]
    out = {"counts": {}, "images": {}, "calibrations": {}, "transforms": []}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[Ros1DecoderFactory(), Ros2DecoderFactory()])
        if reader.get_summary() is None:
            fail("no summary section")
        for schema, channel, message, msg in reader.iter_decoded_messages(log_time_order=False):
            topic = channel.topic
            out["counts"][topic] = out["counts"].get(topic, 0) + 1
            name = schema.name
            if name in ("sensor_msgs/Image", "sensor_msgs/msg/Image"):
                if msg.step * msg.height != len(msg.data):
                    fail(f"{topic}: step {msg.step} x height {msg.height} != {len(msg.data)} bytes")
                out["images"][topic] = [msg.encoding, msg.width, msg.height, msg.header.frame_id]
            elif name in ("sensor_msgs/CameraInfo", "sensor_msgs/msg/CameraInfo"):
                k = list(field(msg, "K", "k"))
                if len(k) != 9 or k[0] <= 0 or k[4] <= 0 or k[8] != 1.0:
                    fail(f"{topic}: bad K {k}")
                out["calibrations"][topic] = {
                    "model": msg.distortion_model,
                    "d": list(field(msg, "D", "d")),
                    "k": k,
                    "size": [msg.width, msg.height],
                    "frame_id": msg.header.frame_id,
                }
            elif name in ("tf2_msgs/TFMessage", "tf2_msgs/msg/TFMessage"):
                for t in msg.transforms:
                    tr, q = t.transform.translation, t.transform.rotation
                    out["transforms"].append(
                        [t.header.frame_id, t.child_frame_id, [tr.x, tr.y, tr.z], [q.x, q.y, q.z, q.w]]
                    )
            elif name not in ("geometry_msgs/PoseStamped", "geometry_msgs/msg/PoseStamped"):
                fail(f"{topic}: unexpected schema {name}")
    print(json.dumps(out, sort_keys=True))


if __name__ == "__main__":
    main()
