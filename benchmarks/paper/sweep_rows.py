"""The rows of a sweep: one optimum per point, its CSV schema, reading and appending rows.

A point's result is one row of ``<out>/<run>.csv``, keyed by a hash of the point's inputs
(:func:`point_key`), so an interrupted sweep continues where it stopped."""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from benchmarks.paper.points import INPUT_COLUMNS
from fence_sorter.optimize import solve
from fence_sorter.optimize.problem import OptimizeSpec

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
