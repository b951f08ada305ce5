"""A Rerun recording's rows read back with Rerun's own reader (RrdReader), for the tests."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path


def read_rrd(path: Path) -> dict[str, list[tuple[float, dict]]]:
    """Per entity on the timeline ``sim_time``: (sim time [s], {component: that row's
    value}) in time order, e.g. ``strips``, ``labels`` and ``colors`` of line strips,
    ``scalars`` of a plot."""
    from rerun.chunk import RrdReader

    rows: dict[str, list[tuple[float, dict]]] = defaultdict(list)
    for chunk in RrdReader(path).stream():
        if chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        cols = batch.schema.names
        if "sim_time" not in cols:
            continue
        t = batch.column("sim_time").cast("int64").to_pylist()  # [ns]
        data = {c.split(":")[-1]: batch.column(c).to_pylist() for c in cols if ":" in c}
        for i, ti in enumerate(t):
            ts = ti * 1e-9
            rows[chunk.entity_path].append((ts, {k: v[i] for k, v in data.items()}))
    for v in rows.values():
        v.sort(key=lambda r: r[0])
    return rows
