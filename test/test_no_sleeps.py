"""Tests wait on conditions, never sleep for a guessed time and then assert.

Every module under test/ is parsed and searched for calls of ``time.sleep`` (under any name
the module imports it as). A child process's script written as a string is not code of the
module and is not searched (a child that must hang uses ``signal.pause()`` or
``threading.Event().wait()``). The few functions where the pacing itself is the subject are
named in PACED, each with its reason.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: (module, function) -> why a sleep there paces what the test is about
PACED = {
    ("test/ros/test_recording.py", "publish"): (
        "a 1 kHz /clock publisher: the recorder closes segments and flushes on wall time"
    ),
}


def sleeps(source: str) -> list[tuple[int, str]]:
    """(line, enclosing function) of every call of time.sleep in ``source``."""
    tree = ast.parse(source)
    modules = {"time"} | {
        alias.asname or alias.name
        for node in ast.walk(tree)
        if isinstance(node, ast.Import)
        for alias in node.names
        if alias.name == "time"
    }
    functions = {
        alias.asname or alias.name
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom) and node.module == "time"
        for alias in node.names
        if alias.name == "sleep"
    }
    found: list[tuple[int, str]] = []

    def visit(node: ast.AST, where: str) -> None:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            where = node.name if where == "<module>" else where
        if isinstance(node, ast.Call):
            f = node.func
            by_module = (
                isinstance(f, ast.Attribute)
                and f.attr == "sleep"
                and isinstance(f.value, ast.Name)
                and f.value.id in modules
            )
            if by_module or (isinstance(f, ast.Name) and f.id in functions):
                found.append((node.lineno, where))
        for child in ast.iter_child_nodes(node):
            visit(child, where)

    visit(tree, "<module>")
    return found


@pytest.mark.parametrize(
    "source",
    [
        "import time\ndef test_x():\n    time.sleep(0.3)\n",
        "import time as _t\ndef wait():\n    _t.sleep(1)\n",
        "from time import sleep\nclass A:\n    def f(self):\n        sleep(1)\n",
    ],
)
def test_a_sleep_is_found_under_any_name(source: str) -> None:
    assert len(sleeps(source)) == 1


def test_a_child_script_and_other_sleeps_are_not_counted() -> None:
    source = (
        "import asyncio, time\n"
        'CHILD = "import time; time.sleep(60)"\n'
        "def f(ev):\n    ev.wait(1.0)\n    asyncio.sleep(0)\n    time.monotonic()\n"
    )
    assert sleeps(source) == []


def test_no_test_sleeps_to_wait_for_something() -> None:
    files = sorted((ROOT / "test").rglob("*.py"))
    assert len(files) > 50
    found = [
        (str(f.relative_to(ROOT)), line, where)
        for f in files
        for line, where in sleeps(f.read_text(encoding="utf-8"))
    ]
    report = [f"{f}:{line} in {where}" for f, line, where in found if (f, where) not in PACED]
    assert not report, (
        "time.sleep in tests (wait on a condition: fence_sorter.testing.wait_until):\n"
        + "\n".join(report)
    )
