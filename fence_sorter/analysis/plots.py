"""Plots of a recorded run in the paper's style (Fig. 11/12): (a) centre-of-gravity trajectory
with parcel outlines and fence positions, (b) fence tip deflection, (c) N against N_stiff."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fence_sorter.analysis.run import WORKED_STAGES, RecordedRun  # noqa: E402

OUTLINES = 8  # parcel outlines drawn along a trajectory


def footprint(spec: dict | None, x: float, y: float, yaw: float) -> np.ndarray:
    """Closed polygon (5 x 2) of the parcel footprint with C_s at (x, y) [m]."""
    a = spec["length_a"] if spec else 0.4
    b = spec["width_b"] if spec else 0.3
    xp = spec["cog_offset_x"] if spec else 0.0
    yp = spec["cog_offset_y"] if spec else 0.0
    c, s = math.cos(yaw), math.sin(yaw)
    local = np.array([(-xp + sx * a / 2, -yp + sy * b / 2) for sx, sy in
                      ((1, 1), (-1, 1), (-1, -1), (1, -1), (1, 1))])  # fmt: skip
    rot = np.array([[c, -s], [s, c]])
    return local @ rot.T + np.array([x, y])


def _window(run: RecordedRun, pid: int) -> tuple[float, float] | None:
    s = run.series.get(pid)
    if s is None or s.t.size == 0:
        return None
    touched = np.nonzero(np.isin(s.stage, WORKED_STAGES))[0]
    if touched.size == 0:
        return None
    return float(s.t[touched[0]] - 0.3), float(s.t[-1] + 0.1)


def plot_parcel(run: RecordedRun, pid: int, path: Path) -> Path | None:
    """Figure (a, b, c) of one parcel the fence worked on; None if it never touched it."""
    win = _window(run, pid)
    if win is None:
        return None
    s, spec, f = run.series[pid], run.parcels.get(pid), run.fence
    o = run.outcomes.get(pid)
    sel = (s.t >= win[0]) & (s.t <= win[1])
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.6))
    a = ax[0]
    a.axhline(0.0, color="0.3", lw=1)
    a.axhline(run.belt_width, color="0.3", lw=1, ls="--", label="belt edge y0 = s")
    a.plot(s.x[sel], s.y[sel], "C0-", lw=1.5, label="C_s")
    idx = np.nonzero(sel)[0]
    for k in idx[:: max(1, idx.size // OUTLINES)]:
        poly = footprint(spec, s.x[k], s.y[k], s.yaw[k])
        a.plot(poly[:, 0], poly[:, 1], "C0-", lw=0.6, alpha=0.6)
        if f.t.size:
            j = int(np.argmin(np.abs(f.t - s.t[k])))
            a.plot(f.node_x[j], f.node_y[j], "C3-", lw=1.0, alpha=0.6)
    a.plot([], [], "C3-", lw=1.0, label="fence")
    a.set_xlabel("x0 [m]")
    a.set_ylabel("y0 [m]")
    a.set_aspect("equal", adjustable="datalim")
    a.set_title("(a) trajectory of the centre of gravity")
    a.legend(loc="best", fontsize=8)
    b = ax[1]
    fs = (f.t >= win[0]) & (f.t <= win[1]) if f.t.size else np.zeros(0, dtype=bool)
    b.plot(f.t[fs], 1e3 * f.tip[fs], "C3-")
    b.set_xlabel("t [s]")
    b.set_ylabel("tip deflection [mm]")
    b.set_title("(b) fence tip deflection")
    b.grid(alpha=0.3)
    c = ax[2]
    c.plot(s.t[sel], s.n[sel], "C0.-", label="N (sampled)")
    c.plot(s.t[sel], s.n_stiff[sel], "C1.--", label="N_stiff (sampled)")
    if o and math.isfinite(o["peak_normal_force"]):
        c.axhline(o["peak_normal_force"], color="C0", lw=0.8, ls=":", label="peak N (live)")
        c.axhline(
            o["peak_normal_force_stiff"], color="C1", lw=0.8, ls=":", label="peak N_stiff (live)"
        )
    c.set_xlabel("t [s]")
    c.set_ylabel("normal force [N]")
    c.set_title("(c) reaction N against N_stiff")
    c.legend(loc="best", fontsize=8)
    c.grid(alpha=0.3)
    verdict = f"{o['reason_name']}" if o else "no outcome in bag"
    fig.suptitle(f"parcel {pid}: {verdict}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_overview(run: RecordedRun, path: Path) -> Path:
    """C_s trajectories of every parcel over the belt."""
    fig, ax = plt.subplots(figsize=(10, 3.8))
    ax.axhline(0.0, color="0.3", lw=1)
    ax.axhline(run.belt_width, color="0.3", lw=1, ls="--")
    for pid, s in sorted(run.series.items()):
        o = run.outcomes.get(pid)
        style = "-" if (o and o["sorted"]) else ":"
        ax.plot(s.x, s.y, style, lw=1.2, label=f"{pid} {o['reason_name'] if o else '?'}")
    ax.set_xlabel("x0 [m]")
    ax.set_ylabel("y0 [m]")
    ax.set_title("centre-of-gravity trajectories (solid: sorted)")
    if len(run.series) <= 12:
        ax.legend(fontsize=7, loc="upper left", ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
