"""A line over DDS: two ``line_unit`` processes (namespaces /unit_1, /unit_2) and the
``line_owner`` process, real rclpy nodes talking over Fast DDS on an isolated domain.

The owner's lockstep clock makes the line's figures those of the in-process line on the same
stream and seed, exactly; every hand-off is counted at both ends of its link.
"""

from __future__ import annotations

import json
import subprocess
import sys
from contextlib import ExitStack

import pytest
from processes import managed_process

from fence_sorter.jsonsafe import json_safe
from fence_sorter.line.line_file import load_line
from fence_sorter.line.multi_unit import LinePlant, LineRunConfig

pytestmark = [pytest.mark.ros, pytest.mark.slow]

TWO = load_line("two_units")
WALL = ("wall_time_s", "real_time_factor")


def _node(name: str, *ros_args: str) -> list[str]:
    return [sys.executable, "-m", f"fence_sorter.nodes.{name}", "--ros-args", *ros_args]


def test_two_units_over_dds_give_the_in_process_line_s_figures(env, tmp_path):
    """10 parcels on two_units, seed 3: the owner's summary equals LinePlant's field by field
    (wall-clock fields aside), the line drained with conservation exact, and on every link
    as many hand-offs were received as sent."""
    cfg = LineRunConfig(parcels=10, seed=3)
    ref = json_safe(LinePlant(TWO, cfg).run())
    out = tmp_path / "summary.json"
    with ExitStack() as stack:
        for k, u in enumerate(TWO.units):
            stack.enter_context(
                managed_process(
                    _node(
                        "line_unit",
                        "-r",
                        f"__ns:=/{u.name}",
                        "-p",
                        f"unit_index:={k}",
                        "-p",
                        "line:=two_units",
                    ),  # fmt: skip
                    env,
                    stdout=subprocess.DEVNULL,
                    stderr=(tmp_path / f"{u.name}.err").open("w"),
                )
            )
        owner = stack.enter_context(
            managed_process(
                _node(
                    "line_owner",
                    "-r",
                    "__ns:=/line",
                    "-p",
                    "line:=two_units",
                    "-p",
                    "parcels:=10",
                    "-p",
                    "seed:=3",
                    "-p",
                    "warm_up:=false",
                    "-p",
                    f"summary:={out}",
                ),  # fmt: skip
                env,
            )
        )
        _, err = owner.communicate(timeout=900)
        units = "".join((tmp_path / f"{u.name}.err").read_text()[-1500:] for u in TWO.units)
        assert owner.returncode == 0, err[-2000:] + units
    got = json.loads(out.read_text())
    diff = {k: (ref[k], got.get(k)) for k in ref if k not in WALL and ref[k] != got.get(k)}
    assert diff == {}
    assert got["drained"] and got["conservation_ok"] and got["handoffs_balanced"]
    for link, v in got["links"].items():
        assert v["sent"] == v["received"] > 0, link
        assert v["lost"] == 0 and sum(v["refused"].values()) == 0, link
