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
    ev = run.events.get(pid)
    if ev is not None:  # every solver step of the stroke
        b.plot(ev.t, 1e3 * ev.tip_deflection, "C3-", lw=1.0, label="solver steps (/sort_events)")
    fs = (f.t >= win[0]) & (f.t <= win[1]) if f.t.size else np.zeros(0, dtype=bool)
    b.plot(f.t[fs], 1e3 * f.tip[fs], "k.", ms=3, label="sampled (/fence_state)")
    b.legend(loc="best", fontsize=8)
    b.set_xlabel("t [s]")
    b.set_ylabel("tip deflection [mm]")
    b.set_title("(b) fence tip deflection")
    b.grid(alpha=0.3)
    c = ax[2]
    if ev is not None:
        c.plot(ev.t, ev.normal_force, "C0-", lw=1.0, label="N (solver steps)")
        c.plot(ev.stiff_t, ev.stiff_force, "C1--", lw=1.0, label="N_stiff (stiff obstacle)")
    c.plot(s.t[sel], s.n[sel], "C0.", ms=4, label="N (sampled)")
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


def plot_impact(run: RecordedRun, pid: int, path: Path, k: int = 0) -> Path | None:
    """Fig. 11c/12c from the full-rate event: N on the flexible fence and N_stiff against an
    undeformable obstacle through impact ``k`` of the parcel (1: onset, 2: end of contact);
    None if the bag has no event with that impact."""
    ev = run.events.get(pid)
    win = ev.impact_window(k) if ev is not None else None
    if win is None:
        return None
    t0, t1 = win
    pad = 0.1 * (t1 - t0) + 1e-3
    sel = (ev.t >= t0 - pad) & (ev.t <= t1 + pad)
    ss = (ev.stiff_t >= t0) & (ev.stiff_t <= t1 + pad)
    ms = 1e3
    fig, ax = plt.subplots(figsize=(7.5, 4.6))
    ax.plot(ms * (ev.t[sel] - t0), ev.normal_force[sel], "C0.-", ms=3, lw=1.2,
            label=f"N, flexible fence ({int(np.count_nonzero(sel))} solver steps)")  # fmt: skip
    ax.plot(ms * (ev.stiff_t[ss] - t0), ev.stiff_force[ss], "C1--", lw=1.2,
            label="N_stiff, undeformable obstacle")  # fmt: skip
    in_imp = (ev.t >= t0) & (ev.t <= t1)
    peak_n = float(np.max(ev.normal_force[in_imp])) if np.any(in_imp) else 0.0
    peak_s = float(ev.impact_force_stiff[k])
    for x, label in ((0.0, "1"), (ms * (t1 - t0), "2")):
        ax.axvline(x, color="0.5", lw=0.7, ls=":")
        ax.annotate(label, (x, 0.0), xytext=(3, 3), textcoords="offset points", color="0.3")
    ax.set_xlabel("time since the onset of the impact [ms]")
    ax.set_ylabel("normal force [N]")
    ratio = peak_s / peak_n if peak_n > 0 else math.nan
    ax.set_title(
        f"parcel {pid}, impact {k + 1}: w_n = {ev.impact_speed[k]:.3f} m/s, peak N "
        f"{peak_n:.0f} N, N_stiff {peak_s:.0f} N (x{ratio:.2f})",
        fontsize=10,
    )
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_damage_risk(rows: list[dict], path: Path, labelled: int = 5) -> Path:
    """The stream's damage risk: (a) every parcel with an impact at (w_n / w_dop, a_N / a_Ndop)
    with the limits at 1 and the worst ``labelled`` parcels named, (b) the share of parcels at
    or below each utilisation (empirical distribution) and the share over each limit."""
    hit = [r for r in rows if math.isfinite(r.get("impact_speed_margin", math.nan))]
    u_w = 1.0 - np.array([r["impact_speed_margin"] for r in hit])
    u_a = 1.0 - np.array([r["accel_margin"] for r in hit])
    ids = [r["parcel_id"] for r in hit]
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.8))
    a = ax[0]
    worst = np.argsort(-np.maximum(u_w, u_a))[:labelled]
    a.scatter(u_w, u_a, c=np.maximum(u_w, u_a), cmap="RdYlGn_r", vmin=0.5, vmax=1.25,
              edgecolors="k", linewidths=0.5, zorder=3)  # fmt: skip
    for j in worst:
        a.annotate(str(ids[j]), (u_w[j], u_a[j]), xytext=(4, 4), textcoords="offset points",
                   fontsize=8)  # fmt: skip
    top = max(1.2, float(np.max(u_w, initial=0.0)) * 1.1, float(np.max(u_a, initial=0.0)) * 1.1)
    a.axvline(1.0, color="C3", lw=1.2)
    a.axhline(1.0, color="C3", lw=1.2, label="limit (w_dop, a_Ndop)")
    a.set_xlim(0.0, top)
    a.set_ylim(0.0, top)
    a.set_xlabel("impact speed w_n / w_dop [-]")
    a.set_ylabel("peak acceleration a_N / a_Ndop [-]")
    a.set_title(f"(a) {len(hit)} parcels with an impact (labels: the worst)", fontsize=10)
    a.legend(loc="upper left", fontsize=8)
    a.grid(alpha=0.3)
    b = ax[1]
    for u, name, color in ((u_w, "w_n / w_dop", "C0"), (u_a, "a_N / a_Ndop", "C1")):
        if not len(u):
            continue
        share = np.count_nonzero(u > 1.0) / len(u)
        x = np.sort(u)
        b.step(x, np.arange(1, len(x) + 1) / len(x), where="post", color=color,
               label=f"{name}: {share:.0%} over the limit")  # fmt: skip
    b.axvline(1.0, color="C3", lw=1.2)
    b.set_xlim(0.0, top)
    b.set_ylim(0.0, 1.02)
    b.set_xlabel("utilisation of the limit [-]")
    b.set_ylabel("share of the parcels at or below [-]")
    b.set_title("(b) distribution over the stream", fontsize=10)
    b.legend(loc="upper left", fontsize=8)
    b.grid(alpha=0.3)
    fig.suptitle("damage risk per parcel (1 = at the limit)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
