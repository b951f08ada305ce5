"""The data-side commands refuse bad input with exit 2 and one line naming it."""

import pytest
from processes import run_cli

from fence_sorter.runner.processes import DomainError, check_domain


@pytest.mark.slow
@pytest.mark.parametrize(
    ("args", "named"),
    [
        (("replay", "/nonexistent"), "/nonexistent: no such bag"),
        (("rrd", "/nonexistent"), "/nonexistent: no such bag"),
        (("replay", "bags/example_4_parcels", "--rate", "0"), "--rate must be in (0, inf)"),
    ],
)
def test_bad_input_exits_2_naming_it(args, named):
    done = run_cli(*args, timeout=120)
    assert done.returncode == 2, done.stderr
    assert named in done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.slow
def test_plots_only_redraws_from_the_saved_results(tmp_path):
    """`accuracy --plots-only`: the figures from the committed results.json, nothing solved; a
    missing input is exit 2 naming it."""
    import shutil
    from pathlib import Path

    docs = Path(__file__).resolve().parents[2] / "docs" / "reports"
    acc = tmp_path / "acc"
    acc.mkdir()
    shutil.copy(docs / "accuracy" / "results.json", acc / "results.json")
    (acc / "arbitrary_stiff_final_pose.png").write_bytes(b"")
    res = run_cli("accuracy", "--plots-only", "--out", str(acc))
    assert res.returncode == 0, res.stderr
    assert (acc / "arbitrary_stiff_final_pose.png").stat().st_size > 10_000
    assert "| default: wall, RTF |" in (acc / "README.md").read_text()  # rendered again
    res = run_cli("accuracy", "--plots-only", "--out", str(tmp_path / "none"))
    assert res.returncode == 2 and "results.json" in res.stderr


@pytest.mark.parametrize("domain", ["-1", "233"])
def test_replay_domain_outside_the_ros_range_exits_2(domain):
    done = run_cli("replay", "bags/example_4_parcels", "--domain", domain, timeout=120)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == [
        f"fence-sorter replay: error: --domain must be in [0, 232], got {domain}"
    ]


@pytest.mark.parametrize(("domain", "ok"), [(0, True), (232, True), (-1, False), (233, False)])
def test_the_ros_domain_range_is_0_to_232(domain, ok):
    if ok:
        assert check_domain(domain) == domain
    else:
        with pytest.raises(DomainError, match=r"--domain must be in \[0, 232\]"):
            check_domain(domain)
