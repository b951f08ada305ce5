"""The solve loop compiled ahead of time: an extension module, so a first solve skips Numba.

The first call of a Numba dispatcher in a process costs ~0.3-1 s even when its machine code
is cached: ~80 % is Numba's one-time set-up of its typing and target registries
(``BaseContext.refresh``), the rest loading and linking the cached object code
(docs/design/numerics.md, "Start-up of a process"). An extension module built by ``numba.pycc``
from the same source loads in a few milliseconds and calls no dispatcher.

:func:`build` (``python -m fence_sorter.warmup``, which scripts/bootstrap.sh runs once
per change of the physics) solves the bench scenes with the
JIT, takes the signatures ``loop.solve`` was compiled for (the types of the ``LoopModel`` and
``LoopState`` fields as the engine passes them) and exports one entry per signature, compiled
for this machine's CPU. The extension lives beside Numba's cache in a directory named after
the same hash of the kernel's sources (:func:`kernel.source_digest`), with a ``build.json``
saying what it was built from; :func:`load` takes it only when sources, Numba, Python and CPU
all match. :class:`Solve` (``kernel.solve``) calls it when the arguments have exactly the
exported types and the JIT dispatcher otherwise, saying so once in the log; under
NUMBA_DISABLE_JIT=1 it is the Python function itself, and FENCE_SORTER_AOT=0 leaves the
extension unused (to measure the JIT).

``numba.pycc`` is pending deprecation in Numba (a NumbaPendingDeprecationWarning on use; the
announced replacement is not released); the build silences that one warning, nothing at run
time imports it.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import json
import logging
import os
import platform
import shutil
import tempfile
import warnings
from pathlib import Path

import llvmlite.binding as ll
import numba
import numpy as np
from numba.np.numpy_support import as_dtype

from .layout import CONTACT, COUNTERS, FIGURES, PARAMS, RECORDED, RESULT, SETTINGS

MODULE = "solve_aot"  # the extension's module name (its PyInit_ symbol)
BUILD_FILE = "build.json"
SEEN = 8  # argument pairs whose entry ``Solve.entry`` remembers
log = logging.getLogger("fence_sorter.physics.kernel")


def host_cpu() -> str:
    """The CPU model the extension is compiled for (LLVM's name, as Numba's JIT uses)."""
    return ll.get_host_cpu_name()


def build_key(digest: str) -> dict:
    """What a built extension must match to be used: sources, Numba, Python, CPU."""
    return {
        "sources": digest,
        "numba": numba.__version__,
        "python": platform.python_version(),
        "cpu": host_cpu(),
    }


def aot_directory(cache: Path) -> Path:
    """The extension's directory beside Numba's cache directory ``numba-<hash>``."""
    return cache.with_name("aot-" + cache.name.removeprefix("numba-"))


# the record dtypes by name, for build.json (a structured dtype's str() does not parse back)
RECORDS = {
    "PARAMS": PARAMS,
    "SETTINGS": SETTINGS,
    "COUNTERS": COUNTERS,
    "FIGURES": FIGURES,
    "CONTACT": CONTACT,
    "RESULT": RESULT,
    "RECORDED": RECORDED,
}


def _dtype_name(dtype: np.dtype) -> str:
    for name, record in RECORDS.items():
        if dtype == record:
            return name
    return str(dtype)


def _dtype(name: str) -> np.dtype:
    return RECORDS[name] if name in RECORDS else np.dtype(name)


def _spec(numba_type) -> tuple:
    """Per field of a (named) tuple argument: (dtype, ndim) of its C-contiguous array."""
    fields = []
    for t in numba_type:
        if not (isinstance(t, numba.types.Array) and t.layout == "C" and t.mutable):
            raise TypeError(f"solve's AOT entry takes C-contiguous writable arrays, not {t}")
        fields.append((as_dtype(t.dtype), t.ndim))
    return tuple(fields)


def _describe(sig) -> dict:
    """A JSON form of one signature of ``loop.solve``: the named tuples' field specs."""
    model, state, attempts, target = sig
    if (str(attempts), str(target)) != ("int64", "float64"):
        raise TypeError(f"solve's scalar arguments are ({attempts}, {target})")
    return {
        name: [[_dtype_name(d), n] for d, n in _spec(t)]
        for name, t in (("model", model), ("state", state))
    }


def build(directory: Path, digest: str, jit, verbose: bool = False) -> Path:
    """Compile the extension into ``directory`` (replaced whole, atomically), one entry per
    signature the dispatcher ``jit`` (``loop.solve``) has compiled; returns the directory."""
    signatures = list(jit.signatures)
    if not signatures:
        raise RuntimeError("loop.solve has no compiled signature to export: solve first")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", numba.NumbaPendingDeprecationWarning)
        from numba.pycc import CC  # lazy: Numba's ahead-of-time compiler, only to compile

        cc = CC(MODULE)
        cc.target_cpu = host_cpu()
        cc.verbose = verbose
        entries = []

        def entry(model, state, max_attempts, t_target):
            # a call of the dispatcher's own compilation (``_nrt=False``: the exported function
            # itself is compiled with Numba's reference counting, which would cost the loop
            # ~40 %), so the extension runs the JIT's machine code
            return jit(model, state, max_attempts, t_target)

        for k, sig in enumerate(signatures):
            cc.export(f"solve_{k}", jit.overloads[sig].signature)(entry)
            entries.append({"name": f"solve_{k}", **_describe(sig)})
        directory.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=directory.name + ".", dir=directory.parent))
        try:
            cc.output_dir = str(tmp)
            cc.compile()
            meta = {"key": build_key(digest), "file": cc.output_file, "entries": entries}
            (tmp / BUILD_FILE).write_text(json.dumps(meta, indent=1))
            old = directory.with_name(directory.name + ".old")
            if directory.exists():
                os.replace(directory, old)
            os.replace(tmp, directory)
            shutil.rmtree(old, ignore_errors=True)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    return directory


def load(directory: Path, digest: str) -> tuple[list, str | None]:
    """The extension's entries ``[(spec of model, spec of state, function)]`` when the one in
    ``directory`` was built from these sources for this Numba, Python and CPU; else ``[]`` and
    the reason."""
    try:
        meta = json.loads((directory / BUILD_FILE).read_text())
    except (OSError, ValueError):
        return [], f"no ahead-of-time solve in {directory}"
    want = build_key(digest)
    stale = [k for k in want if meta.get("key", {}).get(k) != want[k]]
    if stale:
        return [], f"the ahead-of-time solve in {directory} is stale ({', '.join(stale)})"
    path = directory / meta["file"]
    try:
        loader = importlib.machinery.ExtensionFileLoader(MODULE, str(path))
        spec = importlib.util.spec_from_file_location(MODULE, path, loader=loader)
        module = importlib.util.module_from_spec(spec)
        loader.exec_module(module)
    except (ImportError, OSError) as exc:
        return [], f"the ahead-of-time solve {path} does not load: {exc}"
    entries = []
    for e in meta["entries"]:
        model = tuple((_dtype(d), n) for d, n in e["model"])
        state = tuple((_dtype(d), n) for d, n in e["state"])
        entries.append((model, state, getattr(module, e["name"])))
    return entries, None


def _fits(value, spec) -> bool:
    """``value`` is a tuple of C-contiguous writable arrays of the spec's dtypes and ndims."""
    if len(value) != len(spec):
        return False
    for a, (dtype, ndim) in zip(value, spec, strict=True):
        if type(a) is not np.ndarray or a.dtype != dtype or a.ndim != ndim:
            return False
        flags = a.flags
        if not (flags.c_contiguous and flags.writeable):
            return False
    return True


class Solve:
    """``kernel.solve(model, state, max_attempts, t_target)``: the ahead-of-time entry whose
    types the arguments have, the JIT dispatcher ``jit`` otherwise (and always under
    NUMBA_DISABLE_JIT=1). The extension is looked up on the first call."""

    def __init__(self, jit, directory: Path, digest: str):
        self.jit = jit
        self.directory = directory
        self.digest = digest
        self.entries: list | None = None if not numba.config.DISABLE_JIT else []
        self._said_types = False
        self._seen: dict[tuple[int, int], tuple] = {}  # ``entry``'s checked pairs

    def resolve(self) -> list:
        """Load the extension (once); logs once why the JIT solves when it cannot."""
        if self.entries is None:
            if os.environ.get("FENCE_SORTER_AOT", "1") == "0":
                self.entries, why = [], "FENCE_SORTER_AOT=0"
            else:
                self.entries, why = load(self.directory, self.digest)
            if why:
                log.warning(
                    "%s: the JIT solves (its first call in a process costs ~0.3-1 s; "
                    "python -m fence_sorter.warmup builds it)",
                    why,
                )
        return self.entries

    def entry(self, model, state):
        """The function that solves these ``model`` and ``state`` tuples (called with an int
        ``max_attempts`` and a float ``t_target``): the ahead-of-time entry of their types, else
        the JIT dispatcher. Their ~30 arrays are checked once per pair of tuples (~7 us): the
        last SEEN pairs are remembered (held, so their ids are not reused while remembered),
        for a caller that solves with the same tuples again (``stepper.Stepper`` reuses its
        loop model per scenario and its loop states)."""
        entries = self.entries if self.entries is not None else self.resolve()
        key = (id(model), id(state))
        hit = self._seen.get(key)
        if hit is not None and hit[0] is model and hit[1] is state and hit[2] is entries:
            return hit[3]
        for model_spec, state_spec, aot_fn in entries:
            if _fits(model, model_spec) and _fits(state, state_spec):
                fn = aot_fn
                break
        else:
            fn = self._jit_entry()
        if len(self._seen) >= SEEN:
            self._seen.clear()
        self._seen[key] = (model, state, entries, fn)
        return fn

    def _jit_entry(self):
        """The JIT dispatcher, for arguments without an ahead-of-time entry (said once)."""
        if self.resolve() and not self._said_types:
            self._said_types = True
            log.info("solve's arguments have no ahead-of-time entry: the JIT solves them")
        return self.jit

    def __call__(self, model, state, max_attempts, t_target):
        if type(max_attempts) is int and type(t_target) is float:
            fn = self.entry(model, state)
        else:
            fn = self._jit_entry()
        return fn(model, state, max_attempts, t_target)
