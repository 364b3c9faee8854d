"""Write reference bags with the `rosbags` Writer, for the project to read back.

Usage: bag_write_rosbags.py OUT_DIR

Makes OUT_DIR/{mcap_v8,mcap_v9,sqlite3_v8,sqlite3_v9}, each with 20 /scan LaserScans
(ranges [0.5*i, inf, nan, 1.25]) and 20 /odom Odometry (covariance[k] = 0.5*k), log time
1e9 + i*5e7 ns; /odom uses a reliable keep-last-7 QoS profile.
"""
import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

ts = get_typestore(Stores.ROS2_JAZZY)
LaserScan = ts.types["sensor_msgs/msg/LaserScan"]
Odometry = ts.types["nav_msgs/msg/Odometry"]
Header = ts.types["std_msgs/msg/Header"]
Time = ts.types["builtin_interfaces/msg/Time"]
PoseWithCovariance = ts.types["geometry_msgs/msg/PoseWithCovariance"]
TwistWithCovariance = ts.types["geometry_msgs/msg/TwistWithCovariance"]
Pose = ts.types["geometry_msgs/msg/Pose"]
Twist = ts.types["geometry_msgs/msg/Twist"]
Point = ts.types["geometry_msgs/msg/Point"]
Quaternion = ts.types["geometry_msgs/msg/Quaternion"]
Vector3 = ts.types["geometry_msgs/msg/Vector3"]


def qos_reliable_keep_last_7():
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    zero = QosTime(0, 0)
    return [Qos(QosHistory.KEEP_LAST, 7, QosReliability.RELIABLE, QosDurability.VOLATILE, zero, zero,
                QosLiveliness.AUTOMATIC, zero, False)]


def scan(i):
    return LaserScan(
        header=Header(stamp=Time(sec=i, nanosec=7), frame_id="laser"),
        angle_min=-1.5, angle_max=1.5, angle_increment=0.01, time_increment=0.0, scan_time=0.05,
        range_min=0.1, range_max=12.0,
        ranges=np.array([0.5 * i, np.inf, np.nan, 1.25], dtype=np.float32),
        intensities=np.array([1, 2, 3, 4], dtype=np.float32),
    )


def odom(i):
    pose = PoseWithCovariance(
        pose=Pose(position=Point(x=0.1 * i, y=-2.0, z=0.0), orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
        covariance=np.array([0.5 * k for k in range(36)], dtype=np.float64),
    )
    twist = TwistWithCovariance(
        twist=Twist(linear=Vector3(x=0.2, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.3)),
        covariance=np.zeros(36, dtype=np.float64),
    )
    return Odometry(header=Header(stamp=Time(sec=i, nanosec=0), frame_id="odom"), child_frame_id="base_link",
                    pose=pose, twist=twist)


def main():
    out = Path(sys.argv[1])
    for storage, plugin in (("mcap", StoragePlugin.MCAP), ("sqlite3", StoragePlugin.SQLITE3)):
        for version in (8, 9):
            with Writer(out / f"{storage}_v{version}", version=version, storage_plugin=plugin) as writer:
                scan_conn = writer.add_connection("/scan", LaserScan.__msgtype__, typestore=ts)
                odom_conn = writer.add_connection("/odom", Odometry.__msgtype__, typestore=ts,
                                                  offered_qos_profiles=qos_reliable_keep_last_7())
                for i in range(20):
                    t = 1_000_000_000 + i * 50_000_000
                    writer.write(scan_conn, t, ts.serialize_cdr(scan(i), LaserScan.__msgtype__))
                    writer.write(odom_conn, t + 1, ts.serialize_cdr(odom(i), Odometry.__msgtype__))


if __name__ == "__main__":
    main()
