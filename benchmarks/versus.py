"""The solve's speed against a base commit, both measured in one run on one machine.

``python -m benchmarks.versus BASE`` checks BASE out into a temporary git worktree and times
``simulate()`` of one event on each bench scene (model build included, as in ``python -m benchmarks
bench``) in fresh processes of this tree and of BASE, alternating: the same interpreter and
libraries, ``PYTHONPATH`` and the working directory pointing at each tree, each tree with its own
compiled-kernel cache (its ``__pycache__``). Each process compiles or loads its kernel and warms up
before the timed calls, with the garbage collector off. Per scene: the median wall time of every
timed call of each tree and their ratio (this tree / BASE: below 1 is faster). The figures go to
``docs/reports/versus.json`` and are rendered to ``docs/reports/versus.md``.

Exit codes: 0 measured, 2 bad arguments (one line naming the argument), 1 a child failed.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Callable, Sequence
from datetime import UTC, datetime
from pathlib import Path

from benchmarks import REPO
from fence_sorter.verification.machine import git_revision, load_average, machine_info
from fence_sorter.verification.report import table

SCENES = ("impact_flexible", "slide_flexible", "positioned_stiff", "arbitrary_stiff")
ROUNDS = 5  # fresh processes per tree and scene, alternating
CALLS = 20  # timed calls per process
WARM_UP = 3  # untimed calls per process before the timed ones
#: the warm-up module of a tree: this tree's, then the one of trees older than it
WARMUP_MODULES = ("fence_sorter.warmup", "fence_sorter.physics.warmup")
OUT_JSON = "docs/reports/versus.json"
OUT_MD = "docs/reports/versus.md"

#: run in a fresh process of one tree (cwd and PYTHONPATH the tree): the tree's own
#: fence_sorter, WARM_UP untimed calls, then CALLS timed ones with the collector off
CHILD = """
import gc, json, sys, time
args = json.loads(sys.argv[1])
import fence_sorter
from fence_sorter.scene import load_scene
from fence_sorter.physics.simulate import simulate
sc = load_scene(args["scene"]).scenario
for _ in range(args["warm_up"]):
    r = simulate(sc)
gc.collect()
gc.disable()
walls = []
for _ in range(args["calls"]):
    t0 = time.perf_counter()
    r = simulate(sc)
    walls.append(time.perf_counter() - t0)
gc.enable()
from fence_sorter.physics import kernel
print(json.dumps({"module": fence_sorter.__file__, "walls": walls,
                  "peak_force": float(r.peak_contact_force),
                  "aot": bool(getattr(kernel.solve, "entries", None))}))
"""


def commit_of(rev: str, root: Path = REPO) -> str:
    """The full hash of ``rev``; ValueError naming it when git does not know it."""
    out = subprocess.run(
        ["git", "-C", str(root), "rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}"],
        capture_output=True,
        text=True,
    )
    if out.returncode != 0:
        raise ValueError(f"BASE must be a commit of this repository, got {rev!r}")
    return out.stdout.strip()


def tree_env(tree: Path) -> dict[str, str]:
    """The environment of a process of ``tree``: its own PYTHONPATH and kernel cache."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["PYTHONPATH"] = str(tree)
    return env


def prepare(tree: Path) -> bool:
    """Compile ``tree``'s kernel as scripts/bootstrap.sh does for a clone (``python -m
    fence_sorter.warmup``, ``fence_sorter.physics.warmup`` in older trees: the JIT's cache and
    the ahead-of-time solve), so that both trees solve through the same kind of entry; False
    when the tree has no such module."""
    for module in WARMUP_MODULES:
        p = subprocess.run(
            [sys.executable, "-m", module],
            cwd=tree,
            env=tree_env(tree),
            capture_output=True,
            text=True,
        )
        if p.returncode == 0:
            return True
    return False


def run_child(tree: Path, scene: str, calls: int, warm_up: int) -> dict:
    """One fresh process of ``tree``: its timed calls of ``scene`` (JSON)."""
    env = tree_env(tree)
    arg = json.dumps({"scene": scene, "calls": calls, "warm_up": warm_up})
    p = subprocess.run(
        [sys.executable, "-c", CHILD, arg], cwd=tree, env=env, capture_output=True, text=True
    )
    if p.returncode != 0:
        raise RuntimeError(f"{tree} on {scene}: exit {p.returncode}\n{p.stderr[-2000:]}")
    data = json.loads(p.stdout.strip().splitlines()[-1])
    if not Path(data["module"]).resolve().is_relative_to(tree.resolve()):
        raise RuntimeError(f"the child of {tree} imported {data['module']}")
    return data


def measure(
    trees: dict[str, Path],
    scenes: Sequence[str],
    rounds: int,
    calls: int,
    warm_up: int = WARM_UP,
    log: Callable[[str], None] = print,
) -> list[dict]:
    """Per scene, ``rounds`` alternating processes of each tree (the order flips every round);
    each tree's timed calls, their median and the ratio of the medians (first tree / second)."""
    names = list(trees)
    results = []
    for scene in scenes:
        walls: dict[str, list[float]] = {n: [] for n in names}
        peaks: dict[str, float] = {}
        aot: dict[str, bool] = {}
        round_ratios = []
        for k in range(rounds):
            this_round = {}
            for name in names if k % 2 == 0 else names[::-1]:
                data = run_child(trees[name], scene, calls, warm_up)
                walls[name] += data["walls"]
                peaks[name] = data["peak_force"]
                aot[name] = data.get("aot", False)
                this_round[name] = statistics.median(data["walls"])
            round_ratios.append(this_round[names[0]] / this_round[names[1]])
        medians = {n: statistics.median(walls[n]) for n in names}
        row = {
            "scene": scene,
            "calls": {n: len(walls[n]) for n in names},
            "median_ms": {n: medians[n] * 1e3 for n in names},
            "peak_force": peaks,
            "aot": aot,
            "ratio": medians[names[0]] / medians[names[1]],
            "round_ratios": round_ratios,
        }
        log(
            f"{scene}: "
            + ", ".join(f"{n} {row['median_ms'][n]:.3f} ms" for n in names)
            + f", ratio {row['ratio']:.3f}"
        )
        results.append(row)
    return results


def render(data: dict) -> str:
    """The markdown of a versus run (from its JSON alone)."""
    head, base = data["head"], data["base"]
    lines = [
        "# Solve speed against a base commit",
        "",
        f"Generated by `{data['command']}` on {data['finished']}: this tree `{head}` against "
        f"`{base}`, {data['rounds']} alternating fresh processes per tree and scene, "
        f"{data['calls']} timed calls each after {data['warm_up']} untimed ones; load average "
        f"(1, 5, 15 min) {data['load_before']} before, {data['load_after']} after. How it is "
        "measured: "
        "[verification.md](../design/verification.md#solve-speed-against-a-base-commit).",
        "",
    ]
    if "prepared" in data:
        entry = {
            n: "the ahead-of-time solve"
            if all(r.get("aot", {}).get(n) for r in data["scenes"])
            else "the JIT"
            for n in ("head", "base")
        }
        lines += [
            f"Each tree's kernel compiled first (as scripts/bootstrap.sh's kernel step does): "
            f"`{head}` solved through {entry['head']}, `{base}` through {entry['base']}.",
            "",
        ]
    lines += table(
        (
            "scene",
            f"{head} median [ms]",
            f"{base} median [ms]",
            "ratio",
            "ratio per round (min - max)",
            "peak N [N] (both)",
        ),
        [
            (
                r["scene"],
                f"{r['median_ms']['head']:.3f}",
                f"{r['median_ms']['base']:.3f}",
                f"{r['ratio']:.3f}",
                f"{min(r['round_ratios']):.3f} - {max(r['round_ratios']):.3f}",
                f"{r['peak_force']['head']:.6g} / {r['peak_force']['base']:.6g}",
            )
            for r in data["scenes"]
        ],
    )
    lines += ["", "| machine |  |", "|---|---|"]
    lines += [f"| {k} | {v} |" for k, v in data["machine"].items()]
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.versus",
        description="time simulate() per event on the bench scenes, this tree against BASE",
    )
    parser.add_argument("base", metavar="BASE", help="the commit to compare against")
    parser.add_argument("--scenes", nargs="+", metavar="NAME", help="default: the bench's four")
    parser.add_argument("--rounds", type=int, default=ROUNDS, help=f"default {ROUNDS}")
    parser.add_argument("--calls", type=int, default=CALLS, help=f"default {CALLS}")
    parser.add_argument("--json", default=OUT_JSON, metavar="FILE", help=f"default {OUT_JSON}")
    parser.add_argument("--out", default=OUT_MD, metavar="FILE", help=f"default {OUT_MD}")
    args = parser.parse_args(argv)

    def error(message: str) -> int:
        print(f"versus: error: {message}", file=sys.stderr)
        return 2

    scenes = [n for item in args.scenes or SCENES for n in item.split(",") if n]
    unknown = [n for n in scenes if n not in SCENES]
    if unknown:
        return error(f"unknown bench scene {unknown[0]!r}; allowed: {', '.join(SCENES)}")
    if not 1 <= args.rounds <= 100:
        return error(f"--rounds must be in [1, 100], got {args.rounds}")
    if not 1 <= args.calls <= 10000:
        return error(f"--calls must be in [1, 10000], got {args.calls}")
    try:
        base = commit_of(args.base)
    except ValueError as exc:
        return error(str(exc))
    command = shlex.join(["python", "-m", "benchmarks.versus", *sys.argv[1:]])
    load_before = load_average()
    with tempfile.TemporaryDirectory(prefix="versus-") as tmp:
        base_tree = Path(tmp) / "base"
        subprocess.run(
            ["git", "-C", str(REPO), "worktree", "add", "--detach", str(base_tree), base],
            check=True,
            capture_output=True,
        )
        prepared = {name: prepare(tree) for name, tree in (("head", REPO), ("base", base_tree))}
        try:
            rows = measure(
                {"head": REPO, "base": base_tree}, scenes, args.rounds, args.calls,
                log=lambda m: print(m, flush=True),
            )  # fmt: skip
        except RuntimeError as exc:
            print(f"versus: {exc}", file=sys.stderr)
            return 1
        finally:
            subprocess.run(
                ["git", "-C", str(REPO), "worktree", "remove", "--force", str(base_tree)],
                capture_output=True,
            )
    data = {
        "command": command,
        "finished": datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "head": git_revision(),
        "base": base[:7],
        "rounds": args.rounds,
        "calls": args.calls,
        "warm_up": WARM_UP,
        "prepared": prepared,
        "load_before": load_before,
        "load_after": load_average(),
        "machine": machine_info(),
        "scenes": rows,
    }
    Path(args.json).write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    text = render(data)
    Path(args.out).write_text(text, encoding="utf-8")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
