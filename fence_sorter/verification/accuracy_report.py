"""The work-precision campaign's report (see :mod:`fence_sorter.verification.accuracy`):
observed orders and comparisons, the diagrams, the sampled references, results.json and the
README.md rendered from it."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path

import numpy as np

from fence_sorter.jsonsafe import json_safe
from fence_sorter.physics.params import OUR_METHODS
from fence_sorter.verification.accuracy_runs import (
    GRID_STEP,
    MARKERS,
    MEASURE_TEXT,
    MEASURES,
    Campaign,
    Reference,
    ReferenceCheck,
    RunPoint,
    SceneResult,
    describe,
)
from fence_sorter.verification.report import table


# -- convergence and comparisons (numbers for the report) ---------------------------------------
def observed_order(points: Sequence[RunPoint], measure: str, floor: float) -> float:
    """Least-squares slope of log(error) over log(dt) (errors above 10x ``floor``)."""
    xs, ys = [], []
    for p in points:
        e = p.errors.get(measure, math.nan)
        if p.status == "ok" and math.isfinite(e) and e > 10.0 * max(floor, 0.0) and e > 0:
            xs.append(math.log(p.value))
            ys.append(math.log(e))
    if len(xs) < 3:
        return math.nan
    return float(np.polyfit(xs, ys, 1)[0])


def fastest_reaching(
    points: Sequence[RunPoint], measure: str, target: float, *, ode: bool = False
) -> RunPoint | None:
    """The quickest run that reaches ``target`` in ``measure`` and keeps it.

    A setting counts only if it and every tighter setting of the same method that finished
    have an error at most ``target`` (a lucky cancellation at one loose setting does not
    count). ``ode``: use the errors against the ODE-form reference.
    """

    def err(p: RunPoint) -> float:
        return (p.errors_ode if ode else p.errors).get(measure, math.inf)

    hits = []
    runs = [p for p in points if not p.is_default]
    for method in dict.fromkeys(p.method for p in runs):
        done = [p for p in runs if p.method == method and p.status == "ok"]
        for k, p in enumerate(done):
            if all(err(q) <= target for q in done[k:]):
                hits.append(p)
                break
    return min(hits, key=lambda p: p.wall) if hits else None


def non_monotone(points: Sequence[RunPoint], measure: str, factor: float = 2.0) -> bool:
    """Whether a tighter setting (later point) has an error ``factor`` times a looser one's."""
    errs = [p.errors.get(measure, math.nan) for p in points]
    errs = [e for e in errs if math.isfinite(e)]
    return any(b > factor * a for k, a in enumerate(errs) for b in errs[k + 1 :])


# -- report -------------------------------------------------------------------------------------
def _e(v: float) -> str:
    return "n/a" if v is None or not math.isfinite(v) else f"{v:.2e}"


def _f(v: float, spec: str = ".2f") -> str:
    return "n/a" if v is None or not math.isfinite(v) else f"{v:{spec}}"


def _value(p: RunPoint) -> str:
    if p.setting == "dt":
        return f"dt {p.value * 1e3:.4g} ms"
    return f"rtol {p.value:.0e}"


def _measures(sr: SceneResult) -> tuple[str, ...]:
    main = sr.reference.main
    skip = set()
    if not main.flexible:
        skip.add("tip_deflection")
    if not main.runs_on_after_sort:
        skip.add("trajectory_to_sort")
    return tuple(m for m in MEASURES if m not in skip)


def plot_scene(sr: SceneResult, out_dir: Path) -> list[str]:
    """``<scene>_<measure>.png``: error against wall time, one curve per method, default star."""
    ref = sr.reference
    files = []
    for measure in _measures(sr):
        name = f"{sr.scene}_{measure}.png"
        plot_measure(
            sr.scene, measure, sr.points, ref.uncertainty(measure), ref.ode_gap(measure),
            out_dir / name,
        )  # fmt: skip
        files.append(name)
    return files


def plot_measure(
    scene: str,
    measure: str,
    points: Sequence[RunPoint],
    uncertainty: float,
    ode_gap: float,
    path: Path,
) -> Path:
    """One work-precision diagram: error in ``measure`` against wall time, one curve per
    method, the default as a star, the reference's own error and the ODE form's gap as lines;
    the legend beside the axes (never over the data)."""
    import matplotlib  # lazy: Matplotlib (0.7-1.3 s), only to plot

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: Matplotlib (0.7-1.3 s), only to plot

    methods = list(dict.fromkeys(p.method for p in points if not p.is_default))
    fig, ax = plt.subplots(figsize=(9.0, 5.0))
    for method in methods:
        pts = [p for p in points if p.method == method and not p.is_default and p.status == "ok"]
        pts = [p for p in pts if p.errors.get(measure, math.nan) > 0]
        if not pts:
            continue
        (line,) = ax.loglog(
            [p.wall * 1e3 for p in pts],
            [p.errors[measure] for p in pts],
            marker=MARKERS.get(method, "o"),
            linestyle="--" if method.startswith("scipy:") else "-",
            label=method,
        )
        for p in {id(q): q for q in (pts[0], pts[-1])}.values():
            ax.annotate(
                _value(p).split(" ", 1)[1],
                (p.wall * 1e3, p.errors[measure]),
                textcoords="offset points",
                xytext=(4, 3),
                fontsize=6,
                color=line.get_color(),
            )
    for p in points:
        e = p.errors.get(measure, math.nan)
        if p.is_default and p.status == "ok" and e > 0:
            ax.loglog(
                [p.wall * 1e3],
                [e],
                marker="*",
                markersize=18,
                color="gold",
                markeredgecolor="black",
                linestyle="none",
                label=f"default ({describe(p.method, p.value)})",
                zorder=5,
            )
    if uncertainty > 0:
        ax.axhline(uncertainty, color="grey", linestyle=":", label="reference vs its halved step")
    if ode_gap > 0 and any(m.startswith("scipy:") for m in methods):
        ax.axhline(ode_gap, color="tab:red", linestyle="-.", lw=1, label="ODE form vs reference")
    title, unit = MEASURE_TEXT[measure]
    ax.set_title(f"{scene}: {title}")
    ax.set_xlabel("wall time per solve [ms] (median)")
    ax.set_ylabel(unit)
    ax.grid(True, which="both", alpha=0.3)
    ax.margins(x=0.08)  # room for the setting labels at the last points
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _nan(value):
    """A value of results.json back in Python: null -> NaN, also inside dicts."""
    if value is None:
        return math.nan
    if isinstance(value, dict):
        return {k: _nan(v) for k, v in value.items()}
    return value


def replot(out_dir: Path | str) -> list[Path]:
    """Redraw every ``<scene>_<measure>.png`` in ``out_dir`` from its ``results.json`` (the
    plots alone: no solve runs)."""
    out = Path(out_dir)
    data = json.loads((out / "results.json").read_text(encoding="utf-8"))
    done = []
    for sc in data["scenes"]:
        points, ref, _ = scene_data(sc)
        for measure in MEASURES:
            path = out / f"{sc['scene']}_{measure}.png"
            if path.exists():
                unc, gap = ref.uncertainty(measure), ref.ode_gap(measure)
                done.append(plot_measure(sc["scene"], measure, points, unc, gap, path))
    return done


def save_reference(sr: SceneResult, out_dir: Path) -> str:
    """The reference sampled on the 1 ms grid (small; for inspection, not used as a cache)."""
    ref = sr.reference.main
    g = np.arange(0.0, ref.trace.t_end, GRID_STEP)
    x, y, phi = ref.trace.pose(g)
    arrays = {"t": g, "x": x, "y": y, "phi": phi}
    tip = ref.trace.tip_at(g)
    if tip is not None:
        arrays["tip_deflection"] = tip
    path = out_dir / "reference" / f"{sr.scene}.npz"
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        path,
        **arrays,
        peak_contact_force=ref.peak,
        sim_time=ref.sim_time,
        label=np.array(ref.label),
    )
    return str(path.relative_to(out_dir))


def _reference_section(scenes: Sequence[dict]) -> list[str]:
    lines = ["## Reference solutions and their check", ""]
    for sc in scenes:
        points, ref, ms = scene_data(sc)
        main = sc["reference"]
        lines += [
            f"### {sc['scene']}",
            "",
            f"Reference: {main['label']}, {main['steps']} steps, "
            f"{main['sim_time']:.4f} s simulated, peak N = {main['peak_contact_force']:.6g} N, "
            f"wall {main['wall']:.1f} s.",
            "",
        ]
        rows = []
        for c in ref.checks:
            cells = (
                [_e(c.errors.get(m, math.nan)) for m in ms]
                if c.status == "ok"
                else ([c.status + ": " + c.note] + [""] * (len(ms) - 1))
            )
            rows.append([c.label, *cells, f"{c.wall:.1f}"])
        head = ["compared with the reference", *(MEASURE_TEXT[m][0] for m in ms), "wall [s]"]
        lines += table(head, rows)
        lines.append("")
        smallest = {m: _smallest(points, m) for m in ms}
        lines.append(
            "Smallest error reported below, per measure: "
            + ", ".join(f"{MEASURE_TEXT[m][0]} {_e(smallest[m])}" for m in ms)
            + "; reference vs halved step: "
            + ", ".join(f"{_e(ref.uncertainty(m))}" for m in ms)
            + "."
        )
        lines.append("")
    return lines


def _smallest(points: Sequence[RunPoint], measure: str) -> float:
    """The smallest error of the finished runs in ``measure`` (NaN if none)."""
    errs = [p.errors.get(measure, math.inf) for p in points if p.status == "ok"]
    small = min(errs, default=math.inf)
    return small if math.isfinite(small) else math.nan


def _scene_table(points: Sequence[RunPoint], ms: Sequence[str]) -> list[str]:
    head = ["method", "setting", "wall [ms]", "RTF", "steps"]
    head += [MEASURE_TEXT[m][0] for m in ms] + ["peak N vs ODE form", "note"]
    rows = []
    for p in points:
        name = f"**default** ({p.method})" if p.is_default else p.method
        if p.status == "skipped":
            rows.append([name, _value(p), "", "", "", *("" for _ in ms), "", p.note])
            continue
        errs = [_e(p.errors.get(m, math.nan)) if p.status == "ok" else "-" for m in ms]
        rtf = f"{p.rtf:.3g}"
        note = p.note
        if p.status == "capped":
            rtf += " (capped)"
            note = f"capped at {p.sim_time:.3f} s simulated: {note}"
        elif p.status == "failed":
            note = f"failed: {note}"
        if p.status == "ok" and not p.sorted:
            note = (note + "; " if note else "") + "not sorted"
        if len(p.walls) > 1:
            note = (note + "; " if note else "") + f"median of {len(p.walls)}"
        ode = _e(p.errors_ode.get("peak_force", math.nan)) if p.errors_ode else ""
        rows.append([name, _value(p), f"{p.wall * 1e3:.1f}", rtf, str(p.steps), *errs, ode, note])
    return table(head, rows)


def _unfinished_after(points: Sequence[RunPoint], hit: RunPoint) -> str:
    """ "; tighter settings ... did not finish" when some of them were not ok."""
    same = [p for p in points if p.method == hit.method and not p.is_default]
    later = same[same.index(hit) + 1 :]
    bad = [p for p in later if p.status != "ok"]
    if not bad:
        return ""
    return (
        f"; tighter {', '.join(_value(p) for p in bad)}: "
        f"{', '.join(sorted({p.status for p in bad}))}"
    )


def _run(p: RunPoint, default: RunPoint, points: Sequence[RunPoint]) -> str:
    """ "LSODA rtol 1e-04: 180.0 ms, 97x the default, error 2.1e-05" of a run."""
    return (
        f"{describe(p.method, p.value)}: {p.wall * 1e3:.1f} ms, {p.wall / default.wall:.3g}x "
        f"the default, error {_e(p.errors['peak_force'])}{_unfinished_after(points, p)}"
    )


def summary(points: Sequence[RunPoint], ref: Reference, ms: Sequence[str]) -> list[list[str]]:
    """The figures a scene's results come down to, as (figure, value) rows: the default, the
    fastest runs at its peak-force error, observed orders, the adaptive scheme over rtol, the
    reference's limits. How to read them: docs/design/verification.md."""
    rows: list[list[str]] = []
    default = next((p for p in points if p.is_default), None)
    scipy_pts = [p for p in points if p.method.startswith("scipy:")]
    if default is not None and default.status == "ok":
        e = default.errors["peak_force"]
        rows += [
            ["default", describe(default.method, default.value)],
            ["default: wall, RTF", f"{default.wall * 1e3:.1f} ms, {default.rtf:.3g}"],
            [
                "default: peak-force, trajectory, final-pose error",
                f"{_e(e)}, {_e(default.errors['trajectory'])} m, "
                f"{_e(default.errors['final_pose'])} m",
            ],
        ]
        hit = fastest_reaching(scipy_pts, "peak_force", e)
        if hit is not None:
            rows.append(["fastest SciPy run at that error", _run(hit, default, points)])
        elif scipy_pts:
            ok = [p for p in scipy_pts if p.status == "ok"]
            if ok:
                b = min(ok, key=lambda p: p.errors["peak_force"])
                closest = f"none; closest {_run(b, default, points)}"
                rows.append(["fastest SciPy run at that error", closest])
        hit = fastest_reaching(scipy_pts, "peak_force", e, ode=True)
        if hit is not None:
            what = "fastest SciPy run at that error of its own ODE form"
            rows.append([what, _run(hit, default, points)])
        ours = [p for p in points if p.method in OUR_METHODS and not p.is_default]
        hit = fastest_reaching(ours, "peak_force", e)
        if hit is not None and hit.wall < default.wall / 1.5:
            rows.append(["faster of ours at that error", _run(hit, default, points)])
        whole = default.errors.get("trajectory", math.nan)
        to_sort = default.errors.get("trajectory_to_sort", math.nan)
        if math.isfinite(to_sort):
            what = "default: trajectory error to the sort, whole run"
            rows.append([what, f"{_e(to_sort)} m, {_e(whole)} m"])
    elif default is not None:
        rows.append(["default", f"did not finish: {default.status}, {default.note}"])
    for method in ("trapezoidal", "generalized_alpha"):
        pts = [p for p in points if p.method == method]
        order_ms = [m for m in ms if m != "final_pose"]
        orders = {m: observed_order(pts, m, ref.uncertainty(m)) for m in order_ms}
        if any(math.isfinite(v) for v in orders.values()):
            rows.append(
                [
                    f"{method}: observed order in dt",
                    ", ".join(f"{_f(orders[m])} ({MEASURE_TEXT[m][0]})" for m in order_ms),
                ]
            )
    ad = [p for p in points if p.method == "adaptive" and p.status == "ok" and not p.is_default]
    ad = [p for p in ad if p.errors]
    if len(ad) >= 2:
        lo, hi = ad[0], ad[-1]
        monotone = not any(non_monotone(ad, m) for m in ("peak_force", "trajectory"))
        rows += [
            [
                f"adaptive rtol {lo.value:.0e} to {hi.value:.0e}: peak-force error",
                f"{_e(lo.errors['peak_force'])} to {_e(hi.errors['peak_force'])}",
            ],
            [
                f"adaptive rtol {lo.value:.0e} to {hi.value:.0e}: trajectory error",
                f"{_e(lo.errors['trajectory'])} to {_e(hi.errors['trajectory'])} m",
            ],
            [
                f"adaptive rtol {lo.value:.0e} to {hi.value:.0e}: wall",
                f"{lo.wall * 1e3:.1f} to {hi.wall * 1e3:.1f} ms",
            ],
            ["adaptive: errors monotone in rtol (within 2x)", "yes" if monotone else "no"],
        ]
    gap = ref.ode_gap("peak_force")
    if math.isfinite(gap):
        rows.append(
            [
                "ODE form vs reference: peak force, trajectory",
                f"{_e(gap)}, {_e(ref.ode_gap('trajectory'))} m "
                f"(reference vs halved step: {_e(ref.uncertainty('peak_force'))}, "
                f"{_e(ref.uncertainty('trajectory'))} m)",
            ]
        )
    unresolved = []
    for m in ms:
        unc = ref.uncertainty(m)
        small = _smallest(points, m)
        if math.isfinite(unc) and math.isfinite(small) and unc > 0.1 * small:
            unresolved.append(f"{MEASURE_TEXT[m][0]} (reference {_e(unc)}, smallest {_e(small)})")
    if unresolved:
        rows.append(["errors not resolved by the reference", "; ".join(unresolved)])
    for status in ("capped", "failed"):
        methods = sorted({p.method for p in scipy_pts if p.status == status})
        if methods:
            rows.append([f"SciPy methods {status}", ", ".join(methods)])
    return rows


def scene_data(sc: Mapping) -> tuple[list[RunPoint], Reference, tuple[str, ...]]:
    """One scene of results.json as run points, the reference's checks and the measures that
    apply to it (those with a finite error somewhere)."""
    names = set(RunPoint.__dataclass_fields__)
    points = [RunPoint(**{k: _nan(v) for k, v in p.items() if k in names}) for p in sc["points"]]
    checks = [ReferenceCheck(**_nan(c)) for c in sc["reference"]["checks"]]
    ms = tuple(
        m for m in MEASURES if any(math.isfinite(p.errors.get(m, math.nan)) for p in points)
    )
    return points, Reference(sc["scene"], None, None, checks), ms


def _settings(data: Mapping) -> list[str]:
    """The campaign's settings as a table, from the data."""

    def values(method: str) -> list[float]:
        return sorted(
            {
                p["value"]
                for sc in data["scenes"]
                for p in sc["points"]
                if p["method"] == method and not p["is_default"]
            },
            reverse=True,
        )

    scipy = {v for m in data["methods"] if m.startswith("scipy:") for v in values(m)}
    scipy = sorted(scipy, reverse=True)
    rows = [
        ["scenes", ", ".join(sc["scene"] for sc in data["scenes"])],
        ["methods", ", ".join(data["methods"])],
        ["adaptive rtol", ", ".join(f"{v:.0e}" for v in values("adaptive"))],
        ["fixed-step dt [ms]", ", ".join(f"{v * 1e3:.4g}" for v in values("trapezoidal"))],
        ["SciPy rtol", ", ".join(f"{v:.0e}" for v in scipy)],
        ["timed runs per setting (median)", str(data["repeats"])],
        ["wall-time cap per solve [s]", f"{data['max_wall_s']:g}"],
        ["reduced grid (--quick)", "yes" if data["quick"] else "no"],
    ]
    return table(["setting", "value"], rows)


def render_readme(data: Mapping) -> str:
    """README.md of a campaign from its results.json alone."""
    scenes = data["scenes"]
    lines = [
        "# Accuracy: work-precision diagrams of the time integrators",
        "",
        "Generated by `fence-sorter accuracy` (`fence_sorter/verification/accuracy.py`) from "
        "`results.json`; do not edit by hand. What is measured and how to read it: "
        "docs/design/verification.md of the fence_sorter repository, section Accuracy (a path,\n"
        "not a link: the report is written wherever `--out` says).",
        "",
        "Command:",
        "",
        "```",
        data["command"] or "fence-sorter accuracy",
        "```",
        "",
        f"Run {data['started']}, {data['duration_s'] / 60:.1f} min.",
        "",
    ]
    lines += table(["machine", ""], data["machine"].items())
    lines += ["", "## Settings", ""] + _settings(data) + [""]
    lines += _reference_section(scenes)
    lines += ["## Results", ""]
    for sc in scenes:
        points, ref, ms = scene_data(sc)
        lines += [f"### {sc['scene']}", ""]
        lines += [f"![{sc['scene']}_{m}.png]({sc['scene']}_{m}.png)" for m in ms]
        lines += ["", f"Reference sampled on the 1 ms grid: `reference/{sc['scene']}.npz`.", ""]
        lines += _scene_table(points, ms)
        lines += ["", "Summary:", ""]
        lines += table(["figure", "value"], summary(points, ref, ms))
        lines += [""]
    return "\n".join(lines)


def results_dict(campaign: Campaign) -> dict:
    """Everything the report shows, as plain JSON data (``results.json``)."""
    scenes = []
    for sr in campaign.scenes:
        ref = sr.reference
        scenes.append(
            {
                "scene": sr.scene,
                "reference": {
                    "label": ref.main.label,
                    "method": ref.main.method,
                    "value": ref.main.value,
                    "peak_contact_force": ref.main.peak,
                    "sim_time": ref.main.sim_time,
                    "steps": ref.main.steps,
                    "wall": ref.main.wall,
                    "checks": [asdict(c) for c in ref.checks],
                },
                "points": [dict(asdict(p), rtf=p.rtf) for p in sr.points],
            }
        )
    return json_safe(
        {
            "command": campaign.command,
            "started": campaign.started,
            "duration_s": campaign.duration,
            "machine": campaign.machine,
            "quick": campaign.quick,
            "repeats": campaign.repeats,
            "max_wall_s": campaign.max_wall,
            "methods": list(campaign.methods),
            "scenes": scenes,
        }
    )


def write_report(campaign: Campaign, out_dir: Path | str) -> Path:
    """results.json, the PNGs, the sampled references and README.md (rendered from
    results.json) into ``out_dir``; returns the README's path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    data = results_dict(campaign)
    (out_dir / "results.json").write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    for sr in campaign.scenes:
        plot_scene(sr, out_dir)
        save_reference(sr, out_dir)
    return rerender(out_dir)


def rerender(out_dir: Path | str) -> Path:
    """README.md of ``out_dir`` from its results.json (no solve runs)."""
    out_dir = Path(out_dir)
    data = json.loads((out_dir / "results.json").read_text(encoding="utf-8"))
    path = out_dir / "README.md"
    path.write_text(render_readme(data) + "\n", encoding="utf-8")
    return path
