"""Eclipse Cyclone DDS on the other side of the lidar_har nodes (run inside a private network
namespace by tests/tests/ros_nodes.rs).

    ros_cyclone_interop.py receive TOPIC COUNT TIMEOUT [MIN]   JSON line per message on stdout
                                   (SIGTERM: stop waiting, succeed if MIN came)
    ros_cyclone_interop.py receive-topics TIMEOUT TOPIC=COUNT...
                                   every reader made first; {"topic", "msg"} JSON lines
    ros_cyclone_interop.py publish-scan COUNT RATE_HZ    LaserScans with ranges [i, i, ...],
                                   once a reader has matched
    ros_cyclone_interop.py publish-map DURABILITY SECONDS
                                   a 4 x 3 OccupancyGrid on /map, reliable, keep-last 1,
                                   DURABILITY volatile (cartographer's occupancy_grid_node)
                                   or transient_local (map_server), twice a second for
                                   SECONDS; "matched" on stdout once a reader has;
                                   fails if none did

Topics use ROS 2 naming (`rt/` prefix) and the QoS of the topic contract (`lidar_har_msgs::topics`),
but for publish-map's DURABILITY; /rosout (rcl_interfaces/msg/Log) is read as rcl's subscribers
read it.
"""

import json
import signal
import sys
import time
from dataclasses import asdict

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from ros_idl import Activity, FallAlert, Header, LaserScan, Log, MapMetaData, OccupancyGrid, Time


TYPES = {
    "/scan": (LaserScan, Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(5))),
    "/human/activity": (Activity, Qos(Policy.Reliability.Reliable(duration(milliseconds=100)),
                                      Policy.History.KeepLast(10))),
    "/human/fall_alert": (FallAlert, Qos(Policy.Reliability.Reliable(duration(milliseconds=100)),
                                         Policy.Durability.TransientLocal, Policy.History.KeepLast(10))),
    # rcl's rosout subscription (rqt_console's).
    "/rosout": (Log, Qos(Policy.Reliability.Reliable(duration(milliseconds=100)),
                         Policy.Durability.TransientLocal, Policy.History.KeepLast(1000))),
}


def valid_samples(reader):
    """Takes up to 16 samples, leaving out the data-less ones Cyclone delivers when an
    instance changes state (e.g. no writers left after the publisher exits)."""
    for sample in reader.take(N=16):
        info = getattr(sample, "sample_info", None)
        if info is None or info.valid_data:
            yield sample


STOP = []


def stop_on_sigterm():
    """SIGTERM ends a receive loop early (the publisher is known to be done), not the process."""
    signal.signal(signal.SIGTERM, lambda *_: STOP.append(True))


def receive(participant, topic_name, count, timeout, minimum):
    """Prints up to `count` samples as JSON lines; succeeds when at least `minimum` came
    (best-effort topics may lose the first samples while discovery completes). SIGTERM stops
    the wait early."""
    cls, qos = TYPES[topic_name]
    reader = DataReader(participant, Topic(participant, "rt" + topic_name, cls), qos=qos)
    got = 0
    end = time.monotonic() + timeout
    stop_on_sigterm()
    while got < count and time.monotonic() < end and not STOP:
        for sample in valid_samples(reader):
            print(json.dumps(asdict(sample)), flush=True)
            got += 1
        time.sleep(0.005)
    # Done: a SIGTERM from now on (the test stopping a receiver that has just finished) must
    # not kill the process on its way out (Python restores the default action at exit, but
    # leaves an ignored signal ignored).
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    return 0 if got >= minimum else 1


def receive_topics(participant, timeout, wanted):
    """Reads every topic of `wanted` ({topic: count}) at once, all readers created before
    the first take, and prints {"topic", "msg"} JSON lines; succeeds when each topic brought
    its count (meant for reliable topics, where nothing may be lost)."""
    readers = {}
    for topic_name in wanted:
        cls, qos = TYPES[topic_name]
        readers[topic_name] = DataReader(participant, Topic(participant, "rt" + topic_name, cls),
                                         qos=qos)
    stamps = {topic_name: [] for topic_name in wanted}
    end = time.monotonic() + timeout
    while any(len(stamps[t]) < wanted[t] for t in wanted) and time.monotonic() < end:
        for topic_name, reader in readers.items():
            for sample in valid_samples(reader):
                print(json.dumps({"topic": topic_name, "msg": asdict(sample)}), flush=True)
                stamps[topic_name].append(f"{sample.header.stamp.sec}.{sample.header.stamp.nanosec:09d}")
        time.sleep(0.005)
    ok = True
    for topic_name in wanted:
        if len(stamps[topic_name]) != wanted[topic_name]:
            ok = False
            print(f"{topic_name}: received {len(stamps[topic_name])} of {wanted[topic_name]}"
                  f" (stamps {' '.join(stamps[topic_name])})", file=sys.stderr)
    return 0 if ok else 1


def wait_for_reader(writer, timeout):
    """Waits until `writer` has matched a reader; False after `timeout` seconds."""
    end = time.monotonic() + timeout
    while not writer.get_matched_subscriptions():
        if time.monotonic() >= end:
            return False
        time.sleep(0.01)
    return True


def publish_scans(participant, count, rate_hz):
    """Publishes once the subscriber's reader has matched (the subscriber must be started
    first); fails if none matches within 15 s."""
    cls, qos = TYPES["/scan"]
    writer = DataWriter(participant, Topic(participant, "rt/scan", cls), qos=qos)
    if not wait_for_reader(writer, 15.0):
        print("publish-scan: no reader of /scan matched within 15 s", file=sys.stderr)
        return 1
    # The reader's side matches our writer on its own discovery, about as soon: a little
    # time for it (the test accepts a few lost first scans should it come later still).
    time.sleep(0.3)
    for i in range(count):
        ns = 1_700_000_000_000_000_000 + i * 50_000_000
        writer.write(LaserScan(
            header=Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="laser"),
            angle_min=-3.14159, angle_max=3.14159, angle_increment=6.28318 / 8, scan_time=0.05,
            range_min=0.1, range_max=12.0, ranges=[float(i)] * 8, intensities=[]))
        time.sleep(1.0 / rate_hz)
    time.sleep(0.5)
    return 0


MAP_DURABILITY = {"volatile": Policy.Durability.Volatile,
                  "transient_local": Policy.Durability.TransientLocal}


def publish_map(participant, durability, seconds):
    """Publishes a small map on /map twice a second for `seconds`, with the durability
    given (a volatile map reaches only the readers matched when it is written, so it is
    written again, as cartographer's occupancy_grid_node does). Succeeds if a reader matched
    (a transient-local reader does not match a volatile writer)."""
    qos = Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), MAP_DURABILITY[durability],
              Policy.History.KeepLast(1))
    writer = DataWriter(participant, Topic(participant, "rt/map", OccupancyGrid), qos=qos)
    grid = OccupancyGrid(
        header=Header(stamp=Time(sec=1_700_000_000), frame_id="map"),
        info=MapMetaData(resolution=0.05, width=4, height=3),
        data=[0, 100, -1, 0, 0, 0, 100, 100, 0, 0, -1, 0])
    matched = 0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        now_matched = len(writer.get_matched_subscriptions())
        if now_matched and not matched:
            print("matched", flush=True)
        matched = max(matched, now_matched)
        writer.write(grid)
        time.sleep(0.5)
    print(f"publish-map: {durability} /map matched {matched} reader(s)", file=sys.stderr)
    return 0 if matched else 1


def main(argv):
    participant = DomainParticipant(0)
    if argv[1] == "receive":
        minimum = int(argv[5]) if len(argv) > 5 else int(argv[3])
        return receive(participant, argv[2], int(argv[3]), float(argv[4]), minimum)
    if argv[1] == "receive-topics":
        wanted = {t: int(n) for t, n in (arg.split("=", 1) for arg in argv[3:])}
        return receive_topics(participant, float(argv[2]), wanted)
    if argv[1] == "publish-scan":
        return publish_scans(participant, int(argv[2]), float(argv[3]))
    if argv[1] == "publish-map":
        return publish_map(participant, argv[2], float(argv[3]))
    print(f"unknown mode {argv[1]!r}", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv))
