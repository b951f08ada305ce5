"""The speed bench's report: its data (:class:`BenchReport`), as JSON and back, and rendered
as docs/benchmarks.md (see :mod:`benchmarks.bench`)."""

from __future__ import annotations

import dataclasses as dc
import math
import types
import typing
from collections.abc import Sequence
from dataclasses import dataclass, field

from benchmarks.bench_baselines import BaselineResult
from benchmarks.bench_children import JitResult, MemoryResult
from benchmarks.bench_parts import PartsResult
from benchmarks.bench_runs import EVENT_SCENES, TARGET_EVENT_S, DefaultResult, Reference, rel_error
from fence_sorter.jsonsafe import json_safe
from fence_sorter.verification.report import table


@dataclass
class BeltProbe:
    """Both references again with ``conveyor.mu_belt = 0`` (no belt friction)."""

    ours_peak: float
    scipy_peak: float

    @property
    def gap(self) -> float:
        return rel_error(self.scipy_peak, self.ours_peak)


@dataclass
class SceneBench:
    scene: str
    ours: Reference
    scipy_ref: Reference
    default: DefaultResult
    baselines: BaselineResult
    parts: PartsResult
    memory: MemoryResult
    belt: BeltProbe | None = None  # when the two references disagree beyond their convergence
    peers: BaselineResult | None = None  # the compiled peers' ladder (None: not run)


@dataclass
class TargetCheck:
    target: str
    scene: str
    measured: str
    limit: str
    verdict: str  # PASS, FAIL, N/A
    note: str = ""


@dataclass
class BenchReport:
    command: str
    started: str
    finished: str
    commit: str
    machine: dict[str, str]
    load_before: str
    load_after: str
    options: dict
    scenes: list[SceneBench]
    jit: JitResult
    process_max_rss_kib: int
    total_wall: float
    targets: list[TargetCheck] = field(default_factory=list)


# -- JSON -----------------------------------------------------------------------------------------
def report_dict(report: BenchReport) -> dict:
    """The report as plain JSON data (derived figures such as medians included)."""
    d = dc.asdict(report)
    for sd, sb in zip(d["scenes"], report.scenes, strict=True):
        df = sd["default"]
        df.update(wall=sb.default.wall, cpu=sb.default.cpu, rtf=sb.default.rtf)
        sd["ours"]["check_change"] = sb.ours.check_change
        sd["scipy_ref"]["check_change"] = sb.scipy_ref.check_change
        sd["scipy_ref"]["distance_to_ours"] = rel_error(sb.scipy_ref.peak, sb.ours.peak)
        for family in ("baselines", "peers"):
            if getattr(sb, family) is None:
                continue
            for key in ("by_ref", "by_self"):
                comp = getattr(getattr(sb, family), key)
                best = comp.best
                sd[family][key]["best"] = (
                    None
                    if best is None
                    else {"method": best.method, "rtol": best.run.rtol, "wall": best.wall}
                )
                sd[family][key]["ratio"] = comp.ratio
        for vd, v in zip(sd["parts"]["variants"], sb.parts.variants, strict=True):
            vd["wall"] = v.wall
    d["jit"].update(
        jit_wall=report.jit.jit_wall, nojit_wall=report.jit.nojit_wall, ratio=report.jit.ratio
    )
    return json_safe(d)


def _from_json(kind, value):
    """``value`` (JSON data) as an instance of the annotated type ``kind``."""
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin in (types.UnionType, typing.Union):
        if value is None:
            return math.nan if float in args else None
        (kind,) = [a for a in args if a is not type(None)]
        return _from_json(kind, value)
    if dc.is_dataclass(kind):
        hints = typing.get_type_hints(kind)
        names = {f.name for f in dc.fields(kind) if f.init}
        return kind(**{k: _from_json(hints[k], v) for k, v in value.items() if k in names})
    if origin is list:
        return [_from_json(args[0], v) for v in value]
    if origin is tuple:
        return tuple(_from_json(args[0], v) for v in value)
    if kind is float:
        return math.nan if value is None else float(value)
    return value


def report_from_dict(data: dict) -> BenchReport:
    """The report back from :func:`report_dict`'s JSON (derived figures are recomputed)."""
    return _from_json(BenchReport, data)


# -- markdown -------------------------------------------------------------------------------------
def _ms(s: float) -> str:
    return "n/a" if not math.isfinite(s) else f"{s * 1e3:.2f}"


def _e(x: float) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.1e}"


def _mib(kib: float) -> str:
    return f"{kib / 1024:.0f}"


def _family_table(sc: Sequence[SceneBench], family: str) -> list[str]:
    """The table of a family's (``baselines``: SciPy, ``peers``: compiled) chosen rungs."""
    L: list[str] = []
    add = L.append
    digits = 1 if family == "peers" else 0  # the compiled peers' ratios are a few x
    rows = []
    for s in sc:
        b = getattr(s, family)
        if b is None:
            continue
        for comp in (b.by_self, b.by_ref):
            which = "SciPy ref." if comp.metric == "self" else "our ref."
            thr = f"<= {comp.threshold:.1e}" + (" (1e-3 target)" if comp.relaxed else "")
            if comp.metric == "self" and not math.isfinite(s.scipy_ref.peak):
                why = f"no SciPy reference ({s.scipy_ref.label} did not finish)"
                rows.append((s.scene, which, "n/a", "all", why, "", "", "", "", ""))
                continue
            for c in comp.choices:
                if c.run is None:
                    best_err = min(
                        (
                            (r.err_self if comp.metric == "self" else r.err_ref)
                            for r in b.runs
                            if r.method == c.method and r.ok
                        ),
                        default=math.nan,
                    )
                    capped = any(r.capped for r in b.runs if r.method == c.method)
                    why = "did not reach"
                    if capped:
                        why += f" (capped at {b.cap:g} s)"
                    if math.isfinite(best_err):
                        why += f"; best error {best_err:.1e}"
                    rows.append((s.scene, which, thr, c.method, why, "", "", "", "", ""))
                    continue
                r = c.run
                err = r.err_self if comp.metric == "self" else r.err_ref
                best = comp.best is c
                nxt = b.next_rung(r)
                if nxt is None:
                    nxt_err = "not run"
                else:
                    e2 = nxt.err_self if comp.metric == "self" else nxt.err_ref
                    nxt_err = _e(e2) if nxt.ok else "failed"
                    if nxt.ok and math.isfinite(e2) and e2 > comp.threshold:
                        nxt_err += " (not sustained)"
                rows.append(
                    (
                        s.scene,
                        which,
                        thr,
                        f"**{c.method}**" if best else c.method,
                        f"rtol {r.rtol:g}",
                        _e(err),
                        nxt_err,
                        f"{r.outcome.steps}",
                        _ms(c.wall),
                        f"{c.wall / s.default.wall:.{digits}f}x"
                        + (f" ({c.note})" if c.note else ""),
                    )
                )
    L += table(
        (
            "scene",
            "error vs",
            "same error",
            "method",
            "loosest rung reaching it",
            "its error",
            "error at the next tighter rung",
            "steps",
            "wall median [ms]",
            "wall / default's",
        ),
        rows,
    )
    add("")
    return L


def render_markdown(rep: BenchReport) -> str:
    sc = rep.scenes
    L: list[str] = []
    add = L.append
    add("# Benchmarks")
    add("")
    add(
        f"Generated by `{rep.command}` (the file is overwritten on every run; nothing here is "
        "edited by hand). Started {start}, finished {end}, {total:.0f} s in all; commit "
        "`{commit}`.".format(
            start=rep.started, end=rep.finished, total=rep.total_wall, commit=rep.commit
        )
    )
    add("")
    add("## Machine")
    add("")
    rows = [(k, v) for k, v in rep.machine.items()]
    rows.append(
        ("load average (1, 5, 15 min)", f"{rep.load_before} before, {rep.load_after} after")
    )
    L += table(("", ""), rows)
    add("")
    add(
        "How the figures are measured and how to read them: "
        "[verification.md](../design/verification.md#benchmarks)."
    )
    add("")

    add("## Targets")
    add("")
    L += table(
        ("target", "scene", "measured", "limit", "verdict", "note"),
        [
            (t.target, t.scene, t.measured, t.limit, f"**{t.verdict}**", t.note)
            for t in rep.targets
        ],
    )
    add("")

    add("## Default configuration per scene")
    add("")
    rows = []
    for s in sc:
        d = s.default
        rows.append(
            (
                s.scene,
                f"{d.method} rtol {d.rtol:g} dt_max {d.dt_max:g}",
                f"{d.outcome.sim_time:.3f}",
                _ms(d.wall),
                _ms(d.cpu),
                f"{d.rtf:.1f}",
                f"{d.rtf_cpu:.1f}",
                f"{d.outcome.steps} / {d.outcome.rejected}",
                f"{d.outcome.peak_force:.6g}",
                f"{s.ours.peak:.6g}",
                _e(d.error),
                _e(d.exit_speed_diff),
                _ms(d.first_call),
                str(len(d.walls)),
            )
        )
    L += table(
        (
            "scene",
            "method",
            "sim time [s]",
            "wall median [ms]",
            "CPU median [ms]",
            "real-time factor",
            "real-time factor on CPU time",
            "steps / rejected",
            "peak N [N]",
            "reference peak N [N]",
            "rel. error",
            "exit speed diff [m/s]",
            "first call in this process [ms]",
            "repeats",
        ),
        rows,
    )
    add("")

    add("## References")
    add("")
    if sc:
        o, r = sc[0].ours, sc[0].scipy_ref
        add(
            f"Our reference: {o.label}, checked at {o.check_label}. SciPy's: {r.label}, "
            f"checked at {r.check_label}."
        )
        add("")
    rows = []
    for s in sc:
        o, r = s.ours, s.scipy_ref
        rows.append(
            (
                s.scene,
                f"{o.peak:.9g}",
                _e(o.check_change),
                f"{o.wall + o.check_wall:.1f}",
                f"{r.peak:.9g}" if math.isfinite(r.peak) else f"failed: {r.diagnosis}",
                _e(r.check_change),
                f"{r.wall + r.check_wall:.1f}",
                _e(rel_error(r.peak, o.peak)),
                _e(s.belt.gap) if s.belt is not None else "not run",
            )
        )
    L += table(
        (
            "scene",
            "our reference peak N [N]",
            "change at dt / 2",
            "wall [s]",
            "SciPy reference peak N [N]",
            "change at rtol / 10",
            "wall [s]",
            "SciPy ref. vs ours",
            "the same with conveyor.mu_belt = 0",
        ),
        rows,
    )
    add("")
    if any(s.peers is not None for s in sc):
        add("## Compiled peers at the same error")
        add("")
        add(
            "CyRK's C++ solvers (`cyrk:*`, fence_sorter/physics/peers.py) on the same compiled "
            "right-hand side, every accepted step observed by the loop's reductions, restarts "
            "at t1 and 2 t1 and at the belt-edge crossing (found from the accepted steps); the "
            "same rtol ladder and search as the SciPy baselines below."
        )
        add("")
        L += _family_table(sc, "peers")
    add("## SciPy baselines at the same error")
    add("")
    add(
        "rtol ladder "
        f"{', '.join(f'{x:g}' for x in rep.options['rtol_ladder'])}; every SciPy run capped at "
        f"{rep.options['scipy_cap_s']:g} s of wall time."
    )
    add("")
    L += _family_table(sc, "baselines")
    add("Every ladder run (one run each; the wall time of a single run):")
    add("")
    rows = []
    for s in sc:
        for r in (*(s.peers.runs if s.peers is not None else ()), *s.baselines.runs):
            state = "capped" if r.capped else ("ok" if r.outcome.success else "failed")
            if r.capped:
                state += f" at t = {r.outcome.sim_time:.3f} s"
            elif not r.outcome.success:
                state += f": {r.outcome.diagnosis}"
            rows.append(
                (
                    s.scene,
                    r.method,
                    f"{r.rtol:g}",
                    f"{r.wall:.3f}",
                    str(r.outcome.steps),
                    _e(r.err_ref),
                    _e(r.err_self),
                    state,
                )
            )
    L += table(
        (
            "scene",
            "method",
            "rtol",
            "wall [s]",
            "steps",
            "error vs our ref.",
            "error vs SciPy ref.",
            "status",
        ),
        rows,
    )
    add("")

    ev = [s for s in sc if s.scene in EVENT_SCENES]
    if ev:
        add("## Stiff-fence events (optimisation inner loop)")
        add("")
        add(
            "One sorting event on the stiff fence, stopped when sorted (as the scenes are "
            "loaded), model build included; the second column records nothing (what an "
            f"optimisation loop needs). Target <= {TARGET_EVENT_S * 1e3:g} ms per event."
        )
        add("")
        rows = []
        for s in ev:
            lean = s.parts.get("leaner")
            rows.append(
                (
                    s.scene,
                    _ms(s.default.wall),
                    _ms(lean.wall) if lean else "n/a",
                    f"{s.default.outcome.steps}",
                    f"{s.default.outcome.sim_time:.3f}",
                    "PASS" if s.default.wall <= TARGET_EVENT_S else "FAIL",
                )
            )
        L += table(
            (
                "scene",
                "ms per event (as loaded)",
                "ms per event (no recording)",
                "steps",
                "sim time [s]",
                "target",
            ),
            rows,
        )
        add("")

    add("## Peak memory")
    add("")
    rows = [
        (
            s.scene,
            f"{s.memory.tracemalloc_peak / 1024:.0f}",
            _mib(s.memory.rss_after_import_kib),
            _mib(s.memory.rss_after_run_kib),
        )
        for s in sc
    ]
    L += table(
        (
            "scene",
            "tracemalloc peak of one run [KiB]",
            "fresh process max RSS after imports [MiB]",
            "... after one event [MiB]",
        ),
        rows,
    )
    add("")
    add(
        f"The bench process itself (every run above, SciPy included; every accepted step "
        f"of a run is observed and the scenes record time series) peaked at "
        f"{_mib(rep.process_max_rss_kib)} MiB resident."
    )
    add("")

    add("## Model parts: what each scene leaves out")
    add("")
    rows = []
    for s in sc:
        built = s.parts.get("built")
        for v in s.parts.variants:
            added = [p for p in v.parts if p not in built.parts]
            dropped = [p for p in built.parts if p not in v.parts]
            diff = " ".join(["+" + p for p in added] + ["-" + p for p in dropped]) or "(built)"
            if v.same_physics:
                physics = "yes"
            elif v.role == "truncated":
                physics = "approximation (fewer modes)"
            else:
                physics = "no (rigid fence -> flexible)"
            rows.append(
                (
                    s.scene,
                    v.label,
                    physics,
                    diff,
                    _ms(v.wall),
                    f"{v.wall / built.wall:.2f}",
                    f"{v.outcome.steps}",
                    f"{v.outcome.peak_force:.6g}",
                    _e(rel_error(v.outcome.peak_force, built.outcome.peak_force)),
                    f"{v.outcome.exit_speed:.6f}",
                    "yes" if v.outcome.sorted else "no",
                )
            )
    L += table(
        (
            "scene",
            "variant",
            "same physics",
            "parts vs built",
            "wall median [ms]",
            "/ built",
            "steps",
            "peak N [N]",
            "peak vs built",
            "exit speed [m/s]",
            "sorted",
        ),
        rows,
    )
    add("")
    rows = []
    for s in sc:
        built, full = s.parts.get("built"), s.parts.get("full")
        if full is None:
            continue
        saved = full.wall - built.wall
        rows.append(
            (
                s.scene,
                _ms(built.wall),
                _ms(full.wall),
                f"{saved * 1e3:+.2f} ms ({saved / full.wall * 100:+.0f} %)",
                _e(rel_error(full.outcome.peak_force, built.outcome.peak_force)),
                _e(abs(full.outcome.exit_speed - built.outcome.exit_speed)),
                "yes" if full.outcome.sorted == built.outcome.sorted else "no",
            )
        )
    if rows:
        add("Built against the full model (nothing left out):")
        add("")
        L += table(
            (
                "scene",
                "built [ms]",
                "full [ms]",
                "time saved by the built model",
                "peak N difference",
                "exit speed difference [m/s]",
                "same sorted outcome",
            ),
            rows,
        )
        add("")

    j = rep.jit
    add("## Compiled kernel: the same code with and without the JIT")
    add("")
    add(
        f"`{j.scene}` with `--set solver.t_end={j.t_end:g}` ({j.steps} steps, "
        f"{j.sim_time:.3f} s simulated), the same script in two fresh processes: one as usual, "
        "one with `NUMBA_DISABLE_JIT=1` (the kernel's functions then run as plain Python, "
        "the code unchanged). Each process makes one untimed first call, then the timed ones."
    )
    add("")
    L += table(
        ("", "JIT (Numba)", "NUMBA_DISABLE_JIT=1"),
        [
            ("wall median [ms]", _ms(j.jit_wall), _ms(j.nojit_wall)),
            ("timed calls", str(len(j.jit_walls)), str(len(j.nojit_walls))),
            (
                "real-time factor",
                f"{j.sim_time / j.jit_wall:.1f}",
                f"{j.sim_time / j.nojit_wall:.2f}",
            ),
            ("peak N [N]", f"{j.jit_peak:.9g}", f"{j.nojit_peak:.9g}"),
        ],
    )
    add("")
    confirmed = (
        "both child processes reported the JIT state asked for"
        if j.jit_child_confirmed
        else "WARNING: the child processes did not report the JIT state asked for"
    )
    add(
        f"Without the JIT the same run takes **{j.ratio:.0f}x** as long ({confirmed}; the peak "
        f"forces differ by {_e(rel_error(j.nojit_peak, j.jit_peak))})."
    )
    if math.isfinite(j.cold_first_call):
        add(
            f"Compilation: the first call of `{j.cold_scene}` (full scene) in a fresh process "
            f"with an empty Numba cache (`NUMBA_CACHE_DIR` pointing to a new directory) took "
            f"{j.cold_first_call:.1f} s, the second {_ms(j.cold_second_call)} ms; with the "
            f"on-disk cache the first call of the shortened run took "
            f"{_ms(j.warm_cache_first_call)} ms."
        )
    else:
        add(
            f"With the on-disk cache the first call of the shortened run took "
            f"{_ms(j.warm_cache_first_call)} ms (cold compilation not measured in this run)."
        )
    add("")

    add(
        "What these figures mean: "
        "[docs/design/verification.md](../design/verification.md#benchmarks)."
    )
    return "\n".join(L).rstrip() + "\n"
