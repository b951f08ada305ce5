"""The paper's optimisation sweeps (Figs. 3-10, section 4): CSV rows, resume, PNG plots.

Each sweep is a list of points (one optimum (1) each, under the constraints the figure names);
a point's result is appended to ``<out>/<run>.csv`` as one row and flushed, keyed by a hash of
the point's inputs, so an interrupted sweep continues where it stopped (points already in the
CSV are skipped). Points go through a ``concurrent.futures`` executor, one serial optimisation
per point (on 2 cores, parallel over points beats parallel inside one optimisation: see
docs/reports/paper/README.md). Then ``<out>/<name>.png`` in the style of the paper's figure.

``python -m benchmarks paper-sweep NAME`` calls :func:`main`; NAME is one of :data:`SWEEPS`
(``fig3`` ... ``fig10``, ``decision-table``), several separated by commas, or ``all``.
``decision-table`` also writes the controller's starting candidates (``--table``,
config/decision_table.yaml; :mod:`benchmarks.paper.decision`).
"""

from __future__ import annotations

import math
import sys
import textwrap
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Executor, Future, as_completed
from pathlib import Path

from tqdm import tqdm

from benchmarks.paper.points import INPUT_COLUMNS
from benchmarks.paper.sweep_defs import PAPER_SWEEPS, SWEEPS, SweepDef, get_sweep
from benchmarks.paper.sweep_rows import RowWriter, point_key, read_rows, solve_point
from fence_sorter.capacity.decision_table import build_table, write_table
from fence_sorter.optimize.executor import evaluation_pool

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130


class SweepError(RuntimeError):
    """Some points of a sweep raised (the others were saved; a rerun retries them)."""


# -- running ------------------------------------------------------------------------------------
def _progress(total: int, initial: int, desc: str, enabled: bool):
    if not enabled:
        return None
    return tqdm(total=total, initial=initial, desc=desc, unit="optimum", file=sys.stderr)


def _order(sweep: SweepDef, rows: Iterable[dict]) -> list[dict]:
    """Rows of the sweep's points in point order (the last row of a key wins)."""
    by_key = {r["key"]: r for r in rows}
    out = []
    for inputs in sweep.points:
        r = by_key.get(point_key(inputs))
        if r is not None:
            out.append(r)
    return out


def run_sweep(
    name: str | SweepDef,
    out_dir: str | Path,
    executor: Executor,
    resume: bool = True,
    progress: bool = True,
    *,
    max_points: int | None = None,
) -> list[dict]:
    """Run the points of sweep ``name`` not yet in ``<out_dir>/<run>.csv`` through
    ``executor`` (one serial optimisation per point), appending each result as it lands.

    ``resume=False`` starts the CSV afresh. ``max_points`` stops after that many new points
    (a sweep done in chunks). Returns the rows of all the sweep's points found, in point order.
    """
    return run_sweeps([name], out_dir, executor, resume, progress, max_points=max_points)[0]


def run_sweeps(
    names: Sequence[str | SweepDef],
    out_dir: str | Path,
    executor: Executor,
    resume: bool = True,
    progress: bool = True,
    *,
    max_points: int | None = None,
) -> list[list[dict]]:
    """:func:`run_sweep` for several sweeps at once: all their open points are submitted
    together (no idle worker between two sweeps); sweeps sharing a run share its CSV."""
    sweeps = [get_sweep(n) if isinstance(n, str) else n for n in names]
    out_dir = Path(out_dir)
    runs: dict[str, list[tuple[str, dict, SweepDef]]] = {}
    n_total = 0
    for sweep in sweeps:
        if sweep.run in runs:
            continue
        path = out_dir / f"{sweep.run}.csv"
        if not resume and path.exists():
            path.unlink()
        done = {r["key"] for r in read_rows(path, repair=True)}
        todo: dict[str, tuple[str, dict, SweepDef]] = {}
        for inputs in sweep.points:
            key = point_key(inputs)
            if key not in done:
                todo.setdefault(key, (key, inputs, sweep))
        n_total += len({point_key(p) for p in sweep.points})
        runs[sweep.run] = list(todo.values())
    jobs = [(run, job) for run, todo in runs.items() for job in todo]
    n_open = len(jobs)
    if max_points is not None:
        jobs = jobs[:max_points]
    bar = _progress(n_total, n_total - n_open, ",".join(runs), progress)
    writers = {run: RowWriter(out_dir / f"{run}.csv") for run in runs}
    futures: dict[Future, tuple[str, str, dict]] = {}
    written: set[Future] = set()
    failed: list[str] = []

    def write(fut: Future) -> None:
        run, key, inputs = futures[fut]
        writers[run].write({"key": key, **inputs, **fut.result()})
        written.add(fut)
        if bar is not None:
            bar.update(1)

    try:
        for run, (key, inputs, sweep) in jobs:
            futures[executor.submit(sweep.solve, inputs)] = (run, key, inputs)
        for fut in as_completed(futures):
            if fut.exception() is not None:
                run, key, inputs = futures[fut]
                failed.append(
                    f"{run} point {key}: {type(fut.exception()).__name__}: {fut.exception()}"
                )
                print(f"benchmarks: {failed[-1]}", file=sys.stderr)
                continue
            write(fut)
    finally:
        # interrupted or failed: keep every finished point, drop the rest
        for fut in futures:
            if fut not in written and fut.done() and not fut.cancelled():
                if fut.exception() is None:
                    write(fut)
            else:
                fut.cancel()
        for w in writers.values():
            w.close()
        if bar is not None:
            bar.close()
    if failed:
        raise SweepError(f"{len(failed)} point(s) failed (the others are saved): {failed[0]}")
    return [_order(s, read_rows(out_dir / f"{s.run}.csv")) for s in sweeps]


# -- consistency -------------------------------------------------------------------------------
#: (tight, loose) sweeps with the same points but one constraint more in ``tight`` ((12))
NESTED_RUNS = (("fig7", "fig6"), ("fig10", "fig8"))
#: sweeps whose series is a limit of (10) or (11): a larger value is a looser problem
LIMIT_SERIES = ("fig3", "fig5", "fig6", "fig7", "fig8", "fig10")


def nested_pairs(rows_of: Callable[[str], Sequence[dict]]) -> list[tuple[str, dict, dict, str]]:
    """Every nested pair of optima in the rows given by ``rows_of(name)``: (what the pair is,
    the tighter problem's row, the looser problem's row, the run (CSV) of the looser one).
    A looser limit (w_dop, a_Ndop) or one constraint less ((12)) widens the feasible set."""
    out = []
    for tight, loose in NESTED_RUNS:
        sd = get_sweep(tight)
        other = {(r[sd.x], r[sd.series]): r for r in rows_of(loose)}
        for r in rows_of(tight):
            k = (r[sd.x], r[sd.series])
            if k in other:
                tag = f"{tight} vs {loose} at {sd.x} {k[0]:g}, {sd.series} {k[1]:g}"
                out.append((tag, r, other[k], get_sweep(loose).run))
    for name in LIMIT_SERIES:
        sd = get_sweep(name)
        rs = rows_of(name)
        for xv in sorted({r[sd.x] for r in rs}):
            col = sorted((r for r in rs if r[sd.x] == xv), key=lambda r: r[sd.series])
            for a, b in zip(col, col[1:], strict=False):
                tag = f"{name} at {sd.x} {xv:g}: {sd.series} {a[sd.series]:g} vs {b[sd.series]:g}"
                out.append((tag, a, b, sd.run))
    return out


def _w(r: Mapping) -> float:
    return r["W_t"] if r["feasible"] else 0.0


def nesting_violations(
    rows_of: Callable[[str], Sequence[dict]], tol: float = 0.005
) -> tuple[int, list[str]]:
    """Check the optima against the nesting of their problems (:func:`nested_pairs`): the
    looser problem's optimum W_t (1) cannot be lower. Returns (pairs checked, the pairs where
    the tighter problem's W_t exceeds the looser one's by more than ``tol``, relative)."""
    pairs = nested_pairs(rows_of)
    bad = [
        f"{tag}: tighter {_w(t):.0f} > looser {_w(lo):.0f} pcs/h"
        for tag, t, lo, _ in pairs
        if _w(t) > _w(lo) * (1.0 + tol)
    ]
    return len(pairs), bad


def repair_nesting(
    out_dir: str | Path,
    executor: Executor,
    tol: float = 0.005,
    rounds: int = 8,
    progress: bool = False,
    runs: Iterable[str] | None = None,
) -> tuple[int, set[str]]:
    """Re-solve every looser problem whose optimum lies below a tighter neighbour's, starting
    the search from the tighter optima (feasible for the looser problem, so the answer cannot
    be lower); the new rows are appended (the last row of a key wins) and name the points they
    started from (``started_from``). Repeated while a repair moves a point above its own
    looser neighbour, at most ``rounds`` times. Only the rows of ``runs`` (CSV names; None:
    every run) are re-solved; the tighter neighbours may come from any CSV present. Returns
    (points re-solved, runs changed)."""
    only = None if runs is None else set(runs)
    out_dir = Path(out_dir)

    def rows_of(name: str) -> list[dict]:
        return _order(get_sweep(name), read_rows(out_dir / f"{get_sweep(name).run}.csv"))

    solved, changed = 0, set()
    for _ in range(rounds):
        todo: dict[str, tuple[str, dict, list[dict]]] = {}
        for _tag, tight, loose, run in nested_pairs(rows_of):
            tried = set(loose["started_from"].split())
            if only is not None and run not in only:
                continue
            if _w(tight) > _w(loose) * (1.0 + tol) and tight["key"] not in tried:
                todo.setdefault(loose["key"], (run, loose, []))[2].append(tight)
        if not todo:
            break
        futures = {}
        for run, loose, tights in todo.values():
            inputs = {k: loose[k] for k in INPUT_COLUMNS}
            starts = [{n: t[n] for n in ("R_s", "v", "t1", "R_z")} for t in tights]
            keys = set(loose["started_from"].split()) | {t["key"] for t in tights}
            fut = executor.submit(solve_point, inputs, starts, " ".join(sorted(keys)))
            futures[fut] = (run, loose["key"], inputs)
        bar = _progress(len(futures), 0, "nesting repair", progress)
        try:
            for fut in as_completed(futures):
                run, key, inputs = futures[fut]
                with RowWriter(out_dir / f"{run}.csv") as w:
                    w.write({"key": key, **inputs, **fut.result()})
                solved += 1
                changed.add(run)
                if bar is not None:
                    bar.update(1)
        finally:
            for fut in futures:
                fut.cancel()
            if bar is not None:
                bar.close()
    return solved, changed


# -- plots --------------------------------------------------------------------------------------
#: share of a panel's height kept free at its top for the "no feasible X" band
INFEASIBLE_BAND = 0.12


def plot_sweep(sweep: SweepDef, rows: Sequence[dict], path: str | Path) -> Path:
    """The figure's panels (one curve per series value). A point with no feasible optimum has
    no value: it is marked with a cross in a grey band at the top of each panel, above every
    value (a real value such as R_s = 0 is never taken for it). One legend, outside the
    panels; the title wrapped to the figure's width."""
    # matplotlib takes ~0.5 s to import and only the plots need it (workers never plot)
    import matplotlib  # lazy: Matplotlib (0.7-1.3 s), only to plot

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: Matplotlib (0.7-1.3 s), only to plot
    from matplotlib.patches import Rectangle
    from matplotlib.transforms import blended_transform_factory

    n = len(sweep.panels)
    ncols = 3 if n > 4 else n
    nrows = math.ceil(n / ncols)
    width = 4.2 * ncols + 1.6  # the legend's column on the right
    fig, axes = plt.subplots(nrows, ncols, figsize=(width, 3.4 * nrows + 0.4), squeeze=False)
    levels = sorted({r[sweep.series] for r in rows}, key=lambda s: (str(type(s)), s))
    letters = "abcdefgh"
    any_bad = any(not r["feasible"] for r in rows)
    for i, panel in enumerate(sweep.panels):
        ax = axes[i // ncols][i % ncols]
        band = blended_transform_factory(ax.transData, ax.transAxes)
        values = []
        for k, lev in enumerate(levels):
            pts = sorted((r[sweep.x], r) for r in rows if r[sweep.series] == lev)
            xs = [x for x, _ in pts]
            ys = [r[panel.column] * panel.scale if r["feasible"] else math.nan for _, r in pts]
            values += [y for y in ys if math.isfinite(y)]
            color = f"C{k}"
            ax.plot(
                xs,
                ys,
                marker="o",
                ms=3.5,
                color=color,
                label=f"{lev:g}" if isinstance(lev, float) else str(lev),
            )
            bad = [x for x, r in pts if not r["feasible"]]
            if bad:
                ax.plot(bad, [1.0 - 0.5 * INFEASIBLE_BAND] * len(bad), "x", color=color,
                        ms=6, mew=1.5, transform=band, clip_on=False)  # fmt: skip
        if any_bad:
            ax.add_patch(Rectangle((0.0, 1.0 - INFEASIBLE_BAND), 1.0, INFEASIBLE_BAND,
                                   transform=ax.transAxes, color="0.9", zorder=0))  # fmt: skip
            if values:  # the values stay below the band
                lo, hi = min(values), max(values)
                pad = 0.05 * (hi - lo) if hi > lo else 0.1 * max(abs(hi), 1.0)
                top = hi + pad
                bottom = lo - pad
                ax.set_ylim(bottom, bottom + (top - bottom) / (1.0 - INFEASIBLE_BAND))
                ax.set_yticks([t for t in ax.get_yticks() if bottom <= t <= top])
            ax.text(0.01, 1.0 - 0.5 * INFEASIBLE_BAND, "no feasible X", transform=ax.transAxes,
                    fontsize=7, color="0.4", va="center", style="italic")  # fmt: skip
        ax.set_xlabel(sweep.x_label)
        ax.set_ylabel(panel.label)
        ax.set_title(f"{letters[i]})", loc="left", fontsize=10)
        ax.grid(True, alpha=0.3)
    for j in range(n, nrows * ncols):
        axes[j // ncols][j % ncols].axis("off")
    handles, labels = axes[0][0].get_legend_handles_labels()
    if any_bad:
        handles.append(plt.Line2D([], [], ls="", marker="x", color="0.3", mew=1.5))
        labels.append("no feasible X\n(grey band)")
    fig.legend(handles, labels, title=sweep.series_label, fontsize=8, title_fontsize=8,
               loc="upper right", bbox_to_anchor=(1.0, 0.9))  # fmt: skip
    title = textwrap.fill(f"{sweep.figure}: {sweep.title}", width=int(13 * width))
    fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0.0, 0.0, 1.0 - 1.5 / width, 1.0))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


# -- command line -------------------------------------------------------------------------------
def parse_names(text: str) -> list[str]:
    """``fig6``, ``fig6,fig7`` or ``all`` -> sweep names (KeyError naming the allowed ones)."""
    names = list(PAPER_SWEEPS) if text == "all" else [t.strip() for t in text.split(",")]
    for n in names:
        if n not in SWEEPS:
            raise KeyError(f"unknown sweep {n!r}; allowed: {', '.join(SWEEPS)}, all")
    return names


def _csv(out: Path, name: str) -> Path:
    return out / f"{get_sweep(name).run}.csv"


def finish(sweep: SweepDef, out: Path, table_path: Path) -> list[str]:
    """Plot a sweep from its CSV (and, for ``decision-table`` with every point done, write
    the controller's table); the lines to print."""
    rows = _order(sweep, read_rows(out / f"{sweep.run}.csv"))
    if not rows:
        return []
    png = plot_sweep(sweep, rows, out / f"{sweep.name}.png")
    n_ok = sum(r["feasible"] for r in rows)
    lines = [
        f"{sweep.name}: {len(rows)}/{len(sweep.points)} points ({n_ok} feasible) in "
        f"{out / (sweep.run + '.csv')}, plot {png}"
    ]
    if sweep.name == "decision-table" and len(rows) == len(sweep.points):
        table = build_table(rows, source=str(out / f"{sweep.run}.csv"))
        write_table(table, table_path)
        n_classes = len(table["decision_table"]["classes"])
        lines.append(f"decision table: {n_classes} load classes -> {table_path}")
    return lines


def replot(names: Sequence[str], out: Path) -> int:
    """``python -m benchmarks paper-sweep NAME --plots-only``: the figures from the CSVs in
    ``out`` (no solve, no table written). Exit 0, or 2 for a missing CSV."""
    for name in names:
        sw = get_sweep(name)
        csv_path = out / f"{sw.run}.csv"
        if not csv_path.is_file():
            print(f"benchmarks: error: --out: no {csv_path} to plot {name}", file=sys.stderr)
            return EXIT_BAD_INPUT
        print(plot_sweep(sw, _order(sw, read_rows(csv_path)), out / f"{sw.name}.png"))
    return EXIT_OK


def main(args) -> int:
    """``python -m benchmarks paper-sweep NAME``: run (or resume) the sweeps, write CSV + PNG.

    Uses ``args.sweep``, ``args.out`` (docs/reports/paper), ``args.resume`` (True),
    ``args.workers``,
    ``args.scheduler`` and, when present, ``args.table`` (config/decision_table.yaml),
    ``args.max_points``, ``args.plots_only`` (True: :func:`replot` alone). Exit 0 done, 1 a
    point failed, 2 bad input, 130 interrupted.
    """
    try:
        names = parse_names(str(args.sweep))
    except KeyError as exc:
        print(f"benchmarks: error: NAME: {exc.args[0]}", file=sys.stderr)
        return EXIT_BAD_INPUT
    out = Path(getattr(args, "out", None) or "docs/reports/paper")
    if getattr(args, "plots_only", False):
        return replot(names, out)
    resume = bool(getattr(args, "resume", True))
    max_points = getattr(args, "max_points", None)
    table_path = Path(getattr(args, "table", None) or "config/decision_table.yaml")
    try:
        sweeps = [get_sweep(n) for n in names]
    except Exception as exc:  # e.g. the decision table's config cannot be read
        print(f"benchmarks: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    repair = bool(getattr(args, "repair", True))
    changed: set[str] = set()
    wall0 = time.perf_counter()
    status = EXIT_OK
    try:
        with evaluation_pool(
            scheduler=getattr(args, "scheduler", None), workers=getattr(args, "workers", None)
        ) as executor:
            run_sweeps(sweeps, out, executor, resume=resume, max_points=max_points)
            if repair:
                runs = {s.run for s in sweeps}
                n_solved, changed = repair_nesting(out, executor, progress=True, runs=runs)
                if n_solved:
                    print(
                        f"nesting repair: {n_solved} looser problem(s) re-solved from their "
                        f"tighter neighbours' optima ({', '.join(sorted(changed))})"
                    )
    except KeyboardInterrupt:
        print(
            "benchmarks: interrupted; finished points are in the CSV, rerun to resume",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    except Exception as exc:
        print(f"benchmarks: sweep failed: {type(exc).__name__}: {exc}", file=sys.stderr)
        status = EXIT_FAILED
    for sweep in [get_sweep(n) for n in names]:
        for line in finish(sweep, out, table_path):
            print(line)
    pairs, bad = nesting_violations(lambda n: _order(get_sweep(n), read_rows(_csv(out, n))))
    if pairs:
        print(f"nesting check: {len(bad)} of {pairs} nested pairs of optima out of order")
        for line in bad:
            print(f"  {line}")
    print(f"wall time {time.perf_counter() - wall0:.1f} s", file=sys.stderr)
    return status


__all__ = [
    "SweepError",
    "finish",
    "main",
    "nested_pairs",
    "nesting_violations",
    "parse_names",
    "plot_sweep",
    "repair_nesting",
    "replot",
    "run_sweep",
    "run_sweeps",
]
