"""Tests wait on conditions, never sleep for a guessed time and then assert, and never assert
a time measured on the wall clock (timing belongs in the benchmark commands).

Every module under test/ is parsed and searched for calls of ``time.sleep`` (under any name
the module imports it as), and for asserts on a value read from a clock (``perf_counter``,
``monotonic``, ``time``, ``process_time``) or computed from one in the same function. A child
process's script written as a string is not code of the module and is not searched (a child
that must hang uses ``signal.pause()`` or ``threading.Event().wait()``). The few functions
where the pacing itself is the subject are named in PACED, each with its reason.
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
    ("test/processes.py", "wait_until"): (
        "the one bounded wait on a condition: the poll interval between two checks"
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


CLOCKS = {"perf_counter", "monotonic", "time", "process_time", "perf_counter_ns", "monotonic_ns"}


def clock_asserts(source: str) -> list[int]:
    """Lines of asserts on a clock reading, or on a name assigned from one (or from such a
    name) earlier in the same function."""
    found: list[int] = []
    for func in ast.walk(ast.parse(source)):
        if not isinstance(func, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        timed: set[str] = set()

        def from_clock(expr: ast.AST, timed: set[str] = timed) -> bool:
            for n in ast.walk(expr):
                if isinstance(n, ast.Call):
                    f = n.func
                    name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
                    if name in CLOCKS:
                        return True
                if isinstance(n, ast.Name) and n.id in timed:
                    return True
            return False

        for node in ast.walk(func):
            if isinstance(node, ast.Assign) and from_clock(node.value):
                timed |= {t.id for t in node.targets if isinstance(t, ast.Name)}
            elif isinstance(node, ast.Assert) and from_clock(node.test):
                found.append(node.lineno)
    return found


@pytest.mark.parametrize(
    "source",
    [
        "import time\ndef test_x():\n    t0 = time.perf_counter()\n    f()\n"
        "    wall = time.perf_counter() - t0\n    assert wall < 1.0\n",
        "import time\ndef test_x():\n    assert time.monotonic() - T0 < 5\n",
    ],
)
def test_an_assert_on_a_clock_reading_is_found(source: str) -> None:
    assert len(clock_asserts(source)) == 1


def test_a_deadline_of_a_wait_is_not_an_assert() -> None:
    source = (
        "import time\ndef wait(p):\n    end = time.monotonic() + 5\n"
        "    while time.monotonic() < end:\n        if p():\n            return\n"
        "    raise AssertionError('timed out')\n"
    )
    assert clock_asserts(source) == []


def test_no_test_asserts_a_wall_clock_time() -> None:
    report = [
        f"{f.relative_to(ROOT)}:{line}"
        for f in sorted((ROOT / "test").rglob("*.py"))
        if f.resolve() != Path(__file__).resolve()
        for line in clock_asserts(f.read_text(encoding="utf-8"))
    ]
    assert not report, "asserts on wall-clock times (a benchmark's figures):\n" + "\n".join(report)


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
        "time.sleep in tests (wait on a condition: processes.wait_until):\n" + "\n".join(report)
    )
