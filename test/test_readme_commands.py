"""Every command of the README runs in a test.

:data:`COVERED` maps each command line of the README's ``bash`` blocks to the test that runs
it (the same subcommand and options; smaller amounts where the README's take minutes), or to
the cheap run of it here (:data:`RUN_HERE`); a few lines need what this machine has not (a
ROS install under /opt/ros, a viewer window, a Dask cluster) and say so in
:data:`NOT_HERE`. A new README command without an entry fails this test, and so does an
entry whose test does not exist or does not use the command's subcommand and options."""

from __future__ import annotations

import ast
import re
import shlex
from pathlib import Path

import pytest
from processes import run_cli

REPO = Path(__file__).resolve().parents[1]
#: the documents whose commands are run here: the front door and the user guide
DOCUMENTS = ("README.md", "docs/guide/guide.md")

HERE = "test/test_readme_commands.py::test_readme_command_runs"
REPORTS_MADE = "test/test_readme_commands.py::test_make_reports_writes_every_generated_report"
MAKE = "test/test_readme_commands.py::test_make_targets_run_the_documented_commands"
ACCURACY = (
    "test/cli/test_accuracy_cli.py::test_quick_report_has_the_command_plots_and_reference_check"
)
RUN_AT_A_RATE = "test/ros/test_run_rate.py::test_a_run_at_a_rate_scans_3600_over_rate_s_apart"

#: README command -> "test file::test function" that runs it
COVERED: dict[str, str] = {
    "make run": MAKE,
    "make reports": REPORTS_MADE,
    "fence-sorter check": "test/cli/test_cli.py::test_check_passes_in_the_bootstrapped_env",
    "fence-sorter demo-roundtrip": "test/cli/test_cli.py::test_demo_roundtrip",
    "simulator --ros-args -p real_time_factor:=2.0": (
        "test/ros/test_simulator.py::test_real_time_factor_can_change_at_run_time"
    ),
    "fence-sorter run": "test/ros/test_shutdown.py::test_interrupted_run_ends_every_process",
    "fence-sorter run --parcels 40 --rtf 2 --seed 7": HERE,
    "fence-sorter run --duration 60 --bag bags/run1": HERE,
    "fence-sorter run --stream config/streams/example_manifest.csv": HERE,
    "fence-sorter run --rtf 0 --json": HERE,
    "fence-sorter run --param controller:a_ndop=150": HERE,
    "fence-sorter run --rate 1200 --parcels 10": RUN_AT_A_RATE,
    "fence-sorter run --set conveyor.belt_speed=1.5": RUN_AT_A_RATE,
    "fence-sorter run --sensors camera60 --bag bags/cal": (
        "test/ros/test_sensors_run.py::test_the_bag_carries_the_truth_and_calibrate_fits_it"
    ),
    "fence-sorter run --parcels 4 --foxglove 8765 --bag /tmp/fg": (
        "test/ros/test_foxglove_live.py::test_npm_client_gets_the_runs_joint_states_and_outcomes"
    ),
    "fence-sorter replay bags/example_4_parcels --foxglove 8765 --wait 30": (
        "test/ros/test_foxglove_live.py::test_replay_serves_the_bag_to_the_npm_client"
    ),
    "python -m benchmarks bench-suite": HERE,
    "fence-sorter analyze bags/example_4_parcels": HERE,
    "fence-sorter analyze bags/example_4_parcels --json --out /tmp/ex": (
        "test/ros/test_recording.py::test_analysis_of_the_run_matches_the_live_outcomes"
    ),
    "fence-sorter rrd bags/example_4_parcels --out /tmp/ex.rrd": HERE,
    "fence-sorter views --mid 10.3": (
        "test/views/test_views_browser.py::test_example_recording_renders_in_the_web_viewer"
    ),
    "fence-sorter line-sim four_units --parcels 30 --rrd /tmp/line.rrd": (
        "test/views/test_views_browser.py::test_line_recording_renders_in_the_web_viewer"
    ),
    "fence-sorter views /tmp/line.rrd --out /tmp/line-views": (
        "test/views/test_views_browser.py::test_line_recording_renders_in_the_web_viewer"
    ),
    "fence-sorter replay bags/example_4_parcels --rate 2": (
        "test/ros/test_recording.py::test_replay_republishes_the_run"
    ),
    "fence-sorter run --parcels 4 --bag /tmp/b --rrd /tmp/b.rrd": (
        "test/ros/test_recording.py::test_live_rrd_of_the_run_has_every_published_frame"
    ),
    "python -m rerun mcap check --full bags/example_4_parcels/example_4_parcels_0.mcap": (
        "test/ros/test_recording.py::test_rerun_full_check_accepts_every_segment_of_the_run"
    ),
    "source scripts/env.sh": MAKE,
    "fence-sorter simulate impact_flexible": (
        "test/cli/test_simulate_cli.py::test_simulate_impact_flexible_json"
    ),
    "fence-sorter simulate slide_flexible --json": HERE,
    "fence-sorter simulate positioned_stiff --set parcel.mass=20 --set drive.alpha_k_deg=35": HERE,
    "fence-sorter modes impact_flexible --tip-load 100": HERE,
    "fence-sorter simulate impact_flexible --set solver.method=generalized_alpha "
    "--set solver.dt=2.5e-4": HERE,
    "fence-sorter simulate impact_flexible --set solver.method=scipy:Radau "
    "--set solver.rtol=1e-6": HERE,
    "fence-sorter simulate impact_flexible --set solver.method=cyrk:LSODA "
    "--set solver.rtol=1e-6": HERE,
    "fence-sorter accuracy": ACCURACY,
    "fence-sorter stability": "test/cli/test_stability_cli.py::test_quick_writes_the_report",
    "python -m benchmarks bench": HERE,
    "fence-sorter optimize --case positioned --alpha-k 40 --constraints 7,8,11 --json": HERE,
    "fence-sorter optimize --case arbitrary --alpha-k 35 --w-dop 2.4 --mu1 0.5 --mu2 0.3": HERE,
    "fence-sorter bag info bags/example_4_parcels": (
        "test/recording/test_baginfo.py::test_example_bag_info_matches_the_independent_reader"
    ),
    "fence-sorter bag info bags/example_4_parcels --json": (
        "test/recording/test_baginfo.py::test_example_bag_info_matches_the_independent_reader"
    ),
    "fence-sorter topic list -t --domain 219": (
        "test/ros/test_topic_cli.py::test_echo_yaml_and_list_show_the_topic"
    ),
    "fence-sorter topic echo /sort_outcomes --domain 219 -n 3": (
        "test/ros/test_topic_cli.py::test_echo_prints_the_published_messages"
    ),
    "fence-sorter topic hz /joint_states --domain 219": (
        "test/ros/test_topic_cli.py::test_hz_reports_the_stamp_rate"
    ),
    "fence-sorter param list controller --domain 219": (
        "test/ros/test_param_cli.py::test_param_list_get_set_through_the_services"
    ),
    "fence-sorter param set controller a_ndop 150 --domain 219 --key-file LOGDIR/run.key": (
        "test/ros/test_param_cli.py::test_a_ndop_changed_during_a_run_holds_for_the_next_plans"
    ),
    "fence-sorter run --parcels 4 --bag /tmp/b": (
        "test/ros/test_recording.py::test_run_bag_has_every_topic_and_consistent_counts"
    ),
    "python -m benchmarks paper-sweep fig6 --out docs/reports/paper": (
        "test/campaigns/test_paper_sweep.py::test_plots_only_redraws_from_the_saved_results"
    ),
}

#: README commands that need what this machine has not, and why
NOT_HERE: dict[str, str] = {
    "ros2 run fence_sorter fence-sorter check": (
        "the ros2 CLI of a full ROS 2 install (the lib/fence_sorter layout it runs: "
        "test/cli/test_packaging.py::test_console_scripts)"
    ),
    "make test": "the suite itself (what CI runs; its recipe is checked by " + MAKE + ")",
    "pytest test/ros test/cli": "a part of the suite itself (make test runs all of it)",
    'pytest -m "not slow"': "a part of the suite itself (make test runs all of it)",
    "rerun bags/example_4_parcels.rrd": "opens a viewer window",
    "fence-sorter run --line two_units --rtf 1 --rerun-url rerun+http://127.0.0.1:9876/proxy": (
        "streams to a viewer window listening at the url (the same live view to a file: "
        "test/ros/test_line_live_view.py)"
    ),
    "mkdir -p ~/ws/src && cd ~/ws/src && git clone <this repository> fence_sorter": (
        "a full ROS 2 install (colcon workspace)"
    ),
    "cd ~/ws": "a full ROS 2 install (colcon workspace)",
    "source /opt/ros/jazzy/setup.bash": "a full ROS 2 install under /opt/ros",
    "colcon build --paths src/fence_sorter src/fence_sorter/msg_defs": "a full ROS 2 install",
    "source install/setup.bash": "a full ROS 2 install (colcon workspace)",
    "ros2 run fence_sorter simulator": "a full ROS 2 install (ros2 CLI)",
    "fence-sorter optimize --case positioned --alpha-k 40 --scheduler tcp://10.0.0.5:8786": (
        "a Dask scheduler at 10.0.0.5 (a local cluster: "
        "test/optimize/test_optimize.py::test_dask_cluster_gives_the_process_pool_optimum)"
    ),
}

#: what this test runs of a README command: the command with smaller amounts, and text its
#: output must hold (the command's own figures, not just an exit status)
#: one run of `fence-sorter run` for the README's run commands that can share it
_RUN = (
    [
        "run",
        "--stream",
        "config/streams/example_manifest.csv",
        "--parcels",
        "3",
        "--rtf",
        "0",
        "--seed",
        "7",
        "--json",
        "--param",
        "controller:a_ndop=150",
    ],
    '"parcels_seen": 3',
)
RUN_HERE: dict[str, tuple[list[str], str]] = {
    "fence-sorter run --parcels 40 --rtf 2 --seed 7": _RUN,
    "fence-sorter run --stream config/streams/example_manifest.csv": _RUN,
    "fence-sorter run --rtf 0 --json": _RUN,
    "fence-sorter run --param controller:a_ndop=150": _RUN,
    "fence-sorter run --duration 60 --bag bags/run1": (
        ["run", "--duration", "4", "--rtf", "2", "--bag", "{tmp}/run1"],
        "parcels seen",
    ),
    "python -m benchmarks bench-suite": (
        ["bench-suite", "--duration", "3", "--unpaced-parcels", "3", "--no-write"],
        "deadline",
    ),
    "fence-sorter analyze bags/example_4_parcels": (
        ["analyze", "bags/example_4_parcels"],
        "SORTED",
    ),
    "fence-sorter rrd bags/example_4_parcels --out /tmp/ex.rrd": (
        ["rrd", "bags/example_4_parcels", "--out", "{tmp}/ex.rrd"],
        "frames",
    ),
    "fence-sorter simulate slide_flexible --json": (
        ["simulate", "slide_flexible", "--json"],
        '"sorted"',
    ),
    "fence-sorter simulate positioned_stiff --set parcel.mass=20 --set drive.alpha_k_deg=35": (
        [
            "simulate",
            "positioned_stiff",
            "--set",
            "parcel.mass=20",
            "--set",
            "drive.alpha_k_deg=35",
        ],
        "sorted",
    ),
    "fence-sorter modes impact_flexible --tip-load 100": (
        ["modes", "impact_flexible", "--tip-load", "100"],
        "Hz",
    ),
    "fence-sorter simulate impact_flexible --set solver.method=generalized_alpha "
    "--set solver.dt=2.5e-4": (
        [
            "simulate",
            "impact_flexible",
            "--set",
            "solver.method=generalized_alpha",
            "--set",
            "solver.dt=2.5e-4",
        ],
        "sorted",
    ),
    "fence-sorter simulate impact_flexible --set solver.method=scipy:Radau "
    "--set solver.rtol=1e-6": (
        [
            "simulate",
            "impact_flexible",
            "--set",
            "solver.method=scipy:Radau",
            "--set",
            "solver.rtol=1e-6",
        ],
        "sorted",
    ),
    "fence-sorter simulate impact_flexible --set solver.method=cyrk:LSODA "
    "--set solver.rtol=1e-6": (
        [
            "simulate",
            "impact_flexible",
            "--set",
            "solver.method=cyrk:LSODA",
            "--set",
            "solver.rtol=1e-6",
        ],
        "sorted",
    ),
    "python -m benchmarks bench": (
        [
            "bench",
            "--quick",
            "--scenes",
            "impact_flexible",
            "--repeats",
            "1",
            "--scipy-cap",
            "5",
            "--out",
            "{tmp}/bench.md",
        ],
        "impact_flexible",
    ),
    "fence-sorter optimize --case positioned --alpha-k 40 --constraints 7,8,11 --json": (
        [
            "optimize",
            "--case",
            "positioned",
            "--alpha-k",
            "40",
            "--constraints",
            "7,8,11",
            "--json",
            "--restarts",
            "1",
        ],
        '"feasible"',
    ),
    "fence-sorter optimize --case arbitrary --alpha-k 35 --w-dop 2.4 --mu1 0.5 --mu2 0.3": (
        [
            "optimize",
            "--case",
            "arbitrary",
            "--alpha-k",
            "35",
            "--w-dop",
            "2.4",
            "--mu1",
            "0.5",
            "--mu2",
            "0.3",
            "--restarts",
            "1",
        ],
        "pcs/h",
    ),
}


def readme_commands() -> list[str]:
    """The command lines of the ``bash`` blocks of the README and the guide, comments stripped."""
    text = "\n".join((REPO / f).read_text() for f in DOCUMENTS)
    commands = []
    for block in re.findall(r"```bash\n(.*?)```", text, re.S):
        for line in block.splitlines():
            command = line.split("  #", 1)[0].split(" # ", 1)[0].strip()
            if command and not command.startswith("#"):
                commands.append(command)
    return commands


def test_every_readme_command_has_its_test() -> None:
    commands = readme_commands()
    missing = [c for c in commands if c not in COVERED and c not in NOT_HERE]
    assert missing == [], f"README commands without a test (add them to COVERED): {missing}"
    stale = [c for c in list(COVERED) + list(NOT_HERE) if c not in commands]
    assert stale == [], f"entries for commands the README no longer has: {stale}"
    assert set(RUN_HERE) <= set(COVERED)


def _functions(path: Path) -> set[str]:
    return {
        node.name
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.FunctionDef)
    }


@pytest.mark.parametrize("command", sorted(COVERED))
def test_the_covering_test_runs_the_command(command: str) -> None:
    """The test named for a command exists and uses its subcommand and every option."""
    file, _, function = COVERED[command].partition("::")
    path = REPO / file
    assert path.is_file() and function in _functions(path), COVERED[command]
    if command in RUN_HERE:
        words = RUN_HERE[command][0]
        source = " ".join(words)
    else:
        source = path.read_text()
    tokens = shlex.split(command)
    wanted = [t for t in tokens if t.startswith("--")]
    if tokens[0] == "fence-sorter":
        wanted.append(tokens[1])
    if tokens[:3] == ["python", "-m", "benchmarks"]:
        wanted.append(tokens[3])
    missing = [w for w in wanted if w not in source]
    assert missing == [], f"{COVERED[command]} does not use {missing} of {command!r}"


def program(command: str) -> str:
    """The module a README command runs: ``python -m benchmarks ...`` the campaigns, else the
    command line ``fence-sorter``."""
    if command.startswith("python -m benchmarks "):
        return "benchmarks"
    return "fence_sorter.cli.main"


#: each distinct run of RUN_HERE once
_RUNS = sorted({(program(c), tuple(args), expected) for c, (args, expected) in RUN_HERE.items()})


@pytest.mark.slow
@pytest.mark.parametrize(
    ("module", "args", "expected"), _RUNS, ids=[" ".join(a[:2]) for _, a, _ in _RUNS]
)
def test_readme_command_runs(
    module: str, args: tuple[str, ...], expected: str, tmp_path: Path
) -> None:
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    done = run_cli(*args, timeout=600, module=module)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert expected in done.stdout, done.stdout[-2000:]


@pytest.mark.slow
def test_make_targets_run_the_documented_commands() -> None:
    """`make run` is the documented `fence-sorter run` and `make test` bootstraps, sources
    scripts/env.sh, runs ruff and pytest over test/ (which holds test/ros and test/cli): what
    make would run, without running it (make test is this very run)."""
    import subprocess

    def dry(target: str) -> str:
        return subprocess.run(
            ["make", "-n", target], cwd=REPO, capture_output=True, text=True, check=True
        ).stdout

    run = dry("run")
    assert "fence-sorter run --parcels 12 --bag bags/run-" in run and "--rrd bags/run-" in run
    test = dry("test")
    assert "scripts/bootstrap.sh" in test and "source scripts/env.sh" in test
    assert "ruff check" in test and "pytest -q test/" in test


#: every generated report of docs/ -> the command of `make reports` that writes it
REPORTS = {
    "docs/reports/accuracy/README.md": "fence-sorter accuracy --out docs/reports/accuracy",
    "docs/reports/stability/README.md": "fence-sorter stability --out docs/reports/stability",
    "docs/reports/paper/fig8.csv": (
        "python -m benchmarks paper-sweep all --no-resume --out docs/reports/paper"
    ),
    "docs/reports/paper/decision-table.csv": "decision-table",
    "config/decision_table.yaml": "--table config/decision_table.yaml",
    "docs/reports/benchmarks.md": "python -m benchmarks bench --out docs/reports/benchmarks.md",
    "docs/reports/bench-suite.json": "--rrd --no-write --json docs/reports/bench-suite.json",
    "docs/reports/reliability.md": "python -m benchmarks faults --out docs/reports/reliability.md",
    "docs/reports/calibration.md": "python -m benchmarks calibrate-bench",
    "docs/reports/line-bench.md": "--out docs/reports/line-bench.md",
    "docs/reports/line-speed.json": "--json docs/reports/line-speed.json",
    "docs/reports/planner.json": "planner-latency --rate-factor 1,2",
    "docs/reports/limits.json": "limits --parcels 60 --rtf 1 --out docs/reports/limits.md",
    "docs/reports/stability/random.json": "stability-random --events 100000 --seed 1",
    "docs/reports/line-scale.json": "line-scale --units 1,2,4,8 --parcels 8 --seed 3 --rtf 1",
    "docs/reports/line-scale-hosts.json": "--seed 3 --hosts 2 --skip-unless-root",
    "docs/reports/startup/README.md": "python -m benchmarks.startup",
    "docs/reports/convergence.json": "python -m benchmarks.convergence",
    "docs/reports/imports.json": "python -m benchmarks.imports",
    "docs/reports/dt_max.json": "python -m benchmarks.dt_max",
}


def test_make_reports_writes_every_generated_report() -> None:
    """`make reports` runs the command of every generated report (each report names the
    command it was made with), the node-suite section of benchmarks.md included: what make
    would run, without running it (hours of CPU)."""
    import subprocess

    run = subprocess.run(
        ["make", "-n", "reports"], cwd=REPO, capture_output=True, text=True, check=True
    ).stdout
    run = " ".join(run.replace("\\\n", " ").split())
    for report, command in REPORTS.items():
        assert (REPO / report).is_file(), report
        assert command in run, f"make reports does not write {report} ({command})"
    assert "python -m benchmarks bench-suite --out docs/reports/benchmarks.md" in run
    assert "--out docs/reports/startup" in run
    assert "--doc docs/reports/calibration.md" in run and "scripts/env.sh" in run
