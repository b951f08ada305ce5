"""The fit's intervals and its parallel schedulers: each channel's noise counted with its own
level, and Dask's scheduler giving the process pool's estimates."""

from __future__ import annotations

import numpy as np
import pytest

from fence_sorter.calibration.bag import read_measured_bag
from fence_sorter.calibration.emulate import emulate_bag
from fence_sorter.calibration.fit import Z95, _covariance, calibrate
from fence_sorter.calibration.replay import with_values
from fence_sorter.calibration.sensors import load_sensors
from fence_sorter.cli.main import main
from fence_sorter.scene import load_scene


def test_interval_counts_each_channel_with_its_own_noise():
    """A linear model, two channels divided by an assumed noise level of 1: 60 rows whose
    noise is in truth 2 (they alone determine theta_0) and 3000 rows of noise 1. Over 400
    noise draws the 95 % interval of every parameter holds the truth for 92-98 % of them
    (binomial 95 % +- 2.7 sd); one s^2 pooled over the rows would be set by the many rows of
    noise 1 and cover theta_0 for only about two thirds."""
    rng = np.random.default_rng(3)
    m_a, m_b = 60, 3000
    jac = np.zeros((m_a + m_b, 3))
    jac[:m_a, 0] = rng.normal(1.0, 0.3, m_a)
    jac[m_a:, 1] = rng.normal(0.0, 1.0, m_b)
    jac[:, 2] = 0.5
    level = np.r_[np.full(m_a, 2.0), np.ones(m_b)]
    theta = np.array([0.3, -1.2, 2.0])
    inside = np.zeros(3)
    inside_pooled = np.zeros(3)
    trials = 400
    for _ in range(trials):
        y = jac @ theta + rng.normal(0.0, 1.0, level.size) * level
        est, *_ = np.linalg.lstsq(jac, y, rcond=None)
        r = jac @ est - y
        cov, _, factors = _covariance(jac, r, (m_a, m_b), np.inf)
        inside += np.abs(est - theta) <= Z95 * np.sqrt(np.diag(cov))
        pooled = float(r @ r) / (r.size - 3) * np.linalg.inv(jac.T @ jac)
        inside_pooled += np.abs(est - theta) <= Z95 * np.sqrt(np.diag(pooled))
    assert np.all((inside / trials > 0.92) & (inside / trials < 0.98)), inside / trials
    assert inside_pooled[0] / trials < 0.8
    # the last draw's variance factors are the channels' noise variances
    assert factors[0] == pytest.approx(4.0, rel=0.5) and factors[1] == pytest.approx(1.0, rel=0.1)


def test_dask_scheduler_gives_the_estimates_of_the_process_pool(tmp_path):
    """The parcels' replays run by Dask's scheduler over two worker processes: the same
    replays, so the same estimates and intervals as the process pool's, to the last bits."""
    base = load_scene("arbitrary_stiff").scenario
    truth = with_values(base, {"mu_fence": 0.40, "mu_belt": 0.55})
    bag = emulate_bag(
        tmp_path / "b", truth, load_sensors("camera60"), scene_name="x", stream="default",
        count=3, seed=8,
    )  # fmt: skip
    mb = read_measured_bag(bag)
    names = ["mu_fence", "mu_belt"]
    pool = calibrate(base, mb, names, workers=2)
    dask = calibrate(base, mb, names, workers=2, scheduler="dask")
    assert dask.replays == pool.replays and dask.nfev == pool.nfev
    for a, b in zip(pool.estimates, dask.estimates, strict=True):
        assert a.verdict == b.verdict == "identified"
        assert b.value == pytest.approx(a.value, rel=1e-12)
        assert b.ci95 == pytest.approx(a.ci95, rel=1e-9)
    assert dask.estimates[0].ci95[0] < 0.40 < dask.estimates[0].ci95[1]


def test_unknown_scheduler_exits_2(capsys):
    assert main(["calibrate", "no_such_bag", "--fit", "k_p", "--scheduler", "threads"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--scheduler threads" in err[0] and "dask" in err[0]
