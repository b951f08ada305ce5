"""`fence-sorter run --rate --set`: the nodes run the stream's mix at the rate on the scene with
the overrides (three parcels, unpaced)."""

from __future__ import annotations

import json

import pytest
from processes import run_cli

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def test_a_run_at_a_rate_scans_3600_over_rate_s_apart():
    proc = run_cli(
        "run",
        "--parcels",
        "3",
        "--rate",
        "1200",
        "--set",
        "conveyor.belt_speed=1.5",
        "--rtf",
        "0",
        "--json",
        timeout=180,
    )
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["parcels_seen"] == 3 and s["outcomes"] == 3 and s["missing_outcomes"] == []
    # scan times are sim times on the 1 kHz loop: 2 headways of 3 s within 2 ms
    assert s["throughput_pcs_h"] == pytest.approx(1200.0, rel=1e-3)
