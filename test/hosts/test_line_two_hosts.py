"""A line split over two hosts: two network namespaces joined by a veth pair.

Host A runs the owner of two_units (induction, recirculation, the lockstep clock) and unit_1
(``fence-sorter run --line two_units --units 1``); host B runs unit_2 alone (``--units 2
--no-owner``). The link unit_1 -> unit_2 and every command and reply to unit_2 cross the veth
as UDP (each namespace has its own addresses, so Fast DDS sees two hosts). Checked: both
commands exit 0, B's ends with the line; A's --json summary equals ``fence-sorter line-sim`` of
the same line, parcels and seed (the lockstep makes them equal exactly, the wall-clock fields
aside), conservation is exact and the hand-offs unit_1 sent on the link equal those unit_2
received.

Four units with the recorder: host A runs units 1-2 of four_units without the owner, host B
the owner, units 3-4 and the recorder (``--bag``); the link unit_2 -> unit_3 crosses the
veth. Checked as above, and the bag is complete: ``fence-sorter analyze`` of it gives B's
summary field by field. And the traffic crossed the veth, not /dev/shm (which the two
namespaces share): each veth end's kernel counters grew by at least what the messages that
must cross carry, counted from the summary (:func:`_least_on_the_link`), and no Fast DDS file
of /dev/shm was open in both namespaces during the run (each namespace's participants map
segments of their own).
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import uuid
from pathlib import Path

import pytest
from processes import run_cli
from rclpy.serialization import serialize_message
from std_msgs.msg import String

from benchmarks.netns import fastdds_shm, grown, link_counters, wait_both
from fence_sorter.line.lockstep import Command, Done, Step, encode
from fence_sorter.nodes.parameters import LINE_OWNER_PARAMETERS
from fence_sorter_msgs.msg import HandOff

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.hosts]

REPO = Path(__file__).resolve().parents[2]
PARCELS, SEED = 10, 3
WALL = ("wall_time_s", "real_time_factor")
#: the line clock's step [s] (the owner's default)
DT = next(p.default for p in LINE_OWNER_PARAMETERS if p.name == "dt")
#: an RTPS DATA submessage without its payload: submessage header (4), flags and inline-QoS
#: offset (4), reader and writer entity ids (8), sequence number (8)
DATA_BYTES = 24
#: the headers of one datagram on the veth: Ethernet (14), IPv4 (20), UDP (8), RTPS (20)
DATAGRAM_BYTES = 62


def _line(ns: str, *args: str, cwd: Path, line: str = "two_units", parcels: int = PARCELS):
    return subprocess.Popen(
        ["ip", "netns", "exec", ns, sys.executable, "-m", "fence_sorter.cli.main", "run",
         "--line", line, "--parcels", str(parcels), "--seed", str(SEED), "--json",
         "--timeout", "600", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd,
    )  # fmt: skip


def test_a_line_over_two_hosts_equals_line_sim(two_hosts, tmp_path: Path) -> None:
    a, addr_a, b, addr_b = two_hosts.a, two_hosts.addr_a, two_hosts.b, two_hosts.addr_b
    domain = str(150 + int(uuid.uuid4().hex[:4], 16) % 50)
    sim = run_cli("line-sim", "two_units", "--parcels", str(PARCELS), "--seed", str(SEED),
                  "--json")  # fmt: skip
    assert sim.returncode == 0, sim.stderr
    ref = json.loads(sim.stdout)
    # B first: the owner's start gate then waits for unit_2 across the link
    side_b = _line(b, "--units", "2", "--no-owner", "--domain", domain, "--interface", addr_b,
                   "--peers", addr_a, cwd=tmp_path)  # fmt: skip
    side_a = _line(a, "--units", "1", "--domain", domain, "--interface", addr_a,
                   "--peers", addr_b, cwd=tmp_path)  # fmt: skip
    out_a, err_a, out_b, err_b = wait_both(side_a, side_b, 660, 60)
    assert side_a.returncode == 0, err_a[-3000:]
    assert side_b.returncode == 0, err_b[-3000:]
    got = json.loads(out_a)
    assert {k: (v, got.get(k)) for k, v in ref.items() if k not in WALL and got.get(k) != v} == {}
    n = got["parcels_inducted"]
    assert n == PARCELS == got["sorted"] + got["rejected"] + got["still_on_line"]
    assert got["conservation_ok"] and got["drained"] and got["handoffs_balanced"]
    # sent: unit_1's count on host A; received: unit_2's on host B (its report to the owner)
    across = got["links"]["unit_1>unit_2"]
    assert across["sent"] == across["received"] > 0 and across["lost"] == 0, across
    # B's runner ran unit_2 only and ended with the line
    b_says = json.loads(out_b)
    assert b_says["units_here"] == ["unit_2"] and b_says["line"] == got["line"]


def test_four_units_over_two_hosts_with_the_recorder(two_hosts, tmp_path: Path) -> None:
    a, addr_a, b, addr_b = two_hosts.a, two_hosts.addr_a, two_hosts.b, two_hosts.addr_b
    domain = str(150 + int(uuid.uuid4().hex[:4], 16) % 50)
    parcels = 6
    sim = run_cli("line-sim", "four_units", "--parcels", str(parcels), "--seed", str(SEED),
                  "--json")  # fmt: skip
    assert sim.returncode == 0, sim.stderr
    ref = json.loads(sim.stdout)
    before = (link_counters(a, two_hosts.dev_a), link_counters(b, two_hosts.dev_b))
    side_a = _line(a, "--units", "1,2", "--no-owner", "--domain", domain, "--interface",
                   addr_a, "--peers", addr_b, cwd=tmp_path, line="four_units",
                   parcels=parcels)  # fmt: skip
    bag = tmp_path / "bag"
    side_b = _line(b, "--units", "3,4", "--bag", str(bag), "--domain", domain, "--interface",
                   addr_b, "--peers", addr_a, cwd=tmp_path, line="four_units",
                   parcels=parcels)  # fmt: skip
    shm: tuple[set[str], set[str]] = (set(), set())
    done = threading.Event()

    def watch() -> None:
        while not done.wait(1.0):
            shm[0].update(fastdds_shm(a))
            shm[1].update(fastdds_shm(b))

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    try:
        out_b, err_b, out_a, err_a = wait_both(side_b, side_a, 660, 60)
    finally:
        done.set()
        watcher.join()
    into_a = grown(before[0], link_counters(a, two_hosts.dev_a))
    into_b = grown(before[1], link_counters(b, two_hosts.dev_b))
    assert side_b.returncode == 0, err_b[-3000:]
    assert side_a.returncode == 0, err_a[-3000:]
    got = json.loads(out_b)
    assert {k: (v, got.get(k)) for k, v in ref.items() if k not in WALL and got.get(k) != v} == {}
    assert parcels == got["parcels_inducted"] == got["sorted"] + got["rejected"]
    assert got["conservation_ok"] and got["drained"] and got["handoffs_balanced"]
    across = got["links"]["unit_2>unit_3"]  # sent on host A, received on host B
    assert across["sent"] == across["received"] > 0 and across["lost"] == 0, across
    assert json.loads(out_a)["units_here"] == ["unit_1", "unit_2"]
    # no shared memory between the hosts: each side's Fast DDS files are its own
    assert shm[0] and shm[1] and not shm[0] & shm[1], shm
    # the veth carried the line's traffic between the hosts: each way at least what crosses
    assert got["units_down"] == {}  # units 1-2 answered every step
    least_b_to_a, least_a_to_b = _least_on_the_link(got)
    assert into_a["rx_packets"] >= least_b_to_a[0] and into_a["rx_bytes"] >= least_b_to_a[1], (
        into_a, least_b_to_a)  # fmt: skip
    assert into_b["rx_packets"] >= least_a_to_b[0] and into_b["rx_bytes"] >= least_a_to_b[1], (
        into_b, least_a_to_b)  # fmt: skip
    ana = run_cli("analyze", str(bag), "--json")
    assert ana.returncode == 0, ana.stderr
    from_bag = json.loads(ana.stdout)
    for k in ("sorted", "rejected", "sorted_per_destination", "declined", "links", "units"):
        assert from_bag[k] == got[k], k


def _wire(msg: object) -> int:
    """The least bytes a message takes on the link: its DATA submessage and the CDR payload
    rmw serializes (encapsulation header included)."""
    return DATA_BYTES + len(serialize_message(msg))


def _least_on_the_link(s: dict) -> tuple[tuple[int, int], tuple[int, int]]:
    """(packets, bytes) that must cross the veth B -> A and A -> B in the four-unit run (host
    A: units 1-2; host B: the owner, units 3-4 and the recorder), from the summary ``s``.

    Every step of the line clock the owner sends units 1 and 2 a Step command and waits for
    both their Done replies before the next step's commands: each way at least one datagram
    per step, each with its headers. B -> A: two Step commands per step and the induction's
    hand-offs to unit_1; A -> B: two Done replies per step, unit_2's hand-offs to unit_3 and
    unit_1's to unit_2 (for the recorder). Each message at its least size (the shortest Step
    and Done the wire format can write, a HandOff with empty strings)."""
    steps = round(s["sim_time_s"] / DT)
    step = _wire(String(data=encode(Command(0, Step(0.0, 0.0)))))
    done = _wire(String(data=encode(Done(0.0, (), ()))))
    handoff = _wire(HandOff())
    links = s["links"]
    b_to_a = steps * (DATAGRAM_BYTES + 2 * step) + links["induction>unit_1"]["received"] * handoff
    a_to_b = steps * (DATAGRAM_BYTES + 2 * done) + handoff * (
        links["unit_1>unit_2"]["received"] + links["unit_2>unit_3"]["received"]
    )
    return (steps, b_to_a), (steps, a_to_b)
