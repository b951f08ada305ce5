"""Every answer of the bench scenes, saved to compare two trees bitwise.

``python -m benchmarks.answers dump FILE`` solves the four bench scenes with their own settings
and with each scheme of ``--methods`` (the compiled adaptive, trapezoidal and generalized-alpha
steppers to the end, scipy:LSODA to 0.15 s by default), each with the default recording and
with every series recorded, and saves every result array to an ``.npz``: each field of the
``SimulationResult`` but its wall time, each figure of its energy audit, each recorded series,
the stage names and times; a field that is a Python object (the diagnosis text, the impacts)
as its repr. ``python -m benchmarks.answers compare A B`` compares two such files array by
array: dtype, shape and bytes.

A change that must leave the answers as they are (a refactoring of the kernel) is checked by a
dump of each tree (the working directory and ``PYTHONPATH`` at each) and a compare.

Exit codes: 0 dumped, or compared equal; 1 some arrays differ (the first ones named); 2 bad
arguments (one line naming the argument).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

SCENES = ("impact_flexible", "slide_flexible", "positioned_stiff", "arbitrary_stiff")
METHODS = ("adaptive", "trapezoidal", "generalized_alpha", "scipy:LSODA")
OWN = "own"  # the scene's own solver settings
SCIPY_END = 0.15  # [s] a SciPy baseline's end time (a whole event takes it minutes)
SHOWN = 10  # differing arrays named


def answers(scenes: Sequence[str], methods: Sequence[str]) -> dict[str, np.ndarray]:
    """Every result array of ``scenes`` solved with their own settings and with ``methods``,
    each with the default recording and with every series; keys ``scene|method|record|field``."""
    from fence_sorter.physics.scenario import RECORDABLE  # lazy: the physics, only to solve
    from fence_sorter.physics.simulate import simulate  # lazy: the physics, only to solve
    from fence_sorter.scene import load_scene  # lazy: the physics, only to solve

    out: dict[str, np.ndarray] = {}
    for name in scenes:
        base = load_scene(name).scenario
        for method in (OWN, *methods):
            sc = base
            if method != OWN:
                solver = dataclasses.replace(sc.solver, method=method)
                if method.startswith("scipy:"):
                    solver = dataclasses.replace(solver, t_end=SCIPY_END)
                sc = dataclasses.replace(sc, solver=solver)
            for record in ((), RECORDABLE):
                r = simulate(dataclasses.replace(sc, record=record))
                key = f"{name}|{method}|{'all' if record else 'default'}"
                out.update({f"{key}|{k}": v for k, v in _arrays(r).items()})
    return out


def _arrays(r) -> dict[str, np.ndarray]:
    """The result arrays of one SimulationResult (its wall time left out)."""
    arrays: dict[str, np.ndarray] = {}
    for f in dataclasses.fields(r):
        value = getattr(r, f.name)
        if f.name == "wall_time":
            continue
        if f.name == "series":
            arrays.update({f"series.{k}": np.asarray(v) for k, v in value.items()})
        elif f.name == "energy":
            for g in dataclasses.fields(value):
                arrays[f"energy.{g.name}"] = np.asarray(getattr(value, g.name))
        elif f.name == "stages":
            arrays["stages.names"] = np.array([s for s, _ in value], dtype=str)
            arrays["stages.t"] = np.array([t for _, t in value], dtype=float)
        else:
            a = np.asarray(value)
            arrays[f.name] = np.array(repr(value)) if a.dtype == object else a
    return arrays


def differing(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> list[str]:
    """The keys whose arrays differ in dtype, shape or bytes, or are in one of a, b only."""
    keys = sorted(set(a) | set(b))
    return [
        k
        for k in keys
        if k not in a
        or k not in b
        or a[k].dtype != b[k].dtype
        or a[k].shape != b[k].shape
        or a[k].tobytes() != b[k].tobytes()
    ]


def _load(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as data:
        return {k: data[k] for k in data.files}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.answers",
        description="save every answer of the bench scenes, or compare two saved sets bitwise",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    dump = sub.add_parser("dump", help="solve and save every result array to FILE (.npz)")
    dump.add_argument("file", metavar="FILE")
    dump.add_argument("--scenes", nargs="+", metavar="NAME", help="default: the bench's four")
    dump.add_argument(
        "--methods", nargs="+", metavar="METHOD", help=f"default: {' '.join(METHODS)}"
    )
    compare = sub.add_parser("compare", help="compare two dumps array by array")
    compare.add_argument("a", metavar="A")
    compare.add_argument("b", metavar="B")
    args = parser.parse_args(argv)

    def error(message: str) -> int:
        print(f"answers: error: {message}", file=sys.stderr)
        return 2

    if args.command == "compare":
        for path in (args.a, args.b):
            if not Path(path).is_file():
                return error(f"{path} is not a file (a dump of python -m benchmarks.answers)")
        try:
            a, b = _load(Path(args.a)), _load(Path(args.b))
        except (OSError, ValueError) as exc:
            return error(f"{args.a} or {args.b} is not a dump: {exc}")
        bad = differing(a, b)
        print(f"{len(set(a) | set(b))} arrays compared, {len(bad)} differ")
        for k in bad[:SHOWN]:
            print(f"  {k}")
        return 1 if bad else 0
    from fence_sorter.physics.params import SOLVER_METHODS  # lazy: the physics, only to solve

    scenes = [n for item in args.scenes or SCENES for n in item.split(",") if n]
    unknown = [n for n in scenes if n not in SCENES]
    if unknown:
        return error(f"unknown bench scene {unknown[0]!r}; allowed: {', '.join(SCENES)}")
    methods = [n for item in args.methods or METHODS for n in item.split(",") if n]
    unknown = [n for n in methods if n not in SOLVER_METHODS]
    if unknown:
        return error(f"unknown method {unknown[0]!r}; allowed: {', '.join(SOLVER_METHODS)}")
    path = Path(args.file)
    if path.suffix != ".npz" or not path.parent.is_dir():
        return error(f"FILE must be an .npz in an existing directory, got {args.file}")
    data = answers(scenes, methods)
    np.savez(path, **data)
    print(f"{len(data)} arrays of {len(scenes)} scenes saved to {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
