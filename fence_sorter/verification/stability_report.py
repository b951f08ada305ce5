"""The stability campaign's report: ``README.md``, ``results.json`` and ``summary.png`` from the
results of :mod:`fence_sorter.verification.stability` (the README from results.json alone)."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from fence_sorter.verification.report import table
from fence_sorter.verification.stability import CaseResult
from fence_sorter.verification.stability_cases import DIAGNOSED, FAIL, PASS, yaml_value

# -- the report ----------------------------------------------------------------------------------
REQUIRED_RANGES = (
    "fence meshes up to 50 elements",
    "contact stiffness k_p x1000",
    "parcel masses 0.1 kg to 60 kg",
    "belt 0.2 and 2.5 m/s",
    "belt beyond the range (5 m/s)",
    "t1 = 0.1 s with alpha_k = 60 deg",
    "mu1, mu2 = 0 and 1.2",
    "parcels 0.02 m and 1.2 m long",
    "grazing contact",
    "zero damping",
    "a parcel exactly on the border (E3)",
    "Karnopp thresholds 1e-3 to 1e-9",
    "results converge when the step is halved",
    "a case that cannot be solved ends with a clear diagnosis",
    "none hangs (each bounded in time)",
)


def _fmt(v, spec: str = ".3g") -> str:
    if isinstance(v, str):
        return v
    if v is None or not math.isfinite(v):
        return "n/a"
    return f"{v:{spec}}"


def worst_ratio(cr: CaseResult, prefixes: tuple[str, ...] = ("conv_", "ref_")) -> float:
    """Largest |difference| / allowed over the numeric comparisons (nan if none)."""
    ratios = [
        i.value / i.limit
        for i in cr.invariants
        if i.name.startswith(prefixes)
        and isinstance(i.value, float)
        and isinstance(i.limit, float)
        and i.limit > 0
    ]
    return max(ratios) if ratios else math.nan


def results_json(results: Sequence[CaseResult], meta: dict) -> dict:
    return {**meta, "cases": [cr.to_dict() for cr in results]}


def plot_summary(results: Sequence[CaseResult], path) -> None:
    """One PNG: energy rise / tolerance, D_max / limit, worst convergence ratio, per case.

    A bar is green when its invariant holds and red when not; the case's verdict follows its
    name. Diagnosed cases have no values (nothing past a diagnosis is data).
    """
    import matplotlib  # lazy: Matplotlib (0.7-1.3 s), only to plot

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: Matplotlib (0.7-1.3 s), only to plot

    n = len(results)
    floor, top = 1e-6, 100.0

    def energy(cr):
        inv = cr.invariant("energy")
        return (math.nan, True) if inv is None else (inv.value / inv.limit, inv.passed)

    def depth(cr):
        inv = cr.invariant("penetration")
        return (math.nan, True) if inv is None else (inv.value, inv.passed)

    def conv(cr):
        ok = all(i.passed for i in cr.invariants if i.name.startswith(("conv_", "ref_")))
        return worst_ratio(cr), ok

    panels = (
        ("energy rise / tolerance", energy),
        ("D_max / deep-penetration limit", depth),
        ("halved step, fine reference: |diff| / allowed (worst)", conv),
    )
    fig, axes = plt.subplots(1, 3, figsize=(15, 0.28 * n + 1.8), sharey=True)
    ypos = np.arange(n)[::-1]
    for ax, (title, fn) in zip(axes, panels, strict=True):
        for y, cr in zip(ypos, results, strict=True):
            v, ok = fn(cr)
            c = "tab:green" if ok else "tab:red"
            if not math.isfinite(v):
                label = "diagnosed" if cr.verdict == DIAGNOSED else "n/a"
                ax.text(floor * 1.5, y, label, va="center", fontsize=7, color="tab:orange")
                continue
            ax.barh(y, min(max(v, floor), top), left=0, color=c, height=0.7)
            if v <= floor:
                ax.text(floor * 1.5, y, "0", va="center", fontsize=7, color=c)
        ax.axvline(1.0, color="k", lw=1.0, ls="--")
        ax.set_xscale("log")
        ax.set_xlim(floor, top)
        ax.set_title(title, fontsize=9)
        ax.grid(True, axis="x", which="major", alpha=0.3)
    axes[0].set_yticks(ypos)
    labels = axes[0].set_yticklabels(
        [f"{cr.case.name} [{cr.verdict}]" for cr in results], fontsize=7
    )
    for lab, cr in zip(labels, results, strict=True):
        if not cr.meets_expectation:
            lab.set_color("tab:red")
    fig.suptitle(
        "fence-sorter stability: invariant value / limit per case (dashed: limit; red: violated)"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _cell(inv: Mapping | None, spec: str = ".3g") -> str:
    """``value / limit`` of an invariant of results.json, a cross on a failed one."""
    if inv is None:
        return "-"
    value, limit = inv["value"], inv["limit"]
    if isinstance(value, str) and isinstance(limit, str):
        text = value
    else:
        text = f"{_fmt(_num(value), spec)} / {_fmt(_num(limit), spec)}"
    return text if inv["passed"] else f"**{text} ✗**"


def _num(v):
    """A number of results.json (non-finite ones are stored as "nan", "inf")."""
    return float(v) if v in ("nan", "inf", "-inf") else v


def render_readme(data: Mapping) -> str:
    """``<out>/README.md`` from results.json alone: the run, the verdict table, the
    cases that missed their expectation, diagnoses and costly solves. What the verdicts and
    invariants mean: docs/design/verification.md."""
    cases = data["cases"]

    def inv(c: Mapping, name: str) -> Mapping | None:
        return next((i for i in c["invariants"] if i["name"] == name), None)

    counts = {v: sum(c["verdict"] == v for c in cases) for v in (PASS, DIAGNOSED, FAIL)}
    missed = [c for c in cases if not c["meets_expectation"]]
    mi = data["machine"]
    lines = [
        "# Stability campaign",
        "",
        "Generated by `fence-sorter stability` (`fence_sorter/verification/stability.py`) from "
        "`results.json`; do not edit by hand. `summary.png` is the overview. What the verdicts "
        "and invariants mean: "
        "docs/design/verification.md of the fence_sorter repository, section Stability (a path,\n"
        "not a link: the report is written wherever `--out` says).",
        "",
        f"- command: `{data['command']}`",
        f"- date: {data['date']}, commit {data['commit']}",
        f"- machine: {mi['cpu']}, {mi['cores']} cores, {mi['os']}; Python {mi['python']}, "
        f"NumPy {mi['numpy']}, SciPy {mi['scipy']}, Numba {mi['numba']}",
        f"- {len(cases)} cases: {counts[PASS]} PASS, {counts[DIAGNOSED]} DIAGNOSED, "
        f"{counts[FAIL]} FAIL; {len(cases) - len(missed)} meet their expectation",
        f"- wall time: {data['wall_time_s']:.1f} s for the campaign "
        f"(plus {data['warm_up_s']:.1f} s compiling the kernel first)",
        "",
        "![summary](summary.png)",
        "",
        "## Results",
        "",
    ]
    head = [
        "case", "description", "expected", "verdict", "energy rise / tol [J]",
        "D_max / limit", "Δ peak N / allowed [N]", "Δ y_max / allowed [m]",
        "Δ exit / allowed [m/s]", "sorted (h, h/2)", "wall [s]", "method", "steps (rejected)",
    ]  # fmt: skip
    rows = []
    for c in cases:
        r, rr = c["result"], c["refined"]
        verdict = (
            c["verdict"]
            if c["meets_expectation"]
            else f"**{c['verdict']}** (expected {c['expected']})"
        )
        if r is None:
            sorted_cell = steps = method = "-"
        else:
            sorted_cell = "yes" if r["sorted"] else "no"
            if rr is not None:
                sorted_cell += ", " + ("yes" if rr["sorted"] else "no")
            steps = f"{r['steps']} ({r['rejected_steps']})"
            method = r["method"]
        pen = inv(c, "penetration")
        rows.append(
            [
                f"`{c['name']}`",
                c["description"],
                c["expected"],
                verdict,
                _cell(inv(c, "energy")),
                "-" if pen is None else _cell(pen, ".3f"),
                _cell(inv(c, "conv_peak_force")),
                _cell(inv(c, "conv_y_max")),
                _cell(inv(c, "conv_exit_speed")),
                sorted_cell,
                f"{c['wall_time_s']:.2f}",
                method,
                steps,
            ]
        )
    lines += table(head, rows)
    lines += ["", "## Cases that did not meet their expectation", ""]
    if not missed:
        lines.append("None.")
    for c in missed:
        sets = " ".join(f"--set {k}={yaml_value(v)}" for k, v in c["overrides"].items())
        lines += [
            f"### `{c['name']}`: {c['verdict']} (expected {c['expected']})",
            "",
            f"{c['description']}. Reproduce: `fence-sorter simulate {c['scene']} {sets}`.",
            "",
        ]
        if c["error"]:
            lines.append(f"- error: `{c['error']}`")
        if c["diagnosis"]:
            lines.append(f"- diagnosis: {c['diagnosis']}")
        for i in c["invariants"]:
            if not i["passed"]:
                lines.append(
                    f"- `{i['name']}`: {_fmt(_num(i['value']))} against {_fmt(_num(i['limit']))}"
                    + (f"; {i['note']}" if i["note"] else "")
                )
        lines.append("")
    lines += ["## Diagnoses, warnings, other invariants", ""]
    for c in cases:
        extra = [f"warning: {w}" for w in c["warnings"]]
        if c["diagnosis"]:
            extra.append(f"diagnosis: {c['diagnosis']}")
        for name in ("energy_conserved", "stage"):
            i = inv(c, name)
            if i is not None:
                extra.append(
                    f"{name}: {_fmt(_num(i['value']))} against {_fmt(_num(i['limit']))}"
                    + ("" if i["passed"] else " (FAILED)")
                )
        refs = [i for i in c["invariants"] if i["name"].startswith("ref_")]
        if refs:
            extra.append(
                "reference: "
                + "; ".join(
                    f"{i['name']} {_fmt(_num(i['value']))} / {_fmt(_num(i['limit']))}"
                    + ("" if i["passed"] else " ✗")
                    for i in refs
                )
            )
        if c["result"] is not None:
            extra.append("stages: " + " → ".join(c["result"]["stages"]))
        if extra:
            lines.append(f"- `{c['name']}`: " + "; ".join(extra))
    slow = [
        c
        for c in cases
        if c["result"] is not None
        and max(c["result"]["wall_time_s"], (c["refined"] or {}).get("wall_time_s", 0.0)) > 2.0
    ]
    lines += ["", "## Costly solves (more than 2 s of wall time)", ""]
    if not slow:
        lines.append("None.")
    for c in slow:
        r, rr = c["result"], c["refined"]
        text = (
            f"- `{c['name']}`: {r['steps']} steps ({r['rejected_steps']} rejected) in "
            f"{r['wall_time_s']:.2f} s for {r['sim_time_s']:.3f} s simulated"
        )
        if rr is not None:
            text += (
                f"; at half the step ({c['refinement']}) {rr['steps']} steps "
                f"({rr['rejected_steps']} rejected) in {rr['wall_time_s']:.2f} s"
            )
        lines.append(text)
    notes = [c for c in cases if c.get("note")]
    if notes:
        lines += ["", "## Case notes", ""]
        lines += [f"- `{c['name']}`: {c['note']}" for c in notes]
    lines += ["", "## Coverage of the required ranges", ""]
    names_by_item: dict[str, list[str]] = {}
    for c in cases:
        names_by_item.setdefault(c["item"], []).append(c["name"])
    for item in REQUIRED_RANGES:
        got = names_by_item.get(item)
        lines.append(
            f"- {item}: " + (", ".join(f"`{n}`" for n in got) if got else "(not in this run)")
        )
    lines.append("")
    return "\n".join(lines)


def rerender(out_dir) -> Path:
    """README.md of ``out_dir`` from its results.json (no solve runs)."""
    out = Path(out_dir)
    data = json.loads((out / "results.json").read_text(encoding="utf-8"))
    path = out / "README.md"
    path.write_text(render_readme(data), encoding="utf-8")
    return path


def write_report(results: Sequence[CaseResult], out_dir, meta: dict) -> dict[str, str]:
    """Write results.json, summary.png and README.md (rendered from results.json) into
    ``out_dir``; return their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "readme": out / "README.md",
        "json": out / "results.json",
        "png": out / "summary.png",
    }
    paths["json"].write_text(
        json.dumps(results_json(results, meta), indent=1, allow_nan=False, default=str) + "\n",
        encoding="utf-8",
    )
    plot_summary(results, paths["png"])
    rerender(out)
    return {k: str(v) for k, v in paths.items()}
