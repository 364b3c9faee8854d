"""Read a bag's offered QoS the way rosbag2 Humble does, and with `rosbags`; print JSON.

Usage: bag_qos_humble.py BAG_DIR

Humble reads metadata.yaml's `offered_qos_profiles` as a string (yaml-cpp `as<std::string>`),
and each QoS enum in it, and in the storage file's copy (MCAP channel metadata, sqlite
`topics.offered_qos_profiles`), as an integer (`as<int>`). Output:
{"version": N, "messages": count read by rosbags,
 "topics": {topic: {"metadata": [profile, ...] or an error string,
                    "storage": [profile, ...] or an error string,
                    "rosbags": [{"reliability": int, "durability": int}, ...]}}}
"""
import json
import sqlite3
import sys
from pathlib import Path

from ruamel.yaml import YAML

ENUMS = ("history", "reliability", "durability", "liveliness")


def as_humble(text):
    """The profiles, or why Humble's decoder would throw on them."""
    if not isinstance(text, str):
        return f"not a string: {type(text).__name__}"
    if not text:
        return []
    profiles = YAML(typ="safe").load(text)
    for profile in profiles:
        for key in ENUMS:
            if not isinstance(profile.get(key), int):
                return f"`{key}` is not an integer: {profile.get(key)!r}"
    return profiles


def storage_qos(path):
    out = {}
    for file in path.glob("*.mcap"):
        from mcap.reader import make_reader

        with open(file, "rb") as f:
            for channel in make_reader(f).get_summary().channels.values():
                out[channel.topic] = channel.metadata.get("offered_qos_profiles", "")
    for file in path.glob("*.db3"):
        with sqlite3.connect(file) as db:
            for name, qos in db.execute("SELECT name, offered_qos_profiles FROM topics"):
                out[name] = qos
    return out


def main():
    path = Path(sys.argv[1])
    info = YAML(typ="safe").load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    stored = storage_qos(path)
    topics = {}
    for entry in info["topics_with_message_count"]:
        meta = entry["topic_metadata"]
        topics[meta["name"]] = {
            "metadata": as_humble(meta["offered_qos_profiles"]),
            "storage": as_humble(stored.get(meta["name"])),
        }

    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn in reader.connections:
            topics[conn.topic]["rosbags"] = [
                {"reliability": q.reliability.value, "durability": q.durability.value}
                for q in conn.ext.offered_qos_profiles
            ]
        messages = sum(1 for _ in reader.messages())
    json.dump({"version": info["version"], "messages": messages, "topics": topics}, sys.stdout)


if __name__ == "__main__":
    main()
