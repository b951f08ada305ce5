"""The model-parts probe of the speed bench: the scene as built against variants that leave
nothing out, interleaved (see :mod:`benchmarks.bench`)."""

from __future__ import annotations

import dataclasses as dc
from dataclasses import dataclass

from benchmarks.bench_runs import (
    STIFF_FEM_MODULUS,
    TRUNCATED_MODES,
    Log,
    Outcome,
    _median,
    _quiet,
    build_model,
    collect,
    timed_run,
)
from fence_sorter.physics.params import FenceParams
from fence_sorter.physics.scenario import RECORDABLE


# -- model parts ----------------------------------------------------------------------------------
@dataclass
class PartsVariant:
    label: str
    role: str  # "built", "leaner", "fuller", "full", "truncated"
    same_physics: bool
    parts: tuple[str, ...]
    walls: list[float]
    outcome: Outcome

    @property
    def wall(self) -> float:
        return _median(self.walls)


@dataclass
class PartsResult:
    scene: str
    variants: list[PartsVariant]
    note: str = ""

    def get(self, role: str) -> PartsVariant | None:
        return next((v for v in self.variants if v.role == role), None)


def parts_variants(sc) -> list[tuple[str, str, bool, object, bool]]:
    """(label, role, same physics, scenario, force border) of the model-parts comparison."""
    md = build_model(sc)
    out = [("as built (the scene)", "built", True, sc, False)]
    if sc.record:
        out.append(("no time series recorded", "leaner", True, dc.replace(sc, record=()), False))
    full_sc, full_border, fuller = sc, False, []
    if set(sc.record) != set(RECORDABLE):
        rec = dc.replace(sc, record=RECORDABLE)
        out.append(("+ every time series recorded", "fuller", True, rec, False))
        full_sc = dc.replace(full_sc, record=RECORDABLE)
        fuller.append("records")
    if not md.use_border:
        out.append(("+ border contact forced on", "fuller", True, sc, True))
        full_border = True
        fuller.append("border")
    if sc.fence is None:
        fp = FenceParams(length=sc.fence_length, youngs_modulus=STIFF_FEM_MODULUS)
        fem = dc.replace(sc, fence=fp, fence_modes=None)
        label = f"+ FEM fence E = {STIFF_FEM_MODULUS:g} Pa, all modes"
        out.append((label, "fuller", False, fem, False))
        full_sc = dc.replace(full_sc, fence=fp, fence_modes=None)
        fuller.append("fem")
    elif sc.fence_modes is not None:
        out.append(("+ every fence mode", "fuller", True, dc.replace(sc, fence_modes=None), False))
        full_sc = dc.replace(full_sc, fence_modes=None)
        fuller.append("modes")
    if len(fuller) > 1:
        same = sc.fence is not None
        out.append(("full model (nothing left out)", "full", same, full_sc, full_border))
    elif fuller:
        label, _, same, s, b = out[-1]
        out[-1] = (label + " = full model", "full", same, s, b)
    if sc.fence is not None:
        n = TRUNCATED_MODES
        if md.n_modes > n:
            label = f"fence.modes = {n} (truncated; not the scene's choice)"
            out.append((label, "truncated", False, dc.replace(sc, fence_modes=n), False))
    return out


def model_parts(sc, repeats: int, log: Log = _quiet) -> PartsResult:
    """Time the variants round-robin (``repeats`` rounds) and keep each one's outcome."""
    specs = parts_variants(sc)
    walls: list[list[float]] = [[] for _ in specs]
    outcomes: list[Outcome | None] = [None] * len(specs)
    for _, _, _, s, b in specs:  # warm-up (a new model shape can need a cache load)
        timed_run(s, b)
    collect()
    n = len(specs)
    for k in range(repeats):
        for i in [(k + j) % n for j in range(n)]:  # rotated: no variant always runs first
            _, _, _, s, b = specs[i]
            o, w, _ = timed_run(s, b)
            walls[i].append(w)
            outcomes[i] = o
    variants = [
        PartsVariant(label, role, same, outcomes[i].parts, walls[i], outcomes[i])
        for i, (label, role, same, _, _) in enumerate(specs)
    ]
    for v in variants:
        log(f"  {v.label:52s} {v.wall * 1e3:9.2f} ms  peak {v.outcome.peak_force:.6g} N")
    return PartsResult(scene="", variants=variants)
