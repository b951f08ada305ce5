"""Every fence_sorter_msgs message between two real rclpy processes over Fast DDS."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from processes import managed_process

from fence_sorter.nodes.roundtrip import DEFAULT_SEED
from fence_sorter.recording.msgtypes import make_typestore, message_names, msgtype_name
from fence_sorter.recording.samples import diff_values, sample_values

pytestmark = [pytest.mark.ros, pytest.mark.slow]

TIMEOUT = 60.0  # s; a round trip normally takes 1-3 s


def test_every_message_round_trips_between_two_processes(
    env: dict[str, str], tmp_path: Path
) -> None:
    record = tmp_path / "received.json"
    module = [sys.executable, "-m", "fence_sorter.nodes.roundtrip"]
    echo_cmd = [*module, "echo", "--record", str(record), "--timeout", str(TIMEOUT + 10)]
    publish_cmd = [*module, "publish", "--timeout", str(TIMEOUT)]
    with (
        managed_process(echo_cmd, env) as echo,
        managed_process(publish_cmd, env) as publisher,
    ):
        pub_out, pub_err = publisher.communicate(timeout=TIMEOUT + 15)
        echo_out, echo_err = echo.communicate(timeout=15)

    names = message_names()
    assert publisher.returncode == 0, pub_out + pub_err
    assert echo.returncode == 0, echo_out + echo_err
    for name in names:
        assert f"OK   {name}:" in pub_out, pub_out

    # What the echo process received, checked field by field against what was sent.
    received = json.loads(record.read_text())
    assert sorted(received) == sorted(names)
    typestore = make_typestore()
    for name in names:
        expected = sample_values(typestore, msgtype_name(name), DEFAULT_SEED)
        assert diff_values(expected, received[name]) == [], name


def test_samples_set_every_field_to_a_non_default_value() -> None:
    """The round trip proves something only if no field keeps its default value."""
    typestore = make_typestore()

    def leaves(value: object, path: str) -> list[tuple[str, object]]:
        if isinstance(value, dict):
            return [leaf for key, sub in value.items() for leaf in leaves(sub, f"{path}.{key}")]
        if isinstance(value, list):
            assert value, f"{path}: empty sequence"
            return [leaf for i, sub in enumerate(value) for leaf in leaves(sub, f"{path}[{i}]")]
        return [(path, value)]

    for name in message_names():
        sample = sample_values(typestore, msgtype_name(name), DEFAULT_SEED)
        defaults = [(path, v) for path, v in leaves(sample, name) if v in (0, 0.0, False, "")]
        assert defaults == []
        assert sample != sample_values(typestore, msgtype_name(name), DEFAULT_SEED + 1)


def test_diff_values_reports_every_difference() -> None:
    expected = {"a": 1.0, "b": [1, 2], "c": {"d": "x", "e": True}}
    assert diff_values(expected, expected) == []
    actual = {"a": 1, "b": [1, 3], "c": {"d": "x"}, "f": 0}
    assert diff_values(expected, actual) == [
        "a: 1 != 1.0",
        "b[1]: 3 != 2",
        "c.e: missing",
        "f: unexpected",
    ]
    assert diff_values(expected, {**expected, "b": [1]}) == ["b: length 1 != 2"]
