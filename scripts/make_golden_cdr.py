#!/usr/bin/env python3
"""Writes the golden CDR files the `lidar-har-msgs` tests compare the Rust codec against.

For every message type the crate mirrors, a fixed, non-trivial value (non-zero numbers,
odd-length strings and sequences, so alignment and padding are exercised) is serialised by
`rosbags` (an implementation nobody on this project wrote) with the ROS 2 Humble type store;
our own `lidar_har_msgs` types are registered from `msg/msg/*.msg`.

Output, in crates/msgs/tests/golden/:
  <pkg>__<Type>.cdr            the CDR bytes (encapsulation header included)
  values.json                  every value, as the serde mirrors read it (field -> value)
  sensor_msgs__LaserScan_nonfinite.cdr   a scan with inf, -inf and NaN ranges (JSON has no
                               NaN, so the Rust test builds that value itself; see the test)

Run with the project's venv:  .venv/bin/python scripts/make_golden_cdr.py
(--check: compare with the committed files instead of writing; exit 1 on a difference).

--check-schemas DIR: the other direction, used by the crate's `external_checkers` test. DIR
holds, per type, `<pkg>__<Type>.msg` (the schema text our crate writes into MCAP files) and
`<pkg>__<Type>.cdr` (our encoding of the same fixed value). Both `rosbags` (a type store built
only from that schema text) and `mcap-ros2-support` (its dynamic decoder) must parse the schema
and decode our bytes to the fixed value.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from pathlib import Path

import numpy as np
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = ROOT / "crates" / "msgs" / "tests" / "golden"
OUR_MSGS = ROOT / "msg" / "msg"

TS = get_typestore(Stores.ROS2_HUMBLE)
for msg_file in sorted(OUR_MSGS.glob("*.msg")):
    TS.register(get_types_from_msg(msg_file.read_text(), f"lidar_har_msgs/msg/{msg_file.stem}"))


def t(name: str):
    return TS.types[name]


# --- builders of the fixed values (each distinct, so a swapped field shows) -------------------

def time(sec=1_700_000_123, nanosec=456_789_012):
    return t("builtin_interfaces/msg/Time")(sec=sec, nanosec=nanosec)


def duration(sec=-3, nanosec=250_000_001):
    return t("builtin_interfaces/msg/Duration")(sec=sec, nanosec=nanosec)


def header(frame="laser", sec=1_700_000_123):
    # odd-length frame ids put the next field off its natural alignment
    return t("std_msgs/msg/Header")(stamp=time(sec=sec), frame_id=frame)


def color(r=0.25, g=0.5, b=0.75, a=1.0):
    return t("std_msgs/msg/ColorRGBA")(r=r, g=g, b=b, a=a)


def point(x=1.5, y=-2.25, z=0.125):
    return t("geometry_msgs/msg/Point")(x=x, y=y, z=z)


def point32(x=0.5, y=-1.75, z=3.0):
    return t("geometry_msgs/msg/Point32")(x=x, y=y, z=z)


def quaternion(x=0.0, y=0.0, z=0.6, w=0.8):
    return t("geometry_msgs/msg/Quaternion")(x=x, y=y, z=z, w=w)


def vector3(x=0.3125, y=-0.0625, z=9.75):
    return t("geometry_msgs/msg/Vector3")(x=x, y=y, z=z)


def pose():
    return t("geometry_msgs/msg/Pose")(position=point(), orientation=quaternion())


def covariance(scale=1.0):
    return np.array([scale * (i + 1) / 64.0 for i in range(36)], dtype=np.float64)


def pose_with_covariance():
    return t("geometry_msgs/msg/PoseWithCovariance")(pose=pose(), covariance=covariance())


def twist():
    return t("geometry_msgs/msg/Twist")(linear=vector3(), angular=vector3(0.0, 0.0, -0.5))


def twist_with_covariance():
    return t("geometry_msgs/msg/TwistWithCovariance")(twist=twist(), covariance=covariance(-2.0))


def transform():
    return t("geometry_msgs/msg/Transform")(translation=vector3(0.1, 0.0, 0.2), rotation=quaternion())


def transform_stamped(child="base_laser"):
    return t("geometry_msgs/msg/TransformStamped")(header=header("base"), child_frame_id=child, transform=transform())


def f32(value: float) -> float:
    """`value` rounded to float32, so the JSON holds exactly what the CDR holds."""
    return float(np.float32(value))


def f32s(*values):
    return np.array(values, dtype=np.float32)


def compressed_image():
    return t("sensor_msgs/msg/CompressedImage")(
        header=header("cam"), format="png", data=np.array([137, 80, 78, 71, 13], dtype=np.uint8)
    )


def uv(u=0.25, v=0.75):
    return t("visualization_msgs/msg/UVCoordinate")(u=u, v=v)


def mesh_file():
    return t("visualization_msgs/msg/MeshFile")(filename="a.stl", data=np.array([1, 2, 3], dtype=np.uint8))


def marker(marker_id=7):
    return t("visualization_msgs/msg/Marker")(
        header=header("map"),
        ns="person",
        id=marker_id,
        type=7,
        action=0,
        pose=pose(),
        scale=vector3(0.05, 0.05, 0.05),
        color=color(),
        lifetime=duration(0, 500_000_000),
        frame_locked=True,
        points=[point(), point(0.5, 0.5, 0.0), point(-1.0, 2.0, 0.0)],
        colors=[color(1.0, 0.0, 0.0, 1.0)],
        texture_resource="tex",
        texture=compressed_image(),
        uv_coordinates=[uv(), uv(0.5, 0.125), uv(1.0, 0.0)],
        text="walking",
        mesh_resource="package://m",
        mesh_file=mesh_file(),
        mesh_use_embedded_materials=True,
    )


def key_value(key="rate_hz", value="19.9"):
    return t("diagnostic_msgs/msg/KeyValue")(key=key, value=value)


def diagnostic_status():
    return t("diagnostic_msgs/msg/DiagnosticStatus")(
        level=1,
        name="lidar: scan rate",
        message="below target",
        hardware_id="rplidar-s2",
        values=[key_value(), key_value("missed", "3"), key_value("port", "/dev/ttyUSB0")],
    )


def log_record():
    return t("rcl_interfaces/msg/Log")(
        stamp=time(),
        level=30,
        name="robot1.replay",
        msg="bag has no topic /missing",
        file="nodes/src/bin/replay.rs",
        function="replay",
        line=277,
    )


def map_meta_data():
    return t("nav_msgs/msg/MapMetaData")(
        map_load_time=time(12, 34), resolution=f32(0.05), width=3, height=2, origin=pose()
    )


VALUES = {
    "builtin_interfaces/msg/Time": lambda: time(),
    "builtin_interfaces/msg/Duration": lambda: duration(),
    "std_msgs/msg/Header": lambda: header(),
    "std_msgs/msg/ColorRGBA": lambda: color(),
    "geometry_msgs/msg/Point": lambda: point(),
    "geometry_msgs/msg/Point32": lambda: point32(),
    "geometry_msgs/msg/Quaternion": lambda: quaternion(),
    "geometry_msgs/msg/Vector3": lambda: vector3(),
    "geometry_msgs/msg/Pose": lambda: pose(),
    "geometry_msgs/msg/PoseStamped": lambda: t("geometry_msgs/msg/PoseStamped")(header=header("map"), pose=pose()),
    "geometry_msgs/msg/PoseWithCovariance": lambda: pose_with_covariance(),
    "geometry_msgs/msg/PoseWithCovarianceStamped": lambda: t("geometry_msgs/msg/PoseWithCovarianceStamped")(
        header=header("map"), pose=pose_with_covariance()
    ),
    "geometry_msgs/msg/Twist": lambda: twist(),
    "geometry_msgs/msg/TwistWithCovariance": lambda: twist_with_covariance(),
    "geometry_msgs/msg/Transform": lambda: transform(),
    "geometry_msgs/msg/TransformStamped": lambda: transform_stamped(),
    "sensor_msgs/msg/LaserScan": lambda: t("sensor_msgs/msg/LaserScan")(
        header=header("laser"),
        angle_min=-3.125,
        angle_max=3.0,
        angle_increment=0.0087890625,
        time_increment=f32(0.0000625),
        scan_time=f32(0.05),
        range_min=f32(0.15),
        range_max=12.0,
        ranges=f32s(1.5, 2.25, 0.75, 11.5, 3.0),
        intensities=f32s(47.0, 10.0, 0.0),
    ),
    "sensor_msgs/msg/CompressedImage": lambda: compressed_image(),
    "nav_msgs/msg/Odometry": lambda: t("nav_msgs/msg/Odometry")(
        header=header("odom"), child_frame_id="base_link", pose=pose_with_covariance(), twist=twist_with_covariance()
    ),
    "nav_msgs/msg/MapMetaData": lambda: map_meta_data(),
    "nav_msgs/msg/OccupancyGrid": lambda: t("nav_msgs/msg/OccupancyGrid")(
        header=header("map"), info=map_meta_data(), data=np.array([0, 100, -1, 0, 100, 50], dtype=np.int8)
    ),
    "tf2_msgs/msg/TFMessage": lambda: t("tf2_msgs/msg/TFMessage")(
        transforms=[transform_stamped(), transform_stamped("odom"), transform_stamped("laser")]
    ),
    "rosgraph_msgs/msg/Clock": lambda: t("rosgraph_msgs/msg/Clock")(clock=time(42, 999_999_999)),
    "visualization_msgs/msg/Marker": lambda: marker(),
    "visualization_msgs/msg/MarkerArray": lambda: t("visualization_msgs/msg/MarkerArray")(
        markers=[marker(1), marker(2), marker(3)]
    ),
    "visualization_msgs/msg/UVCoordinate": lambda: uv(),
    "visualization_msgs/msg/MeshFile": lambda: mesh_file(),
    "diagnostic_msgs/msg/DiagnosticArray": lambda: t("diagnostic_msgs/msg/DiagnosticArray")(
        header=header("robot"), status=[diagnostic_status()]
    ),
    "diagnostic_msgs/msg/DiagnosticStatus": lambda: diagnostic_status(),
    "diagnostic_msgs/msg/KeyValue": lambda: key_value(),
    "rcl_interfaces/msg/Log": lambda: log_record(),
    "lidar_har_msgs/msg/Activity": lambda: t("lidar_har_msgs/msg/Activity")(
        header=header("map"),
        activity=8,
        label="walking_unsteadily",
        confidence=0.625,
        probabilities=f32s(0.0, 0.03125, 0.0, 0.0, 0.0625, 0.0, 0.125, 0.15625, 0.625),
    ),
    "lidar_har_msgs/msg/FallAlert": lambda: t("lidar_har_msgs/msg/FallAlert")(
        header=header("map"),
        kind=1,
        position=point(2.125, 0.375, 0.0),
        confidence=0.875,
        event_time=time(1_700_000_100, 1),
        description="person down for 23 s",
    ),
    "lidar_har_msgs/msg/HumanObservation": lambda: t("lidar_har_msgs/msg/HumanObservation")(
        header=header("map"),
        track_id=3,
        visible=True,
        seconds_since_seen=0.0,
        position=point(2.125, 0.375, 0.0),
        velocity=vector3(0.5, -0.25, 0.0),
        covariance=np.array([0.01, 0.002, 0.002, 0.03], dtype=np.float64),
        sensor_position=point(0.0, -1.5, 0.2),
        points=[point32(2.0, 0.25, 0.0), point32(2.25, 0.5, 0.0), point32(2.125, 0.375, 0.0)],
    ),
}

# A scan whose ranges hold what real Lidars publish for "no return": inf, -inf and NaN
# (a quiet NaN with payload, to check bits survive). The Rust test builds the same value.
NONFINITE_RANGES = np.array([1.5, np.inf, -np.inf, 0.25, 0.0], dtype=np.float32)
NONFINITE_RANGES = np.concatenate([NONFINITE_RANGES, np.array([0x7FC00001], dtype=np.uint32).view(np.float32)])


def nonfinite_scan():
    return t("sensor_msgs/msg/LaserScan")(
        header=header("laser"),
        angle_min=-math.pi,
        angle_max=math.pi,
        angle_increment=0.5,
        time_increment=0.0,
        scan_time=0.1,
        range_min=0.15,
        range_max=math.inf,
        ranges=NONFINITE_RANGES,
        intensities=f32s(math.nan),
    )


def message_fields(value) -> list[str]:
    """The field names of a rosbags message: its dataclass fields without `__msgtype__` and
    the constants (ROS 2 field names are lower case, constant names upper case)."""
    return [f.name for f in dataclasses.fields(value) if not f.name.startswith("__") and not f.name.isupper()]


def to_json(value):
    """A message as serde_json reads the Rust mirror: nested objects, arrays as lists."""
    if dataclasses.is_dataclass(value):
        return {name: to_json(getattr(value, name)) for name in message_fields(value)}
    if isinstance(value, np.ndarray):
        return [to_json(v) for v in value.tolist()]
    if isinstance(value, list):
        return [to_json(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError("JSON cannot hold non-finite floats; put them in the nonfinite golden")
    return value


def file_name(type_name: str) -> str:
    pkg, _, name = type_name.split("/")
    return f"{pkg}__{name}.cdr"


def outputs() -> dict[str, bytes]:
    files: dict[str, bytes] = {}
    values = {}
    for type_name, make in VALUES.items():
        msg = make()
        files[file_name(type_name)] = bytes(TS.serialize_cdr(msg, type_name, little_endian=True))
        values[type_name] = to_json(msg)
    files["sensor_msgs__LaserScan_nonfinite.cdr"] = bytes(
        TS.serialize_cdr(nonfinite_scan(), "sensor_msgs/msg/LaserScan", little_endian=True)
    )
    files["values.json"] = (json.dumps(values, indent=1, allow_nan=False) + "\n").encode()
    return files


def plain(value):
    """A decoded message (rosbags dataclass or mcap_ros2 namespace) as JSON-like data."""
    if dataclasses.is_dataclass(value):
        return {name: plain(getattr(value, name)) for name in message_fields(value)}
    slots = getattr(type(value), "__slots__", None)
    if slots and not isinstance(value, (str, bytes)):
        return {name: plain(getattr(value, name)) for name in slots}
    if isinstance(value, np.ndarray):
        return [plain(v) for v in value.tolist()]
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, (list, tuple)) or type(value).__name__ == "array":
        return [plain(v) for v in value]
    return value


def signed_time_seconds(value, type_name):
    """mcap_ros2 reads builtin_interfaces Time/Duration `sec` as uint32 (ROS says int32)."""
    if isinstance(value, dict):
        out = {k: signed_time_seconds(v, type_name) for k, v in value.items()}
        if set(out) == {"sec", "nanosec"} and out["sec"] >= 2**31:
            out["sec"] -= 2**32
        return out
    if isinstance(value, list):
        return [signed_time_seconds(v, type_name) for v in value]
    return value


def check_schemas(directory: Path) -> int:
    from mcap_ros2._dynamic import generate_dynamic

    failures = []
    for type_name, make in VALUES.items():
        stem = file_name(type_name)[: -len(".cdr")]
        schema = (directory / f"{stem}.msg").read_text()
        data = (directory / f"{stem}.cdr").read_bytes()
        expected = to_json(make())
        try:
            store = get_typestore(Stores.EMPTY)
            store.register(get_types_from_msg(schema, type_name))
            got = plain(store.deserialize_cdr(data, type_name))
            if got != expected:
                failures.append(f"rosbags: {type_name}: decoded {got}, expected {expected}")
        except Exception as exc:  # noqa: BLE001 - report every failure, not only the first
            failures.append(f"rosbags: {type_name}: {type(exc).__name__}: {exc}")
        try:
            decoder = generate_dynamic(type_name, schema)[type_name]
            got = signed_time_seconds(plain(decoder(data)), type_name)
            if got != expected:
                failures.append(f"mcap_ros2: {type_name}: decoded {got}, expected {expected}")
        except Exception as exc:  # noqa: BLE001
            failures.append(f"mcap_ros2: {type_name}: {type(exc).__name__}: {exc}")
    for failure in failures:
        print(failure, file=sys.stderr)
    print(f"checked {len(VALUES)} schemas with rosbags and mcap_ros2: {len(failures)} failures")
    return 1 if failures else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare with the committed files, write nothing")
    parser.add_argument("--check-schemas", type=Path, metavar="DIR", help="check our schema texts and CDR in DIR")
    args = parser.parse_args()
    if args.check_schemas:
        return check_schemas(args.check_schemas)
    files = outputs()
    if args.check:
        stale = [n for n, data in files.items() if not (GOLDEN / n).is_file() or (GOLDEN / n).read_bytes() != data]
        for name in stale:
            print(f"golden file differs or is missing: {GOLDEN / name}", file=sys.stderr)
        print(f"checked {len(files)} golden files, {len(stale)} differ")
        return 1 if stale else 0
    GOLDEN.mkdir(parents=True, exist_ok=True)
    for name, data in files.items():
        (GOLDEN / name).write_bytes(data)
    print(f"wrote {len(files)} files to {GOLDEN}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
