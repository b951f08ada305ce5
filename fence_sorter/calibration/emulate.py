"""Emulated measured bags: parcels of a stream run through the twin, seen by emulated sensors.

:func:`emulate` draws ``count`` parcels from a stream (seeded), strokes each with the scene's
drive (alpha_k, t1, R_s), one after the other in bag time, replays every event on the twin
(parallel processes) and measures the tracks with :func:`~fence_sorter.calibration.sensors.
measure`. The same seed gives the same parcels, truth and noise.
"""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

from fence_sorter.physics.simulate import Scenario
from fence_sorter.stream.model import load_stream

from .bag import SCAN_LEAD, write_measured_bag
from .replay import PARAMETERS, ParcelEvent, replay, scene_value
from .sensors import Measurements, SensorConfig, TruthEvent, measure

#: the camera sees each parcel from this long before its stroke [s]
PRE_TIME = 0.5


def draw_events(base: Scenario, stream: str | Path, count: int, seed: int) -> list[ParcelEvent]:
    """``count`` parcels of ``stream`` (seeded), each stroked by the scene's drive in turn."""
    specs = load_stream(
        stream, base.conveyor.belt_speed, count=count, seed=seed, belt_width=base.conveyor.width
    )
    d = base.drive
    period = SCAN_LEAD + 2.0 * d.t1 + 1.0
    events = []
    for k, spec in enumerate(specs):
        events.append(
            ParcelEvent(
                spec.parcel_id,
                spec.to_parcel_params(),
                d.alpha_k,
                d.t1,
                d.r_s,
                SCAN_LEAD + 1.0 + k * period,
            )
        )
    return events


def _replay_one(args):
    base, ev = args
    return replay(base, ev)


def truth_tracks(base: Scenario, events: list[ParcelEvent], workers: int | None = None):
    workers = max(1, min(workers or os.cpu_count() or 1, len(events)))
    jobs = [(base, ev) for ev in events]
    if workers == 1:
        return [_replay_one(j) for j in jobs]
    first = _replay_one(jobs[0])  # compiles (or loads) the kernel before the workers fork
    with ProcessPoolExecutor(workers) as pool:
        return [first, *pool.map(_replay_one, jobs[1:])]


def truth_values(base: Scenario) -> dict[str, float]:
    return {n: scene_value(base, n) for n in PARAMETERS if scene_value(base, n) is not None}


def truth_record(
    scene_name: str, base: Scenario, sensors: SensorConfig, seed: int, **extra
) -> dict:
    """What a measured bag was made from, for its metadata (:data:`bag.TRUTH_KEY`): the
    scene, its fit parameters' values, the sensors, the noise seed and the camera frame."""
    return {
        "scene": scene_name,
        "sensors": sensors.name,
        "seed": seed,
        "values": truth_values(base),
        "camera_offset": list(sensors.camera.offset),
        **extra,
    }


def emulate(
    base: Scenario,
    sensors: SensorConfig,
    *,
    stream: str | Path,
    count: int,
    seed: int,
    workers: int | None = None,
) -> tuple[list[ParcelEvent], Measurements]:
    """The events and their measured samples (see the module docstring)."""
    events = draw_events(base, stream, count, seed)
    truth = truth_events(base, events, workers)
    return events, measure_events(base, sensors, events, truth, seed + 1)


def truth_events(base: Scenario, events: list[ParcelEvent], workers: int | None = None):
    """Each event's true track on the twin, placed at its stroke start."""
    tracks = truth_tracks(base, events, workers)
    return [
        TruthEvent(e.parcel_id, e.t_start, e.alpha_k, e.t1, tr)
        for e, tr in zip(events, tracks, strict=True)
    ]


def measure_events(
    base: Scenario,
    sensors: SensorConfig,
    events: list[ParcelEvent],
    truth: list[TruthEvent],
    noise_seed: int,
) -> Measurements:
    """The sensors' samples of the true tracks, the noise seeded by ``noise_seed`` (no strain
    gauge on a stiff fence)."""
    t_end = (events[-1].t_start + events[-1].t_end + 1.0) if events else 1.0
    if base.fence is None:
        sensors = replace(sensors, strain=None)
    return measure(truth, sensors, noise_seed, PRE_TIME, t_end)


def emulate_bag(
    path: Path | str,
    base: Scenario,
    sensors: SensorConfig,
    *,
    scene_name: str,
    stream: str | Path,
    count: int,
    seed: int,
    workers: int | None = None,
) -> Path:
    """:func:`emulate` written to a bag, with the truth in its metadata."""
    events, m = emulate(base, sensors, stream=stream, count=count, seed=seed, workers=workers)
    truth = truth_record(scene_name, base, sensors, seed)
    return write_measured_bag(path, events, m, truth)
