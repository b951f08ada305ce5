"""The calibration benchmark's coverage figures against closed forms: Wilson's interval of a
share (SciPy's), the binomial probability that a block of 20 seeds holds the truth 17-19
times, and the per-block counts of a known sequence of misses."""

from __future__ import annotations

import math

import pytest
from scipy import stats

from benchmarks.calibrate_bench import (
    TRUTH,
    binomial_share,
    coverage_figures,
    wilson,
)


@pytest.mark.parametrize(("k", "n"), [(44, 50), (16, 20), (190, 200), (0, 12), (30, 30)])
def test_wilson_interval_is_scipys(k, n) -> None:
    ci = stats.binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    assert wilson(k, n) == pytest.approx((ci.low, ci.high), abs=1e-12)


def test_block_probability_is_the_binomial_sum() -> None:
    """P(17 <= K <= 19), K ~ B(20, 0.95): 1 - cdf(16) - pmf(20) = 0.6256."""
    want = stats.binom.cdf(19, 20, 0.95) - stats.binom.cdf(16, 20, 0.95)
    assert binomial_share(20, 0.95, 17, 19) == pytest.approx(want, rel=1e-12)
    assert want == pytest.approx(0.6256, abs=1e-4)


def _rows(miss_seeds: set[int], n: int) -> list[dict]:
    rows = []
    for i in range(n):
        z = 2.5 if i in miss_seeds else (-1.0) ** i
        est = {"value": 1.0, "ci95": [0.9, 1.1], "inside": abs(z) <= 1.96, "z": z,
               "verdict": "identified"}  # fmt: skip
        rows.append({"seed": 100 + i, **{name: est for name in TRUTH}})
    return rows


def test_coverage_figures_count_blocks_and_the_first_seeds() -> None:
    """45 seeds, misses at 0, 1, 2, 3 (first block: 16 inside), 25 (second: 19) and 44 (in
    the incomplete third block, which is not counted as a block)."""
    rows = _rows({0, 1, 2, 3, 25, 44}, 45)
    fig = coverage_figures(rows)
    name = next(iter(TRUTH))
    assert fig["blocks"] == 2
    assert fig["block_counts"][name] == [16, 19]
    assert fig["blocks_in_target"][name] == 1
    assert fig["share_inside_first"][name] == pytest.approx(16 / 20)
    assert fig["share_inside"][name] == pytest.approx(39 / 45)
    assert fig["share_inside_ci95"][name] == pytest.approx(wilson(39, 45))
    assert fig["rms_z"][name] == pytest.approx(math.sqrt((6 * 2.5**2 + 39) / 45))
    assert fig["median_rel_halfwidth"][name] == pytest.approx(0.1 / TRUTH[name])
