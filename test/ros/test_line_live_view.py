"""The live Rerun view of a line over DDS: ``fence-sorter run --line two_units --live-rrd FILE``.

The units publish their view (``/<unit>/fence_state``, ``/<unit>/load_states``) every 0.05 s of
sim time and the ``line_viewer`` process logs the line view from those messages and the
hand-offs. The lockstep line is deterministic, so at each sample time the live view must show
what ``line-sim``'s view (visualisation/line_view.py on a LinePlant, same line, parcels and
seed) shows: every unit's fence at the same nodes, and each parcel it draws (those in the
units' simulations) with the same footprint. Both recordings are read with Rerun's own reader.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from processes import run_cli
from rrd_read import read_rrd

from fence_sorter.line.line_file import load_line
from fence_sorter.line.multi_unit import LinePlant, LineRunConfig
from fence_sorter.visualisation.line_view import LineRerunLogger, line_blueprint, open_recording

pytestmark = [pytest.mark.ros, pytest.mark.slow]

CONFIG = Path(__file__).resolve().parents[2] / "config" / "lines" / "two_units.yaml"
UNITS = ["unit_1", "unit_2"]
PARCELS, SEED, PERIOD = 3, 3, 0.05
TOL = 1e-9  # [m]: the same floats, the parcels' yaw through a quaternion


def _corners(strip) -> np.ndarray:
    """A closed footprint's four corners in a fixed order (a parcel turned by pi is the same
    rectangle with its corners in another order)."""
    c = np.asarray(strip, dtype=float)[:4]
    return c[np.lexsort((c[:, 1].round(6), c[:, 0].round(6)))]


def _by_time(rows) -> dict[int, dict]:
    return {round(t / 0.01): row for t, row in rows}


@pytest.fixture(scope="module")
def views(tmp_path_factory) -> tuple[dict, dict, dict]:
    base = tmp_path_factory.mktemp("live_view")
    live = base / "live.rrd"
    proc = run_cli(
        "run", "--line", "two_units", "--parcels", str(PARCELS), "--seed", str(SEED), "--json",
        "--live-rrd", str(live), "--log-dir", str(base / "logs"), timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary = json.loads(proc.stdout)
    ref = base / "sim.rrd"
    line = load_line(CONFIG)
    plant = LinePlant(line, LineRunConfig(parcels=PARCELS, seed=SEED))  # line-sim --rrd
    plant.warm_up()
    logger = LineRerunLogger(
        open_recording(ref, layout=lambda paused: line_blueprint(line, paused)), line, PERIOD
    )
    plant.observers.append(logger.observe)
    plant.run()
    logger.close(plant)
    return summary, read_rrd(live), read_rrd(ref)


def test_live_view_has_every_unit_and_the_parcels(views) -> None:
    """Every unit's fence and plots are in the live view at (nearly) every sample time of
    line-sim's view, and every parcel of the run shows up in it."""
    summary, got, want = views
    assert summary["parcels_inducted"] == PARCELS
    for u in UNITS:
        for e in (f"/top/units/{u}/fence", f"/plots/alpha_w/{u}", f"/plots/contact/{u}"):
            times = {round(t / 0.01) for t, _ in got[e]}
            ref = {round(t / 0.01) for t, _ in want[e]}
            assert times <= ref, e
            # best effort on one host: a sample may be lost, not many
            assert len(times) >= 0.95 * len(ref), (e, len(times), len(ref))

    def pids(rows) -> set[str]:
        return {lab.split()[0] for _, row in rows for lab in row["labels"] or []}

    assert pids(got["/top/parcels"]) == pids(want["/top/parcels"])
    assert len(pids(want["/top/parcels"])) == PARCELS


def test_live_view_equals_line_sims_view_at_the_same_sim_times(views) -> None:
    """At each sample time: each unit's fence strip, alpha_w and N equal line-sim's; each
    parcel the live view draws is drawn by line-sim's view with the same footprint."""
    _, got, want = views
    for u in UNITS:
        ref = _by_time(want[f"/top/units/{u}/fence"])
        for step, row in _by_time(got[f"/top/units/{u}/fence"]).items():
            a, b = np.asarray(row["strips"][0]), np.asarray(ref[step]["strips"][0])
            assert a.shape == b.shape and np.abs(a - b).max() <= TOL, (u, step)
        for plot in ("alpha_w", "contact"):
            ref = _by_time(want[f"/plots/{plot}/{u}"])
            for step, row in _by_time(got[f"/plots/{plot}/{u}"]).items():
                assert row["scalars"] == pytest.approx(ref[step]["scalars"], abs=TOL), (u, step)
    ref = _by_time(want["/top/parcels"])
    compared = 0
    moving = set()
    for step, row in _by_time(got["/top/parcels"]).items():
        want_row = ref[step]
        drawn = {
            lab.split()[0]: s
            for lab, s in zip(want_row["labels"] or [], want_row["strips"] or [], strict=True)
        }
        for lab, strip in zip(row["labels"] or [], row["strips"] or [], strict=True):
            pid = lab.split()[0]
            assert pid in drawn, (step, lab)
            a, b = _corners(strip), _corners(drawn[pid])
            assert np.abs(a - b).max() <= TOL, (step, lab, a, b)
            compared += 1
            moving.add((pid, round(float(a[:, 0].mean()), 1)))
    # the parcels were compared along their ride through both units' zones
    print(f"{compared} parcel footprints compared, {len(moving)} (parcel, 0.1 m) places")
    assert compared > 100 and len(moving) > 40, (compared, len(moving))
