"""The module graph of fence_sorter has no cycle, and imports inside functions are lazy on purpose.

Every ``import`` and ``from ... import`` of a fence_sorter module counts, also one inside a
function: an import moved into a function hides a cycle from the interpreter, not from the
design. The graph is read from the sources with ``ast`` (nothing is imported).

An import inside a function is allowed only for a heavy or optional dependency
(:data:`fence_sorter.lazy.HEAVY`, or a fence_sorter module that loads one when imported) and
says why in a ``# lazy: <why>`` comment on the import or on the line above it (one comment may
head a block of consecutive imports). Everything else is imported at the top of its module.
"""

from __future__ import annotations

import ast
from pathlib import Path

import fence_sorter
from fence_sorter.lazy import HEAVY

PACKAGE = Path(fence_sorter.__file__).parent


LAZY_MARK = "# lazy:"


def module_names(root: Path = PACKAGE) -> dict[str, Path]:
    """Dotted module name -> source file, for every module of the package."""
    names = {}
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        names[".".join(parts)] = path
    return names


def import_targets(node: ast.Import | ast.ImportFrom, name: str, path: Path) -> list[str]:
    """Absolute names an import statement of module ``name`` (file ``path``) may load:
    ``from pkg import mod`` the module pkg.mod, ``from mod import f`` mod."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    base = node.module or ""
    if node.level:
        anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
        base = ".".join(anchor + ([base] if base else []))
    return [base] + [f"{base}.{alias.name}" for alias in node.names]


def imported_modules(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The package's modules that ``name`` imports anywhere in its source."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            targets = import_targets(node, name, path)
            found.update(t for t in targets if t in modules and t != name)
    return found


def split_imports(tree: ast.Module) -> tuple[list, list]:
    """(imports run when the module is imported, imports inside functions)."""
    top: list = []
    inner: list = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                (inner if in_function else top).append(child)
            nested = isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            visit(child, in_function or nested)

    visit(tree, False)
    return top, inner


def heavy_modules(root: Path = PACKAGE) -> set[str]:
    """The package's modules whose import loads a :data:`HEAVY` dependency (through their own
    top-level imports, their packages' ``__init__`` or other modules of the package)."""
    modules = module_names(root)
    loads: dict[str, set[str]] = {}
    heavy = set()
    for name, path in modules.items():
        top, _ = split_imports(ast.parse(path.read_text(), str(path)))
        parts = name.split(".")
        loads[name] = {".".join(parts[:i]) for i in range(1, len(parts))} & set(modules)
        for node in top:
            for target in import_targets(node, name, path):
                if target.split(".")[0] in HEAVY:
                    heavy.add(name)
                elif target in modules and target != name:
                    loads[name].update(
                        ".".join(target.split(".")[:i]) for i in range(1, target.count(".") + 2)
                    )
    changed = True
    while changed:
        before = len(heavy)
        heavy.update(n for n, deps in loads.items() if deps & heavy)
        changed = len(heavy) != before
    return heavy


def unjustified_lazy_imports(root: Path = PACKAGE, allowed: set[str] | None = None) -> list[str]:
    """``file:line module`` of every import inside a function that is not of a heavy dependency
    or has no ``# lazy:`` comment on it, on the line above, or on the import block it follows."""
    modules = module_names(root)
    allowed = heavy_modules(root) if allowed is None else allowed
    bad = []
    for name, path in modules.items():
        lines = path.read_text().splitlines()
        _, inner = split_imports(ast.parse("\n".join(lines), str(path)))
        commented: set[int] = set()  # last lines of imports that carry or inherit the comment
        for node in sorted(inner, key=lambda n: n.lineno):
            own = lines[node.lineno - 1 : node.end_lineno]
            above = lines[node.lineno - 2].strip() if node.lineno > 1 else ""
            marked = (
                any(LAZY_MARK in line for line in own)
                or (above.startswith("#") and LAZY_MARK in above)
                or node.lineno - 1 in commented
            )
            targets = import_targets(node, name, path)
            heavy = [t for t in targets if t.split(".")[0] in HEAVY or t in allowed]
            if marked:
                commented.add(node.end_lineno)
            if not heavy or not marked:
                where = path.relative_to(root.parent)
                why = "not a heavy dependency" if not heavy else f"no {LAZY_MARK!r} comment"
                bad.append(f"{where}:{node.lineno} {targets[0]} ({why})")
    return bad


def import_graph() -> dict[str, set[str]]:
    modules = module_names()
    return {name: imported_modules(name, path, modules) for name, path in modules.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_cycle_finder_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(graph) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_relative_and_function_level_imports_are_edges(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "a.py").write_text("def f():\n    from . import b\n")
    (pkg / "sub" / "b.py").write_text("from ..sub.a import f\n")
    modules = module_names(pkg)
    graph = {n: imported_modules(n, p, modules) for n, p in modules.items()}
    assert graph["pkg.sub.a"] == {"pkg.sub", "pkg.sub.b"}
    assert "pkg.sub.a" in graph["pkg.sub.b"]
    assert cycles(graph) == [["pkg.sub.a", "pkg.sub.b"]]


def test_fence_sorter_has_no_import_cycle():
    graph = import_graph()
    assert len(graph) > 50 and "fence_sorter.physics.simulate" in graph
    assert "fence_sorter.physics.stepper" in graph["fence_sorter.physics.simulate"]
    assert cycles(graph) == []


def test_the_lazy_import_check_tells_heavy_and_commented_imports_apart(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "light.py").write_text("import json\n")
    (pkg / "core.py").write_text("import numba\n")
    (pkg / "uses_core.py").write_text("from . import core\n")
    (pkg / "cli.py").write_text(
        "def ok():\n"
        "    import scipy  # lazy: 0.6 s\n"
        "    # lazy: loads Numba\n"
        "    from pkg.uses_core import x\n"
        "    from pkg.core import y\n"
        "def plain():\n"
        "    from pkg import light  # lazy: not heavy\n"
        "def silent():\n"
        "    import rclpy\n"
    )
    assert heavy_modules(pkg) == {"pkg.core", "pkg.uses_core"}
    assert unjustified_lazy_imports(pkg) == [
        "pkg/cli.py:7 pkg (not a heavy dependency)",
        "pkg/cli.py:9 rclpy (no '# lazy:' comment)",
    ]


def test_the_scene_reader_and_the_command_line_are_light():
    heavy = heavy_modules()
    assert "fence_sorter.physics.kernel" in heavy and "fence_sorter.physics.simulate" in heavy
    assert "fence_sorter.scene" not in heavy and "fence_sorter.cli.main" not in heavy


def test_imports_inside_functions_are_heavy_and_say_why():
    assert unjustified_lazy_imports() == []
