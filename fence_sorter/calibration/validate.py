"""Predict held-out parcels with a (calibrated) scene and compare with what was measured.

Per parcel, the same estimators run on the measured camera track and on the twin's replay
sampled at the same instants (so the comparison is not biased by the camera's rate): sorted or
not (the centre crossed the chute edge y0 = s), exit speed (ydot at that crossing, a local
linear fit over +-``EXIT_WINDOW``), y_max (largest centre ordinate seen) and peak acceleration
(largest |a| of a local quadratic fit over +-``ACCEL_WINDOW``). The twin's own full-rate
figures (``simulate``'s exit speed, y_max, a_N) are reported beside them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fence_sorter.physics.simulate import Scenario, simulate

from .bag import MeasuredBag
from .evaluate import Evaluator
from .events import align_camera, event_data
from .replay import event_scenario
from .sensors import camera_to_sorter

EXIT_WINDOW = 0.05  # [s]
ACCEL_WINDOW = 0.05  # [s]


def track_figures(tau: np.ndarray, x: np.ndarray, y: np.ndarray, width: float) -> dict:
    """Sorted, exit speed, y_max and peak acceleration of a sampled centre track."""
    out = {
        "sorted": bool(y.size and y.max() >= width),
        "y_max": float(y.max()) if y.size else math.nan,
    }
    exit_speed = math.nan
    if out["sorted"]:
        k = int(np.argmax(y >= width))
        tc = tau[k] if k == 0 else np.interp(width, y[k - 1 : k + 1], tau[k - 1 : k + 1])
        sel = np.abs(tau - tc) <= EXIT_WINDOW
        if sel.sum() >= 2:
            exit_speed = float(np.polyfit(tau[sel] - tc, y[sel], 1)[0])
    out["exit_speed"] = exit_speed
    peak = math.nan
    acc = []
    for tc in tau:
        sel = np.abs(tau - tc) <= ACCEL_WINDOW
        if sel.sum() >= 4:
            ax = 2.0 * np.polyfit(tau[sel] - tc, x[sel], 2)[0]
            ay = 2.0 * np.polyfit(tau[sel] - tc, y[sel], 2)[0]
            acc.append(math.hypot(ax, ay))
    if acc:
        peak = float(max(acc))
    out["peak_accel"] = peak
    return out


@dataclass
class ParcelCheck:
    parcel_id: int
    measured: dict
    predicted: dict
    twin: dict  # the replay's full-rate figures

    def to_dict(self) -> dict:
        return {
            "parcel_id": self.parcel_id,
            "measured": self.measured,
            "predicted": self.predicted,
            "twin_full_rate": self.twin,
        }


def validate(base: Scenario, mb: MeasuredBag, workers: int | None = None):
    """Per-parcel checks and the error summary of ``base`` on every parcel of ``mb``."""
    offset, _ = align_camera(base, mb)
    eds = [ed for ed in event_data(mb, base.solver.settle_time) if ed.cam_tau.size >= 3]
    evaluate = Evaluator(base, eds, workers)
    try:
        preds = evaluate([{}])[0]
    finally:
        evaluate.close()
    width = base.conveyor.width
    checks = []
    for ed, (px, py, _, _) in zip(eds, preds, strict=True):
        mx, my, _ = camera_to_sorter(offset, ed.cam_x, ed.cam_y, ed.cam_yaw)
        res = simulate(event_scenario(base, ed.ev))
        twin = {
            "sorted": res.sorted,
            "exit_speed": res.exit_speed_y,
            "y_max": res.y_max,
            "peak_accel": res.peak_normal_accel,
        }
        checks.append(
            ParcelCheck(
                ed.ev.parcel_id,
                track_figures(ed.cam_tau, mx, my, width),
                track_figures(ed.cam_tau, px, py, width),
                twin,
            )
        )
    return checks, summary(checks)


def summary(checks: list[ParcelCheck]) -> dict:
    agree = sum(c.measured["sorted"] == c.predicted["sorted"] for c in checks)
    out = {"parcels": len(checks), "sorted_agree": agree}
    for key in ("exit_speed", "y_max", "peak_accel"):
        err = np.array([c.predicted[key] - c.measured[key] for c in checks])
        ref = np.array([abs(c.measured[key]) for c in checks])
        ok = np.isfinite(err) & np.isfinite(ref)
        out[key] = {
            "n": int(ok.sum()),
            "mean_error": float(err[ok].mean()) if ok.any() else None,
            "rms_error": float(np.sqrt(np.mean(err[ok] ** 2))) if ok.any() else None,
            "max_abs_error": float(np.abs(err[ok]).max()) if ok.any() else None,
            "rms_relative_error": float(np.sqrt(np.mean((err[ok] / ref[ok]) ** 2)))
            if ok.any() and np.all(ref[ok] > 0)
            else None,
        }
    return out


def plot_checks(checks: list[ParcelCheck], path) -> None:
    """Predicted against measured for exit speed, y_max and peak acceleration."""
    import matplotlib  # lazy: Matplotlib (0.7-1.3 s), only to plot

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: Matplotlib (0.7-1.3 s), only to plot

    keys = (
        ("exit_speed", "exit speed [m/s]"),
        ("y_max", "y_max [m]"),
        ("peak_accel", "peak acceleration [m/s^2]"),
    )
    fig, axes = plt.subplots(1, 3, figsize=(12, 4))
    for ax, (key, label) in zip(axes, keys, strict=True):
        m = np.array([c.measured[key] for c in checks], dtype=float)
        p = np.array([c.predicted[key] for c in checks], dtype=float)
        ok = np.isfinite(m) & np.isfinite(p)
        ax.plot(m[ok], p[ok], "o", ms=4)
        if ok.any():
            lo, hi = min(m[ok].min(), p[ok].min()), max(m[ok].max(), p[ok].max())
            ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
        ax.set_xlabel(f"measured {label}")
        ax.set_ylabel(f"predicted {label}")
    fig.suptitle("held-out parcels: twin against measured")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
