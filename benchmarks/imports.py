"""Start-up of the command line: the modules each subcommand's ``--help`` imports, its wall time.

``python -m benchmarks.imports`` runs each command of :data:`COMMANDS` in fresh interpreters:
once as ``python -X importtime -m fence_sorter.cli.main ARGS`` for the modules it imports and
which of them are heavy (:data:`fence_sorter.lazy.HEAVY`, by top-level name), then ``--rounds``
times as ``fence-sorter ARGS`` (the console script of this environment) for the best wall time.
Then each module of :data:`MODULES` is imported alone (``python -X importtime -c "import M"``)
for the modules and heavy dependencies it loads, and whether the compiled kernel is among them.
The figures go, with the command line, commit and load, to docs/reports/imports.json and are
rendered into the marked section of docs/design/imports.md; ``--from-json`` renders a
committed JSON again without measuring. Exit codes: 0 done, 2 bad arguments, 1 a command failed.
"""

from __future__ import annotations

import argparse
import importlib.util
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

from benchmarks import REPO
from benchmarks.sections import SectionReport, framed
from fence_sorter.lazy import HEAVY
from fence_sorter.verification.machine import git_revision, load_average
from fence_sorter.verification.report import table

JSON = REPO / "docs" / "reports" / "imports.json"
DOC = REPO / "docs" / "design" / "imports.md"
#: the section of DOC the renderer rewrites
BEGIN, END = "<!-- imports:begin -->", "<!-- imports:end -->"
#: the commands measured: the top level and the subcommands with the most imports at their top
COMMANDS = (
    ("--help",),
    ("simulate", "--help"),
    ("run", "--help"),
    ("calibrate", "--help"),
    ("topic", "--help"),
    ("optimize", "--help"),
)
#: the modules whose import a node process or a scene reader pays before its first line runs
MODULES = (
    "fence_sorter.nodes.scanner",
    "fence_sorter.nodes.controller",
    "fence_sorter.nodes.simulator",
    "fence_sorter.nodes.recorder",
    "fence_sorter.scene",
)
KERNEL = "fence_sorter.physics.kernel"


def imported_modules(importtime_stderr: str) -> list[str]:
    """The modules ``python -X importtime`` reports imported by the last interpreter of its
    output (an interpreter that re-executes itself reports twice), each once, in order; the
    imports of modules this platform lacks (``nt``, ``_winapi``) are tried, not imported."""
    modules: dict[str, None] = {}
    for line in importtime_stderr.splitlines():
        if line.startswith("import time:") and "|" in line:
            name = line.rsplit("|", 1)[1].strip()
            if name == "imported package":  # the header of an interpreter's report
                modules.clear()
            elif importlib.util.find_spec(name.split(".", 1)[0]) is not None:
                modules[name] = None
    return list(modules)


def heavy_of(modules: list[str]) -> list[str]:
    """The heavy dependencies among ``modules`` (top-level names, sorted)."""
    return sorted({m.split(".", 1)[0] for m in modules} & HEAVY)


def traced(what: str, *argv: str) -> list[str]:
    """The modules ``python -X importtime ARGV`` imports in a fresh interpreter (RuntimeError
    naming ``what`` when it fails)."""
    done = subprocess.run(
        [sys.executable, "-X", "importtime", *argv],
        capture_output=True,
        text=True,
        cwd=REPO,
        check=False,
    )
    if done.returncode != 0:
        raise RuntimeError(f"{what} exited {done.returncode}")
    return imported_modules(done.stderr)


def measure(args: tuple[str, ...], rounds: int, script: str) -> dict:
    """Modules and heavy dependencies of ``fence-sorter ARGS``, and its best wall time [s]."""
    command = " ".join(("fence-sorter", *args))
    modules = traced(command, "-m", "fence_sorter.cli.main", *args)
    walls = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        subprocess.run([script, *args], capture_output=True, cwd=REPO, check=True)
        walls.append(time.perf_counter() - t0)
    return {
        "command": command,
        "modules": len(modules),
        "heavy": heavy_of(modules),
        "wall": min(walls),
    }


def measure_module(module: str) -> dict:
    """Modules and heavy dependencies that importing ``module`` in a fresh interpreter loads."""
    modules = traced(f"import {module}", "-c", f"import {module}")
    return {
        "module": module,
        "modules": len(modules),
        "heavy": heavy_of(modules),
        "kernel": any(m == KERNEL or m.startswith(KERNEL + ".") for m in modules),
    }


def render(data: dict) -> str:
    """The marked section of docs/design/imports.md, from the JSON alone."""
    rows = [
        [
            f"`{c['command']}`",
            c["modules"],
            f"{1e3 * c['wall']:.0f}",
            ", ".join(c["heavy"]) or "none",
        ]
        for c in data["commands"]
    ]
    body = [
        f"At {data['commit']} (load average {data['load_average']} at the start, on 2 cores "
        "shared with other work, so the module counts are the firm figures): `python -X "
        "importtime -m fence_sorter.cli.main ARGS` for the modules imported and the heavy ones "
        f"among them, the best of {data['rounds']} wall times of `fence-sorter ARGS`; measured by "
        f"`{data['command']}`.",
        "",
        *table(["command", "modules imported", "wall time [ms]", "heavy modules loaded"], rows),
        "",
        'Importing one module alone (`python -X importtime -c "import M"`), as a node process '
        "or a reader of a scene does first:",
        "",
        *table(
            ["module", "modules imported", "heavy modules loaded", "the kernel"],
            [
                [
                    f"`{m['module']}`",
                    m["modules"],
                    ", ".join(m["heavy"]) or "none",
                    "yes" if m["kernel"] else "no",
                ]
                for m in data["modules"]
            ],
        ),
    ]
    return framed(BEGIN, END, "docs/reports/imports.json", data["command"], body)


REPORT = SectionReport("imports", JSON, DOC, BEGIN, END, render)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.imports",
        description="Modules imported and wall time of the command line's --help per subcommand.",
    )
    ap.add_argument("--rounds", type=int, default=5, help="timed runs per command (best)")
    REPORT.add_arguments(ap)
    args = ap.parse_args(argv)
    if args.rounds < 1:
        ap.error(f"--rounds must be >= 1, got {args.rounds}")
    section = REPORT.rendered_again(ap, args)
    data = None
    if section is None:
        script = shutil.which("fence-sorter", path=str(Path(sys.executable).parent))
        if script is None:
            ap.error(f"no fence-sorter script beside {sys.executable}: run scripts/bootstrap.sh")
        command = "python -m benchmarks.imports " + shlex.join(
            sys.argv[1:] if argv is None else argv
        )
        data = {
            "command": command.rstrip(),
            "commit": git_revision(REPO),
            "load_average": load_average(),
            "rounds": args.rounds,
        }
        try:
            data["commands"] = [measure(c, args.rounds, script) for c in COMMANDS]
            data["modules"] = [measure_module(m) for m in MODULES]
        except (RuntimeError, subprocess.CalledProcessError) as exc:
            print(f"benchmarks.imports: {exc}", file=sys.stderr)
            return 1
        section = render(data)
    return REPORT.write(section, data, args)


if __name__ == "__main__":
    sys.exit(main())
