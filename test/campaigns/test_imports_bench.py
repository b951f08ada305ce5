"""``python -m benchmarks.imports``: its reading of ``python -X importtime``, the heavy modules
among those read, a real measurement of one light command, and bad arguments."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks.imports import COMMANDS, heavy_of, imported_modules, main, measure, measure_module

IMPORTTIME = """import time: self [us] | cumulative | imported package
import time:        99 |         99 |   encodings
import time: self [us] | cumulative | imported package
import time:       120 |        120 |   _io
import time:        80 |        200 |     numba.core.config
import time:        30 |         30 |     no_such_module_here
import time:        10 |         10 | scipy
import time:        10 |         10 | scipy
some other line on stderr
"""


def test_importtime_lines_are_read_as_modules_and_heavy_ones_named() -> None:
    """The last interpreter's report, each module once, the failed tries left out."""
    modules = imported_modules(IMPORTTIME)
    assert modules == ["_io", "numba.core.config", "scipy"]
    assert heavy_of(modules) == ["numba", "scipy"]
    assert heavy_of(["numpy", "yaml", "fence_sorter.cli.main"]) == []


def test_a_measured_help_counts_what_the_interpreter_holds() -> None:
    """The modules importtime reports for ``fence-sorter --help`` are those an independent
    reader finds in ``sys.modules`` of a fresh interpreter that ran the same command, but for
    the interpreter's own built-ins, loaded before importtime reports."""
    reader = (
        "import sys\n"
        "from fence_sorter.cli.main import main\n"
        "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
        "print(' '.join(sys.modules), file=sys.stderr)\n"
    )
    done = subprocess.run([sys.executable, "-c", reader], capture_output=True, text=True)
    held = set(done.stderr.strip().splitlines()[-1].split())
    traced = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "fence_sorter.cli.main", "--help"],
        capture_output=True,
        text=True,
    )
    listed = set(imported_modules(traced.stderr))
    assert len(listed) > 50
    assert listed - held <= {"runpy"}  # what -m runs the module with
    # the module itself runs as __main__ under -m; the frozen import system and os.path are
    # set up by the interpreter, not imported
    assert held - listed <= set(sys.builtin_module_names) | {
        "__main__",
        "fence_sorter.cli.main",
        "_frozen_importlib",
        "importlib._bootstrap",
        "importlib._bootstrap_external",
        "os.path",
    }
    figures = measure(COMMANDS[0], 1, str(Path(sys.executable).with_name("fence-sorter")))
    assert figures["modules"] == len(listed) and figures["heavy"] == [] and figures["wall"] > 0


@pytest.mark.parametrize(
    ("args", "names"),
    [
        (["--rounds", "0"], "--rounds must be >= 1"),
        (["--doc", "/nonexistent/x.md"], "--doc"),
        (["--from-json", "/nonexistent/x.json", "--doc", ""], "--from-json"),
    ],
)
def test_bad_arguments_exit_2_with_one_line_naming_them(args, names, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main(args)
    assert exc.value.code == 2
    assert names in capsys.readouterr().err.strip().splitlines()[-1]


def test_importing_one_module_names_its_heavy_dependencies_and_the_kernel() -> None:
    scene = measure_module("fence_sorter.scene")
    assert scene["heavy"] == [] and not scene["kernel"] and scene["modules"] > 20
    kernel = measure_module("fence_sorter.physics.kernel")
    assert kernel["kernel"] and "numba" in kernel["heavy"]
    assert kernel["modules"] > scene["modules"]
