"""json_safe: the one NaN -> null conversion of the JSON outputs (run, analyze, accuracy)."""

import json
import math

from fence_sorter.jsonsafe import json_safe


def test_non_finite_floats_become_null_and_keys_strings():
    value = {"a": math.nan, 1: [math.inf, 2.0, (-math.inf, "x")], "b": {"c": 3}}
    out = json_safe(value)
    assert out == {"a": None, "1": [None, 2.0, [None, "x"]], "b": {"c": 3}}
    json.dumps(out, allow_nan=False)  # strict JSON
