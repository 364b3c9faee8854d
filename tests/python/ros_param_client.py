"""A `ros2 param` client made of Eclipse Cyclone DDS, for a lidar_har node's parameter services
(run inside a private network namespace by tests/tests/ros_nodes.rs).

    ros_param_client.py NODE TIMEOUT SET_NAME SET_VALUE
        asks NODE what `ros2 param list`, `ros2 param get`, `ros2 param describe` and
        `ros2 param set SET_NAME SET_VALUE` (JSON: a bool, integer, double or string) ask (list_parameters with no prefixes
        and depth 0, then get_parameters, describe_parameters and set_parameters /
        set_parameters_atomically) and prints the answers as one JSON object:
        {"names", "values": {name: value}, "descriptors", "set", "set_atomically"}

The services as rclcpp serves them over rmw_fastrtps (ROS 2's default RMW): topics
`rq/NODE/list_parametersRequest` and `rr/NODE/list_parametersReply`, types
`rcl_interfaces::srv::dds_::ListParameters_Request_` / `_Response_`, the request's CDR alone
in the payload (the "Enhanced" request/reply mapping; rmw_cyclonedds would put a 16-byte
header before it). rmw_fastrtps also sends a related_sample_identity inline QoS, which
Cyclone's Python API cannot: the server then takes the request's own sample identity. One
client at a time, so every reply on the reply topic is ours.
"""

import json
import sys
import time
from dataclasses import asdict

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from ros_idl import (
    ParameterValue,
    Parameter,
    ListRequest,
    ListResponse,
    GetRequest,
    GetResponse,
    DescribeRequest,
    DescribeResponse,
    SetRequest,
    SetResponse,
    SetAtomicallyRequest,
    SetAtomicallyResponse,
)

# rmw_qos_profile_services_default
SERVICE_QOS = Qos(Policy.Reliability.Reliable(duration(milliseconds=100)),
                  Policy.Durability.Volatile, Policy.History.KeepLast(10))


class Service:
    """A client of the service `name` (absolute, e.g. `/replay/get_parameters`): its request
    writer and reply reader."""

    def __init__(self, participant, name, request_type, response_type):
        self.name = name
        self.writer = DataWriter(participant, Topic(participant, f"rq{name}Request",
                                                    request_type), qos=SERVICE_QOS)
        self.reader = DataReader(participant, Topic(participant, f"rr{name}Reply",
                                                    response_type), qos=SERVICE_QOS)

    def call(self, request, timeout):
        """The server's reply to `request`, once both ends are matched (as rclpy's
        `wait_for_service`); exits with status 1 after `timeout` seconds. The request is sent
        again after each second without a reply: the server's reply writer may not have
        discovered our reader yet when our side sees the match, and a reply to no reader is
        lost (the queries change nothing, so asking twice is harmless)."""
        end = time.monotonic() + timeout
        while not (self.writer.get_matched_subscriptions()
                   and self.reader.get_matched_publications()):
            if time.monotonic() >= end:
                sys.exit(f"{self.name}: no server matched within {timeout} s")
            time.sleep(0.01)
        while time.monotonic() < end:
            self.writer.write(request)
            resend = time.monotonic() + 1.0
            while time.monotonic() < min(resend, end):
                for reply in self.reader.take(N=1):
                    return reply
                time.sleep(0.01)
        sys.exit(f"{self.name}: no reply within {timeout} s")


def value_json(v):
    """The value a `ParameterValue` holds, by its type (rcl_interfaces/msg/ParameterType)."""
    return {1: v.bool_value, 2: v.integer_value, 3: v.double_value, 4: v.string_value,
            6: v.bool_array_value, 7: v.integer_array_value, 8: v.double_array_value,
            9: v.string_array_value}.get(v.type)


def parameter_value(v):
    """A bool, integer, double or string as a `ParameterValue`."""
    if isinstance(v, bool):
        return ParameterValue(type=1, bool_value=v)
    if isinstance(v, int):
        return ParameterValue(type=2, integer_value=v)
    if isinstance(v, float):
        return ParameterValue(type=3, double_value=v)
    return ParameterValue(type=4, string_value=str(v))


def main(argv):
    node, timeout, set_name, set_value = argv[1], float(argv[2]), argv[3], json.loads(argv[4])
    participant = DomainParticipant(0)

    def client(service, request_type, response_type):
        return Service(participant, f"/{node}/{service}", request_type, response_type)

    names = client("list_parameters", ListRequest, ListResponse).call(
        ListRequest(prefixes=[], depth=0), timeout).result.names
    values = client("get_parameters", GetRequest, GetResponse).call(
        GetRequest(names=names), timeout).values
    descriptors = client("describe_parameters", DescribeRequest, DescribeResponse).call(
        DescribeRequest(names=names), timeout).descriptors
    param = Parameter(name=set_name, value=parameter_value(set_value))
    results = client("set_parameters", SetRequest, SetResponse).call(
        SetRequest(parameters=[param]), timeout).results
    atomic = client("set_parameters_atomically", SetAtomicallyRequest,
                    SetAtomicallyResponse).call(SetAtomicallyRequest(parameters=[param]),
                                                timeout).result
    print(json.dumps({
        "names": list(names),
        "values": {n: value_json(v) for n, v in zip(names, values)},
        "descriptors": [asdict(d) for d in descriptors],
        "set": [asdict(r) for r in results],
        "set_atomically": asdict(atomic),
    }))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
