"""The package's layers (docs/design/architecture.md): no module imports a layer above its own.

A unit is a subpackage of fence_sorter (``physics``, ``nodes``, ...) or a module at its top
(``scene``, ``codes``, ...). :data:`LAYERS` orders the units bottom to top; a unit may import
its own layer and the layers below, never one above. Every ``import`` counts, also one inside a
function: a lazy import hides a dependency from the interpreter, not from the design. The
graph of units has no cycle either, inside a layer included. The graph is read from the
sources with ``ast`` (nothing is imported).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

from test_import_cycles import PACKAGE, cycles, import_targets, module_names

#: (layer, its units), bottom to top: the order of docs/design/architecture.md's "Layers" block
LAYERS: tuple[tuple[str, frozenset[str]], ...] = (
    (
        "base",
        frozenset(
            {"fence_sorter", "affinity", "codes", "jsonsafe", "lazy", "provenance", "resources"}
            | {"rosdistro", "stamps", "textinput"}
        ),
    ),
    ("physics", frozenset({"physics"})),
    (
        "model",
        frozenset({"inputs", "scene", "stream", "capacity", "recording", "pool", "warmup"}),
    ),
    ("line", frozenset({"line"})),
    (
        "analysis",
        frozenset({"analysis", "calibration", "optimize", "verification", "visualisation"}),
    ),
    ("nodes", frozenset({"nodes"})),
    ("runner", frozenset({"runner"})),
    ("cli", frozenset({"cli"})),
)
#: the layers whose modules may import rclpy and the ROS message packages (nodes and above)
ROS_LAYERS = frozenset({"nodes", "runner", "cli"})
#: rclpy and the ROS message and interface packages (rosbags reads bags without ROS)
ROS_PACKAGES = re.compile(r"^(rclpy|rcl_interfaces|[a-z0-9_]+_msgs)(\.|$)")

ARCHITECTURE = Path(__file__).resolve().parents[1] / "docs" / "design" / "architecture.md"
#: what stands beside the package in the checkout, never imported by it: the campaigns and the
#: tests' helpers (not installed)
OUTSIDE = re.compile(r"^(benchmarks|test|processes|conftest)(\.|$)")


def unit_of(module: str) -> str:
    """``fence_sorter.physics.kernel.loop`` -> ``physics``; ``fence_sorter`` -> itself."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def layer_index(layers=LAYERS) -> dict[str, int]:
    return {unit: i for i, (_, units) in enumerate(layers) for unit in units}


def imports_of(root: Path = PACKAGE) -> list[tuple[str, int, str]]:
    """(importing module's file, line, imported name) of every import in the package, inside
    functions included; the imported name is absolute."""
    modules = module_names(root)
    found = []
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                where = str(path.relative_to(root.parent))
                found += [(where, node.lineno, t) for t in import_targets(node, name, path)]
    return found


def upward_imports(root: Path = PACKAGE, layers=LAYERS) -> list[str]:
    """``file:line unit (layer) -> unit (layer)`` for every import of a higher layer; a unit
    with no layer is named too."""
    modules = module_names(root)
    index = layer_index(layers)
    names = [name for name, _ in layers]
    bad = [f"{unit_of(m)}: no layer" for m in modules if unit_of(m) not in index]
    for where, line, target in imports_of(root):
        if target not in modules:
            continue
        source = unit_of(".".join(Path(where).with_suffix("").parts))
        a, b = index.get(source), index.get(unit_of(target))
        if a is not None and b is not None and b > a:
            bad.append(f"{where}:{line} {source} ({names[a]}) -> {unit_of(target)} ({names[b]})")
    return sorted(set(bad))


def unit_graph(root: Path = PACKAGE) -> dict[str, set[str]]:
    """unit -> the other units it imports."""
    modules = module_names(root)
    graph: dict[str, set[str]] = {unit_of(m): set() for m in modules}
    for where, _, target in imports_of(root):
        if target in modules:
            source = unit_of(".".join(Path(where).with_suffix("").parts))
            if unit_of(target) != source:
                graph[source].add(unit_of(target))
    return graph


def ros_below_nodes(root: Path = PACKAGE, layers=LAYERS) -> list[str]:
    """``file:line package`` of every import of ROS in a layer below the nodes."""
    index = layer_index(layers)
    allowed = {i for i, (name, _) in enumerate(layers) if name in ROS_LAYERS}
    bad = []
    for where, line, target in imports_of(root):
        unit = unit_of(".".join(Path(where).with_suffix("").parts))
        if ROS_PACKAGES.match(target) and index.get(unit) not in allowed:
            bad.append(f"{where}:{line} {target}")
    return sorted(set(bad))


def outside_imports(root: Path = PACKAGE) -> list[str]:
    """``file:line module`` of every import of the checkout's campaigns or test helpers."""
    return sorted({f"{w}:{n} {t}" for w, n, t in imports_of(root) if OUTSIDE.match(t)})


def test_the_layer_check_finds_an_upward_import_inside_a_function(tmp_path):
    pkg = tmp_path / "pkg"
    for sub in ("low", "high"):
        (pkg / sub).mkdir(parents=True)
        (pkg / sub / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "low" / "a.py").write_text("import json\n\ndef f():\n    from pkg.high import b\n")
    (pkg / "high" / "b.py").write_text("from ..low.a import f\nimport rclpy\n")
    (pkg / "stray.py").write_text("")
    layers = (("low", frozenset({"pkg", "low"})), ("high", frozenset({"high"})))
    assert upward_imports(pkg, layers) == [
        "pkg/low/a.py:4 low (low) -> high (high)",
        "stray: no layer",
    ]
    assert unit_graph(pkg)["high"] == {"low"}
    assert cycles(unit_graph(pkg)) == [["high", "low"]]
    assert ros_below_nodes(pkg, layers) == ["pkg/high/b.py:2 rclpy"]
    (pkg / "stray.py").write_text("def f():\n    from benchmarks import bench\n")
    assert outside_imports(pkg) == ["pkg/stray.py:2 benchmarks", "pkg/stray.py:2 benchmarks.bench"]


def test_no_module_imports_a_layer_above_its_own():
    assert len(module_names()) > 50
    assert upward_imports() == []


def test_the_units_import_each_other_without_a_cycle():
    graph = unit_graph()
    assert "physics" in graph["line"] and "nodes" in graph["runner"]
    assert cycles(graph) == []


def test_the_package_imports_neither_the_campaigns_nor_the_tests():
    """benchmarks/ and test/ are not installed: an import of them would fail in an install."""
    assert outside_imports() == []


def test_ros_is_imported_only_from_the_nodes_up():
    assert ros_below_nodes() == []


def test_the_architecture_page_names_the_layers_in_this_order():
    """docs/design/architecture.md's block under "Layers" lists each layer's units, top first."""
    text = ARCHITECTURE.read_text()
    block = text.split("## Layers", 1)[1].split("```", 2)[1]
    rows = [line.split() for line in block.strip().splitlines()]
    documented = [(row[0].rstrip(":"), frozenset(row[1:])) for row in rows]
    assert documented == list(reversed(LAYERS))
