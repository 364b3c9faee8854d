"""Write sqlite3 bags as ROS 2 Foxy and Humble recorded them: no stored message definitions.

Usage: bag_write_sqlite_markers.py OUT_DIR

Makes OUT_DIR/{foxy,humble}, each with 3 /human/markers MarkerArrays (two markers each, in
that distribution's layout: Foxy's Marker has no texture and mesh fields) and 3 /scan
LaserScans, log time 1e9 + i*1e8 ns; humble also has, at 1.3e9 ns, one more of each cut
to half its length (damaged rows).
"""
import sqlite3
import sys
from pathlib import Path

import numpy as np
from rosbags.typesys import Stores, get_typestore

METADATA = """rosbag2_bagfile_information:
  version: {version}
  storage_identifier: sqlite3
  relative_file_paths:
    - {name}_0.db3
  duration:
    nanoseconds: 200000000
  starting_time:
    nanoseconds_since_epoch: 1000000000
  message_count: {total}
  topics_with_message_count:
    - topic_metadata:
        name: /human/markers
        type: visualization_msgs/msg/MarkerArray
        serialization_format: cdr
        offered_qos_profiles: ""
      message_count: {per_topic}
    - topic_metadata:
        name: /scan
        type: sensor_msgs/msg/LaserScan
        serialization_format: cdr
        offered_qos_profiles: ""
      message_count: {per_topic}
  compression_format: ""
  compression_mode: ""
"""


def write(out: Path, name: str, store, version: int, damaged: bool):
    ts = get_typestore(store)
    t = ts.types
    header = t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=1, nanosec=2), frame_id="map")
    fields = dict(
        header=header, ns="person", id=1, type=2, action=0,
        pose=t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=0.0),
            orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)),
        scale=t["geometry_msgs/msg/Vector3"](x=0.3, y=0.3, z=0.3),
        color=t["std_msgs/msg/ColorRGBA"](r=1.0, g=0.0, b=0.0, a=1.0),
        lifetime=t["builtin_interfaces/msg/Duration"](sec=0, nanosec=0), frame_locked=False,
        points=[], colors=[], text="hi", mesh_resource="", mesh_use_embedded_materials=False)
    if "visualization_msgs/msg/MeshFile" in t:
        fields.update(
            texture_resource="", texture=t["sensor_msgs/msg/CompressedImage"](header=header, format="", data=np.array([], dtype=np.uint8)),
            uv_coordinates=[], mesh_file=t["visualization_msgs/msg/MeshFile"](filename="", data=np.array([], dtype=np.uint8)))
    marker = t["visualization_msgs/msg/Marker"](**fields)
    markers = bytes(ts.serialize_cdr(t["visualization_msgs/msg/MarkerArray"](markers=[marker, marker]),
                                     "visualization_msgs/msg/MarkerArray"))
    scan = bytes(ts.serialize_cdr(t["sensor_msgs/msg/LaserScan"](
        header=header, angle_min=0.0, angle_max=1.0, angle_increment=0.5, time_increment=0.0,
        scan_time=0.1, range_min=0.1, range_max=10.0, ranges=np.array([1.0, 2.0, 3.0], dtype=np.float32),
        intensities=np.array([], dtype=np.float32)), "sensor_msgs/msg/LaserScan"))
    bag = out / name
    bag.mkdir(parents=True)
    db = sqlite3.connect(bag / f"{name}_0.db3")
    db.executescript(
        "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,"
        " serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);"
        "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,"
        " timestamp INTEGER NOT NULL, data BLOB NOT NULL);")
    db.execute("INSERT INTO topics VALUES (1, '/human/markers', 'visualization_msgs/msg/MarkerArray', 'cdr', '')")
    db.execute("INSERT INTO topics VALUES (2, '/scan', 'sensor_msgs/msg/LaserScan', 'cdr', '')")
    for i in range(3):
        t_ns = 1_000_000_000 + i * 100_000_000
        db.execute("INSERT INTO messages(topic_id, timestamp, data) VALUES (2, ?, ?)", (t_ns, scan))
        db.execute("INSERT INTO messages(topic_id, timestamp, data) VALUES (1, ?, ?)", (t_ns, markers))
    if damaged:
        for topic_id, data in ((2, scan), (1, markers)):
            db.execute("INSERT INTO messages(topic_id, timestamp, data) VALUES (?, ?, ?)",
                       (topic_id, 1_300_000_000, data[: len(data) // 2]))
    db.commit()
    db.close()
    per_topic = 4 if damaged else 3
    (bag / "metadata.yaml").write_text(
        METADATA.format(version=version, name=name, total=2 * per_topic, per_topic=per_topic))


out = Path(sys.argv[1])
write(out, "foxy", Stores.ROS2_FOXY, 4, damaged=False)
write(out, "humble", Stores.ROS2_HUMBLE, 5, damaged=True)
