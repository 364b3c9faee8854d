"""Compute the RIHS01 type hash of message types from their ros2msg schema texts with rosbags.

Usage: type_hashes.py SCHEMAS_JSON

SCHEMAS_JSON holds [{"type": "pkg/msg/Type", "schema": "<ros2msg schema text>"}, ...]: the
type's .msg text, then for each dependency a line of `=`, `MSG: pkg/Type` and its .msg text,
as rosbag2 stores it. Output: {type: {"ours": hash of the type as the schema defines it,
"jazzy": hash of rosbags' own ROS 2 Jazzy definition of the type, or null where it has none}}.
rosbags' `hash_rihs01` follows rosidl_generator_type_description (the hash rosbag2 records).
"""
import json
import re
import sys
from pathlib import Path

from rosbags.typesys import Stores, get_types_from_msg, get_typestore

SEPARATOR = re.compile(r"^=+$", re.MULTILINE)


def types_of(name, schema):
    """Every type a schema defines: the root `name`, then each `MSG: pkg/Type` section."""
    sections = SEPARATOR.split(schema)
    types = dict(get_types_from_msg(sections[0], name))
    for section in sections[1:]:
        header, body = section.strip("\n").split("\n", 1)
        if not header.startswith("MSG: "):
            raise ValueError(f"{name}: section without `MSG:` line: {header!r}")
        package, _, short = header[len("MSG: "):].strip().rpartition("/")
        package = package.split("/")[0]
        types.update(get_types_from_msg(body, f"{package}/msg/{short}"))
    return types


def main():
    jazzy = get_typestore(Stores.ROS2_JAZZY)
    out = {}
    for entry in json.loads(Path(sys.argv[1]).read_text()):
        name = entry["type"]
        store = get_typestore(Stores.EMPTY)
        store.register(types_of(name, entry["schema"]))
        out[name] = {
            "ours": store.hash_rihs01(name),
            "jazzy": jazzy.hash_rihs01(name) if name in jazzy.fielddefs else None,
        }
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
