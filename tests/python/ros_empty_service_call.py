"""`ros2 service call SERVICE std_srvs/srv/Empty` made of Eclipse Cyclone DDS (run inside a
private network namespace by tests/tests/ros_nodes.rs).

    ros_empty_service_call.py SERVICE TIMEOUT

Calls the absolute service name SERVICE (e.g. `/stop_motor`) once it is matched, prints
`SERVICE answered` and exits 0 on the reply; exits 1 naming SERVICE after TIMEOUT seconds
without one. The mapping is rmw_fastrtps's, as in ros_param_client.py.
"""

import sys

from cyclonedds.domain import DomainParticipant

from ros_idl import EmptyRequest, EmptyResponse
from ros_param_client import Service


def main(argv):
    name, timeout = argv[1], float(argv[2])
    service = Service(DomainParticipant(0), name, EmptyRequest, EmptyResponse)
    service.call(EmptyRequest(), timeout)
    print(f"{name} answered")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
