"""How far the restarts of :func:`fence_sorter.optimize.solve.optimize` agree.

Each restart is an independent differential evolution (seed ``seed + i``) with its own compass
search; the spread of their optima W_t (1) says how sure the best one is. An optimum that only
one restart reached may be a lucky hit: more restarts tell.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence

#: a restart counts as reaching the best when its W_t is within this fraction of it
NEAR_BEST = 0.01


def restart_spread(optima: Sequence[float]) -> dict | None:
    """Best, median and worst W_t [pcs/h] over the restarts that found a feasible point, how
    many reached within NEAR_BEST of the best (``near_best``) and how many found nothing
    feasible; None without restarts."""
    if not optima:
        return None
    found = sorted(float(w) for w in optima if math.isfinite(w))
    out = {
        "restarts": len(optima),
        "none_feasible": len(optima) - len(found),
        "near_best_share": NEAR_BEST,
        "best": math.nan,
        "median": math.nan,
        "worst": math.nan,
        "near_best": 0,
    }
    if found:
        best = found[-1]
        out.update(
            best=best,
            median=statistics.median(found),
            worst=found[0],
            near_best=sum(w >= best * (1.0 - NEAR_BEST) for w in found),
        )
    return out


def spread_lines(spread: dict | None, optima: Sequence[float]) -> list[str]:
    """The text of a spread: every restart's optimum, best/median/worst, and a warning line
    when only one restart reached the best."""
    if not spread:
        return []
    each = ", ".join("none feasible" if not math.isfinite(w) else f"{w:.0f}" for w in optima)
    n = spread["restarts"]
    if spread["near_best"] == 0:
        return [f"restarts ({n}): {each}", "warning: no restart found a feasible point"]
    lines = [
        f"restarts ({n}): {each} pcs/h; best {spread['best']:.0f}, median "
        f"{spread['median']:.0f}, worst {spread['worst']:.0f}; {spread['near_best']} of {n} "
        f"within {spread['near_best_share']:.0%} of the best"
    ]
    if spread["near_best"] == 1:
        lines.append(
            f"warning: only one of {n} restarts reached the best W_t: it may be a local hit; "
            f"rerun with more restarts (e.g. --restarts {max(2 * n, 5)}) and compare"
        )
    return lines
