"""The controller's decision table as a sweep: starting strokes (R_s, t1) per load class.

``python -m benchmarks paper-sweep decision-table`` optimises W_t (1) over (R_s, t1) with the belt
speed v and the fence length R_z held at the controller's scene values and alpha_k, the
constraint profile and the ranges of R_s (3) and t1 (5) taken from config/controller.yaml, for
each load class: placement (``positioned``: at the fence-side border, section 4.2;
``arbitrary``: anywhere on the width, section 4.1) x load length A. The table file and its
lookup are :mod:`fence_sorter.capacity.decision_table`; :func:`compare_planner` measures what
the table buys the planner.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass
from pathlib import Path

import yaml

from benchmarks.paper.points import point
from fence_sorter.capacity.decision_table import PLACEMENTS
from fence_sorter.capacity.planner import LoadRequest, Planner, PlannerConfig
from fence_sorter.physics.params import ParameterError
from fence_sorter.scene import load_scene
from fence_sorter.stream import load_stream

#: load lengths A of the table [m] (the default stream draws 0.2-0.5 m; 0.7 m is the paper's
#: limiting load)
TABLE_LENGTHS = (0.2, 0.3, 0.4, 0.5, 0.6, 0.7)
#: load width B of the table's loads [m] (the middle of the default stream's 0.15-0.35 m)
TABLE_WIDTH = 0.2
CONTROLLER_CONFIG = "config/controller.yaml"
CONTROLLER_SCENE = "impact_flexible"  # the controller's default scene


@dataclass(frozen=True)
class ControllerSettings:
    """What the table is built for (SI, alpha_k in deg as in the config)."""

    alpha_k_deg: float
    belt_speed: float
    fence_length: float
    constraints: tuple[int, ...]
    w_dop: float
    a_ndop: float
    ydot_dop: float
    mu1: float
    mu2: float
    r_s_range: tuple[float, float]
    t1_range: tuple[float, float]


def controller_settings(
    config: str | Path = CONTROLLER_CONFIG, scene: str | None = None
) -> ControllerSettings:
    """alpha_k, constraints and ranges from the controller's config; v, R_z, mu from its scene."""
    path = Path(config)
    try:
        data = yaml.safe_load(path.read_text())
        params = data["controller"]["ros__parameters"]
    except (OSError, KeyError, TypeError, yaml.YAMLError) as exc:
        raise ParameterError(
            f"{path}: cannot read controller.ros__parameters ({type(exc).__name__}: {exc})"
        ) from None
    cfg = PlannerConfig.from_mapping(params)
    sc = load_scene(scene or params.get("scene") or CONTROLLER_SCENE).scenario
    return ControllerSettings(
        alpha_k_deg=math.degrees(cfg.alpha_k),
        belt_speed=sc.conveyor.belt_speed,
        fence_length=sc.length,
        constraints=tuple(cfg.profile.active),
        w_dop=cfg.profile.w_dop,
        a_ndop=cfg.profile.a_ndop,
        ydot_dop=cfg.profile.ydot_dop,
        mu1=sc.conveyor.mu_belt,
        mu2=sc.contact.mu_fence,
        r_s_range=(cfg.r_s_min, cfg.r_s_max),
        t1_range=(cfg.t1_min, cfg.t1_max),
    )


def decision_points(settings: ControllerSettings | None = None) -> tuple[dict, ...]:
    """The sweep's points: placement x A, with v and R_z fixed (inputs of points.point)."""
    s = settings or controller_settings()
    return tuple(
        point(
            case=case,
            alpha_k_deg=s.alpha_k_deg,
            w_dop=s.w_dop,
            a_ndop=s.a_ndop,
            exit_speed_limit=s.ydot_dop,
            constraints=" ".join(str(c) for c in s.constraints),
            mu1=s.mu1,
            mu2=s.mu2,
            load_length=a,
            load_width=TABLE_WIDTH,
            fixed=f"v={s.belt_speed!r} R_z={s.fence_length!r}",
            bounds=(
                f"R_s={s.r_s_range[0]!r}:{s.r_s_range[1]!r} t1={s.t1_range[0]!r}:{s.t1_range[1]!r}"
            ),
        )
        for case in PLACEMENTS
        for a in TABLE_LENGTHS
    )


def compare_planner(
    table: str | Path = "config/decision_table.yaml",
    scene: str = CONTROLLER_SCENE,
    stream: str = "config/streams/default.yaml",
    count: int = 200,
    seed: int = 11,
    budget: int = 30,
) -> dict[str, dict[str, float]]:
    """The planner with and without ``table`` on the divert loads of ``count`` parcels of
    ``stream``: each load planned alone from a cold planner (no cache, no hints, no timing
    pressure). Per variant: loads, feasible, mean and median twin evaluations to the first
    feasible stroke, mean W_t (1), loads with a table entry, loads that kept the table's stroke."""
    base = load_scene(scene).scenario
    loads = [
        s
        for s in load_stream(stream, base.conveyor.belt_speed, count=count, seed=seed)
        if s.divert
    ]
    out = {}
    for label, cfg in (
        ("without", PlannerConfig()),
        ("with", PlannerConfig(decision_table=str(table))),
    ):
        planner = Planner(base, cfg)
        evals, w_t, feasible, entries, kept = [], [], 0, 0, 0
        for s in loads:
            planner.cache.clear()
            planner.chosen.clear()
            planner.record.clear()
            req = LoadRequest(s.parcel_id, s.to_parcel_params(), 0.0, -3.0)
            cand = planner.table_candidate(req, 0.0)
            plan = planner.plan(req, 0.0, commit=False, budget=budget, use_hint=False)
            evals.append(plan.evaluations)
            if plan.feasible:
                feasible += 1
                w_t.append(plan.evaluation.capacity_pcs_h)
            if cand is not None:
                entries += 1
                kept += plan.feasible and (plan.evaluation.r_s, plan.evaluation.t1) == cand
        out[label] = {
            "loads": len(loads),
            "feasible": feasible,
            "evaluations_mean": statistics.mean(evals),
            "evaluations_median": statistics.median(evals),
            "W_t_mean": statistics.mean(w_t) if w_t else math.nan,
            "table_entries": entries,
            "table_stroke_kept": kept,
        }
    return out


if __name__ == "__main__":  # python -m benchmarks.paper.decision
    for name, figures in compare_planner().items():
        print(name, " ".join(f"{k}={v:.4g}" for k, v in figures.items()))


__all__ = [
    "ControllerSettings",
    "compare_planner",
    "controller_settings",
    "decision_points",
]
