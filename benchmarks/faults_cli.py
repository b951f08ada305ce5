"""The fault campaign's bad input at the command line (see :mod:`benchmarks.faults`): the
catalogue of files, scenes, streams and parameters, and one case run."""

from __future__ import annotations

import random
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from benchmarks.faults_processes import fence_sorter_cmd
from fence_sorter.resources import data_path


# -- bad input at the command line -----------------------------------------------------------
@dataclass(frozen=True)
class CliCase:
    category: str  # files | scenes | streams | parameters
    name: str
    argv: tuple[str, ...]  # {dir} is the case's scratch directory
    files: dict = field(default_factory=dict)  # name -> bytes
    expected: int = 2


def _nested(depth: int) -> bytes:
    return ("[" * depth + "]" * depth).encode()


def cli_cases() -> list[CliCase]:
    scene_ok = data_path("config", "scenes", "impact_flexible.yaml").read_bytes()
    run = ("run", "--parcels", "1", "--rtf", "0", "--timeout", "120")
    csv_head = b"parcel_id,arrival_time,length_a,width_b,height,mass,divert\n"

    def scene(name: str, data: bytes) -> CliCase:
        return CliCase("scenes", name, (*run, "--scene", "{dir}/s.yaml"), {"s.yaml": data})

    def stream(name: str, data: bytes, ext: str = "csv") -> CliCase:
        return CliCase("streams", name, (*run, "--stream", f"{{dir}}/m.{ext}"), {f"m.{ext}": data})

    def param(name: str, *argv: str) -> CliCase:
        return CliCase("parameters", name, (*run, *argv))

    junk = bytes(random.Random(7).getrandbits(8) for _ in range(4096))
    return [
        scene("non-UTF-8 scene", b"\xff\xfe\x00conveyor: {belt_speed: 1}\n"),
        scene("deeply nested scene", _nested(5000)),
        scene("empty scene", b""),
        scene("scene is a list", b"- 1\n- 2\n"),
        scene("unknown key", scene_ok + b"\nbogus_key: 1\n"),
        scene("negative belt speed", scene_ok.replace(b"belt_speed: 1.0", b"belt_speed: -1.0")),
        scene("random bytes", junk),
        CliCase("scenes", "missing scene file", (*run, "--scene", "{dir}/none.yaml")),
        stream("mass not a number", csv_head + b"1,0,0.4,0.3,0.2,x,true\n"),
        stream("negative mass", csv_head + b"1,0,0.4,0.3,0.2,-5,true\n"),
        stream("duplicate parcel id", csv_head + b"1,0,0.4,0.3,0.2,5,true\n1,2,0.4,0.3,0.2,5,y\n"),
        stream("unknown column", b"parcel_id,colour\n1,red\n"),
        stream("missing column", b"parcel_id,arrival_time\n1,0\n"),
        stream("empty manifest", b""),
        stream("non-UTF-8 manifest", b"\xff\xfe" + csv_head),
        stream("wider than the belt", csv_head + b"1,0,0.4,0.9,0.2,5,true\n"),
        stream(
            "mu_fence 5",
            csv_head.replace(b",divert", b",mu_fence,divert") + b"1,0,0.4,0.3,0.2,5,5,1\n",
        ),
        stream("rate 0 in a stream config", b"stream:\n  rate_pcs_h: 0\n  parcel: {}\n", "yaml"),
        stream("deeply nested stream config", _nested(5000), "yaml"),
        stream("unknown distribution", b"stream:\n  parcel:\n    mass: {dist: zipf}\n", "yaml"),
        param("--param without NODE:", "--param", "a_ndop=150"),
        param("--param unknown node", "--param", "planner:a_ndop=150"),
        param("--param unknown key", "--param", "controller:no_such_key=1"),
        param("--param out of range", "--param", "controller:a_ndop=-5"),
        param("--param wrong type", "--param", "simulator:real_time_factor=fast"),
        param("--param loop_cpu 99", "--param", "simulator:loop_cpu=99"),
        param("--rtf -1", "--rtf", "-1"),
        CliCase("parameters", "--parcels 0", ("run", "--parcels", "0")),
        CliCase("parameters", "--duration -5", ("run", "--duration", "-5")),
        CliCase("parameters", "--seed -1", ("run", "--parcels", "1", "--seed", "-1")),
        CliCase("parameters", "--rrd into a missing directory", (*run, "--rrd", "{dir}/no/x.rrd")),
        CliCase("files", "analyze: zero-byte .mcap", ("analyze", "{dir}/b"), {"b/b_0.mcap": b""}),
        CliCase("files", "analyze: random bytes", ("analyze", "{dir}/b"), {"b/b_0.mcap": junk}),
        CliCase(
            "files",
            "analyze: bad magic",
            ("analyze", "{dir}/b"),
            {"b/b_0.mcap": b"\x89XCAP0\r\n" + junk},
        ),
        CliCase("files", "analyze: missing bag", ("analyze", "{dir}/nothing")),
        CliCase(
            "files",
            "rrd: random bytes",
            ("rrd", "{dir}/b", "--out", "{dir}/o.rrd"),
            {"b/b_0.mcap": junk},
        ),
        CliCase(
            "files",
            "rrd: zero-byte .mcap",
            ("rrd", "{dir}/b", "--out", "{dir}/o.rrd"),
            {"b/b_0.mcap": b""},
        ),
    ]


@dataclass
class CliResult:
    case: CliCase
    code: int | None
    traceback: bool
    line: str  # the last line on stderr
    output_written: bool
    ok: bool


def run_cli_case(case: CliCase, workdir: Path) -> CliResult:
    d = Path(tempfile.mkdtemp(prefix="case-", dir=workdir))
    for name, data in case.files.items():
        (d / name).parent.mkdir(parents=True, exist_ok=True)
        (d / name).write_bytes(data)
    argv = [a.replace("{dir}", str(d)) for a in case.argv]
    try:
        proc = subprocess.run(
            fence_sorter_cmd(*argv), capture_output=True, text=True, timeout=300.0, cwd=d
        )
        code, out, err = proc.returncode, proc.stdout, proc.stderr
    except subprocess.TimeoutExpired as exc:
        code, out, err = None, str(exc.stdout or ""), str(exc.stderr or "")
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    written = (d / "o.rrd").exists()
    tb = "Traceback" in out + err
    ok = code == case.expected and not tb and bool(lines) and not written
    return CliResult(case, code, tb, lines[-1] if lines else "", written, ok)
