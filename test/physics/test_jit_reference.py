"""The kernel's Python reference is its own source run with NUMBA_DISABLE_JIT=1; its cache.

Every bench scene is solved twice with the default adaptive scheme, and a flexible scene with
generalized-alpha: here, compiled by Numba, and in a fresh process with NUMBA_DISABLE_JIT=1,
where every kernel function runs as the plain Python it is written in. The two must take the
same steps and events and agree on every figure of the result to round-off (LLVM may reorder a
few floating-point operations).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from fence_sorter.physics.simulate import simulate
from fence_sorter.scene import load_scene

SCENES = ("positioned_stiff", "arbitrary_stiff", "impact_flexible", "slide_flexible")
# (name, overrides) of every solve compared: the bench scenes as loaded, and generalized-alpha
RUNS = [(name, []) for name in SCENES] + [
    ("impact_flexible", ["solver.method=generalized_alpha", "solver.dt=5e-4"])
]
COUNTS = ("steps", "rejected_steps", "forced_steps", "events", "sorted")
FIGURES = (
    "peak_contact_force",
    "peak_contact_force_stiff",
    "impact_normal_speed",
    "exit_speed_y",
    "y_max",
    "peak_tip_deflection",
    "sim_time",
    "max_penetration",
    "energy_excess",
)

SOLVE = """
import json, sys
import numba
from fence_sorter.physics.simulate import simulate
from fence_sorter.scene import load_scene
assert numba.config.DISABLE_JIT
keys = json.loads(sys.argv[1])
out = []
for name, sets in json.loads(sys.argv[2]):
    r = simulate(load_scene(name, sets).scenario)
    out.append({k: getattr(r, k) for k in keys})
    out[-1]["stages"] = [s for s, _ in r.stages]
print(json.dumps(out))
"""


@pytest.mark.slow
def test_every_bench_scene_and_generalized_alpha_solve_the_same_without_the_jit():
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    proc = subprocess.run(
        [sys.executable, "-c", SOLVE, json.dumps(COUNTS + FIGURES), json.dumps(RUNS)],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    python = json.loads(proc.stdout.strip().splitlines()[-1])
    for (name, sets), ref in zip(RUNS, python, strict=True):
        r = simulate(load_scene(name, sets).scenario)
        assert r.steps > 100 and r.sorted and r.events >= 2, name  # real sorting events
        for key in COUNTS:
            assert getattr(r, key) == ref[key], (name, key)
        assert [s for s, _ in r.stages] == ref["stages"], name
        for key in FIGURES:
            got, want = getattr(r, key), ref[key]
            assert math.isclose(got, want, rel_tol=1e-9, abs_tol=1e-12), (name, key, got, want)


def test_the_kernel_cache_is_keyed_on_every_module_of_the_package(tmp_path, monkeypatch):
    """A change to any module of the kernel (a callee inlined into another module's function)
    names a new cache directory, and the caches of earlier sources are removed."""
    import shutil

    from fence_sorter.physics import kernel as K

    package = tmp_path / "kernel"
    shutil.copytree(Path(K.__file__).parent, package, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    first = K.cache_directory(package)
    assert first == K.cache_directory(package)
    assert first.parent == package / "__pycache__" and first.name.startswith("numba-")
    first.mkdir(parents=True)
    forces = package / "forces.py"
    forces.write_text(forces.read_text() + "\n# a change to a callee\n")
    second = K.cache_directory(package)
    assert second != first and not first.exists()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "user"))
    assert K.cache_directory(package) == tmp_path / "user" / second.name
