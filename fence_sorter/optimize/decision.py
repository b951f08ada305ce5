"""The controller's decision table: starting strokes (R_s, t1) per load class from optima.

``fence-sorter optimize --sweep decision-table`` optimises W_t (1) over (R_s, t1) with the belt
speed v and the fence length R_z held at the controller's scene values and alpha_k, the
constraint profile and the ranges of R_s (3) and t1 (5) taken from config/controller.yaml, for
each load class: placement (``positioned``: at the fence-side border, section 4.2;
``arbitrary``: anywhere on the width, section 4.1) x load length A. :func:`build_table` turns
those rows into ``config/decision_table.yaml``; the planner (``PlannerConfig.decision_table``)
tries the entry of a load's class first and verifies it on the twin like any candidate.

A load's class: ``positioned`` if its lateral gap is at most ``positioned_max_gap`` and its
yaw at most ``positioned_max_yaw_deg``, else ``arbitrary``; the entry is the one of the shortest
tabulated A at least as long as the load's footprint along the belt (the longest if none is).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import yaml

from fence_sorter.physics.params import ParameterError
from fence_sorter.resources import find_data

#: load lengths A of the table [m] (the default stream draws 0.2-0.5 m; 0.7 m is the paper's
#: limiting load)
TABLE_LENGTHS = (0.2, 0.3, 0.4, 0.5, 0.6, 0.7)
#: load width B of the table's loads [m] (the middle of the default stream's 0.15-0.35 m)
TABLE_WIDTH = 0.2
PLACEMENTS = ("positioned", "arbitrary")
POSITIONED_MAX_GAP = 0.05  # [m]
POSITIONED_MAX_YAW_DEG = 5.0
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
    from fence_sorter.capacity.planner import PlannerConfig
    from fence_sorter.scene import load_scene

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
    """The sweep's points: placement x A, with v and R_z fixed (inputs of sweep.point)."""
    from fence_sorter.optimize.sweep import point

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


def _fixed(row: Mapping, name: str) -> float:
    for item in str(row["fixed"]).split():
        key, _, value = item.partition("=")
        if key == name:
            return float(value)
    raise ValueError(
        f"decision-table row {row.get('key')}: {name} is not fixed ({row['fixed']!r})"
    )


def build_table(rows: Sequence[Mapping], source: str = "") -> dict:
    """The YAML document of the table from the decision sweep's rows (feasible optima only).

    All rows must share alpha_k, v and R_z (ValueError otherwise)."""
    if not rows:
        raise ValueError("no rows: run fence-sorter optimize --sweep decision-table first")
    alphas = {float(r["alpha_k_deg"]) for r in rows}
    speeds = {_fixed(r, "v") for r in rows}
    lengths = {_fixed(r, "R_z") for r in rows}
    if len(alphas) != 1 or len(speeds) != 1 or len(lengths) != 1:
        raise ValueError(
            f"rows mix settings: alpha_k {sorted(alphas)} deg, v {sorted(speeds)} m/s, "
            f"R_z {sorted(lengths)} m; one table is for one alpha_k and belt speed"
        )
    classes = []
    for r in sorted(rows, key=lambda r: (PLACEMENTS.index(r["case"]), r["load_length"])):
        if not r["feasible"]:
            continue
        classes.append(
            {
                "placement": str(r["case"]),
                "length_max": float(r["load_length"]),
                "R_s": round(float(r["R_s"]), 4),
                "t1": round(float(r["t1"]), 4),
                "W_t": round(float(r["W_t"]), 1),
            }
        )
    return {
        "decision_table": {
            "source": source,
            "alpha_k_deg": alphas.pop(),
            "belt_speed": speeds.pop(),
            "fence_length": lengths.pop(),
            "constraints": [int(c) for c in str(rows[0]["constraints"]).split()],
            "positioned_max_gap": POSITIONED_MAX_GAP,
            "positioned_max_yaw_deg": POSITIONED_MAX_YAW_DEG,
            "classes": classes,
        }
    }


def write_table(table: Mapping, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    head = (
        "# The controller's starting strokes per load class (fence_sorter/optimize/decision.py).\n"
        "# Generated by `fence-sorter optimize --sweep decision-table`; do not edit by hand.\n"
        "# R_s [m], t1 [s] maximise W_t (1) [pcs/h] at alpha_k and belt speed below, for a load\n"
        "# up to length_max [m] along the belt; the planner verifies each on the twin.\n"
    )
    path.write_text(head + yaml.safe_dump(dict(table), sort_keys=False))
    return path


@dataclass(frozen=True)
class DecisionTable:
    """A loaded table: the stroke to try first for a load."""

    alpha_k: float  # [rad]
    belt_speed: float  # [m/s]
    positioned_max_gap: float  # [m]
    positioned_max_yaw: float  # [rad]
    entries: tuple[tuple[str, float, float, float], ...]  # (placement, length_max, R_s, t1)
    path: str = ""

    @classmethod
    def load(cls, path: str | Path, prefix: str = "controller.decision_table") -> DecisionTable:
        """Read a table file (a path, or one of the package's as "config/decision_table.yaml");
        ParameterError naming the file and what is wrong."""
        p = find_data("config", path, (".yaml",)) or Path(path)
        try:
            doc = yaml.safe_load(p.read_text())["decision_table"]
            entries = tuple(
                (str(c["placement"]), float(c["length_max"]), float(c["R_s"]), float(c["t1"]))
                for c in doc["classes"]
            )
            table = cls(
                alpha_k=math.radians(float(doc["alpha_k_deg"])),
                belt_speed=float(doc["belt_speed"]),
                positioned_max_gap=float(doc.get("positioned_max_gap", POSITIONED_MAX_GAP)),
                positioned_max_yaw=math.radians(
                    float(doc.get("positioned_max_yaw_deg", POSITIONED_MAX_YAW_DEG))
                ),
                entries=entries,
                path=str(p),
            )
        except OSError as exc:
            raise ParameterError(f"{prefix}: cannot read {p}: {exc.strerror or exc}") from None
        except (KeyError, TypeError, ValueError, yaml.YAMLError) as exc:
            raise ParameterError(
                f"{prefix}: {p} is not a decision table (needs decision_table: alpha_k_deg, "
                f"belt_speed, classes of placement, length_max, R_s, t1): "
                f"{type(exc).__name__}: {exc}"
            ) from None
        bad = [e for e in entries if e[0] not in PLACEMENTS or not all(map(math.isfinite, e[1:]))]
        if bad:
            raise ParameterError(
                f"{prefix}: {p}: class {bad[0]} must have placement one of "
                f"{', '.join(PLACEMENTS)} and finite length_max, R_s, t1"
            )
        return table

    def check(self, alpha_k: float, belt_speed: float, prefix: str) -> DecisionTable:
        """ParameterError unless the table was built for this alpha_k and belt speed."""
        if abs(alpha_k - self.alpha_k) > 1e-9 or abs(belt_speed - self.belt_speed) > 1e-9:
            raise ParameterError(
                f"{prefix}: {self.path} is for alpha_k {math.degrees(self.alpha_k):g} deg and "
                f"belt speed {self.belt_speed:g} m/s, the controller runs "
                f"{math.degrees(alpha_k):g} deg and {belt_speed:g} m/s; rebuild it with "
                "fence-sorter optimize --sweep decision-table"
            )
        return self

    def placement(self, lateral_gap: float, yaw: float) -> str:
        positioned = lateral_gap <= self.positioned_max_gap and abs(yaw) <= self.positioned_max_yaw
        return "positioned" if positioned else "arbitrary"

    def lookup(self, length: float, lateral_gap: float, yaw: float) -> tuple[float, float] | None:
        """(R_s, t1) for a load of footprint ``length`` along the belt, or None (no entry)."""
        rows = sorted(
            (e for e in self.entries if e[0] == self.placement(lateral_gap, yaw)),
            key=lambda e: e[1],
        )
        if not rows:
            return None
        for _, length_max, r_s, t1 in rows:
            if length <= length_max + 1e-9:
                return (r_s, t1)
        return (rows[-1][2], rows[-1][3])


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
    import statistics

    from fence_sorter.capacity.planner import LoadRequest, Planner, PlannerConfig
    from fence_sorter.scene import load_scene
    from fence_sorter.stream import load_stream

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


if __name__ == "__main__":  # python -m fence_sorter.optimize.decision
    for name, figures in compare_planner().items():
        print(name, " ".join(f"{k}={v:.4g}" for k, v in figures.items()))


__all__ = [
    "ControllerSettings",
    "DecisionTable",
    "build_table",
    "compare_planner",
    "controller_settings",
    "decision_points",
    "write_table",
]
