"""``fence-sorter simulate`` and ``fence-sorter modes`` run as processes: JSON keys, exit codes,
one-line errors without a traceback. ROS-free (python -m fence_sorter.cli.main)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
from processes import run_cli

REPO = Path(__file__).resolve().parents[2]
TIMEOUT = 120.0
REQUIRED_KEYS = (
    "sorted",
    "peak_contact_force_N",
    "peak_contact_force_stiff_N",
    "peak_normal_accel_mps2",
    "impact_normal_speed_mps",
    "exit_speed_y_mps",
    "y_max_m",
    "stages",
    "sim_time_s",
    "wall_time_s",
    "steps",
    "scene",
    "warnings",
)


def fence_sorter(*args: str) -> subprocess.CompletedProcess:
    return run_cli(*args, timeout=TIMEOUT)


@pytest.mark.slow
def test_simulate_json() -> None:
    r = fence_sorter("simulate", "positioned_stiff", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    for key in REQUIRED_KEYS:
        assert key in out, key
    assert out["sorted"] is True and out["success"] is True
    assert out["scene"] == "positioned_stiff" and out["warnings"] == []
    assert out["stages"][0] == {"stage": "on_belt", "start_s": 0.0}
    assert out["stages"][-1]["stage"] == "sorted"
    assert out["steps"] > 0 and out["sim_time_s"] > 0


@pytest.mark.slow
def test_simulate_impact_flexible_json() -> None:
    r = fence_sorter("simulate", "impact_flexible", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["sorted"] is True
    assert out["impact_normal_speed_mps"] == pytest.approx(2.43, abs=0.1)
    assert 0.0 < out["peak_contact_force_N"] < out["peak_contact_force_stiff_N"]


@pytest.mark.slow
def test_simulate_human_summary_and_set() -> None:
    r = fence_sorter("simulate", "positioned_stiff", "--set", "parcel.mass=6")
    assert r.returncode == 0, r.stderr
    for word in ("sorted", "peak N", "N_stiff", "a_N", "w_n", "exit speed", "y_max", "stages"):
        assert word in r.stdout
    assert "steps" in r.stdout


@pytest.mark.slow
def test_simulate_warning_on_stderr() -> None:
    r = fence_sorter("simulate", "positioned_stiff", "--json", "--set", "conveyor.belt_speed=2.6")
    assert r.returncode in (0, 3)
    assert "warning" in r.stderr and "belt_speed" in r.stderr
    assert len(json.loads(r.stdout)["warnings"]) == 1


@pytest.mark.slow
@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--set", "parcel.colour=red"], "parcel.colour"),
        (["--set", "parcel.mass=-3"], "parcel.mass"),
        (["--set", "fence.elements=ten"], "fence.elements"),
        (["--set", "solver"], "key=value"),
    ],
)
def test_simulate_bad_scene_exits_2(args: list[str], needle: str) -> None:
    r = fence_sorter("simulate", "impact_flexible", *args)
    assert r.returncode == 2
    assert r.stderr.startswith("fence-sorter: error: scene impact_flexible.yaml:")
    assert needle in r.stderr
    assert "Traceback" not in r.stderr + r.stdout
    assert len(r.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_simulate_bad_file_exits_2(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("fence: {type: stiff\nparcel: [")
    for scene in (str(bad), "no_such_scene", str(tmp_path / "missing.yaml")):
        r = fence_sorter("simulate", scene)
        assert r.returncode == 2, scene
        assert r.stderr.startswith("fence-sorter: error: ")
        assert "Traceback" not in r.stderr
    unknown = tmp_path / "unknown.yaml"
    unknown.write_text("fence: {type: stiff}\ndrive: {t1: 0.5, omega: 3}\n")
    r = fence_sorter("simulate", str(unknown))
    assert r.returncode == 2 and "drive.omega" in r.stderr


@pytest.mark.slow
def test_modes_json() -> None:
    r = fence_sorter("modes", "impact_flexible", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    f = out["frequencies_hz"]
    assert len(f) == 5 and all(a < b for a, b in zip(f, f[1:], strict=False)) and f[0] > 0
    assert out["tip_deflection_m"] == pytest.approx(out["closed_form_tip_deflection_m"], rel=0.03)
    # (2/3) P R_z^3 / (E I1), I1 = z h1^3 / 12, P = 100 N
    i1 = 0.1 * 0.08**3 / 12.0
    assert out["closed_form_tip_deflection_m"] == pytest.approx(
        2.0 / 3.0 * 100.0 * 1.2**3 / (3.0e9 * i1)
    )
    assert out["elements"] == 10 and out["mass_kg"] > 0


@pytest.mark.slow
def test_modes_options_and_uniform() -> None:
    r = fence_sorter(
        "modes", "impact_flexible", "--json", "--count", "3", "--tip-load", "50",
        "--set", "fence.profile=uniform",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert len(out["frequencies_hz"]) == 3
    assert out["tip_deflection_m"] == pytest.approx(out["closed_form_tip_deflection_m"], rel=1e-6)
    r = fence_sorter("modes", "impact_flexible")
    assert r.returncode == 0 and "Hz" in r.stdout and "closed form" in r.stdout


@pytest.mark.slow
def test_modes_stiff_scene_exits_2() -> None:
    r = fence_sorter("modes", "positioned_stiff")
    assert r.returncode == 2
    assert "modes needs a flexible fence (fence.type: flexible)" in r.stderr
    assert "Traceback" not in r.stderr


@pytest.mark.slow
@pytest.mark.parametrize(
    ("override", "named", "allowed"),
    [
        ("solver.method=rk4", "solver.method", "adaptive"),
        ("solver.rho_inf=1.5", "solver.rho_inf", "[0, 1]"),
        ("solver.rtol=0", "solver.rtol", "1e-13"),
        ("solver.dt_max=1", "solver.dt_max", "0.05"),
    ],
)
def test_bad_solver_settings_exit_2_naming_the_key(override, named, allowed) -> None:
    r = fence_sorter("simulate", "impact_flexible", "--set", override)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and named in lines[0] and allowed in lines[0], r.stderr
    assert "Traceback" not in r.stderr
