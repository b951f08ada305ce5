"""Parcel streams (ROS-free): seeded random streams from distributions, CSV manifests.

A stream is a list of :class:`ParcelSpec`, each with the time its front crosses the scan line
(``arrival_time``, seconds after the stream starts). Random streams come from a YAML config
(``config/streams/*.yaml``, a ``stream:`` mapping); manifests are CSV files with a header.
Every problem raises :class:`StreamError` naming the file, the field (or line and column) and
the allowed range. Angles are degrees in files (``yaw_deg``) and radians here.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from fence_sorter.inputs import InputError, ParcelSpec, validate_parcel
from fence_sorter.physics.params import ParameterError
from fence_sorter.resources import find_data
from fence_sorter.textinput import TextInputError, load_yaml, read_text

#: the stream of a run and of the scanner when none is named (config/streams/)
DEFAULT_STREAM = "default"


class StreamError(ParameterError):
    """A stream config, manifest or parcel is invalid; the message names where and why."""


def check_parcel(spec: ParcelSpec, belt_width: float, where: str) -> ParcelSpec:
    """The one parcel validation (:func:`fence_sorter.inputs.validate_parcel`) as a
    StreamError that says where; returns ``spec``."""
    try:
        validate_parcel(spec, belt_width)
    except InputError as exc:
        raise StreamError(f"{where}.{exc}") from None
    return spec


# -- distributions -----------------------------------------------------------------------------
DIST_KINDS = {
    "constant": ("value",),
    "uniform": ("low", "high"),
    "normal": ("mean", "std"),
    "lognormal": ("median", "sigma"),
    "choice": ("values",),
}


@dataclass(frozen=True)
class Distribution:
    """A scalar distribution; ``low``/``high`` truncate normal and lognormal (resampling)."""

    kind: str
    params: dict = field(default_factory=dict)
    low: float = -math.inf
    high: float = math.inf

    @classmethod
    def parse(cls, name: str, spec: Any) -> Distribution:
        if isinstance(spec, bool):
            raise StreamError(f"{name} must be a number or a distribution mapping, got {spec!r}")
        if isinstance(spec, (int, float)):
            return cls("constant", {"value": float(spec)})
        if not isinstance(spec, Mapping) or "dist" not in spec:
            raise StreamError(
                f"{name} must be a number or a mapping with dist: one of "
                f"{', '.join(DIST_KINDS)}, got {spec!r}"
            )
        kind = spec["dist"]
        if kind not in DIST_KINDS:
            raise StreamError(f"{name}.dist must be one of {', '.join(DIST_KINDS)}, got {kind!r}")
        need = DIST_KINDS[kind]
        allowed = {"dist", *need, "low", "high", "weights"}
        for k in spec:
            if k not in allowed:
                raise StreamError(
                    f"{name}.{k} is not a known key; allowed: {', '.join(sorted(allowed))}"
                )
        params = {}
        for k in need:
            if k not in spec:
                raise StreamError(f"{name}.{k} is required for dist {kind}")
            params[k] = spec[k]
        if kind == "choice":
            vals = params["values"]
            if not isinstance(vals, list) or not vals:
                raise StreamError(f"{name}.values must be a non-empty list, got {vals!r}")
            w = spec.get("weights")
            if w is not None:
                if (
                    not isinstance(w, list)
                    or len(w) != len(vals)
                    or any(not isinstance(x, (int, float)) or x < 0 for x in w)
                    or sum(w) <= 0
                ):
                    raise StreamError(
                        f"{name}.weights must be {len(vals)} non-negative numbers with a "
                        f"positive sum, got {w!r}"
                    )
                params["weights"] = [x / sum(w) for x in w]
        else:
            for k in need:
                if isinstance(params[k], bool) or not isinstance(params[k], (int, float)):
                    raise StreamError(f"{name}.{k} must be a number, got {params[k]!r}")
                params[k] = float(params[k])
        if kind == "uniform" and not params["low"] <= params["high"]:
            raise StreamError(
                f"{name}: uniform low ({params['low']:g}) must not exceed high "
                f"({params['high']:g})"
            )
        if kind == "normal" and not params["std"] >= 0.0:
            raise StreamError(f"{name}.std must be in [0, inf), got {params['std']:g}")
        if kind == "lognormal" and not (params["median"] > 0.0 and params["sigma"] >= 0.0):
            raise StreamError(
                f"{name}: lognormal median must be in (0, inf) and sigma in [0, inf)"
            )
        low = float(spec.get("low", -math.inf)) if kind in ("normal", "lognormal") else -math.inf
        high = float(spec.get("high", math.inf)) if kind in ("normal", "lognormal") else math.inf
        if low > high:
            raise StreamError(f"{name}: low ({low:g}) must not exceed high ({high:g})")
        return cls(kind, params, low, high)

    def sample(self, rng: np.random.Generator) -> float:
        p = self.params
        if self.kind == "constant":
            return float(p["value"])
        if self.kind == "uniform":
            return float(rng.uniform(p["low"], p["high"]))
        if self.kind == "choice":
            return p["values"][int(rng.choice(len(p["values"]), p=p.get("weights")))]
        for _ in range(100):
            if self.kind == "normal":
                x = float(rng.normal(p["mean"], p["std"]))
            else:
                x = float(p["median"] * math.exp(rng.normal(0.0, p["sigma"])))
            if self.low <= x <= self.high:
                return x
        return min(max(x, self.low), self.high)


# -- stream config -----------------------------------------------------------------------------
PARCEL_FIELDS = (
    "length_a",
    "width_b",
    "height",
    "mass",
    "cog_offset_x",
    "cog_offset_y",
    "lateral_gap",
    "yaw_deg",
    "mu_belt",
    "mu_fence",
)
REQUIRED_PARCEL_FIELDS = ("length_a", "width_b", "height", "mass")
HEADWAYS = ("regular", "poisson")


@dataclass(frozen=True)
class StreamConfig:
    """A random stream: parcel distributions, spacing (rate or gap), share to divert."""

    name: str
    seed: int
    parcel: dict[str, Distribution]
    rate_pcs_h: float | None = 2400.0  # mean arrival rate; None: spacing from ``gap``
    headway: str = "regular"
    gap: Distribution | None = None  # rear-to-front gap [m] when rate_pcs_h is None
    min_gap: float = 0.2  # smallest rear-to-front gap [m]
    divert_share: float = 0.5
    belt_width: float = 0.7
    source: str = "<config>"

    @classmethod
    def from_mapping(cls, data: Any, source: str = "<config>") -> StreamConfig:
        def err(msg: str) -> StreamError:
            return StreamError(f"stream {source}: {msg}")

        if not isinstance(data, Mapping) or "stream" not in data:
            raise err("must contain a 'stream:' mapping")
        s = data["stream"]
        allowed = {
            "name",
            "seed",
            "rate_pcs_h",
            "headway",
            "gap",
            "min_gap",
            "divert_share",
            "belt_width",
            "parcel",
        }
        if not isinstance(s, Mapping):
            raise err("stream must be a mapping")
        for k in s:
            if k not in allowed:
                raise err(f"stream.{k} is not a known key; allowed: {', '.join(sorted(allowed))}")

        def num(key: str, default, lo: float, hi: float, unit: str = "", lo_open=False):
            v = s.get(key, default)
            if v is None:
                return None
            if (
                isinstance(v, bool)
                or not isinstance(v, (int, float))
                or not math.isfinite(v)
                or not ((v > lo if lo_open else v >= lo) and v <= hi)
            ):
                b = "(" if lo_open else "["
                raise err(
                    f"stream.{key} must be in {b}{lo:g}, {hi:g}] {unit}".rstrip() + f", got {v!r}"
                )
            return float(v)

        seed = s.get("seed", 0)
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise err(f"stream.seed must be an integer in [0, inf), got {seed!r}")
        headway = s.get("headway", "regular")
        if headway not in HEADWAYS:
            raise err(f"stream.headway must be one of {', '.join(HEADWAYS)}, got {headway!r}")
        rate = num("rate_pcs_h", None if "gap" in s else 2400.0, 0.0, 1e6, "pcs/h", lo_open=True)
        gap = None
        if "gap" in s:
            if rate is not None:
                raise err("give either stream.rate_pcs_h or stream.gap, not both")
            try:
                gap = Distribution.parse("stream.gap", s["gap"])
            except StreamError as exc:
                raise err(str(exc)) from None
        parcel = s.get("parcel")
        if not isinstance(parcel, Mapping):
            raise err("stream.parcel must be a mapping of distributions")
        dists = {}
        for k, spec in parcel.items():
            if k not in PARCEL_FIELDS:
                raise err(
                    f"stream.parcel.{k} is not a known key; allowed: {', '.join(PARCEL_FIELDS)}"
                )
            try:
                dists[k] = Distribution.parse(f"stream.parcel.{k}", spec)
            except StreamError as exc:
                raise err(str(exc)) from None
        missing = [k for k in REQUIRED_PARCEL_FIELDS if k not in dists]
        if missing:
            raise err(f"stream.parcel.{missing[0]} is required")
        return cls(
            name=str(s.get("name", Path(source).stem)),
            seed=seed,
            parcel=dists,
            rate_pcs_h=rate,
            headway=headway,
            gap=gap,
            min_gap=num("min_gap", 0.2, 0.0, 100.0, "m"),
            divert_share=num("divert_share", 0.5, 0.0, 1.0),
            belt_width=num("belt_width", 0.7, 0.05, 5.0, "m"),
            source=source,
        )

    def at_rate(self, rate_pcs_h: float) -> StreamConfig:
        """This stream's parcel mix arriving at ``rate_pcs_h`` [pcs/h] (a gap spacing dropped;
        headway and min_gap kept)."""
        if not (math.isfinite(rate_pcs_h) and rate_pcs_h > 0.0):
            raise StreamError(
                f"stream {self.source}: rate must be in (0, inf) pcs/h, got {rate_pcs_h!r}"
            )
        return replace(self, rate_pcs_h=float(rate_pcs_h), gap=None)

    @classmethod
    def from_yaml(cls, path: str | Path) -> StreamConfig:
        p = resolve_stream(path)
        try:
            data = load_yaml(read_text(p))
        except TextInputError as exc:
            raise StreamError(f"stream {p}: {exc}") from None
        return cls.from_mapping(data, str(p))


def resolve_stream(path: str | Path) -> Path:
    """A stream file by path, or by bare name in config/streams/ (checkout or share); a
    missing one is named as given (a path: that path; a bare name: also its config file)."""
    found = find_data("config/streams", path, (".yaml", ".yml", ".csv"))
    if found is not None:
        return found
    text = str(path)
    if isinstance(path, Path) or Path(text).suffix or "/" in text:
        raise StreamError(f"stream {text}: file not found")
    raise StreamError(f"stream {text}: file not found (nor config/streams/{text}.yaml)")


def _sample_parcel(cfg: StreamConfig, rng: np.random.Generator, pid: int, t: float) -> ParcelSpec:
    d = cfg.parcel

    def get(k: str, default: float) -> float:
        return d[k].sample(rng) if k in d else default

    a, b = get("length_a", 0.4), get("width_b", 0.3)
    height, mass = get("height", 0.2), get("mass", 5.0)
    xp = min(max(get("cog_offset_x", 0.0), -0.5 * a), 0.5 * a)
    yp = min(max(get("cog_offset_y", 0.0), -0.5 * b), 0.5 * b)
    yaw = math.radians(get("yaw_deg", 0.0))
    spec = ParcelSpec(
        pid,
        length_a=a,
        width_b=b,
        height=height,
        mass=mass,
        cog_offset_x=xp,
        cog_offset_y=yp,
        yaw=yaw,
        mu_belt=get("mu_belt", math.nan),
        mu_fence=get("mu_fence", math.nan),
        divert=bool(rng.random() < cfg.divert_share),
        arrival_time=t,
    )
    room = max(cfg.belt_width - spec.to_parcel_params().footprint_width(), 0.0)
    return replace(spec, lateral_gap=min(max(get("lateral_gap", 0.0), 0.0), room))


def generate(
    cfg: StreamConfig,
    belt_speed: float,
    *,
    count: int | None = None,
    duration: float | None = None,
    seed: int | None = None,
    first_id: int = 1,
) -> list[ParcelSpec]:
    """Draw a stream: ``count`` parcels, or all arriving within ``duration`` s (one is needed).

    Spacing: arrivals at the rate (regular or Poisson headways), or rear-to-front gaps drawn
    from ``gap``; the rear-to-front gap never falls below ``min_gap``.
    """
    if count is None and duration is None:
        raise StreamError("stream: give a parcel count or a duration")
    if count is not None and count < 0:
        raise StreamError(f"stream: count must be in [0, inf), got {count}")
    if duration is not None and not duration >= 0.0:
        raise StreamError(f"stream: duration must be in [0, inf) s, got {duration}")
    if not belt_speed > 0.0:
        raise StreamError(f"stream: belt speed must be in (0, inf) m/s, got {belt_speed}")
    rng = np.random.default_rng(cfg.seed if seed is None else seed)
    out: list[ParcelSpec] = []
    t = 0.0
    prev: ParcelSpec | None = None
    while count is None or len(out) < count:
        pid = first_id + len(out)
        spec = _sample_parcel(cfg, rng, pid, 0.0)
        if prev is not None:
            extent = prev.length_a * abs(math.cos(prev.yaw)) + prev.width_b * abs(
                math.sin(prev.yaw)
            )
            if cfg.rate_pcs_h is not None:
                mean = 3600.0 / cfg.rate_pcs_h
                h = mean if cfg.headway == "regular" else float(rng.exponential(mean))
            else:
                h = (extent + max(cfg.gap.sample(rng), 0.0)) / belt_speed
            t = max(t + h, prev.arrival_time + (extent + cfg.min_gap) / belt_speed)
        if duration is not None and t > duration:
            break
        spec = check_parcel(
            replace(spec, arrival_time=t), cfg.belt_width, f"stream {cfg.source}: parcel {pid}"
        )
        out.append(spec)
        prev = spec
    return out


# -- CSV manifests -----------------------------------------------------------------------------
MANIFEST_COLUMNS = ("parcel_id", "arrival_time", *PARCEL_FIELDS, "divert")
REQUIRED_COLUMNS = ("parcel_id", "arrival_time", "length_a", "width_b", "height", "mass", "divert")
_TRUE, _FALSE = ("1", "true", "yes", "y"), ("0", "false", "no", "n")


def read_manifest(path: str | Path, belt_width: float = 0.7) -> list[ParcelSpec]:
    """Parcels of a CSV manifest (header row; columns :data:`MANIFEST_COLUMNS`, optional ones may
    be missing or empty). Errors name the file, line and column."""
    p = resolve_stream(path)
    try:
        text = read_text(p)
    except TextInputError as exc:
        raise StreamError(f"manifest {p}: {exc}") from None
    rows = csv.reader(line for line in text.splitlines() if not line.lstrip().startswith("#"))
    lines = [
        i + 1 for i, line in enumerate(text.splitlines()) if not line.lstrip().startswith("#")
    ]
    try:
        header = [h.strip() for h in next(rows)]
    except StopIteration:
        raise StreamError(f"manifest {p}: empty file (needs a header row)") from None
    for h in header:
        if h not in MANIFEST_COLUMNS:
            raise StreamError(
                f"manifest {p} line {lines[0]} column {h!r}: unknown column; "
                f"allowed: {', '.join(MANIFEST_COLUMNS)}"
            )
    for h in REQUIRED_COLUMNS:
        if h not in header:
            raise StreamError(f"manifest {p} line {lines[0]}: required column {h!r} is missing")
    out: list[ParcelSpec] = []
    seen: set[int] = set()
    for row, lineno in zip(rows, lines[1:], strict=False):
        if not any(c.strip() for c in row):
            continue
        where = f"manifest {p} line {lineno}"
        if len(row) != len(header):
            raise StreamError(f"{where}: {len(row)} fields, the header has {len(header)}")
        vals: dict[str, Any] = {}
        for h, cell in zip(header, row, strict=True):
            cell = cell.strip()
            try:
                if h == "divert":
                    if cell.lower() not in _TRUE + _FALSE:
                        raise ValueError("must be true or false")
                    vals[h] = cell.lower() in _TRUE
                elif h == "parcel_id":
                    vals[h] = int(cell)
                elif cell == "" and h not in REQUIRED_COLUMNS:
                    continue
                else:
                    vals[h] = float(cell)
            except ValueError as exc:
                raise StreamError(f"{where} column {h!r}: cannot read {cell!r} ({exc})") from None
        if vals["parcel_id"] in seen:
            raise StreamError(f"{where} column 'parcel_id': duplicate id {vals['parcel_id']}")
        seen.add(vals["parcel_id"])
        yaw = math.radians(vals.pop("yaw_deg", 0.0))
        spec = ParcelSpec(yaw=yaw, **vals)
        try:
            validate_parcel(spec, belt_width)
        except InputError as exc:
            col = "yaw_deg" if exc.field == "yaw" else exc.field
            raise StreamError(f"{where} column {col!r}: {exc}") from None
        out.append(spec)
    out.sort(key=lambda s: s.arrival_time)
    return out


def load_stream(
    path: str | Path,
    belt_speed: float,
    *,
    count: int | None = None,
    duration: float | None = None,
    seed: int | None = None,
    belt_width: float = 0.7,
    rate_pcs_h: float | None = None,
) -> list[ParcelSpec]:
    """A stream from a YAML config (drawn; at ``rate_pcs_h`` [pcs/h] instead of its own spacing
    when given) or a CSV manifest (read, then cut to count/duration; it takes no rate)."""
    p = resolve_stream(path)
    if p.suffix.lower() == ".csv":
        if rate_pcs_h is not None:
            raise StreamError(
                f"stream {p}: a rate needs a stream config (YAML) to draw from, not a manifest"
            )
        parcels = read_manifest(p, belt_width)
        if duration is not None:
            parcels = [s for s in parcels if s.arrival_time <= duration]
        return parcels[:count] if count is not None else parcels
    cfg = StreamConfig.from_yaml(p)
    if rate_pcs_h is not None:
        cfg = cfg.at_rate(rate_pcs_h)
    if count is None and duration is None:
        count = 100
    return generate(cfg, belt_speed, count=count, duration=duration, seed=seed)
