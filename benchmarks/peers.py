"""Our default against the compiled peers, warm and alternating (``python -m benchmarks.peers``).

Per scene: the default configuration and each compiled peer's rung (``RUNGS``: the rungs the
bench's ladder search chooses at the default's error; ``--rung method:rtol`` replaces them)
timed in one process, warm, one call of each in turn per round, the garbage collector off
during each call (``bench.timed_run``); the median of each. Then, for the default, where an
event's time goes: the model build and stepper set-up, the compiled loop (``Stepper.busy``),
the result's reduction; and the cost of one ``kernel.rhs`` call at the event's own accepted
states (a compiled loop over them, the cost a peer pays per right-hand side). Prints markdown.
"""

from __future__ import annotations

import argparse
import dataclasses as dc
import gc
import statistics
import sys
import time
from collections.abc import Sequence

import numpy as np
from numba import njit

from benchmarks import bench as B
from fence_sorter.physics import kernel as K
from fence_sorter.physics.params import CYRK_METHODS
from fence_sorter.scene import load_scene
from fence_sorter.verification.machine import git_revision, load_average

#: scene -> the peers' rungs at the default's error, as the bench's ladder search chose them
#: (python -m benchmarks bench at 6012f66; a rung counts when the next tighter one also does)
RUNGS = {
    "positioned_stiff": (
        ("cyrk:Tsit5", 1e-3),
        ("cyrk:RK45", 1e-2),
        ("cyrk:Radau", 1e-2),
        ("cyrk:LSODA", 1e-5),
    ),
    # cyrk:DOP853 rtol 1e-2 reaches 2.5e-4 here by a cancellation of errors (1.1e-2 at 1e-3)
    "arbitrary_stiff": (("cyrk:Tsit5", 1e-3), ("cyrk:BDF", 1e-4)),
    "impact_flexible": (("cyrk:BDF", 1e-5), ("cyrk:LSODA", 1e-5), ("cyrk:Radau", 1e-5)),
    "slide_flexible": (("cyrk:LSODA", 1e-3), ("cyrk:Radau", 1e-2), ("cyrk:BDF", 1e-5)),
}
ROUNDS = 21


@njit(cache=True)
def _rhs_loop(model, ts, ys, on_belt, ev, dy):
    """kernel.rhs at every (t, y) of the event (the contact work of the real states)."""
    total = 0.0
    for k in range(ts.shape[0]):
        K.rhs(model, ts[k], ys[k], on_belt[k], dy, ev)
        total += dy[3]
    return total


def rhs_cost(sc) -> tuple[float, int]:
    """Median cost [s] of one kernel.rhs call over the default's accepted states (stiff fence:
    the state is the load's six components, all recorded), and the number of states."""
    from fence_sorter.physics.simulate import SortingModel, simulate  # lazy: loads the kernel

    r = simulate(dc.replace(sc, record=("trajectory",)))
    md = SortingModel(sc)
    s = r.series
    ts = np.ascontiguousarray(s["t"])
    ys = np.ascontiguousarray(np.stack([s[k] for k in ("x", "y", "phi", "vx", "vy", "phidot")], 1))
    on_belt = ys[:, 1] < sc.conveyor.width
    n_el = md.n_el
    ev = K.Evaluation(
        K.zero_slots(), K.zero_result(), np.zeros(md.n_modes),
        np.zeros(max(2 * n_el, 2)), np.zeros(max(2 * n_el, 2)), np.zeros((n_el + 1, 2)),
        np.zeros(K.N_SLOTS), np.zeros(3),
    )  # fmt: skip
    model = K.ForceModel(md.P, md.corners, md.normals, md.phi, md.rigid_modal, md.omega, md.zeta)
    dy = np.zeros(md.n_state)
    walls = []
    for _ in range(31):
        t0 = time.perf_counter()
        _rhs_loop(model, ts, ys, on_belt, ev, dy)
        walls.append(time.perf_counter() - t0)
    return statistics.median(walls) / len(ts), len(ts)


def split_default(sc, rounds: int) -> dict[str, float]:
    """Median time [s] of the default's build (model and stepper), compiled loop and result."""
    from fence_sorter.physics.simulate import SortingModel  # lazy: loads the kernel
    from fence_sorter.physics.stepper import Stepper

    parts: dict[str, list[float]] = {"build": [], "loop": [], "result": [], "total": []}
    for _ in range(rounds):
        gc.disable()
        t0 = time.perf_counter()
        st = Stepper(SortingModel(sc))
        t1 = time.perf_counter()
        st.advance()
        t2 = time.perf_counter()
        st.result()
        st.release()
        t3 = time.perf_counter()
        gc.enable()
        parts["build"].append(t1 - t0)
        parts["loop"].append(st.busy)
        parts["result"].append(t3 - t2)
        parts["total"].append(t3 - t0)
    return {k: statistics.median(v) for k, v in parts.items()}


def measure(name: str, rungs, rounds: int) -> list[str]:
    sc = load_scene(name).scenario
    ref = B.our_reference(sc).peak
    runs = {"default": sc} | {
        f"{m} rtol {r:g}": B.with_solver(sc, method=m, rtol=r, atol=r * B.ATOL_FACTOR)
        for m, r in rungs
    }
    walls: dict[str, list[float]] = {k: [] for k in runs}
    outcome = {}
    for key, run_sc in runs.items():  # warm-up (and the peers' compilation)
        outcome[key] = B.timed_run(run_sc)[0]
    B.collect()
    for _ in range(rounds):
        for key, run_sc in runs.items():
            walls[key].append(B.timed_run(run_sc)[1])
    base = statistics.median(walls["default"])
    rows = []
    for key in runs:
        o, w = outcome[key], statistics.median(walls[key])
        rows.append(
            f"| {name} | {key} | {w * 1e3:.3f} | {w / base:.2f} | {o.steps} | "
            f"{w / max(o.steps, 1) * 1e6:.2f} | {B.rel_error(o.peak_force, ref):.1e} |"
        )
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.peers", description=__doc__)
    p.add_argument("--scenes", nargs="+", default=list(RUNGS), choices=list(RUNGS))
    p.add_argument("--rounds", type=int, default=ROUNDS)
    p.add_argument("--rung", action="append", default=[], help="method:rtol (replaces RUNGS)")
    args = p.parse_args(argv)
    if args.rounds < 1:
        print(
            f"benchmarks.peers: error: --rounds must be at least 1, got {args.rounds}",
            file=sys.stderr,
        )
        return 2
    rungs = []
    for item in args.rung:
        method, _, rtol = item.rpartition(":")
        try:
            rungs.append((method, float(rtol)))
        except ValueError:
            print(f"benchmarks.peers: error: --rung {item!r} is not method:rtol", file=sys.stderr)
            return 2
        if method not in CYRK_METHODS:
            print(
                f"benchmarks.peers: error: --rung method {method!r} is not one of "
                f"{', '.join(CYRK_METHODS)}",
                file=sys.stderr,
            )
            return 2
    print(f"commit {git_revision()}, load {load_average()}, {args.rounds} alternating rounds")
    print()
    print("| scene | run | wall median [ms] | / default | steps | us per step | error vs ref. |")
    print("|---|---|---|---|---|---|---|")
    for name in args.scenes:
        for row in measure(name, rungs or RUNGS[name], args.rounds):
            print(row, flush=True)
    print()
    print("| scene | build [ms] | compiled loop [ms] | result [ms] | total [ms] | "
          "kernel.rhs per call [us] | states |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for name in args.scenes:
        sc = load_scene(name).scenario
        if sc.fence is not None:
            continue  # a flexible fence's modal states are not recorded
        split = split_default(sc, 4 * args.rounds)
        cost, n = rhs_cost(sc)
        print(
            f"| {name} | {split['build'] * 1e3:.3f} | {split['loop'] * 1e3:.3f} | "
            f"{split['result'] * 1e3:.3f} | {split['total'] * 1e3:.3f} | {cost * 1e6:.2f} | {n} |",
            flush=True,
        )
    print(f"load after: {load_average()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
