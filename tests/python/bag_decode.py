"""Decode every message of a bag with two independent libraries and print them as JSON.

Usage: bag_decode.py BAG_DIR

Output: {"rosbags": {topic: [msg, ...]}, "mcap_ros2": {topic: [msg, ...]},
         "topics": {topic: {"type": ..., "count": ...}}}
Messages become nested dicts of their fields; floats become repr strings ('nan', 'inf',
'0.10000000149011612') so the caller can compare them bit for bit; arrays become lists.
"""
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np


def plain(value):
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (np.floating,)):
        return repr(float(value))
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, np.ndarray):
        return [plain(v) for v in value.tolist()]
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, (bool, int, str)) or value is None:
        return value
    if isinstance(value, bytes):
        return list(value)
    # rosbags dataclasses and mcap_ros2 dynamic objects
    if dataclasses.is_dataclass(value):
        names = [f.name for f in dataclasses.fields(value)]
    else:
        names = list(getattr(value, "__slots__", []))
    return {n: plain(getattr(value, n)) for n in names if not n.startswith("_")}


def with_rosbags(path):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    out = {}
    topics = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn in reader.connections:
            topics[conn.topic] = {"type": conn.msgtype, "count": conn.msgcount}
        for conn, timestamp, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            out.setdefault(conn.topic, []).append({"log_time": timestamp, "msg": plain(msg)})
    return out, topics


def with_mcap(path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    files = sorted(path.glob("*.mcap")) if path.is_dir() else [path]
    out = {}
    for file in files:
        with open(file, "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for _schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
                out.setdefault(channel.topic, []).append({"log_time": message.log_time, "msg": plain(decoded)})
    return out


def main():
    path = Path(sys.argv[1])
    rosbags_msgs, topics = with_rosbags(path)
    result = {"rosbags": rosbags_msgs, "topics": topics}
    if any(path.glob("*.mcap")) or path.suffix == ".mcap":
        result["mcap_ros2"] = with_mcap(path)
    json.dump(result, sys.stdout)


if __name__ == "__main__":
    main()
