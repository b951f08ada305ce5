"""Outputs of a calibration: the calibrated scene file, residual plots, the text report."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml

from .events import EventData
from .fit import CalibrationResult
from .replay import PARAMETERS


def write_scene(source: Path, values: dict[str, float], path: Path, note: str) -> Path:
    """The scene file ``source`` with the identified ``values`` set, written to ``path``."""
    raw = yaml.safe_load(source.read_text(encoding="utf-8")) or {}
    for name, v in values.items():
        section, key = PARAMETERS[name][0].split(".")
        raw.setdefault(section, {})[key] = float(f"{v:.6g}")
    raw["name"] = f"{raw.get('name', source.stem)}_calibrated"
    path.parent.mkdir(parents=True, exist_ok=True)
    text = "".join(f"# {line}\n" for line in note.splitlines())
    path.write_text(text + yaml.safe_dump(raw, sort_keys=False), encoding="utf-8")
    return path


def format_result(res: CalibrationResult) -> str:
    lines = [
        f"calibration of {len(res.parcels)} parcels, {res.samples} residuals, "
        f"{res.replays} replays in {res.wall_time:.1f} s ({res.cpu_time:.1f} CPU s)",
        f"camera frame in the sorter frame: x {res.camera_offset[0]:+.4f} m, "
        f"y {res.camera_offset[1]:+.4f} m, yaw {math.degrees(res.camera_offset[2]):+.3f} deg "
        f"(pre-stroke RMS {res.camera_rms * 1e3:.2f} mm); encoder RMS about the strokes "
        f"{res.encoder_rms:.2e} rad",
        f"noise levels: position {res.sigma[0] * 1e3:.3g} mm, yaw "
        f"{math.degrees(res.sigma[1]):.3g} deg, root moment {res.sigma[2]:.3g} N m; camera "
        f"positions scatter {res.pose_scatter:.3g} times their pre-stroke noise",
        "",
        f"{'parameter':<22}{'prior':>12}{'estimate':>12}{'95 % interval':>28}  verdict",
    ]
    for e in res.estimates:
        if e.value is None:
            lines.append(f"{e.name:<22}{e.prior:>12.5g}{'-':>12}{'-':>28}  {e.verdict}: {e.why}")
            continue
        ci = f"[{e.ci95[0]:.5g}, {e.ci95[1]:.5g}]"
        lines.append(f"{e.name:<22}{e.prior:>12.5g}{e.value:>12.5g}{ci:>28}  {e.verdict}")
        if e.bootstrap_ci95:
            b = e.bootstrap_ci95
            lines.append(f"{'':<22}{'':>12}{'bootstrap':>12}{f'[{b[0]:.5g}, {b[1]:.5g}]':>28}")
    if len(res.names) > 1:
        lines += ["", "correlation (identified parameters):"]
        w = max(len(n) for n in res.names) + 2
        lines.append(" " * w + "".join(f"{n[:10]:>11}" for n in res.names))
        for n, row in zip(res.names, res.correlation, strict=True):
            lines.append(f"{n:<{w}}" + "".join(f"{v:>11.3f}" for v in row))
    return "\n".join(lines)


def plot_residuals(eds: list[EventData], res: CalibrationResult, path: Path) -> Path:
    """Residuals (twin minus measured) of the calibrated twin against time from stroke start."""
    import matplotlib  # lazy: Matplotlib (0.7-1.3 s), only to plot

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: Matplotlib (0.7-1.3 s), only to plot

    pos, yaw, mom = res.residuals
    tau = np.concatenate([ed.cam_tau for ed in eds])
    stau = np.concatenate([ed.str_tau for ed in eds]) if mom.size else np.zeros(0)
    n = len(tau)
    rows = 3 if mom.size else 2
    fig, axes = plt.subplots(rows, 1, figsize=(8, 2.6 * rows), sharex=True)
    axes[0].plot(tau, pos[:n] * 1e3, ".", ms=2, label="x")
    axes[0].plot(tau, pos[n:] * 1e3, ".", ms=2, label="y")
    axes[0].set_ylabel("position [mm]")
    axes[0].legend(loc="upper right")
    axes[1].plot(tau, np.degrees(yaw), ".", ms=2)
    axes[1].set_ylabel("yaw [deg]")
    if mom.size:
        axes[2].plot(stau, mom, ".", ms=1)
        axes[2].set_ylabel("root moment [N m]")
    axes[-1].set_xlabel("time from stroke start [s]")
    fig.suptitle("calibrated twin minus measured")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
