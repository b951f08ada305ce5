"""Line files: a YAML description of a sortation line (several fence units on one conveyor).

A line names the conveyor (width, speed, length from the induction scan line), the induction
(a stream of ``config/streams``, destination shares, a no-read share), the fence units (position
of the fence axis along the belt, side of the belt the fence stands on, a scene for its fence,
drive, contact and solver with per-unit overrides, the destinations its chute serves, an
optional chute capacity), the planner settings the units' controllers share, and the
recirculation loop (transit time back to the induction, maximal passes, the reject chute).

Global frame "line": X along the belt from the induction scan line, Y across the belt from the
right border (0) to the left border (s). A unit on the right has its fence axis at (position, 0)
and its local frame is the paper's O x0 y0 shifted by ``position``; a unit on the left is its
mirror image (axis at (position, s), local y0 = s - Y, yaw and C_s offsets across the belt
negated). Every problem raises :class:`LineError` (a ParameterError) ``line <file>: <key> ...``
naming the key and its allowed range, so the command line prints one line and exits 2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from fence_sorter.capacity.planner import PlannerConfig
from fence_sorter.physics.params import ParameterError
from fence_sorter.physics.scenario import Scenario
from fence_sorter.resources import ResourceNotFound, data_path, find_data
from fence_sorter.scene import LoadedScene, SceneError, load_scene
from fence_sorter.stream.model import StreamConfig, StreamError, resolve_stream
from fence_sorter.textinput import TextInputError, keyed_mapping, load_yaml, read_text

__all__ = ["LineError", "LineSpec", "UnitSpec", "load_line", "UNIT_LEAD", "UNIT_TAIL"]

#: a unit's zone starts this far upstream of its fence axis: its scan line, where the unit
#: takes a parcel and plans (the single-unit line's scan line, x0 = -2 m) [m]
UNIT_LEAD = 2.0
#: a unit's zone ends this far downstream of its fence axis (the single-unit line's end) [m]
UNIT_TAIL = 3.0
SIDES = ("right", "left")

TOP_KEYS = ("name", "description", "conveyor", "induction", "planner", "units", "recirculation")
CONVEYOR_KEYS = ("width", "speed", "length")
INDUCTION_KEYS = ("stream", "no_read_share", "destinations", "merge_gap", "min_gap")
UNIT_KEYS = ("name", "position", "side", "scene", "overrides", "destinations", "chute_capacity")
RECIRC_KEYS = ("transit_time", "max_passes", "reject_chute")
PLANNER_KEYS = (*PlannerConfig.FLOAT_KEYS, "max_evaluations", "active_constraints")


class LineError(ParameterError):
    """A line file is invalid; the message names the file and the dotted key."""


@dataclass(frozen=True)
class UnitSpec:
    """One fence unit: where it stands, its physics (a scene's Scenario) and what it serves."""

    name: str
    position: float  # X of the fence axis [m]
    side: str  # "right" (axis at Y = 0) or "left" (axis at Y = s, mirrored)
    scene: str
    scenario: Scenario  # the scene with the line's conveyor and the unit's overrides
    destinations: tuple[str, ...]
    chute_capacity: int | None = None  # None: unlimited

    @property
    def mirrored(self) -> bool:
        return self.side == "left"

    @property
    def zone(self) -> tuple[float, float]:
        """[X of the unit's scan line, X where a parcel leaves the unit's zone] [m]."""
        return self.position - UNIT_LEAD, self.position + UNIT_TAIL


@dataclass(frozen=True)
class LineSpec:
    """A validated line (SI units; the file's degrees converted)."""

    name: str
    description: str
    source_path: Path
    width: float  # s [m]
    speed: float  # v [m/s]
    length: float  # belt length from the induction scan line [m]
    stream: StreamConfig
    no_read_share: float
    destinations: dict[str, float]  # destination -> share of the stream (sum 1)
    merge_gap: float  # rear-to-front gap a returning parcel needs on both sides [m]
    planner: PlannerConfig
    units: tuple[UnitSpec, ...]  # in belt order
    transit_time: float  # recirculation loop, line end to the induction [s]
    max_passes: int  # a parcel not sorted after this many passes goes to the reject chute
    reject_chute: str
    #: a gapping induction: a new parcel is held until its front is this far behind the rear of
    #: the parcel ahead [m] (0: the stream as drawn)
    min_gap: float = 0.0

    def serving(self, destination: str) -> list[UnitSpec]:
        return [u for u in self.units if destination in u.destinations]


# -- helpers -----------------------------------------------------------------------------------
def _err(src: str, msg: str) -> LineError:
    return LineError(f"line {src}: {msg}")


def _mapping(src: str, key: str, data: Any, allowed: tuple[str, ...]) -> dict:
    try:
        return keyed_mapping(data, key, allowed)
    except TextInputError as exc:
        raise _err(src, str(exc)) from None


def _number(src: str, key: str, value: Any, lo: float, hi: float, unit: str, lo_open=False):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _err(src, f"{key} must be a number, got {value!r}")
    ok = (lo < value if lo_open else lo <= value) and value <= hi
    if not ok:
        left = "(" if lo_open else "["
        raise _err(src, f"{key} must be in {left}{lo:g}, {hi:g}] {unit}, got {value!r}".rstrip())
    return float(value)


def _int(src: str, key: str, value: Any, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise _err(src, f"{key} must be an integer in [{lo}, {hi}], got {value!r}")
    return int(value)


def _str(src: str, key: str, value: Any) -> str:
    if not isinstance(value, str) or not value.strip():
        raise _err(src, f"{key} must be a non-empty string, got {value!r}")
    return value.strip()


def resolve_line(path_or_name: str | Path) -> Path:
    found = find_data("config/lines", path_or_name, (".yaml", ".yml"))
    if found is not None:
        return found
    raise LineError(f"line {path_or_name}: file not found (nor a line in config/lines)")


def _controller_defaults() -> dict:
    """The controller's planner settings of config/controller.yaml (the units' defaults)."""
    try:
        raw = load_yaml(read_text(data_path("config", "controller.yaml")))
    except (ResourceNotFound, TextInputError):
        return {}
    return dict(raw.get("controller", {}).get("ros__parameters", {}))


# -- sections ----------------------------------------------------------------------------------
def _induction(src: str, data: Any, width: float, speed: float):
    d = _mapping(src, "induction", data, INDUCTION_KEYS)
    stream_name = _str(src, "induction.stream", d.get("stream", "default"))
    try:
        path = resolve_stream(stream_name)
        if path.suffix.lower() == ".csv":
            raise _err(src, "induction.stream must be a stream config (YAML), not a manifest")
        stream = StreamConfig.from_yaml(path)
    except StreamError as exc:
        raise _err(src, f"induction.stream: {exc}") from None
    stream = replace(stream, belt_width=width)
    no_read = _number(src, "induction.no_read_share", d.get("no_read_share", 0.0), 0.0, 1.0, "")
    dests = d.get("destinations")
    if not isinstance(dests, dict) or not dests:
        raise _err(
            src, "induction.destinations must be a mapping destination: share (shares sum to 1)"
        )
    shares: dict[str, float] = {}
    for k, v in dests.items():
        name = _str(src, "induction.destinations", str(k))
        shares[name] = _number(src, f"induction.destinations.{k}", v, 0.0, 1.0, "", lo_open=True)
    total = sum(shares.values())
    if abs(total - 1.0) > 1e-6:
        raise _err(src, f"induction.destinations: the shares must sum to 1, got {total:.6g}")
    merge_gap = _number(src, "induction.merge_gap", d.get("merge_gap", 0.3), 0.0, 10.0, "m")
    min_gap = _number(src, "induction.min_gap", d.get("min_gap", 0.0), 0.0, 10.0, "m")
    return stream, no_read, shares, merge_gap, min_gap


def _planner(src: str, data: Any) -> PlannerConfig:
    d = _mapping(src, "planner", data, PLANNER_KEYS)
    merged = {**_controller_defaults(), **d}
    try:
        return PlannerConfig.from_mapping(merged, prefix="planner")
    except ParameterError as exc:
        raise _err(src, str(exc)) from None


def _unit(src: str, i: int, data: Any, width: float, speed: float) -> UnitSpec:
    key = f"units[{i}]"
    d = _mapping(src, key, data, UNIT_KEYS)
    name = _str(src, f"{key}.name", d.get("name", f"unit_{i + 1}"))
    if "position" not in d:
        raise _err(src, f"{key}.position is required (X of the fence axis along the belt, m)")
    position = _number(src, f"{key}.position", d["position"], 0.0, 1e4, "m")
    side = d.get("side", "right")
    if side not in SIDES:
        raise _err(src, f"{key}.side must be one of {', '.join(SIDES)}, got {side!r}")
    scene = _str(src, f"{key}.scene", d.get("scene", "impact_flexible"))
    over = d.get("overrides") or {}
    if not isinstance(over, dict):
        raise _err(src, f"{key}.overrides must be a mapping dotted.key: value, got {over!r}")
    sets = [f"conveyor.belt_speed={speed!r}", f"conveyor.width={width!r}"]
    for k, v in over.items():
        if str(k).startswith("conveyor."):
            raise _err(
                src, f"{key}.overrides.{k}: the line's conveyor section sets the belt, not a unit"
            )
        sets.append(f"{k}={'true' if v is True else 'false' if v is False else v}")
    try:
        loaded: LoadedScene = load_scene(scene, sets)
    except SceneError as exc:
        raise _err(src, f"{key}: {exc}") from None
    dests = d.get("destinations")
    if not isinstance(dests, list) or not dests:
        raise _err(src, f"{key}.destinations must be a non-empty list of destination names")
    dests_t = tuple(_str(src, f"{key}.destinations", str(x)) for x in dests)
    cap = d.get("chute_capacity")
    cap = None if cap is None else _int(src, f"{key}.chute_capacity", cap, 1, 10**9)
    return UnitSpec(name, position, side, scene, loaded.scenario, dests_t, cap)


# -- entry point -------------------------------------------------------------------------------
def load_line(path_or_name: str | Path) -> LineSpec:
    """Load and validate a line file; raise LineError naming the offending key."""
    path = resolve_line(path_or_name)
    src = path.name
    try:
        raw = load_yaml(read_text(path))
    except TextInputError as exc:
        raise _err(src, str(exc)) from None
    raw = _mapping(src, "line", raw, TOP_KEYS) if raw is not None else {}
    name = _str(src, "name", raw.get("name", path.stem))
    description = str(raw.get("description", "")).strip()
    conv = _mapping(src, "conveyor", raw.get("conveyor"), CONVEYOR_KEYS)
    width = _number(src, "conveyor.width", conv.get("width", 0.7), 0.1, 3.0, "m")
    speed = _number(src, "conveyor.speed", conv.get("speed", 1.0), 0.0, 10.0, "m/s", lo_open=True)
    if "length" not in conv:
        raise _err(src, "conveyor.length is required (belt length from the induction, m)")
    length = _number(src, "conveyor.length", conv["length"], 0.0, 1e4, "m", lo_open=True)
    stream, no_read, shares, merge_gap, min_gap = _induction(
        src, raw.get("induction"), width, speed
    )
    planner = _planner(src, raw.get("planner"))
    units_raw = raw.get("units")
    if not isinstance(units_raw, list) or not units_raw:
        raise _err(src, "units must be a non-empty list of fence units")
    units = sorted(
        (_unit(src, i, u, width, speed) for i, u in enumerate(units_raw)), key=lambda u: u.position
    )
    names = [u.name for u in units]
    for n in names:
        if names.count(n) > 1:
            raise _err(src, f"units: the name {n!r} is used twice; unit names must be unique")
    for u in units:
        lo, hi = u.zone
        if lo < 0.0 or hi > length:
            raise _err(
                src,
                f"units.{u.name}.position must be in [{UNIT_LEAD:g}, {length - UNIT_TAIL:g}] m "
                f"(its zone, {UNIT_LEAD:g} m before to {UNIT_TAIL:g} m after the axis, must lie "
                f"on the belt of conveyor.length {length:g} m), got {u.position:g}",
            )
        for dest in u.destinations:
            if dest not in shares:
                raise _err(
                    src,
                    f"units.{u.name}.destinations: {dest!r} is not a destination of the "
                    f"induction; allowed: {', '.join(shares)}",
                )
    for a, b in zip(units, units[1:], strict=False):
        if b.zone[0] < a.zone[1]:
            raise _err(
                src,
                f"units.{b.name}.position overlaps units.{a.name}: zones [{a.zone[0]:g}, "
                f"{a.zone[1]:g}] and [{b.zone[0]:g}, {b.zone[1]:g}] m; it must be >= "
                f"{a.position + UNIT_LEAD + UNIT_TAIL:g} m",
            )
    served = {d for u in units for d in u.destinations}
    for dest in shares:
        if dest not in served:
            raise _err(
                src, f"induction.destinations.{dest}: no unit serves it (add it to a unit's "
                "destinations or drop it)",
            )  # fmt: skip
    rec = _mapping(src, "recirculation", raw.get("recirculation"), RECIRC_KEYS)
    transit = _number(
        src, "recirculation.transit_time", rec.get("transit_time", 30.0), 0.0, 1e5, "s"
    )
    passes = _int(src, "recirculation.max_passes", rec.get("max_passes", 3), 1, 15)
    reject = _str(src, "recirculation.reject_chute", rec.get("reject_chute", "reject"))
    if reject in shares:
        raise _err(src, f"recirculation.reject_chute {reject!r} must not be a destination")
    return LineSpec(
        name, description, path.resolve(), width, speed, length, stream, no_read, shares,
        merge_gap, planner, tuple(units), transit, passes, reject, min_gap,
    )  # fmt: skip
