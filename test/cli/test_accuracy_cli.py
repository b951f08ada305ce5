"""``fence-sorter accuracy --quick``: the report, its reference check, convergence, bad arguments.

The quick campaign (one stiff scene, 2-3 settings per method) runs once in-process; bad
arguments run as processes (exit code 2, one line, no traceback). ROS-free.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
from processes import run_cli

from fence_sorter.cli import main as cli_main

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def quick(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict, str]:
    out = tmp_path_factory.mktemp("accuracy")
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = cli_main.main(["accuracy", "--quick", "--out", str(out)])
    assert code == 0, buf.getvalue()
    results = json.loads((out / "results.json").read_text())
    return out, results, buf.getvalue()


@pytest.mark.slow
def test_quick_report_has_the_command_plots_and_reference_check(quick) -> None:
    out, results, stdout = quick
    readme = (out / "README.md").read_text()
    assert "fence-sorter accuracy --out" in readme and "--quick" in readme
    assert "## Reference solutions and their check" in readme
    assert "trapezoidal at half the reference step" in readme
    assert "| default: wall, RTF |" in readme and "**default**" in readme
    for measure in ("peak_force", "trajectory", "final_pose"):
        png = out / f"positioned_stiff_{measure}.png"
        assert png.is_file() and png.read_bytes()[:4] == b"\x89PNG"
    assert not (out / "positioned_stiff_tip_deflection.png").exists()  # stiff fence
    assert (out / "reference" / "positioned_stiff.npz").is_file()
    assert "report:" in stdout


@pytest.mark.slow
def test_reference_is_far_more_accurate_than_the_runs(quick) -> None:
    _, results, _ = quick
    (scene,) = results["scenes"]
    checks = {c["kind"]: c for c in scene["reference"]["checks"]}
    twin = checks["twin"]
    assert twin["status"] == "ok"
    ok = [p for p in scene["points"] if p["status"] == "ok"]
    for measure in ("peak_force", "trajectory", "final_pose"):
        smallest = min(p["errors"][measure] for p in ok)
        assert twin["errors"][measure] < 0.2 * smallest, measure
    # the independent scheme agrees with the reference far better than the coarse runs do
    assert checks["independent"]["errors"]["trajectory"] < 0.2 * max(
        p["errors"]["trajectory"] for p in ok
    )


@pytest.mark.slow
def test_trapezoidal_converges_as_dt_shrinks(quick) -> None:
    """Physics: the errors fall as the step halves (second order in the peak force)."""
    _, results, _ = quick
    (scene,) = results["scenes"]
    trap = [p for p in scene["points"] if p["method"] == "trapezoidal"]
    assert [p["value"] for p in trap] == sorted((p["value"] for p in trap), reverse=True)
    assert all(p["status"] == "ok" for p in trap)
    for measure in ("peak_force", "trajectory"):
        errs = [p["errors"][measure] for p in trap]
        assert all(b < a for a, b in zip(errs, errs[1:], strict=False)), (measure, errs)
    peak = [p["errors"]["peak_force"] for p in trap]
    assert peak[0] / peak[-1] > 4.0  # dt / 4: at least 4x (second order: 16x)


@pytest.mark.slow
def test_default_point_is_marked_and_timed(quick) -> None:
    _, results, _ = quick
    (scene,) = results["scenes"]
    (default,) = [p for p in scene["points"] if p["is_default"]]
    assert default["method"] == "adaptive" and default["value"] == 1e-4
    assert default["status"] == "ok" and default["wall"] > 0 and default["rtf"] > 0
    assert set(default["errors"]) >= {"peak_force", "trajectory", "final_pose"}


def fence_sorter(*args: str) -> subprocess.CompletedProcess:
    return run_cli(*args, timeout=120)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("args", "named", "allowed"),
    [
        (("--scenes", "no_such_scene"), "no_such_scene", "positioned_stiff"),
        (("--methods", "scipy:Euler"), "scipy:Euler", "scipy:LSODA"),
    ],
)
def test_unknown_scene_or_method_exits_2_with_one_line(tmp_path, args, named, allowed) -> None:
    r = fence_sorter("accuracy", *args, "--out", str(tmp_path / "acc"))
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fence-sorter: error:")
    assert named in lines[0] and allowed in lines[0]
    assert "Traceback" not in r.stderr
    assert not (tmp_path / "acc").exists()
