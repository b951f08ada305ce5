"""How ``python -m benchmarks bench`` times a run (``bench.timed_run``): the garbage collector is
off during the timed call and back in its previous state after it (also when the call raises), and
no collection runs inside the call; the same function times our runs and the SciPy baselines. No
timing assertions (speed targets live in docs/reports/benchmarks.md)."""

from __future__ import annotations

import gc

import pytest

from benchmarks import bench as B
from fence_sorter.physics import simulate as S
from fence_sorter.scene import load_scene


@pytest.fixture
def spy(monkeypatch):
    """Replace ``simulate`` by a spy recording whether the collector ran during the call."""
    seen = {}

    def fake(sc, model=None):
        seen["enabled"] = gc.isenabled()
        before = gc.get_stats()[0]["collections"]
        # allocations that would trigger a generation-0 collection with the collector on
        junk = [[i] for i in range(5 * gc.get_threshold()[0])]
        seen["collections"] = gc.get_stats()[0]["collections"] - before
        del junk
        if seen.get("raise"):
            raise RuntimeError("boom")
        return real(sc, model)

    real = S.simulate
    monkeypatch.setattr(S, "simulate", fake)
    return seen


def test_collector_off_during_the_timed_call_and_restored(spy):
    sc = load_scene("positioned_stiff").scenario
    assert gc.isenabled()
    outcome, wall, cpu = B.timed_run(sc)
    assert spy["enabled"] is False
    assert spy["collections"] == 0
    assert gc.isenabled()
    assert outcome.success and wall > 0.0 and cpu >= 0.0


def test_collector_state_restored_when_the_call_raises(spy):
    sc = load_scene("positioned_stiff").scenario
    spy["raise"] = True
    with pytest.raises(RuntimeError):
        B.timed_run(sc)
    assert gc.isenabled()
    gc.disable()
    try:
        spy["raise"] = False
        B.timed_run(sc)
        assert not gc.isenabled()  # a caller that had it off keeps it off
    finally:
        gc.enable()


def test_scipy_baselines_timed_the_same_way(spy):
    sc = load_scene("positioned_stiff").scenario
    run = B.with_solver(sc, method="scipy:LSODA", rtol=1e-2, atol=1e-4, max_wall_time=60.0)
    outcome, _, _ = B.timed_run(run)
    assert spy["enabled"] is False and spy["collections"] == 0
    assert outcome.success
