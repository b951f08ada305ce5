"""The data-side and bench-suite commands refuse bad input with exit 2 and one line naming it."""

import pytest

from fence_sorter.testing import run_cli


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (("replay", "/nonexistent"), "/nonexistent: no such bag"),
        (("rrd", "/nonexistent"), "/nonexistent: no such bag"),
        (("replay", "bags/example_4_parcels", "--rate", "0"), "--rate must be in (0, inf)"),
        (("bench-suite", "--duration", "-5", "--no-write"), "--duration must be in (0, inf)"),
        (("bench-suite", "--param", "physics_rate=500", "--no-write"), "must be NODE:KEY=VALUE"),
    ],
)
def test_bad_input_exits_2_naming_it(args, named):
    done = run_cli(*args, timeout=120)
    assert done.returncode == 2, done.stderr
    assert named in done.stderr
    assert "Traceback" not in done.stderr
