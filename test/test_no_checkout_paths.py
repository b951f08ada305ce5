"""No module of the package names a path into the source checkout it may be imported from.

The installed package writes only where it is told (``--out DIR``, by default under the
current directory): the reports of this repository are written by ``make reports`` and the
campaigns of ``benchmarks/``, which name ``docs/reports/...`` themselves. Every module is
imported (so each one is a module of the package as installed) and its source is read for
what would reach into a checkout: ``Path(__file__).parents[...]`` or ``.parent.parent``
(the folders above the package) and a string that is a path under ``docs``. Docstrings and
comments may name the documents. ``resources.checkout_root`` is the one place that finds the
checkout, to read the run-time files (config/, launch/, urdf/, msg_defs/) of an editable
install; it never writes there."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest
from test_import_cycles import module_names

#: module -> why it may look above the package
ALLOWED = {
    "fence_sorter.resources": "checkout_root(): reads config/, launch/, urdf/ of a checkout",
}


def _docstrings(tree: ast.AST) -> set[int]:
    """ids of the string constants that are docstrings."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                found.add(id(body[0].value))
    return found


def checkout_paths(source: str) -> list[str]:
    """What in ``source`` reaches above the package or into docs/, as "line N: what"."""
    tree = ast.parse(source)
    docstrings = _docstrings(tree)
    found = []
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Subscript)
            and isinstance(node.value, ast.Attribute)
            and node.value.attr == "parents"
        ):
            found.append(f"line {node.lineno}: .parents[...]")
        elif (
            isinstance(node, ast.Attribute)
            and node.attr == "parent"
            and isinstance(node.value, ast.Attribute)
            and node.value.attr == "parent"
        ):
            found.append(f"line {node.lineno}: .parent.parent")
        elif (
            isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and id(node) not in docstrings
        ):
            text = node.value.strip().strip("./")
            if text == "docs" or text.startswith("docs/") or "/docs/" in text:
                found.append(f"line {node.lineno}: {node.value!r}")
    return found


def test_the_reader_finds_each_kind_of_checkout_path():
    source = (
        '"""Reads docs/guide/x.md."""\n'
        "from pathlib import Path\n"
        "REPO = Path(__file__).resolve().parents[2]\n"
        "UP = Path(__file__).parent.parent\n"
        'OUT = "docs/reports/accuracy"\n'
        'DOCS = REPO / "docs"\n'
        'HELP = "see docs/design/model.md"  # a help text naming a document\n'
        "def f():\n"
        '    """Writes to docs/x (a docstring)."""\n'
        '    return Path("./docs/paper")\n'
    )
    assert checkout_paths(source) == [
        "line 3: .parents[...]",
        "line 4: .parent.parent",
        "line 5: 'docs/reports/accuracy'",
        "line 6: 'docs'",
        "line 10: './docs/paper'",
    ]


MODULES = sorted(module_names())


def test_every_module_of_the_package_is_checked():
    assert len(MODULES) > 100
    assert "fence_sorter.cli.accuracy" in MODULES and "fence_sorter.cli.views" in MODULES


@pytest.mark.parametrize("name", MODULES)
def test_no_module_names_a_path_into_the_checkout(name):
    module = importlib.import_module(name)
    source = Path(module.__file__).read_text(encoding="utf-8")
    found = checkout_paths(source)
    if name in ALLOWED:
        assert found, f"{name} is allowed ({ALLOWED[name]}) but no longer needs it"
        return
    assert not found, f"{name} names a path into the checkout: {found}"
