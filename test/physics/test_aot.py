"""The solve loop's ahead-of-time extension (``kernel.aot``) is the JIT's loop, used only when
fresh.

``kernel.solve`` calls the extension built for the current kernel sources (scripts/bootstrap.sh
builds it; this module builds one into a scratch directory when the sources have changed since)
and the JIT dispatcher otherwise. Every bench scene must solve bitwise alike through both; an
extension built from other sources, another Numba or another CPU is never loaded, and
arguments of other types than it was built for go to the JIT.
"""

from __future__ import annotations

import dataclasses
import json
import math
import shutil

import numba
import numpy as np
import pytest

from fence_sorter.physics import kernel as K
from fence_sorter.physics.kernel import aot
from fence_sorter.physics.simulate import simulate
from fence_sorter.scene import load_scene
from fence_sorter.warmup import solve_bench_scenes

SCENES = ("positioned_stiff", "arbitrary_stiff", "impact_flexible", "slide_flexible")

pytestmark = pytest.mark.skipif(numba.config.DISABLE_JIT, reason="compiled code only")


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """(directory, digest) of an extension built from the current sources."""
    entry = K.solve
    directory, digest = entry.directory, entry.digest
    entries, _ = aot.load(directory, digest)
    if not entries:  # sources changed since set-up: build one for them
        directory = tmp_path_factory.mktemp("aot") / directory.name
        entry.entries = []
        solve_bench_scenes()
        aot.build(directory, digest, entry.jit)
        entry.entries = None
    return directory, digest


@pytest.fixture
def entry(built):
    """A fresh ``kernel.solve`` on the built extension, restored afterwards."""
    saved = K.solve
    K.solve = aot.Solve(saved.jit, *built)
    yield K.solve
    K.solve = saved


def same(a, b, where="result") -> None:
    """``a`` and ``b`` bitwise equal (NaN equal to NaN), through dataclasses and containers."""
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            if f.name != "wall_time":
                same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape, where
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), where
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, list | tuple):
        assert len(a) == len(b), where
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            same(x, y, f"{where}[{k}]")
    elif isinstance(a, float) and math.isnan(a):
        assert isinstance(b, float) and math.isnan(b), where
    else:
        assert a == b, (where, a, b)


@pytest.mark.parametrize("scene", SCENES)
def test_the_extension_solves_every_bench_scene_as_the_jit(entry, scene: str) -> None:
    assert entry.resolve(), "the built extension is not loaded"
    sc = load_scene(scene).scenario
    compiled = simulate(sc)
    assert K.solve.entries and not K.solve._said_types  # the extension took every call
    entry.entries = []  # the JIT dispatcher
    jit = simulate(sc)
    assert jit.sorted and jit.steps > 50  # a real sorting event
    same(compiled, jit)


def test_a_stale_extension_is_not_loaded(built, tmp_path) -> None:
    directory, digest = built
    entries, why = aot.load(directory, digest)
    assert entries and why is None
    other = "0" * len(digest)
    entries, why = aot.load(directory, other)
    assert entries == [] and "stale (sources)" in why
    # built for another CPU (or Numba): not loaded either
    copy = tmp_path / directory.name
    shutil.copytree(directory, copy)
    meta = json.loads((copy / aot.BUILD_FILE).read_text())
    meta["key"]["cpu"] = "i386"
    meta["key"]["numba"] = "0.1"
    (copy / aot.BUILD_FILE).write_text(json.dumps(meta))
    entries, why = aot.load(copy, digest)
    assert entries == [] and "stale (numba, cpu)" in why
    assert aot.load(tmp_path / "missing", digest) == (
        [],
        f"no ahead-of-time solve in {tmp_path}/missing",
    )


def test_a_stale_extension_leaves_the_solve_to_the_jit(built, caplog) -> None:
    directory, _ = built
    stale = aot.Solve(K.solve.jit, directory, "0" * 64)
    with caplog.at_level("WARNING", logger="fence_sorter.physics.kernel"):
        assert stale.resolve() == []
    assert "stale (sources)" in caplog.text and "the JIT solves" in caplog.text
    saved = K.solve
    K.solve = stale
    try:
        r = simulate(load_scene("positioned_stiff").scenario)
    finally:
        K.solve = saved
    assert r.sorted and r.steps > 50


def test_arguments_of_other_types_go_to_the_jit(entry) -> None:
    """The extension's wrapper checks little more than item sizes: the entry is chosen only
    for C-contiguous writable arrays of exactly the exported dtypes and dimensions."""
    (model_spec, state_spec, _), *_ = entry.resolve()
    model = tuple(np.zeros((2,) * n, dtype=d) for d, n in model_spec)
    assert aot._fits(model, model_spec)
    counters = state_spec[0]
    assert counters == (K.COUNTERS, 1)  # the loop's integer state, one named record
    state = [np.zeros((2,) * n, dtype=d) for d, n in state_spec]
    assert aot._fits(tuple(state), state_spec)
    for bad in (
        np.zeros(2 * len(K.COUNTERS.names), dtype=np.int64),  # the same bytes, no record
        np.zeros(2, dtype=K.FIGURES),  # another record
        np.zeros(4, dtype=K.COUNTERS)[::2],  # not contiguous
        np.zeros((2, 1), dtype=K.COUNTERS),  # another dimension
    ):
        assert not aot._fits((bad, *state[1:]), state_spec)
    frozen = np.zeros(2, dtype=K.COUNTERS)
    frozen.flags.writeable = False
    assert not aot._fits((frozen, *state[1:]), state_spec)
    assert not aot._fits(tuple(state[:-1]), state_spec)
