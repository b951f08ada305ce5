"""Scene files: every shipped scene loads and sorts; bad keys, types, ranges and overrides fail
with a ParameterError naming the dotted key. ROS-free."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from fence_sorter.physics.params import ParameterError
from fence_sorter.physics.simulate import simulate
from fence_sorter.resources import data_path
from fence_sorter.scene import SceneError, available_scenes, load_scene

REPO_SCENES = data_path("config", "scenes")

SHIPPED = ("impact_flexible", "slide_flexible", "positioned_stiff", "arbitrary_stiff")
FREE_FALL_SPEED = math.sqrt(2.0 * 9.81 * 0.3)  # 2.43 m/s, a 0.3 m free fall

MINIMAL = """\
name: minimal
description: test scene
conveyor: {belt_speed: 1.0}
fence: {type: stiff, length: 1.2}
drive: {alpha_k_deg: 40, t1: 0.5, r_s: 0.0}
parcel: {length_a: 0.4, width_b: 0.3, mass: 15}
"""


def write(tmp_path: Path, text: str, name: str = "s.yaml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_shipped_scene_set() -> None:
    assert set(SHIPPED) <= set(available_scenes())
    for name in SHIPPED:
        text = (REPO_SCENES / f"{name}.yaml").read_text()
        assert text.startswith("#"), f"{name}.yaml needs a description comment"


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_scene_loads(name: str) -> None:
    loaded = load_scene(name)
    assert loaded.name == name
    assert loaded.description
    assert loaded.warnings == ()
    assert loaded.source_path.name == f"{name}.yaml"
    sc = loaded.scenario
    assert (sc.fence is not None) == name.endswith("flexible")


def test_load_by_path_equals_load_by_name() -> None:
    assert load_scene(REPO_SCENES / "impact_flexible.yaml").scenario == (
        load_scene("impact_flexible").scenario
    )


def test_units_and_shortcuts() -> None:
    sc = load_scene("positioned_stiff").scenario
    assert sc.drive.alpha_k == pytest.approx(math.radians(40.0))
    # cog: rear = Fig. 2a, C_s on the rear corner on the fence side
    assert (sc.parcel.cog_offset_x, sc.parcel.cog_offset_y) == (-0.35, -0.05)
    assert sc.fence is None and sc.fence_length == 1.2
    sc = load_scene("positioned_stiff", ["parcel.cog=front", "parcel.yaw_deg=10"]).scenario
    assert (sc.parcel.cog_offset_x, sc.parcel.cog_offset_y) == (0.35, -0.05)
    assert sc.parcel.yaw == pytest.approx(math.radians(10.0))
    flex = load_scene("impact_flexible").scenario
    assert flex.fence.elements == 10 and flex.fence_modes is None
    assert flex.solver.stop_when_sorted is False
    assert set(flex.record) == {"trajectory", "fence", "forces"}


def test_overrides() -> None:
    sc = load_scene(
        "impact_flexible",
        [
            "parcel.mass=50",
            "fence.elements=20",
            "fence.modes=6",
            "drive.alpha_k_deg=35",
            "solver.dt=1e-4",  # YAML 1.1 reads 1e-4 as a string: still a number here
            "record=[trajectory]",
        ],
    ).scenario
    assert sc.parcel.mass == 50.0
    assert sc.fence.elements == 20 and sc.fence_modes == 6
    assert sc.drive.alpha_k == pytest.approx(math.radians(35.0))
    assert sc.solver.dt == 1e-4
    assert sc.record == ("trajectory",)
    stiff = load_scene("impact_flexible", ["fence.type=stiff"]).scenario
    assert stiff.fence is None and stiff.fence_length == 1.2


def test_belt_speed_warning() -> None:
    loaded = load_scene("positioned_stiff", ["conveyor.belt_speed=3.0"])
    assert len(loaded.warnings) == 1 and "belt_speed" in loaded.warnings[0]


@pytest.mark.parametrize(
    ("extra", "key"),
    [
        ("parcel: {length_a: 0.4, width_b: 0.3, mass: 15, colour: red}\n", "parcel.colour"),
        ("contact: {k_p: 1e9, stiffness: 3}\n", "contact.stiffness"),
        ("solver: {dt: 1.0e-4, order: 2}\n", "solver.order"),
        ("bogus: 1\n", "bogus"),
    ],
)
def test_unknown_key(tmp_path: Path, extra: str, key: str) -> None:
    text = MINIMAL.replace("parcel: {length_a: 0.4, width_b: 0.3, mass: 15}\n", "")
    if not extra.startswith("parcel"):
        text += "parcel: {length_a: 0.4, width_b: 0.3, mass: 15}\n"
    with pytest.raises(ParameterError, match=rf"scene s\.yaml: {key}\b.*allowed keys"):
        load_scene(write(tmp_path, text + extra))


@pytest.mark.parametrize(
    ("override", "key"),
    [
        ("parcel.mass=-1", "parcel.mass"),
        ("conveyor.belt_speed=0", "conveyor.belt_speed"),
        ("drive.alpha_k_deg=120", "drive.alpha_k_deg"),
        ("drive.t1=0.001", "drive.t1"),
        ("contact.mu_fence=3", "contact.mu_fence"),
        ("solver.dt=1", "solver.dt"),
        ("parcel.lateral_gap=0.65", "parcel.lateral_gap"),
        ("fence.elements=0", "fence.elements"),
        ("fence.poisson_ratio=0.7", "fence.poisson_ratio"),
        ("fence.modes=100", "fence.modes"),
        ("fence.profile=square", "fence.profile"),
        ("fence.type=rubber", "fence.type"),
    ],
)
def test_out_of_range(override: str, key: str) -> None:
    scene = "impact_flexible" if override.startswith("fence") else "positioned_stiff"
    with pytest.raises(ParameterError, match=rf"^scene {scene}\.yaml: .*{key}"):
        load_scene(scene, [override])


@pytest.mark.parametrize(
    ("override", "key", "expected"),
    [
        ("parcel.mass=heavy", "parcel.mass", "a number"),
        ("fence.elements=10.5", "fence.elements", "an integer"),
        ("solver.stop_when_sorted=1", "solver.stop_when_sorted", "a boolean"),
        ("parcel.cog=[1, 2]", "parcel.cog", "a string"),
        ("fence.modes=some", "fence.modes", "positive integer"),
        ("record=trajectory", "record", "a list"),
    ],
)
def test_wrong_type(override: str, key: str, expected: str) -> None:
    with pytest.raises(ParameterError, match=rf"scene impact_flexible\.yaml: {key} must be"):
        load_scene("impact_flexible", [override])
    with pytest.raises(ParameterError, match=expected):
        load_scene("impact_flexible", [override])


@pytest.mark.parametrize(
    "override", ["parcel.colour=red", "wheels.count=4", "massive=1", "a.b.c=1"]
)
def test_bad_override_key(override: str) -> None:
    key = override.partition("=")[0]
    with pytest.raises(ParameterError, match=rf"--set {key}: {key} is not a known key"):
        load_scene("impact_flexible", [override])


def test_bad_override_syntax() -> None:
    with pytest.raises(ParameterError, match="key=value"):
        load_scene("impact_flexible", ["parcel.mass"])


def test_unknown_record_entry() -> None:
    with pytest.raises(ParameterError, match=r"record: unknown entry 'video'.*trajectory"):
        load_scene("impact_flexible", ["record=[trajectory, video]"])


def test_stiff_fence_rejects_flexible_keys(tmp_path: Path) -> None:
    text = MINIMAL.replace("{type: stiff, length: 1.2}", "{type: stiff, length: 1.2, elements: 5}")
    with pytest.raises(ParameterError, match="fence.elements is only valid for type: flexible"):
        load_scene(write(tmp_path, text))
    with pytest.raises(ParameterError, match="fence.elements is only valid for type: flexible"):
        load_scene("impact_flexible", ["fence.type=stiff", "fence.elements=5"])


def test_cog_and_offsets_conflict() -> None:
    with pytest.raises(ParameterError, match="parcel.cog and parcel.cog_offset_x"):
        load_scene("positioned_stiff", ["parcel.cog_offset_x=0.1"])


def test_missing_file_and_yaml_error(tmp_path: Path) -> None:
    with pytest.raises(SceneError, match="no_such_scene.*available: .*impact_flexible"):
        load_scene("no_such_scene")
    with pytest.raises(SceneError, match="file not found"):
        load_scene(tmp_path / "missing.yaml")
    with pytest.raises(SceneError, match=r"scene bad\.yaml: YAML syntax error"):
        load_scene(write(tmp_path, "parcel: {mass: 15\nfence: [", "bad.yaml"))


def test_minimal_scene_defaults(tmp_path: Path) -> None:
    loaded = load_scene(write(tmp_path, MINIMAL))
    assert loaded.name == "minimal" and loaded.scenario.record == ()
    assert loaded.scenario.parcel.cog_offset_x == 0.0


# -- scene-level physics ----------------------------------------------------------------------
def test_impact_flexible_speed_and_reduction() -> None:
    """Fig. 11: w_n is that of a 0.3 m free fall; the flexible fence lowers the peak force."""
    r = simulate(load_scene("impact_flexible").scenario)
    assert r.success, r.diagnosis
    assert r.sorted
    assert r.impact_normal_speed == pytest.approx(FREE_FALL_SPEED, abs=0.1)
    assert r.peak_contact_force < 0.6 * r.peak_contact_force_stiff
    assert len(r.series["tip_deflection"]) == r.steps + 1  # recorded through the return motion
    assert r.sim_time == pytest.approx(2 * 0.35 + 0.5)


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_scene_sorts(name: str) -> None:
    r = simulate(load_scene(name, ["solver.stop_when_sorted=true", "record=[]"]).scenario)
    assert r.success, r.diagnosis
    assert r.sorted, r.reason


def test_reading_a_scene_loads_neither_the_kernel_nor_numba_nor_scipy():
    """The scanner reads its scene at start-up: that must not cost the kernel's imports."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from fence_sorter.scene import load_scene\n"
        "sc = load_scene('impact_flexible').scenario\n"
        "assert sc.fence is not None and sc.fence.elements > 0\n"
        "heavy = ('numba', 'scipy', 'fence_sorter.physics.kernel')\n"
        "print(','.join(m for m in heavy if m in sys.modules))\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() == "", proc.stdout
