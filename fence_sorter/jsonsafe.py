"""JSON output of figures: NaN and infinities become null (JSON has no NaN), keys strings."""

from __future__ import annotations

import math


def json_safe(value):
    """``value`` with every non-finite float replaced by None, recursively through dicts,
    lists and tuples (tuples become lists) and dict keys turned into strings."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return value
