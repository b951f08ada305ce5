"""Scene files: a YAML description of one sorting event, loaded into a physics Scenario.

A scene names the conveyor, the fence (``type: flexible`` FEM beam or ``type: stiff``), the
drive, the load, the contact law, the solver and which time series to record. Angles are in
degrees here (``alpha_k_deg``, ``yaw_deg``) and converted to radians for the physics core.
Every problem (unknown key, wrong type, value out of range, bad ``--set`` override, missing
file, YAML syntax error) raises :class:`SceneError` (a :class:`ParameterError`) with the message
``scene <file>: <dotted.key> ...``, so the command line can print one line and exit.

This module is ROS-free; a bare scene name is looked up in ``config/scenes`` of the checkout or
of the installed share directory (:mod:`fence_sorter.resources`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import yaml

from fence_sorter.physics.params import (
    MAX_ELEMENTS,
    PROFILES,
    ContactParams,
    ConveyorParams,
    DriveParams,
    FenceParams,
    ParameterError,
    ParcelParams,
    SolverParams,
)
from fence_sorter.physics.scenario import RECORDABLE, Scenario
from fence_sorter.resources import ResourceNotFound, data_path, find_data
from fence_sorter.textinput import TextInputError, keyed_mapping, load_yaml, read_text

__all__ = [
    "DEFAULT_SCENE",
    "LoadedScene",
    "SceneError",
    "available_scenes",
    "load_scene",
    "resolve_scene",
    "scene_dirs",
    "scene_text",
]

#: the scene of a run, and of every node, when none is named (config/scenes/)
DEFAULT_SCENE = "impact_flexible"


class SceneError(ParameterError):
    """A scene file or an override is invalid; the message names the file and the dotted key."""


# -- schema ------------------------------------------------------------------------------------
# Type tags: "float" (int or float, numeric strings such as 1e-4 accepted because YAML 1.1
# reads them as strings), "int", "bool", "str", "modes" (positive int or "all"), "record".
FLOAT, INT, BOOL, STR = "float", "int", "bool", "str"
TYPE_TEXT = {
    FLOAT: "a number",
    INT: "an integer",
    BOOL: "a boolean (true/false)",
    STR: "a string",
    "modes": 'a positive integer or "all"',
    "record": f"a list of names from {', '.join(RECORDABLE)}",
}

CONVEYOR_KEYS = {"belt_speed": FLOAT, "width": FLOAT, "mu_belt": FLOAT, "gravity": FLOAT}
FENCE_COMMON_KEYS = {"type": STR, "length": FLOAT}
FENCE_FLEXIBLE_KEYS = {
    "height": FLOAT,
    "root_thickness": FLOAT,
    "profile": STR,
    "youngs_modulus": FLOAT,
    "poisson_ratio": FLOAT,
    "density": FLOAT,
    "elements": INT,
    "damping_ratio": FLOAT,
    "modes": "modes",
}
FENCE_TYPES = ("flexible", "stiff")
DRIVE_KEYS = {"alpha_k_deg": FLOAT, "t1": FLOAT, "r_s": FLOAT}
PARCEL_KEYS = {
    "length_a": FLOAT,
    "width_b": FLOAT,
    "height": FLOAT,
    "mass": FLOAT,
    "cog_offset_x": FLOAT,
    "cog_offset_y": FLOAT,
    "lateral_gap": FLOAT,
    "yaw_deg": FLOAT,
    "cog": STR,
}
COG_SHORTCUTS = ("centre", "rear", "front")
CONTACT_KEYS = {
    "b_p": FLOAT,
    "k_p": FLOAT,
    "mu_fence": FLOAT,
    "v_min": FLOAT,
    "phidot_min": FLOAT,
    "deep_penetration": FLOAT,
}
_SOLVER_TYPES = {bool: BOOL, int: INT, float: FLOAT, str: STR}
SOLVER_KEYS = {
    f.name: _SOLVER_TYPES[type(getattr(SolverParams(), f.name))] for f in fields(SolverParams)
}
SECTIONS: dict[str, dict[str, str]] = {
    "conveyor": CONVEYOR_KEYS,
    "fence": {**FENCE_COMMON_KEYS, **FENCE_FLEXIBLE_KEYS},
    "drive": DRIVE_KEYS,
    "parcel": PARCEL_KEYS,
    "contact": CONTACT_KEYS,
    "solver": SOLVER_KEYS,
}
TOP_LEVEL_KEYS = {"name": STR, "description": STR, **dict.fromkeys(SECTIONS, "section")}
TOP_LEVEL_KEYS["record"] = "record"

_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


@dataclass(frozen=True)
class LoadedScene:
    """A validated scene: the Scenario plus its name, description and non-fatal warnings."""

    scenario: Scenario
    name: str
    description: str
    warnings: tuple[str, ...]
    source_path: Path


# -- locating scene files ----------------------------------------------------------------------
def scene_dirs() -> list[Path]:
    """Directories searched for a bare scene name: config/scenes of the checkout or the share."""
    try:
        return [data_path("config", "scenes")]
    except ResourceNotFound:
        return []


def available_scenes() -> list[str]:
    """Names of the shipped scenes (file stems), sorted."""
    names: set[str] = set()
    for d in scene_dirs():
        if d.is_dir():
            names.update(p.stem for p in d.glob("*.yaml"))
    return sorted(names)


def resolve_scene(path_or_name: str | Path) -> Path:
    """The scene file for a path, or for a bare name in the scene directories."""
    text = str(path_or_name)
    found = find_data("config/scenes", path_or_name, (".yaml", ".yml"))
    if found is not None:
        return found
    p = Path(text)
    if isinstance(path_or_name, Path) or p.suffix in (".yaml", ".yml") or "/" in text:
        raise SceneError(f"scene {text}: file not found")
    where = ", ".join(str(d) for d in scene_dirs()) or "no scene directory found"
    avail = ", ".join(available_scenes()) or "none"
    raise SceneError(
        f"scene {text}: no such file or shipped scene (looked in {where}); available: {avail}"
    )


# -- value checks ------------------------------------------------------------------------------
def _err(src: str, msg: str) -> SceneError:
    return SceneError(f"scene {src}: {msg}")


def _allowed(keys) -> str:
    return ", ".join(keys)


def _coerce(src: str, key: str, value: Any, kind: str) -> Any:
    """Check ``value`` against the type tag; return it converted (numeric strings to float)."""
    bad = False
    if kind == FLOAT:
        if isinstance(value, str) and _NUMBER.match(value.strip()):
            value = float(value)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            bad = True
        else:
            value = float(value)
    elif kind == INT:
        bad = isinstance(value, bool) or not isinstance(value, int)
    elif kind == BOOL:
        bad = not isinstance(value, bool)
    elif kind == STR:
        bad = not isinstance(value, str)
    elif kind == "modes":
        if isinstance(value, str) and value.strip().lower() == "all":
            value = "all"
        else:
            bad = isinstance(value, bool) or not isinstance(value, int)
    elif kind == "record":
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            bad = True
        else:
            unknown = [v for v in value if v not in RECORDABLE]
            if unknown:
                raise _err(
                    src,
                    f"{key}: unknown entr{'y' if len(unknown) == 1 else 'ies'} "
                    f"{', '.join(map(repr, unknown))}; allowed: {_allowed(RECORDABLE)}",
                )
            value = list(dict.fromkeys(value))
    if bad:
        raise _err(src, f"{key} must be {TYPE_TEXT[kind]}, got {type(value).__name__} {value!r}")
    return value


def _check_keys(src: str, prefix: str, data: Any, allowed: Mapping[str, str]) -> dict:
    """``data`` must be a mapping with keys from ``allowed``; return the coerced values."""
    try:
        data = keyed_mapping(data, prefix, allowed)
    except TextInputError as exc:
        raise _err(src, str(exc)) from None
    return {k: _coerce(src, f"{prefix}.{k}", v, allowed[k]) for k, v in data.items()}


def _wrap(src: str, fn, *args, **kwargs):
    """Call a validate(); re-raise ValueError as SceneError with the file in the message."""
    try:
        return fn(*args, **kwargs)
    except ValueError as exc:
        raise _err(src, str(exc)) from None


# -- overrides ---------------------------------------------------------------------------------
def _apply_overrides(src: str, raw: dict, overrides: Sequence[str]) -> set[str]:
    """Apply ``key=value`` overrides to the raw mapping in place; return the overridden keys."""
    done: set[str] = set()
    for item in overrides:
        if "=" not in item:
            raise _err(src, f"--set {item!r} must have the form key=value (e.g. parcel.mass=50)")
        key, _, text = item.partition("=")
        key = key.strip()
        try:
            value = load_yaml(text) if text.strip() else None
        except TextInputError as exc:
            raise _err(src, f"--set {key}: cannot parse value {text!r}: {exc}") from None
        parts = key.split(".")
        if len(parts) == 1 and parts[0] in TOP_LEVEL_KEYS and parts[0] not in SECTIONS:
            raw[parts[0]] = value
        elif len(parts) == 2 and parts[0] in SECTIONS and parts[1] in SECTIONS[parts[0]]:
            section = raw.get(parts[0])
            if section is None:
                section = raw[parts[0]] = {}
            if not isinstance(section, dict):
                raise _err(src, f"{parts[0]} must be a mapping, got {section!r}")
            section[parts[1]] = value
        else:
            if len(parts) == 2 and parts[0] in SECTIONS:
                allowed = [f"{parts[0]}.{k}" for k in SECTIONS[parts[0]]]
            else:
                allowed = [k for k in TOP_LEVEL_KEYS if k not in SECTIONS] + [
                    f"{s}.<key>" for s in SECTIONS
                ]
            raise _err(
                src, f"--set {key}: {key} is not a known key; allowed keys: {_allowed(allowed)}"
            )
        done.add(key)
    return done


# -- sections ----------------------------------------------------------------------------------
def _fence(src: str, data: Any, overridden: set[str]):
    """Return (FenceParams or None, stiff length, modes or None)."""
    if data is None:
        data = {}
    if isinstance(data, dict) and "type" not in data:
        raise _err(src, f"fence.type is required; one of {', '.join(FENCE_TYPES)}")
    vals = _check_keys(src, "fence", data, SECTIONS["fence"])
    kind = vals["type"]
    if kind not in FENCE_TYPES:
        raise _err(src, f"fence.type must be one of {', '.join(FENCE_TYPES)}, got {kind!r}")
    if kind == "stiff":
        extra = [k for k in vals if k not in FENCE_COMMON_KEYS]
        if "fence.type" in overridden:
            # --set fence.type=stiff on a flexible scene: drop the file's flexible-only keys,
            # but still reject flexible-only keys given as overrides.
            extra = [k for k in extra if f"fence.{k}" in overridden]
        if extra:
            raise _err(
                src,
                f"fence.{extra[0]} is only valid for type: flexible "
                f"(a stiff fence accepts only: {_allowed(FENCE_COMMON_KEYS)})",
            )
        length = vals.get("length", Scenario().fence_length)
        if not 0.0 < length <= 10.0:
            raise _err(src, f"fence.length must be in (0, 10] m, got {length!r}")
        return None, length, None
    modes = vals.pop("modes", "all")
    vals.pop("type")
    if "profile" in vals and vals["profile"] not in PROFILES:
        raise _err(
            src, f"fence.profile must be one of {', '.join(PROFILES)}, got {vals['profile']!r}"
        )
    fp = FenceParams(**vals)
    _wrap(src, fp.validate)
    if modes == "all":
        modes = None
    elif not 1 <= modes <= 2 * fp.elements:
        raise _err(
            src,
            f'fence.modes must be in [1, {2 * fp.elements}] (2 x fence.elements) or "all", '
            f"got {modes!r}",
        )
    assert fp.elements <= MAX_ELEMENTS
    return fp, fp.length, modes


def _parcel(src: str, vals: dict, belt_width: float) -> ParcelParams:
    vals = dict(vals)
    cog = vals.pop("cog", None)
    if cog is not None:
        explicit = [k for k in ("cog_offset_x", "cog_offset_y") if k in vals]
        if explicit:
            raise _err(
                src,
                f"parcel.cog and parcel.{explicit[0]} are both given; use the cog shortcut "
                "or explicit offsets, not both",
            )
        if cog not in COG_SHORTCUTS:
            raise _err(src, f"parcel.cog must be one of {', '.join(COG_SHORTCUTS)}, got {cog!r}")
        defaults = ParcelParams()
        a = vals.get("length_a", defaults.length_a)
        b = vals.get("width_b", defaults.width_b)
        # Fig. 2a: C_s on the rear corner on the fence side; Fig. 2b: the front corner.
        vals["cog_offset_x"] = {"centre": 0.0, "rear": -0.5 * a, "front": 0.5 * a}[cog]
        vals["cog_offset_y"] = 0.0 if cog == "centre" else -0.5 * b
    if "yaw_deg" in vals:
        yaw_deg = vals.pop("yaw_deg")
        if not -90.0 <= yaw_deg <= 90.0:
            raise _err(src, f"parcel.yaw_deg must be in [-90, 90] deg, got {yaw_deg!r}")
        vals["yaw"] = math.radians(yaw_deg)
    pp = ParcelParams(**vals)
    _wrap(src, pp.validate, belt_width=belt_width)
    return pp


def _drive(src: str, vals: dict) -> DriveParams:
    vals = dict(vals)
    if "alpha_k_deg" in vals:
        deg = vals.pop("alpha_k_deg")
        if not 0.0 < deg <= 90.0:
            raise _err(src, f"drive.alpha_k_deg must be in (0, 90] deg, got {deg!r}")
        vals["alpha_k"] = math.radians(deg)
    dp = DriveParams(**vals)
    _wrap(src, dp.validate)
    return dp


# -- entry point -------------------------------------------------------------------------------
def load_scene(path_or_name: str | Path, overrides: Sequence[str] = ()) -> LoadedScene:
    """Load, override and validate a scene; raise SceneError naming the offending key."""
    path = resolve_scene(path_or_name)
    src = path.name
    try:
        raw = load_yaml(read_text(path))
    except TextInputError as exc:
        raise _err(src, str(exc)) from None
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise _err(src, f"the top level must be a mapping, got {type(raw).__name__}")
    for k in raw:
        if k not in TOP_LEVEL_KEYS:
            raise _err(
                src, f"{k} is not a known top-level key; allowed keys: {_allowed(TOP_LEVEL_KEYS)}"
            )
    overridden = _apply_overrides(src, raw, overrides)

    name = _coerce(src, "name", raw.get("name", path.stem), STR)
    description = _coerce(src, "description", raw.get("description", ""), STR).strip()
    record = tuple(_coerce(src, "record", raw.get("record") or [], "record"))

    conveyor = ConveyorParams(**_check_keys(src, "conveyor", raw.get("conveyor"), CONVEYOR_KEYS))
    warnings = _wrap(src, conveyor.validate)
    fence, length, modes = _fence(src, raw.get("fence"), overridden)
    drive = _drive(src, _check_keys(src, "drive", raw.get("drive"), DRIVE_KEYS))
    parcel = _parcel(
        src, _check_keys(src, "parcel", raw.get("parcel"), PARCEL_KEYS), conveyor.width
    )
    contact = ContactParams(**_check_keys(src, "contact", raw.get("contact"), CONTACT_KEYS))
    _wrap(src, contact.validate)
    solver_vals = _check_keys(src, "solver", raw.get("solver"), SOLVER_KEYS)
    if "dt" in solver_vals and "min_dt" not in solver_vals:
        solver_vals["min_dt"] = min(SolverParams().min_dt, solver_vals["dt"])
    solver = SolverParams(**solver_vals)
    _wrap(src, solver.validate)

    scenario = Scenario(
        conveyor=conveyor,
        parcel=parcel,
        drive=drive,
        contact=contact,
        solver=solver,
        fence=fence,
        fence_length=length,
        fence_modes=modes,
        record=record,
    )
    return LoadedScene(
        scenario=scenario,
        name=name,
        description=description,
        warnings=tuple(warnings),
        source_path=path.resolve(),
    )


def scene_text(path_or_name: str | Path, overrides: Sequence[str]) -> str:
    """The YAML of a scene with ``key=value`` overrides applied, for processes that read the
    scene by path: it loads to the Scenario of ``load_scene(path_or_name, overrides)``.
    SceneError names a bad override."""
    loaded = load_scene(path_or_name, overrides)
    path = loaded.source_path
    raw = load_yaml(read_text(path)) or {}
    overridden = _apply_overrides(path.name, raw, overrides)
    fence = raw.get("fence")
    if "fence.type" in overridden and isinstance(fence, dict) and fence.get("type") == "stiff":
        # as load_scene does: a flexible scene set stiff drops its flexible-only keys
        raw["fence"] = {k: v for k, v in fence.items() if k in FENCE_COMMON_KEYS}
    raw["name"] = loaded.name
    note = f"# {path.name} with --set {' --set '.join(overrides)}\n"
    return note + yaml.safe_dump(raw, sort_keys=False)
