"""The paper's optimisation sweeps (Figs. 3-10, section 4): CSV rows, resume, PNG plots.

Each sweep is a list of points (one optimum (1) each, under the constraints the figure names);
a point's result is appended to ``<out>/<run>.csv`` as one row and flushed, keyed by a hash of
the point's inputs, so an interrupted sweep continues where it stopped (points already in the
CSV are skipped). Points go through a ``concurrent.futures`` executor, one serial optimisation
per point (on 2 cores, parallel over points beats parallel inside one optimisation: see
docs/paper/README.md). Then ``<out>/<name>.png`` in the style of the paper's figure.

``fence-sorter optimize --sweep NAME`` calls :func:`main`; NAME is one of :data:`SWEEPS`
(``fig3`` ... ``fig10``, ``decision-table``), several separated by commas, or ``all``.
``decision-table`` also writes the controller's starting candidates (config/decision_table.yaml,
:mod:`fence_sorter.optimize.decision`).
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import os
import sys
import textwrap
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Executor, Future, as_completed
from dataclasses import dataclass, field
from pathlib import Path

from tqdm import tqdm

from fence_sorter.capacity.decision_table import build_table, write_table
from fence_sorter.optimize import solve
from fence_sorter.optimize.decision import decision_points
from fence_sorter.optimize.executor import evaluation_pool
from fence_sorter.optimize.points import INPUT_COLUMNS, point
from fence_sorter.optimize.problem import OptimizeSpec

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130

G = 9.81


class SweepError(RuntimeError):
    """Some points of a sweep raised (the others were saved; a rerun retries them)."""


def free_fall_speed(height: float) -> float:
    """Impact speed of a free fall from ``height`` [m], to 0.1 m/s as the paper rounds it
    (w_dop = 2.4 m/s for 0.3 m, section 3)."""
    return round(math.sqrt(2.0 * G * height), 1)


#: alpha_k of Figs. 3, 6, 7 [deg] (section 4.2: 20..60 in steps of 5)
ALPHAS_DEG = tuple(float(a) for a in range(20, 61, 5))
#: w_dop levels of Figs. 3 and 5: free falls from 0.1, 0.2, 0.3 (the paper's), 0.5 m
W_DOP_LEVELS = tuple(free_fall_speed(h) for h in (0.1, 0.2, 0.3, 0.5))
#: a_Ndop levels of Figs. 6-10 [m/s^2]: 15 (the paper's "small", ~1.5 g) ... 300 (~30 g)
A_NDOP_LEVELS = (15.0, 50.0, 150.0, 300.0)
#: load lengths A of Figs. 5, 8-10 [m] (the paper names 0.1 and 1.2)
LENGTHS = (0.1, 0.3, 0.5, 0.7, 0.9, 1.2)

# -- CSV schema ---------------------------------------------------------------------------------
#: the outcome of one point
RESULT_COLUMNS: dict[str, type] = {
    "feasible": bool,
    "R_s": float,
    "v": float,
    "t1": float,
    "R_z": float,
    "W_t": float,
    "Delta_c": float,
    "Delta": float,  # required distance between loads, Delta_c - A_max (Fig. 3f)
    "t_z": float,
    "active": str,
    "m7": float,
    "m8": float,
    "m9": float,
    "m10": float,
    "m11": float,
    "m12": float,
    "impact_speed": float,  # w_n of the optimum (margin of (10) + w_dop) [m/s]
    "accel": float,  # a_N (margin of (11) + a_Ndop) [m/s^2]
    "exit_speed": float,  # ydot (margin of (12) + ydot_dop) [m/s]
    "infeasible": str,
    "evaluations": int,
    "wall_time": float,
    # keys of the points whose optima started this search (the nesting repair), space-separated
    "started_from": str,
}
COLUMNS: dict[str, type] = {"key": str, **INPUT_COLUMNS, **RESULT_COLUMNS}


def point_key(inputs: Mapping) -> str:
    """A stable key of a point's inputs (12 hex digits of the SHA-1 of their JSON)."""
    canon = {k: _fmt(INPUT_COLUMNS[k], inputs[k]) for k in INPUT_COLUMNS}
    blob = json.dumps(canon, sort_keys=True).encode()
    return hashlib.sha1(blob).hexdigest()[:12]


def _fmt(kind: type, value) -> str:
    if kind is bool:
        return "1" if value else "0"
    if kind is float:
        value = float(value)
        return "nan" if math.isnan(value) else repr(value)
    return str(value)


def _parse(kind: type, text: str):
    if kind is bool:
        if text not in ("0", "1"):
            raise ValueError(f"not a bool: {text!r}")
        return text == "1"
    if kind is float:
        return float(text)
    if kind is int:
        return int(text)
    return text


def format_row(row: Mapping) -> list[str]:
    """A row as CSV cells (floats by repr, so they read back exactly)."""
    return [_fmt(kind, row[name]) for name, kind in COLUMNS.items()]


def parse_row(cells: Sequence[str]) -> dict:
    """CSV cells back to a row (ValueError on a malformed row)."""
    if len(cells) != len(COLUMNS):
        raise ValueError(f"{len(cells)} cells, expected {len(COLUMNS)}")
    return {name: _parse(kind, c) for (name, kind), c in zip(COLUMNS.items(), cells, strict=True)}


def read_rows(path: Path, *, repair: bool = False) -> list[dict]:
    """The rows of a sweep CSV. Malformed rows (a line cut by an interrupt, a hand edit) are
    dropped; with ``repair`` the file is rewritten without them (so appends stay aligned)."""
    path = Path(path)
    if not path.exists():
        return []
    text = path.read_text()
    lines = text.splitlines(keepends=True)
    good_lines: list[str] = []
    rows: list[dict] = []
    bad = 0
    old = False
    for i, line in enumerate(lines):
        if not line.endswith("\n"):  # cut mid-write
            bad += 1
            continue
        if i == 0:
            header = line.rstrip("\r\n").split(",")
            if header == list(COLUMNS)[:-1]:  # before "started_from": none was started
                old = True
            elif header != list(COLUMNS):
                raise ValueError(
                    f"{path}: header differs from this version's columns; move the file away "
                    "to recompute the sweep"
                )
            good_lines.append(line)
            continue
        try:
            (cells,) = list(csv.reader([line]))
            rows.append(parse_row(cells + [""] if old else cells))
            good_lines.append(line)
        except ValueError:
            bad += 1
    if repair and old:  # rewritten in this version's columns, so appends stay aligned
        path.write_text(_csv_text(rows))
    elif repair and bad:
        path.write_text("".join(good_lines))
    return rows


def _csv_text(rows: Iterable[Mapping]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(list(COLUMNS))
    for r in rows:
        w.writerow(format_row(r))
    return buf.getvalue()


class RowWriter:
    """Appends rows to a sweep CSV, one flushed (and fsynced) line per row."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        new = not self.path.exists() or self.path.stat().st_size == 0
        self._f = self.path.open("a", newline="")
        self._w = csv.writer(self._f, lineterminator="\n")
        if new:
            self._w.writerow(list(COLUMNS))
            self._flush()

    def _flush(self) -> None:
        self._f.flush()
        os.fsync(self._f.fileno())

    def write(self, row: Mapping) -> None:
        self._w.writerow(format_row(row))
        self._flush()

    def close(self) -> None:
        self._f.close()

    def __enter__(self) -> RowWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# -- one point ----------------------------------------------------------------------------------
def _pairs(text: str) -> list[tuple[str, str]]:
    out = []
    for item in text.split():
        name, _, value = item.partition("=")
        out.append((name, value))
    return out


def make_spec(inputs: Mapping):
    """The optimiser's OptimizeSpec of a point (degrees -> radians here)."""
    kw: dict = {
        "case": inputs["case"],
        "alpha_k": math.radians(inputs["alpha_k_deg"]),
        "w_dop": inputs["w_dop"],
        "a_ndop": inputs["a_ndop"],
        "exit_speed_limit": inputs["exit_speed_limit"],
        "constraints": tuple(int(c) for c in inputs["constraints"].split()),
        "mu1": inputs["mu1"],
        "mu2": inputs["mu2"],
        "load_length": inputs["load_length"],
        "load_width": inputs["load_width"],
    }
    if inputs["fixed"]:
        kw["fixed"] = tuple((n, float(v)) for n, v in _pairs(inputs["fixed"]))
    if inputs["bounds"]:
        kw["bounds"] = tuple(
            (n, float(v.split(":")[0]), float(v.split(":")[1]))
            for n, v in _pairs(inputs["bounds"])
        )
    if inputs["budget"]:
        kw["budget"] = int(inputs["budget"])
    return OptimizeSpec(**kw).validate()


def result_row(inputs: Mapping, res) -> dict:
    """The CSV row of a point from its OptimumResult (``res.to_dict()`` or the object)."""
    d = res if isinstance(res, Mapping) else res.to_dict()
    x = d.get("X") or {}
    margins = {int(k): v for k, v in (d.get("margins") or {}).items()}

    def num(v) -> float:
        return math.nan if v is None else float(v)

    def lim(c: int, limit: float) -> float:
        m = margins.get(c)
        return math.nan if m is None else num(m) + limit

    r_s, v, t1 = num(x.get("R_s")), num(x.get("v")), num(x.get("t1"))
    delta_c = num(d.get("Delta_c"))
    # A_max of (2): the limiting load (arbitrary: also the 0.1 m minimal object)
    a_max = max(inputs["load_length"], 0.1 if inputs["case"] == "arbitrary" else 0.0)
    t_z = 2.0 * t1 + abs(r_s) / v if v > 0 else math.nan
    infeasible = d.get("infeasible") or ""
    if not isinstance(infeasible, str):
        infeasible = "; ".join(str(s) for s in infeasible)
    row = {
        "feasible": bool(d.get("feasible")),
        "R_s": r_s,
        "v": v,
        "t1": t1,
        "R_z": num(x.get("R_z")),
        "W_t": num(d.get("W_t")),
        "Delta_c": delta_c,
        "Delta": delta_c - a_max,
        "t_z": t_z,
        "active": " ".join(str(c) for c in (d.get("active") or ())),
        **{f"m{c}": num(margins.get(c)) for c in range(7, 13)},
        "impact_speed": lim(10, inputs["w_dop"]),
        "accel": lim(11, inputs["a_ndop"]),
        "exit_speed": lim(12, inputs["exit_speed_limit"]),
        "infeasible": infeasible.replace("\n", " "),
        "evaluations": int(d.get("evaluations") or 0),
        "wall_time": num(d.get("wall_time")),
        "started_from": "",
    }
    return row


def solve_point(inputs: Mapping, starts: Sequence[Mapping] = (), started_from: str = "") -> dict:
    """One optimum (serial optimiser: the sweep parallelises over points); the result columns.
    ``starts``: points X the search starts from (:func:`repair_nesting`), ``started_from``
    the keys of the points they came from."""
    spec = make_spec(inputs)
    d = solve.optimize(spec, executor=None, starts=starts).to_dict()
    if d.get("feasible") and hasattr(solve, "evaluate_point"):
        # the figures of the constraints the profile leaves out (Fig. 6f: exit speed without
        # (12)): one more twin run of the optimum, worst over the loads of the case
        full = solve.evaluate_point(spec, d["X"])["margins"]
        d["margins"] = {**{int(c): m for c, m in full.items()}, **d["margins"]}
    return {**result_row(inputs, d), "started_from": started_from}


# -- sweep definitions --------------------------------------------------------------------------
@dataclass(frozen=True)
class Panel:
    column: str
    label: str
    scale: float = 1.0  # plotted value = column * scale


@dataclass(frozen=True)
class SweepDef:
    """One figure: the points of its run and how to plot them."""

    name: str
    figure: str
    title: str
    run: str  # the CSV (run) that holds its points: fig9 plots fig8's run
    points: tuple[dict, ...]
    x: str  # column on the abscissa
    x_label: str
    series: str  # one curve per value of this column
    series_label: str
    panels: tuple[Panel, ...]
    solve: Callable[[Mapping], dict] = field(default=solve_point, compare=False)
    note: str = ""


P_T1 = Panel("t1", "t1 [s]")
P_WT = Panel("W_t", "W_t [pcs/h]")
P_RS = Panel("R_s", "R_s [m]")
P_V = Panel("v", "v [m/s]")
P_RZ = Panel("R_z", "R_z [m]")
P_DELTA = Panel("Delta", "required distance Delta [m]")
P_EXIT = Panel("exit_speed", "exit speed ydot [m/s]")
P_ACC = Panel("accel", "a_N [m/s^2]")

C_ARB = "7 8 9 10"
C_POS = "7 8 11"
C_POS12 = "7 8 11 12"


def _fig3() -> tuple[dict, ...]:
    return tuple(
        point(case="arbitrary", alpha_k_deg=a, w_dop=w, constraints=C_ARB)
        for w in W_DOP_LEVELS
        for a in ALPHAS_DEG
    )


def _fig4() -> tuple[dict, ...]:
    return tuple(
        point(
            case="arbitrary",
            alpha_k_deg=40.0,
            w_dop=2.4,
            constraints=C_ARB,
            mu1=m1,
            mu2=m2,
            fixed="R_s=0.0 R_z=1.4",
        )
        for m2 in (0.2, 0.35, 0.5)
        for m1 in (0.35, 0.5, 0.65, 0.8)
    )


def _fig5() -> tuple[dict, ...]:
    return tuple(
        point(case="arbitrary", alpha_k_deg=40.0, w_dop=w, constraints=C_ARB, load_length=a)
        for w in W_DOP_LEVELS[1:]
        for a in LENGTHS
    )


def _fig6(constraints: str) -> tuple[dict, ...]:
    return tuple(
        point(case="positioned", alpha_k_deg=a, a_ndop=an, constraints=constraints)
        for an in A_NDOP_LEVELS
        for a in ALPHAS_DEG
    )


def _fig8(constraints: str, fixed: str = "") -> tuple[dict, ...]:
    return tuple(
        point(
            case="positioned",
            alpha_k_deg=40.0,
            a_ndop=an,
            constraints=constraints,
            load_length=a,
            fixed=fixed,
        )
        for an in A_NDOP_LEVELS
        for a in LENGTHS
    )


#: the extra sweeps' fence: the 1.2 m of section 4.3 (R_z does not enter W_t (1), so with it
#: free the optimiser may shorten the fence until (12) holds at any stroke speed)
FIXED_RZ = "R_z=1.2"


def _fig7_fixed_rz() -> tuple[dict, ...]:
    return tuple(
        point(case="positioned", alpha_k_deg=a, a_ndop=an, constraints=C_POS12, fixed=FIXED_RZ)
        for an in A_NDOP_LEVELS[1:]
        for a in ALPHAS_DEG
    )


def _decision_points() -> tuple[dict, ...]:
    return decision_points()


def _defs() -> dict[str, SweepDef]:
    alpha = ("alpha_k_deg", "alpha_k [deg]")
    defs = [
        SweepDef(
            "fig3",
            "Fig. 3",
            "arbitrary placement, (7)-(10): parameters vs alpha_k and w_dop",
            "fig3",
            _fig3(),
            *alpha,
            "w_dop",
            "w_dop [m/s]",
            (P_T1, P_WT, P_RS, P_V, P_RZ, P_DELTA),
        ),
        SweepDef(
            "fig4",
            "Fig. 4",
            "arbitrary placement, (7)-(10), alpha_k 40 deg, R_s 0, R_z 1.4 m: vs mu1, mu2",
            "fig4",
            _fig4(),
            "mu1",
            "mu1 (belt)",
            "mu2",
            "mu2 (fence)",
            (P_T1, P_WT, P_V),
        ),
        SweepDef(
            "fig5",
            "Fig. 5",
            "arbitrary placement, (7)-(10), alpha_k 40 deg, B 0.1 m: vs load length A and w_dop",
            "fig5",
            _fig5(),
            "load_length",
            "load length A [m]",
            "w_dop",
            "w_dop [m/s]",
            (P_WT, P_RS, P_RZ),
        ),
        SweepDef(
            "fig6",
            "Fig. 6",
            "positioned, (7), (8), (11): parameters vs alpha_k and a_Ndop",
            "fig6",
            _fig6(C_POS),
            *alpha,
            "a_ndop",
            "a_Ndop [m/s^2]",
            (P_T1, P_WT, P_RS, P_V, P_RZ, P_EXIT),
        ),
        SweepDef(
            "fig7",
            "Fig. 7",
            "positioned, (7), (8), (11) and (12): vs alpha_k and a_Ndop",
            "fig7",
            _fig6(C_POS12),
            *alpha,
            "a_ndop",
            "a_Ndop [m/s^2]",
            (P_T1, P_WT, P_ACC),
        ),
        SweepDef(
            "fig8",
            "Fig. 8",
            "positioned, (7), (8), (11), alpha_k 40 deg, B 0.1 m: vs load length A and a_Ndop",
            "fig8",
            _fig8(C_POS),
            "load_length",
            "load length A [m]",
            "a_ndop",
            "a_Ndop [m/s^2]",
            (P_T1, P_WT, P_RS),
        ),
        SweepDef(
            "fig9",
            "Fig. 9",
            "exit speed towards the chute of the Fig. 8 optima (worst centre of gravity)",
            "fig8",
            _fig8(C_POS),
            "load_length",
            "load length A [m]",
            "a_ndop",
            "a_Ndop [m/s^2]",
            (P_EXIT,),
        ),
        SweepDef(
            "fig10",
            "Fig. 10",
            "positioned, (7), (8), (11) and (12), alpha_k 40 deg: vs load length A and a_Ndop",
            "fig10",
            _fig8(C_POS12),
            "load_length",
            "load length A [m]",
            "a_ndop",
            "a_Ndop [m/s^2]",
            (P_T1, P_WT, P_V),
        ),
    ]
    defs += [
        SweepDef(
            "fig7-fixed-rz",
            "Fig. 7 (R_z = 1.2 m)",
            "as Fig. 7 with the fence length held at 1.2 m (section 4.3)",
            "fig7-fixed-rz",
            _fig7_fixed_rz(),
            *alpha,
            "a_ndop",
            "a_Ndop [m/s^2]",
            (P_T1, P_WT, P_ACC, P_RS, P_V, P_EXIT),
        ),
        SweepDef(
            "fig10-fixed-rz",
            "Fig. 10 (R_z = 1.2 m)",
            "as Fig. 10 with the fence length held at 1.2 m (section 4.3)",
            "fig10-fixed-rz",
            _fig8(C_POS12, FIXED_RZ),
            "load_length",
            "load length A [m]",
            "a_ndop",
            "a_Ndop [m/s^2]",
            (P_T1, P_WT, P_V, P_ACC, P_RS, P_EXIT),
        ),
    ]
    return {d.name: d for d in defs}


#: the paper's figures (``--sweep all``)
PAPER_SWEEPS: tuple[str, ...] = tuple(f"fig{i}" for i in range(3, 11))
#: names accepted by --sweep: the paper's figures, two variants with the fence length fixed,
#: and the controller's starting candidates
SWEEPS: tuple[str, ...] = (*PAPER_SWEEPS, "fig7-fixed-rz", "fig10-fixed-rz", "decision-table")


def get_sweep(name: str) -> SweepDef:
    """The definition of sweep ``name`` (KeyError naming the allowed names)."""
    if name == "decision-table":
        return SweepDef(
            "decision-table",
            "Decision table",
            "the controller's starting candidates, R_s and t1 per load class at the "
            "configured alpha_k and belt speed",
            "decision-table",
            _decision_points(),
            "load_length",
            "load length A [m]",
            "case",
            "placement",
            (P_T1, P_RS, P_WT),
        )
    defs = _defs()
    if name not in defs:
        raise KeyError(f"unknown sweep {name!r}; allowed: {', '.join(SWEEPS)}, all")
    return defs[name]


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
                print(f"fence-sorter: {failed[-1]}", file=sys.stderr)
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
    """``fence-sorter optimize --sweep NAME --plots-only``: the figures from the CSVs in
    ``out`` (no solve, no table written). Exit 0, or 2 for a missing CSV."""
    for name in names:
        sw = get_sweep(name)
        csv_path = out / f"{sw.run}.csv"
        if not csv_path.is_file():
            print(f"fence-sorter: error: --out: no {csv_path} to plot {name}", file=sys.stderr)
            return EXIT_BAD_INPUT
        print(plot_sweep(sw, _order(sw, read_rows(csv_path)), out / f"{sw.name}.png"))
    return EXIT_OK


def main(args) -> int:
    """``fence-sorter optimize --sweep NAME``: run (or resume) the sweeps, write CSV + PNG.

    Uses ``args.sweep``, ``args.out`` (docs/paper), ``args.resume`` (True), ``args.workers``,
    ``args.scheduler`` and, when present, ``args.table`` (config/decision_table.yaml),
    ``args.max_points``, ``args.plots_only`` (True: :func:`replot` alone). Exit 0 done, 1 a
    point failed, 2 bad input, 130 interrupted.
    """
    try:
        names = parse_names(str(args.sweep))
    except KeyError as exc:
        print(f"fence-sorter: error: --sweep: {exc.args[0]}", file=sys.stderr)
        return EXIT_BAD_INPUT
    out = Path(getattr(args, "out", None) or "docs/paper")
    if getattr(args, "plots_only", False):
        return replot(names, out)
    resume = bool(getattr(args, "resume", True))
    max_points = getattr(args, "max_points", None)
    table_path = Path(getattr(args, "table", None) or "config/decision_table.yaml")
    try:
        sweeps = [get_sweep(n) for n in names]
    except Exception as exc:  # e.g. the decision table's config cannot be read
        print(f"fence-sorter: error: {exc}", file=sys.stderr)
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
            "fence-sorter: interrupted; finished points are in the CSV, rerun to resume",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    except Exception as exc:
        print(f"fence-sorter: sweep failed: {type(exc).__name__}: {exc}", file=sys.stderr)
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
    "SWEEPS",
    "SweepError",
    "SweepDef",
    "finish",
    "get_sweep",
    "main",
    "make_spec",
    "nested_pairs",
    "nesting_violations",
    "parse_names",
    "plot_sweep",
    "point",
    "point_key",
    "read_rows",
    "repair_nesting",
    "replot",
    "result_row",
    "run_sweep",
    "run_sweeps",
    "solve_point",
]
