"""The package as a ROS user installs it: `colcon build` of the workspace (fence_sorter,
msg_defs/ and msg_defs_tf2/) into a temporary install/, then everything from that install
alone, with the source tree moved out of reach: every run-time file installed, the package
imported from install/, `fence-sorter check`, a 4-parcel `fence-sorter run` with a bag, each
node started through lib/fence_sorter/<node> and stopped cleanly, the launch file's
executables, parameter files and defaults checked against the install.

colcon comes from its own venv (scripts/colcon_venv.sh, requirements/colcon.txt). The ROS 2
wheels of the project venv are the underlay, as /opt/ros/<distro> is on a ROS machine: their
site-packages on PYTHONPATH (a plain path: the venv's .pth files, among them the editable
install of this checkout, are not read), their libraries on LD_LIBRARY_PATH.
"""

from __future__ import annotations

import ast
import json
import os
import shutil
import signal
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

import pytest
from processes import run_domain_id, stop_process

from fence_sorter.resources import SHARE_DIRS, installed_files

pytestmark = [pytest.mark.install, pytest.mark.ros, pytest.mark.slow]

REPO = Path(__file__).resolve().parents[2]
NODES = {  # node: the signal that ends it cleanly (both are used)
    "simulator": signal.SIGINT,
    "scanner": signal.SIGTERM,
    "controller": signal.SIGINT,
    "recorder": signal.SIGTERM,
}
TIMEOUT = 120.0
#: not needed to build or run the package
NOT_COPIED = (
    ".git",
    ".venv",
    ".venv-*",
    ".build",
    "bags",
    "docs",
    "__pycache__",
    "*_cache",
    "*.egg-info",
)


class Workspace:
    """A built colcon workspace whose sources were moved away after the build."""

    def __init__(self, root: Path, domain: int) -> None:
        self.root = root
        self.install = root / "install"
        self.prefix = self.install / "fence_sorter"
        self.share = self.prefix / "share" / "fence_sorter"
        self.lib = self.prefix / "lib" / "fence_sorter"
        self.run_dir = root / "run"  # the working directory: no checkout in it or above it
        self.run_dir.mkdir()
        venv = Path(sys.prefix)
        site = Path(sysconfig.get_paths()["purelib"])
        libs = [venv / "lib", *sorted(site.glob("ros_*.libs"))]
        self.env = {
            "HOME": os.environ.get("HOME", str(root)),
            "PATH": f"{colcon_venv() / 'bin'}:/usr/bin:/bin",
            "PYTHONPATH": str(site),
            "LD_LIBRARY_PATH": os.pathsep.join(map(str, libs)),
            "AMENT_PREFIX_PATH": str(venv),
            "CMAKE_PREFIX_PATH": str(venv),
            "ROS_DOMAIN_ID": str(domain),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "ROS_LOG_DIR": str(root / "ros_log"),
            "RERUN": "off",
        }

    def sourced(self, command: str) -> list[str]:
        """``command`` in bash after ``source install/setup.bash``."""
        return ["bash", "-c", f"source {self.install}/setup.bash && {command}"]

    def run(self, command: str, timeout: float = 600.0) -> subprocess.CompletedProcess:
        return subprocess.run(
            self.sourced(command),
            capture_output=True,
            text=True,
            timeout=timeout,
            cwd=self.run_dir,
            env=self.env,
        )


def colcon_venv() -> Path:
    out = subprocess.run(
        ["bash", str(REPO / "scripts" / "colcon_venv.sh")],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    return Path(out.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def ws(tmp_path_factory) -> Workspace:
    """colcon build --paths src/fence_sorter src/fence_sorter/msg_defs{,_tf2}; src moved away."""
    root = tmp_path_factory.mktemp("colcon_ws")
    src = root / "src" / "fence_sorter"
    shutil.copytree(REPO, src, ignore=shutil.ignore_patterns(*NOT_COPIED))
    w = Workspace(root, run_domain_id() + 1)
    python = colcon_venv() / "bin" / "python"
    paths = "src/fence_sorter src/fence_sorter/msg_defs src/fence_sorter/msg_defs_tf2"
    start = time.monotonic()
    out = subprocess.run(
        ["bash", "-c", f"colcon build --paths {paths} --cmake-args "
         f"-DPython3_EXECUTABLE={python} -DBUILD_TESTING=OFF"],
        capture_output=True, text=True, timeout=1200, cwd=root, env=w.env,
    )  # fmt: skip
    assert out.returncode == 0, (out.stdout + out.stderr)[-4000:]
    print(f"colcon build: {time.monotonic() - start:.1f} s")
    (root / "src").rename(root / "src.moved")  # the sources are out of reach from here on
    # the compiled physics kernel of the installed copy, once (as bootstrap.sh's kernel step)
    start = time.monotonic()
    out = w.run(f"{python} -m fence_sorter.warmup", timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    print(f"kernel compiled from install/: {time.monotonic() - start:.1f} s")
    return w


def test_every_run_time_file_is_installed(ws: Workspace):
    """What the resolver may read (every file under config/, launch/, urdf/) is in the share
    directory, byte for byte, and the executables are where ros2 run and PATH look."""
    expected = installed_files()
    assert "urdf/fence_sorter.urdf" in expected and "config/streams/default.yaml" in expected
    found = sorted(
        str(p.relative_to(ws.share))
        for d in SHARE_DIRS
        for p in (ws.share / d).rglob("*")
        if p.is_file()
    )
    assert found == expected
    for rel in expected:
        assert (ws.share / rel).read_bytes() == (REPO / rel).read_bytes(), rel
    marker = ws.prefix / "share" / "ament_index" / "resource_index" / "packages" / "fence_sorter"
    assert marker.is_file()
    for name in [*NODES, "fence-sorter"]:
        assert os.access(ws.lib / name, os.X_OK), name
    assert os.access(ws.prefix / "bin" / "fence-sorter", os.X_OK)


def test_the_package_is_imported_from_the_install(ws: Workspace):
    probe = (
        "import json, fence_sorter, fence_sorter_msgs, tf2_msgs; "
        "from fence_sorter import resources; "
        "print(json.dumps([fence_sorter.__file__, fence_sorter_msgs.__file__, tf2_msgs.__file__,"
        " str(resources.checkout_root()), str(resources.data_root())]))"
    )
    out = ws.run(f"{colcon_venv() / 'bin' / 'python'} -c '{probe}'")
    assert out.returncode == 0, out.stderr
    package, msgs, tf2, checkout, data = json.loads(out.stdout)
    assert Path(package).is_relative_to(ws.prefix)
    assert Path(msgs).is_relative_to(ws.install / "fence_sorter_msgs")
    assert Path(tf2).is_relative_to(ws.install / "tf2_msgs")
    assert checkout == "None"
    assert Path(data) == ws.share


def test_check_passes_from_the_install(ws: Workspace):
    out = ws.run("command -v fence-sorter && fence-sorter check")
    assert out.returncode == 0, out.stdout + out.stderr
    lines = out.stdout.splitlines()
    assert lines[0] == str(ws.prefix / "bin" / "fence-sorter")  # on PATH from install/bin
    assert f"ament index: {ws.lib}/" in out.stdout
    assert "OK   ros 2: " in out.stdout  # the distribution and Fast DDS of the venv
    assert "check: all 6 passed" in out.stdout


def test_a_run_with_a_bag_from_the_install(ws: Workspace):
    bag = ws.root / "bag"
    start = time.monotonic()
    out = ws.run(
        f"fence-sorter run --parcels 4 --bag {bag} --json --log-dir {ws.root / 'run_logs'}",
        timeout=900,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    print(f"fence-sorter run --parcels 4 from install/: {time.monotonic() - start:.1f} s")
    summary = json.loads(out.stdout)
    assert summary["exit"] == 0 and summary["leftover_processes"] == []
    assert summary["parcel_messages"] == summary["outcome_messages"] == 4
    assert summary["sorted_divert"] == summary["divert"]
    stream = summary["scanner"]["stream"]
    assert Path(stream) == ws.share / "config" / "streams" / "default.yaml"
    info = ws.run(f"{ws.lib / 'fence-sorter'} bag info {bag} --json")
    assert info.returncode == 0, info.stderr
    counts = json.loads(info.stdout)["counts"]
    assert counts["/parcels"] == counts["/sort_outcomes"] == 4
    assert counts["/robot_description"] == counts["/tf_static"] == 1
    assert counts["/tf"] > 100


def test_each_node_runs_through_lib(ws: Workspace):
    """Every node started as `ros2 run fence_sorter <node>` starts it (lib/fence_sorter/<node>
    with the installed parameter file), beats on /diagnostics, and ends with status 0."""
    procs = {}
    listener = None
    try:
        for name in NODES:
            extra = f"-p output_dir:={ws.root / 'node_bag'}" if name == "recorder" else ""
            params = ws.share / "config" / f"{name}.yaml"
            procs[name] = subprocess.Popen(
                ws.sourced(
                    f"exec {ws.lib / name} --ros-args --params-file {params} "
                    f"-p heartbeat_period:=0.2 {extra}"
                ),
                cwd=ws.run_dir, env=ws.env, start_new_session=True, text=True,
                stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            )  # fmt: skip
        listener = subprocess.Popen(
            ws.sourced(f"exec fence-sorter topic echo /diagnostics --json --timeout {TIMEOUT}"),
            cwd=ws.run_dir, env=ws.env, start_new_session=True, text=True,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        )  # fmt: skip
        beating: set[str] = set()
        deadline = time.monotonic() + TIMEOUT
        while beating != set(NODES) and time.monotonic() < deadline:
            line = listener.stdout.readline()
            if not line:
                break
            for status in json.loads(line)["status"]:
                beating.add(status["name"].removeprefix("fence_sorter/"))
        assert beating >= set(NODES), f"no heartbeat from {set(NODES) - beating}"
        for name, sig in NODES.items():
            os.killpg(procs[name].pid, sig)
        for name, proc in procs.items():
            out, err = proc.communicate(timeout=60)
            assert proc.returncode == 0, f"{name}: {proc.returncode}\n{err[-2000:]}"
            assert "Traceback" not in out + err, err[-2000:]
    finally:
        for proc in [*procs.values(), listener]:
            if proc is not None:
                stop_process(proc)


def test_launch_file_against_the_install(ws: Workspace):
    """No `launch` wheel exists here, so the launch file is parsed, not run: its executables
    are installed entry points, its parameter files are in the installed share, its default
    scene and stream resolve there, and every parameter it sets is one the node declares."""
    from fence_sorter.nodes.base import COMMON_PARAMETERS
    from fence_sorter.nodes.controller import ControllerNode
    from fence_sorter.nodes.recorder import RecorderNode
    from fence_sorter.nodes.scanner import ScannerNode
    from fence_sorter.nodes.sensors import SensorsNode
    from fence_sorter.nodes.simulator import SimulatorNode

    declared = {
        node.NODE_NAME: {p.name for p in (*COMMON_PARAMETERS, *node.PARAMETERS)}
        for node in (SimulatorNode, ScannerNode, ControllerNode, RecorderNode, SensorsNode)
    }
    tree = ast.parse((ws.share / "launch" / "sorter.launch.py").read_text())
    defaults = {}
    nodes = {}
    for call in ast.walk(tree):
        if not isinstance(call, ast.Call):
            continue
        name = getattr(call.func, "id", "")
        kw = {k.arg: k.value for k in call.keywords if k.arg}
        if name == "DeclareLaunchArgument":
            defaults[call.args[0].value] = kw["default_value"].value
        elif name == "Node":
            nodes[kw["executable"].value] = kw["parameters"]
    assert set(nodes) == {*NODES, "sensors"}
    for exe, params in nodes.items():
        assert os.access(ws.lib / exe, os.X_OK), exe
        files = [ast.unparse(e) for e in params.elts if not isinstance(e, ast.Dict)]
        if exe == "sensors":  # no parameter file, as the runner starts it
            assert files == [] and not (ws.share / "config" / "sensors.yaml").exists()
            continue
        assert files == [f"str(config / '{exe}.yaml')"], files
        assert (ws.share / "config" / f"{exe}.yaml").is_file()
        keys = {
            k.value
            for e in params.elts
            if isinstance(e, ast.Dict)
            for k in e.keys
            if isinstance(k, ast.Constant)
        }
        assert keys <= declared[exe] | {"use_sim_time"}, keys - declared[exe]
    assert (ws.share / "config" / "scenes" / f"{defaults['scene']}.yaml").is_file()
    assert (ws.share / "config" / "streams" / f"{defaults['stream']}.yaml").is_file()
