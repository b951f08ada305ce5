"""A participant on another host that takes a run's /sort_outcomes and /parcels over the link.

``python test/hosts/listener.py --domain N --interface A --peers B --outcomes K --timeout S``
(run in the other host's network namespace) prints one JSON object: the outcomes (parcel id,
code) and parcel ids it received, in order of reception. Real rclpy, on the transport profile
``fence-sorter run --interface`` writes (fence_sorter.runner.transport).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--interface", required=True)
    ap.add_argument("--peers", required=True)
    ap.add_argument("--outcomes", type=int, required=True)
    ap.add_argument("--timeout", type=float, default=180.0)
    a = ap.parse_args(argv)

    from fence_sorter.rosdistro import set_profile
    from fence_sorter.runner.transport import hosts_transport, write_profile

    profile = write_profile(
        hosts_transport(a.interface, a.peers), Path(tempfile.mkdtemp(prefix="fs_listener_"))
    )
    os.environ["ROS_DOMAIN_ID"] = str(a.domain)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"
    set_profile(os.environ, str(profile))

    import rclpy  # lazy: after the transport's environment is set

    from fence_sorter.nodes.qos import topic_qos
    from fence_sorter.recording import topics
    from fence_sorter_msgs.msg import Parcel, SortOutcome

    rclpy.init()
    node = rclpy.create_node("other_host_listener")
    got: dict[str, list] = {"outcomes": [], "parcels": []}
    node.create_subscription(
        SortOutcome,
        topics.SORT_OUTCOMES,
        lambda m: got["outcomes"].append([int(m.parcel_id), int(m.reason_code)]),
        topic_qos(topics.SORT_OUTCOMES),
    )
    node.create_subscription(
        Parcel,
        topics.PARCELS,
        lambda m: got["parcels"].append(int(m.parcel_id)),
        topic_qos(topics.PARCELS),
    )
    print("listening", file=sys.stderr, flush=True)
    end = time.monotonic() + a.timeout
    while time.monotonic() < end and len(got["outcomes"]) < a.outcomes:
        rclpy.spin_once(node, timeout_sec=0.1)
    print(json.dumps(got), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
