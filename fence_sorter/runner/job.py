"""`fence-sorter run` end to end: validate the input, start the nodes as separate processes on
an isolated ROS domain, watch the run until every parcel has its outcome, stop cleanly, sum up.
"""

from __future__ import annotations

import json
import math
import os
import secrets
import shutil
import signal
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import yaml

from fence_sorter.calibration.sensors import load_sensors, resolve_sensors
from fence_sorter.capacity.constraints import ConstraintProfile
from fence_sorter.inputs import ParcelSpec
from fence_sorter.nodes.parameters import (
    NODE_PARAMETERS,
    ParamOverrideError,
    ParamValue,
    parse_override,
    ros_value,
)
from fence_sorter.physics.params import ParameterError
from fence_sorter.provenance import RUN_KEY_ENV, new_run_key, run_key
from fence_sorter.recording.topics import MEASURED, TOPICS
from fence_sorter.resources import data_path
from fence_sorter.rosdistro import set_profile
from fence_sorter.runner.monitor import MONITOR_NAME, Monitor, Records
from fence_sorter.runner.processes import (
    FASTDDS_PROFILE,
    DomainError,
    ProcessGroup,
    choose_domain,
    clean_shm,
    leftovers,
    node_command,
    node_env,
    wait_until,
)
from fence_sorter.runner.summary import recording_failure, summarise, verdict
from fence_sorter.runner.transport import (
    HostsTransport,
    TransportError,
    hosts_transport,
    write_profile,
)
from fence_sorter.scene import DEFAULT_SCENE, load_scene, resolve_scene, scene_text
from fence_sorter.stream import DEFAULT_STREAM, load_stream, resolve_stream
from fence_sorter.visualisation.foxglove_address import AddressError, check_free, parse_address

DEFAULT_PARCELS = 20
SCAN_LINE_X = -3.0
START_DELAY = 0.5
#: sim time a parcel needs after its scan to leave the line (line end ~3 m) plus margin [s]
LINE_END_X = 3.0
STOP_ORDER = ("scanner", "controller", "simulator", "sensors", "recorder", "foxglove")
#: the run's key in its log directory (mode 0600), for `fence-sorter param set --key-file`
RUN_KEY_FILE = "run.key"
#: controller parameters the simulator takes too (the limits of its outcomes' damage margins)
DAMAGE_LIMITS = ("w_dop", "a_ndop")
#: the nodes that share the run's id (parameter run_id) on /parcels and /fence_commands
RUN_ID_NODES = ("scanner", "controller", "simulator", "sensors")
#: wall time after the scanner's start without any parcel on /parcels before the run gives up
NO_PARCEL_TIMEOUT = 60.0
#: nodes the run restarts when they die (the others end the run with exit 1), and how often
RESTARTABLE = ("controller",)
MAX_CONTROLLER_RESTARTS = 3
#: the highest rate of the simulator's state in a run with sensors [Hz of sim time]: a sensor
#: sampling faster interpolates between states (docs/guide/calibration.md); the sensors node and
#: the recorder keep up with it on a loaded 2-CPU machine at rtf 1, not with 1 kHz
MAX_STATE_RATE = 250.0
#: the upper end of the simulator's publish_rate parameter [Hz of wall time when paced]
MAX_PUBLISH_RATE = next(
    s.max_value for s in NODE_PARAMETERS["simulator"] if s.name == "publish_rate"
)

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130
#: the node logs of a run without --log-dir
LOG_DIR_PREFIX = "fence_sorter_run_"


class BadInput(ValueError):
    """Bad command-line input: one line, exit status 2."""


@dataclass
class RunOptions:
    scene: str = DEFAULT_SCENE
    parcels: int | None = None
    duration: float | None = None
    rtf: float = 1.0
    bag: str | None = None
    rrd: str | None = None
    stream: str = DEFAULT_STREAM
    seed: int | None = None
    timeout: float | None = None
    log_dir: str | None = None
    heartbeat_period: float = 1.0
    params: list[str] = field(default_factory=list)  # NODE:KEY=VALUE
    domain: int | None = None  # ROS domain (None: ROS_DOMAIN_ID if set, else a free one)
    keep_logs: bool = False  # keep the node logs of a clean run too
    sensors: str | None = None  # sensors file or name: the sensors node runs (and is recorded)
    foxglove: str | None = None  # [HOST:]PORT: the Foxglove node serves the run there
    interface: str | None = None  # IPv4 address: the run talks to other hosts on it
    peers: str | None = None  # comma-separated IPv4 addresses of the other hosts
    overrides: list[str] = field(default_factory=list)  # --set KEY=VALUE of the scene
    rate: float | None = None  # [pcs/h]: the stream config's parcel mix at this rate


#: what --rate accepts [pcs/h]
RATE_RANGE = (1.0, 1e5)


@dataclass
class RunResult:
    code: int
    summary: dict
    message: str
    log_dir: Path
    pgids: list[int]
    leftovers: list[int]
    exit_codes: dict[str, int | None]
    records: object = None


@dataclass
class RunPlan:
    """What the job will run (validated input)."""

    scene_path: Path
    belt_speed: float
    belt_width: float
    stream_path: Path
    expected_ids: list[int]
    sim_duration: float  # expected sim time until the last parcel leaves the line [s]
    node_params: dict[str, dict[str, ParamValue]]  # checked --param values by node
    domain: int  # ROS_DOMAIN_ID of the run, free when checked
    divert_ids: list[int] = field(default_factory=list)
    sensors_path: Path | None = None  # the sensors file of a run with sensors
    truth: dict | None = None  # what a calibration bag of the run is made from (its metadata)
    state_rate: float = 0.0  # the state's rate the sensors need [Hz of sim time]; 0: default
    foxglove: tuple[str, int] | None = None  # host and port of the Foxglove node
    transport: HostsTransport | None = None  # the other hosts' transport (None: this host)
    #: the run's identity on the wire (drawn per run; messages with another are foreign)
    run_id: int = field(default_factory=lambda: 1 + secrets.randbelow(2**63 - 1))
    #: the run's key (hex; fence_sorter.provenance): its nodes' tags on what they send, handed
    #: to them in their environment only
    run_key: str = field(default_factory=new_run_key, repr=False)
    #: the stream the run's scanner publishes, by parcel id (what the summary covers)
    stream: dict[int, ParcelSpec] = field(default_factory=dict, repr=False)
    #: the limits (10)-(12) and active constraints the controller plans with: what every
    #: sorted parcel's delivered figures are judged against
    limits: ConstraintProfile = field(default_factory=ConstraintProfile)
    #: the scene with the --set overrides (YAML), written for the nodes at the start; None: none
    scene_yaml: str | None = field(default=None, repr=False)


def controller_limits(overrides: dict[str, ParamValue]) -> ConstraintProfile:
    """The controller's limits (10)-(12) and active constraints: config/controller.yaml with
    the run's ``--param controller.KEY=VALUE`` over it. BadInput names a bad value."""
    doc = yaml.safe_load(data_path("config", "controller.yaml").read_text()) or {}
    values = {**((doc.get("controller") or {}).get("ros__parameters") or {}), **overrides}
    data = {k: values[k] for k in ("w_dop", "a_ndop", "ydot_dop") if k in values}
    if "active_constraints" in values:
        data["active"] = list(values["active_constraints"])
    try:
        return ConstraintProfile.from_mapping(data, "controller")
    except ParameterError as exc:
        msg = str(exc).replace("controller.active", "controller.active_constraints")
        raise BadInput(msg) from None


def make_bag_dir(bag: str) -> None:
    """Make the bag directory ``--bag`` names (its parents too); a path that cannot be a
    directory is a ValueError naming the option."""
    try:
        Path(bag).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(
            f"--bag must be a directory that exists or can be made, got {bag} ({exc.strerror})"
        ) from None


def prepare(opts: RunOptions) -> RunPlan:
    """Check every input before anything starts; BadInput names the option and the range."""
    if opts.parcels is not None and opts.parcels < 1:
        raise BadInput(f"--parcels must be in [1, inf), got {opts.parcels}")
    if opts.duration is not None and not opts.duration > 0:
        raise BadInput(f"--duration must be in (0, inf) s, got {opts.duration}")
    if not (math.isfinite(opts.rtf) and 0.0 <= opts.rtf <= 100.0):
        raise BadInput(f"--rtf must be in [0, 100] (0: unpaced), got {opts.rtf}")
    if opts.seed is not None and opts.seed < 0:
        raise BadInput(f"--seed must be in [0, inf), got {opts.seed}")
    lo, hi = RATE_RANGE
    if opts.rate is not None and not (math.isfinite(opts.rate) and lo <= opts.rate <= hi):
        raise BadInput(f"--rate must be in [{lo:g}, {hi:g}] pcs/h, got {opts.rate:g}")
    if opts.rrd is not None:
        rrd = Path(opts.rrd)
        if rrd.suffix != ".rrd" or not rrd.resolve().parent.is_dir():
            raise BadInput(f"--rrd must be a .rrd file in an existing directory, got {opts.rrd}")
    if opts.bag:
        try:
            make_bag_dir(opts.bag)
        except ValueError as exc:
            raise BadInput(str(exc)) from None
    try:
        scene_path = resolve_scene(opts.scene).resolve()
        base = load_scene(scene_path, opts.overrides).scenario
        scene_yaml = scene_text(scene_path, opts.overrides) if opts.overrides else None
    except (ParameterError, OSError) as exc:
        raise BadInput(str(exc)) from None
    v, width = base.conveyor.belt_speed, base.conveyor.width
    count = opts.parcels if opts.parcels is not None or opts.duration is not None else None
    if count is None and opts.duration is None:
        count = DEFAULT_PARCELS
    try:
        stream_path = resolve_stream(opts.stream).resolve()
        stream = load_stream(
            stream_path,
            v,
            count=count,
            duration=opts.duration,
            seed=opts.seed,
            belt_width=width,
            rate_pcs_h=opts.rate,
        )
    except (ParameterError, OSError) as exc:
        raise BadInput(str(exc)) from None
    if not stream:
        raise BadInput(f"stream {stream_path}: no parcels within the requested count/duration")
    node_params: dict[str, dict[str, ParamValue]] = {}
    for item in opts.params:
        try:
            node, key, value = parse_override(item, STOP_ORDER)
        except ParamOverrideError as exc:
            raise BadInput(str(exc)) from None
        node_params.setdefault(node, {})[key] = value
    # the outcomes' damage margins are taken against the limits the controller plans with
    for key in DAMAGE_LIMITS:
        given = node_params.get("controller", {})
        if key in given and key not in node_params.get("simulator", {}):
            node_params.setdefault("simulator", {})[key] = given[key]
    sensors_path, truth, state_rate = None, None, 0.0
    if opts.sensors is not None:
        sensors_path, truth = _sensors_truth(opts, scene_path, base, stream)
        truth["seed"] = node_params.get("sensors", {}).get("seed", truth["seed"])
        cfg = load_sensors_arg(sensors_path)
        state_rate = sensors_state_rate(cfg, base, opts.rtf, opts.sensors)
    foxglove = None
    if opts.foxglove is not None:
        try:
            foxglove = parse_address(opts.foxglove)
            check_free(foxglove)
        except AddressError as exc:
            raise BadInput(str(exc)) from None
    transport = None
    if (opts.interface is None) != (opts.peers is None):
        raise BadInput("--interface and --peers go together (this host's address, the others')")
    if opts.interface is not None:
        try:
            transport = hosts_transport(opts.interface, opts.peers)
        except TransportError as exc:
            raise BadInput(str(exc)) from None
    sim_duration = START_DELAY + stream[-1].arrival_time + (LINE_END_X - SCAN_LINE_X) / v + 5.0
    try:
        domain = choose_domain(opts.domain)
    except DomainError as exc:
        raise BadInput(str(exc)) from None
    return RunPlan(
        scene_path,
        v,
        width,
        stream_path,
        [s.parcel_id for s in stream],
        sim_duration,
        node_params,
        domain,
        [s.parcel_id for s in stream if s.divert],
        sensors_path=sensors_path,
        truth=truth,
        state_rate=state_rate,
        stream={s.parcel_id: s for s in stream},
        foxglove=foxglove,
        transport=transport,
        limits=controller_limits(node_params.get("controller", {})),
        scene_yaml=scene_yaml,
    )


def scanner_stream_args(plan: RunPlan, opts: RunOptions) -> list[str]:
    """The scanner's stream parameters: it draws the plan's stream again."""
    out = [f"stream:={plan.stream_path}"]
    if opts.parcels is not None or opts.duration is None:
        out.append(f"parcels:={len(plan.expected_ids)}")
    if opts.duration is not None:
        out.append(f"duration:={opts.duration}")
    if opts.seed is not None:
        out.append(f"seed:={opts.seed}")
    if opts.rate is not None:
        out.append(f"rate:={float(opts.rate)}")
    return out


def with_scene_file(plan: RunPlan, log_dir: Path) -> RunPlan:
    """The plan whose nodes read the scene with the --set overrides: written to
    LOG_DIR/scene_set/ under the scene file's own name; the plan itself without overrides."""
    if plan.scene_yaml is None:
        return plan
    path = log_dir / "scene_set" / plan.scene_path.name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(plan.scene_yaml, encoding="utf-8")
    return replace(plan, scene_path=path)


def load_sensors_arg(sensors: str | Path):
    """The sensors file of ``--sensors`` (a path or a name under config/sensors/); BadInput
    names it and the key."""
    try:
        return load_sensors(sensors)
    except ParameterError as exc:
        raise BadInput(f"--sensors: {exc}") from None


def sensors_state_rate(cfg, base, rtf: float, label: str | None = None) -> float:
    """The simulator state's rate [Hz of sim time] the sensors ``cfg`` need on scene ``base``
    (the highest sensor rate, at most MAX_STATE_RATE); BadInput unless ``rtf`` paces the run
    within (0, MAX_PUBLISH_RATE / that rate]: unpaced the simulator publishes faster than the
    sensors node takes its state, and beyond it the state is sparser than they need."""
    rates = [cfg.encoder.rate, cfg.camera.rate]
    rates += [cfg.strain.rate] if cfg.strain is not None and base.fence is not None else []
    state_rate = min(max(rates), MAX_STATE_RATE)
    rtf_max = MAX_PUBLISH_RATE / state_rate
    if not 0.0 < rtf <= rtf_max:
        raise BadInput(
            f"--rtf must be in (0, {rtf_max:g}] with --sensors {label or cfg.name} (the state at "
            f"{state_rate:g} Hz of sim time, at most {MAX_PUBLISH_RATE:g} Hz of wall time), "
            f"got {rtf:g}"
        )
    return state_rate


def sensors_node_parameters(scene: str, sensors: str, seed: int, state_rate: float) -> dict:
    """The sensors node's parameters in a run (``fence-sorter run`` and the launch file)."""
    return {
        "scene": scene,
        "sensors": sensors,
        "seed": seed,
        # no lost state is bridged: across one, interpolating the truth misses an impact by
        # several noise levels (the samples there are dropped and counted)
        "max_state_gap": 1.5 / state_rate,
    }


def state_publish_rate(state_rate: float, rtf: float) -> float:
    """The simulator's publish_rate for ``state_rate`` Hz of sim time: wall Hz when paced (sim
    Hz x rtf), sim Hz when unpaced; within the parameter's [1, 1000]."""
    return min(max(state_rate * rtf if rtf > 0.0 else state_rate, 1.0), MAX_PUBLISH_RATE)


def _sensors_truth(opts: RunOptions, scene_path: Path, base, stream) -> tuple[Path, dict]:
    """The sensors file of the run and the truth its bag carries: the scene's fit parameters
    (a friction the stream sets per parcel is no single truth and is left out), the sensors,
    the noise seed and the stream."""
    from fence_sorter.calibration.emulate import truth_record  # lazy: the physics, numba

    try:
        path = resolve_sensors(opts.sensors).resolve()
    except ParameterError as exc:
        raise BadInput(f"--sensors: {exc}") from None
    sensors = load_sensors_arg(path)
    truth = truth_record(
        scene_path.stem,
        base,
        sensors,
        sensors_seed(opts),
        source="fence-sorter run",
        sensors_file=str(path),
        sensors_spec=asdict(sensors),
        stream=opts.stream,
        stream_seed=opts.seed,
    )
    for key in ("mu_belt", "mu_fence"):
        if any(not math.isnan(getattr(s, key)) for s in stream):
            truth["values"].pop(key, None)
    return path, truth


def sensors_seed(opts: RunOptions) -> int:
    """The sensors' noise seed: the run's --seed + 1 (as ``fence-sorter emulate``), else 1."""
    return (opts.seed if opts.seed is not None else 0) + 1


def _ros_args(node: str, plan: RunPlan, opts: RunOptions, extra: list[str]) -> list[str]:
    args: list[str] = []
    params_file = data_path("config", f"{node}.yaml")
    if params_file.is_file():
        args += ["--params-file", str(params_file)]
    overrides = [f"heartbeat_period:={opts.heartbeat_period}", *extra]
    if node in RUN_ID_NODES:
        overrides.append(f"run_id:={plan.run_id}")
    overrides += [f"{k}:={ros_value(v)}" for k, v in plan.node_params.get(node, {}).items()]
    for o in overrides:
        args += ["-p", o]
    return args


#: the run gives up on parcels without an outcome past the stream's end only after this much
#: wall time without any new outcome [s]
STALL_TIMEOUT = 10.0


def loop_cpu(plan: RunPlan, rtf: float, cpus: set[int]) -> tuple[int, bool]:
    """The simulator's ``loop_cpu`` for this run and whether the run sets it: a ``--param``
    override as given (-1 turns pinning off), else config/simulator.yaml's if >= 0, else, for
    a paced run on two CPUs or more, the last CPU (set by the run)."""
    if "loop_cpu" in plan.node_params.get("simulator", {}):
        return int(plan.node_params["simulator"]["loop_cpu"]), False
    try:
        doc = yaml.safe_load(data_path("config", "simulator.yaml").read_text()) or {}
        configured = int(doc["simulator"]["ros__parameters"].get("loop_cpu", -1))
    except (OSError, KeyError, TypeError, ValueError):
        configured = -1
    if configured >= 0:
        return configured, False
    if rtf > 0.0 and len(cpus) >= 2:
        return max(cpus), True
    return -1, False


class Interrupted(Exception):
    """A stop signal arrived (raised by :meth:`StopRequest.check`, never from a handler)."""


class StopRequest:
    """SIGINT and SIGTERM as a flag: the handler only records the signal, the job checks it
    where it waits (:meth:`check`), so no signal can interrupt a start or a stop half-way;
    any number of them end the run the same way, each one after the first only hurries the
    stop (:meth:`urgent`)."""

    def __init__(self) -> None:
        self.signals: list[int] = []
        self._seen_by_stop = 0
        self._previous: dict[int, object] = {}

    def __call__(self, signum, frame) -> None:
        self.signals.append(signum)

    def install(self) -> None:
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._previous[sig] = signal.signal(sig, self)

    def restore(self) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()

    def check(self) -> None:
        if self.signals:
            raise Interrupted(signal.Signals(self.signals[0]).name)

    def urgent(self) -> bool:
        """A signal arrived since the stop began (or before it)."""
        return len(self.signals) > self._seen_by_stop

    def stopping(self) -> None:
        self._seen_by_stop = len(self.signals)


def run_job(
    opts: RunOptions, say: Callable[[str], None] = print, stop: StopRequest | None = None
) -> RunResult:
    """Run the suite once; never leaves a node process behind: SIGINT or SIGTERM, any
    number of them at any moment, end it with EXIT_INTERRUPTED (``stop``: a StopRequest
    installed earlier by the caller, so that signals during its imports count too)."""
    own = stop is None
    if own:
        stop = StopRequest()
        stop.install()
    affinity = os.sched_getaffinity(0)  # _run may keep this thread off the loop's CPU
    try:
        plan = prepare(opts)
        return _run(plan, opts, say, stop)
    finally:
        os.sched_setaffinity(0, affinity)
        if own:
            stop.restore()


def _run(
    plan: RunPlan, opts: RunOptions, say: Callable[[str], None], stop: StopRequest
) -> RunResult:
    domain = plan.domain
    log_dir = Path(opts.log_dir or tempfile.mkdtemp(prefix=LOG_DIR_PREFIX))
    log_dir.mkdir(parents=True, exist_ok=True)
    plan = with_scene_file(plan, log_dir)
    profile = FASTDDS_PROFILE
    if plan.transport is not None:
        profile = write_profile(plan.transport, log_dir)
    env = node_env(domain, log_dir / "ros", {RUN_KEY_ENV: plan.run_key}, profile)
    # the key for `fence-sorter param set --key-file`: changes at run time from the run's user
    key_file = log_dir / RUN_KEY_FILE
    fd = os.open(key_file, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(plan.run_key + "\n")
    clean_shm()  # what killed runs (of any program) left in /dev/shm
    # this process's participant (the monitor) on the nodes' transports
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = env["ROS_AUTOMATIC_DISCOVERY_RANGE"]
    set_profile(os.environ, str(profile))
    # paced with the loop pinned: every other process of the run keeps off the loop's CPU, so
    # its work does not evict the loop's caches while the loop sleeps (docs/design/simulator.md)
    allowed = set(os.sched_getaffinity(0))
    pinned, set_here = loop_cpu(plan, opts.rtf, allowed)
    others = allowed - {pinned}
    cpus = others if pinned >= 0 and opts.rtf > 0.0 and others else None
    group = ProcessGroup(env, log_dir, cpus)
    monitor = None
    code, message = EXIT_OK, "done"
    stalled = False  # the nodes ran on, but outcomes stayed missing (stall or timeout)
    count = len(plan.expected_ids)
    scene = f"scene:={plan.scene_path}"
    wall0 = time.monotonic()
    try:
        stop.check()
        say(
            f"fence-sorter run: {count} parcels from {plan.stream_path.name}, scene "
            f"{plan.scene_path.stem}, rtf {opts.rtf:g}, ROS domain {domain}, logs {log_dir}"
        )
        group.start(
            "controller",
            node_command(
                "controller",
                _ros_args(
                    "controller",
                    plan,
                    opts,
                    [scene, "use_sim_time:=true", f"warmup_stream:={plan.stream_path}"],
                ),
            ),
        )
        # the stream starts once these nodes subscribe to their topics (by name in the graph)
        gate = ["simulator", "controller", MONITOR_NAME]
        gate += ["recorder"] if opts.bag else []
        gate += ["sensors"] if plan.sensors_path else []
        gate += ["foxglove"] if plan.foxglove else []
        if plan.foxglove:
            host, port = plan.foxglove
            group.start(
                "foxglove",
                node_command(
                    "foxglove_bridge",
                    _ros_args(
                        "foxglove",
                        plan,
                        opts,
                        [f"host:={host}", f"port:={port}", "use_sim_time:=true"],
                    ),
                ),
            )
        if opts.bag:
            rec_args = _recorder_args(plan, opts, log_dir)
            group.start(
                "recorder",
                node_command("recorder", _ros_args("recorder", plan, opts, rec_args)),
            )
        if plan.sensors_path:
            group.start(
                "sensors",
                node_command(
                    "sensors",
                    _ros_args(
                        "sensors",
                        plan,
                        opts,
                        [
                            f"{k}:={v}"
                            for k, v in sensors_node_parameters(
                                str(plan.scene_path),
                                str(plan.sensors_path),
                                sensors_seed(opts),
                                plan.state_rate,
                            ).items()
                        ],
                    ),
                ),
            )
        # every node process starts at once, the scanner too (their imports and DDS discovery
        # overlap): its start gate holds the stream until each node subscribes to its topics
        group.start(
            "simulator",
            node_command(
                "simulator",
                _ros_args(
                    "simulator",
                    plan,
                    opts,
                    [scene, f"real_time_factor:={opts.rtf}"]
                    + ([f"loop_cpu:={pinned}"] if set_here else [])
                    + (
                        [f"publish_rate:={state_publish_rate(plan.state_rate, opts.rtf)}"]
                        if plan.state_rate
                        and "publish_rate" not in plan.node_params.get("simulator", {})
                        else []
                    )
                    + (
                        [
                            f"rrd_path:={Path(opts.rrd).resolve()}",
                            f"rrd_scan_line_x:={SCAN_LINE_X}",
                        ]
                        if opts.rrd
                        else []
                    ),
                ),
            ),
        )
        scanner_args = [
            scene,
            "use_sim_time:=true",
            *scanner_stream_args(plan, opts),
            f"scan_line_x:={SCAN_LINE_X}",
            f"start_delay:={START_DELAY}",
            f"start_gate:={','.join(gate)}",
        ]
        group.start(
            "scanner", node_command("scanner", _ros_args("scanner", plan, opts, scanner_args))
        )
        # this process's node once the node processes are on their way: its rclpy import
        # and set-up (~0.1-0.5 s) overlap with their imports, which take longer, so it is
        # still the first /diagnostics listener each node finds (their first heartbeat goes
        # to the first one)
        if cpus is not None:  # this thread, after the nodes' start (they inherit it), and
            os.sched_setaffinity(0, cpus)  # the monitor's threads created from it
        monitor = Monitor(
            domain,
            MONITOR_NAME,
            run_id=plan.run_id,
            run_key=run_key({RUN_KEY_ENV: plan.run_key}),
            stream=plan.stream,
        )
        stop.check()
        up = {}  # node -> seconds from the start to the arrival of its first heartbeat
        for node, timeout in (
            ("controller", 120.0),
            *((("recorder", 60.0),) if opts.bag else ()),
            *((("sensors", 60.0),) if plan.sensors_path else ()),
            *((("foxglove", 60.0),) if plan.foxglove else ()),
            ("simulator", 60.0),
            ("scanner", 60.0),
        ):
            _wait_for(monitor, group, stop, node, timeout)
            first = monitor.records.diagnostics_history[f"fence_sorter/{node}"][0]
            up[node] = float(first["_wall"]) - wall0
        # the controller listens to /parcels once the simulator has matched its commands
        _wait_for(monitor, group, stop, "controller", 30.0, listening=True)
        scanner_started = time.monotonic()  # the stream may start from here
        beats = ", ".join(f"{node} {t:.1f} s" for node, t in up.items())
        say(f"nodes up in {time.monotonic() - wall0:.1f} s (heartbeats: {beats}); running")
        # their start-up used both CPUs; the run keeps them off the loop's
        group.confine()
        timeout = opts.timeout or 120.0 + 3.0 * plan.sim_duration / max(opts.rtf, 1.0)
        deadline = time.monotonic() + timeout
        expected = set(plan.expected_ids)
        sim_start = None
        outcomes_seen, last_outcome = 0, time.monotonic()
        recording_told = False
        while True:
            monitor.spin_for(0.1)
            stop.check()
            rec = monitor.records
            if not recording_told:
                recording_told = _tell_recording_failure(rec, say)
            if expected <= rec.outcomes.keys():
                break
            if len(rec.outcomes) > outcomes_seen:
                outcomes_seen, last_outcome = len(rec.outcomes), time.monotonic()
            dead = group.dead()
            if (
                dead
                and dead[0].name in RESTARTABLE
                and group.restarts.get(dead[0].name, 0) < MAX_CONTROLLER_RESTARTS
            ):
                # the line goes on without its controller (the simulator gives parcels that
                # reach R_s without a command NO_COMMAND); a new one plans the later parcels
                n = dead[0]
                say(
                    f"node {n.name} exited with status {n.proc.returncode}; restarting it "
                    f"({group.restarts.get(n.name, 0) + 1} of at most {MAX_CONTROLLER_RESTARTS})"
                )
                group.restart(n.name)
                continue
            if dead:
                n = dead[0]
                code, message = (
                    EXIT_FAILED,
                    (
                        f"node {n.name} exited with status {n.proc.returncode}; "
                        f"log tail:\n{n.tail()}"
                    ),
                )
                break
            if not rec.parcels and time.monotonic() - scanner_started > NO_PARCEL_TIMEOUT:
                code, message = (
                    EXIT_FAILED,
                    f"no parcel on /parcels within {NO_PARCEL_TIMEOUT:.0f} s of the scanner's "
                    f"start (scanner: {monitor.node_diag('scanner')})",
                )
                break
            if sim_start is None and rec.parcels:
                # the stream's sim time starts with the first scan (at rtf 0 the scanner may
                # come up long after the simulator's clock started)
                sim_start = min(p["scan_time"] for p in rec.parcels.values()) - START_DELAY
            # past the stream's end in sim time with no outcome for a while in wall time (at
            # rtf 0 the sim time seen here runs ahead of the outcomes still on their way: 30 s
            # of sim time is a fraction of a second of wall time there)
            if (
                sim_start is not None
                and rec.sim_time - sim_start > plan.sim_duration + 30.0
                and time.monotonic() - last_outcome > STALL_TIMEOUT
            ):
                stalled = True
                code, message = (
                    EXIT_FAILED,
                    (
                        f"sim time {rec.sim_time:.1f} s is past the stream's end and "
                        f"{len(expected - rec.outcomes.keys())} parcels have no outcome"
                    ),
                )
                break
            if time.monotonic() > deadline:
                stalled = True
                code, message = (
                    EXIT_FAILED,
                    (
                        f"timeout after {timeout:.0f} s: "
                        f"{len(expected - rec.outcomes.keys())} parcels have no outcome"
                    ),
                )
                break
        # one more heartbeat round for the final counters
        end = time.monotonic() + opts.heartbeat_period + 0.3
        while time.monotonic() < end:
            monitor.spin_for(0.1)
            stop.check()
    except Interrupted as exc:
        code, message = EXIT_INTERRUPTED, f"interrupted ({exc})"
    except KeyboardInterrupt:  # run_job in a thread: no handler of ours
        code, message = EXIT_INTERRUPTED, "interrupted (SIGINT)"
    except _StartFailure as exc:
        code, message = EXIT_FAILED, str(exc)
    finally:
        stop.stopping()
        if code == EXIT_INTERRUPTED:
            exit_codes = group.kill()
        else:
            exit_codes = group.stop(STOP_ORDER, stop.urgent)
        if stop.signals and code != EXIT_INTERRUPTED:
            code = EXIT_INTERRUPTED
            message = f"interrupted ({signal.Signals(stop.signals[0]).name}) while stopping"
        left = leftovers(group.pgids)
        records = monitor.records if monitor is not None else Records()
        summary = summarise(
            records, plan.belt_speed, plan.expected_ids, plan.divert_ids, plan.limits
        )
        if monitor is not None:
            monitor.close()
    bad_exit = {n: c for n, c in exit_codes.items() if c not in (0, None)}
    if summary["recording_failed"]:  # the recorder's exit status 1 is that failure (exit 5)
        bad_exit.pop("recorder", None)
    if code == EXIT_OK and bad_exit:
        code, message = EXIT_FAILED, f"nodes did not exit cleanly: {bad_exit}"
    if left:
        code, message = EXIT_FAILED, f"processes left behind: {left}"
    # the run's own stream: a divert parcel without an outcome (3), foreign traffic (4)
    own = verdict(summary)
    if own is not None and (code == EXIT_OK or stalled) and not bad_exit and not left:
        code, message = own
    summary["wall_time_s"] = time.monotonic() - wall0
    summary["controller_restarts"] = group.restarts.get("controller", 0)
    summary["exit_codes"] = exit_codes
    # a temporary log directory goes with a run that did not fail (kept: --keep-logs)
    key_file.unlink(missing_ok=True)  # the run is over: its key changes nothing any more
    keep = opts.keep_logs or opts.log_dir is not None or code not in (EXIT_OK, EXIT_INTERRUPTED)
    if not keep:
        shutil.rmtree(log_dir, ignore_errors=True)
    summary["log_dir"] = str(log_dir) if keep else None
    summary["process_groups"] = list(group.pgids)
    summary["leftover_processes"] = left
    return RunResult(code, summary, message, log_dir, list(group.pgids), left, exit_codes, records)


def _tell_recording_failure(records, say: Callable[[str], None]) -> bool:
    """Say once that the recorder failed to write (its /diagnostics error): when, and the sim
    time where the bag ends; the run goes on unrecorded. True once said."""
    failure = recording_failure(records.diagnostics)
    if failure is None:
        return False
    say(
        f"recorder: writing the bag failed at sim time {failure['failed_at_sim_s']:.2f} s: "
        f"{failure['error']}; the bag holds every message up to sim time "
        f"{failure['bag_ends_sim_s']:.2f} s, "
        "the run goes on unrecorded"
    )
    return True


def _recorder_args(plan: RunPlan, opts: RunOptions, log_dir: Path) -> list[str]:
    """The recorder's parameters: the bag; with sensors the measured topics too and the truth
    in the bag's metadata (custom_data, :data:`fence_sorter.calibration.bag.TRUTH_KEY`)."""
    args = [f"output_dir:={Path(opts.bag).resolve()}", "use_sim_time:=true"]
    if plan.truth is not None and "topics" not in plan.node_params.get("recorder", {}):
        from fence_sorter.calibration.bag import TRUTH_KEY  # lazy: rosbags and the physics

        truth_file = log_dir / "calibration_truth.json"
        truth_file.write_text(json.dumps({TRUTH_KEY: json.dumps(plan.truth)}), encoding="utf-8")
        args += [
            f"topics:={ros_value([*TOPICS, *MEASURED])}",
            f"custom_data_file:={truth_file}",
        ]
    return args


class _StartFailure(RuntimeError):
    pass


def _wait_for(
    monitor,
    group: ProcessGroup,
    stop: StopRequest,
    node: str,
    timeout: float,
    listening: bool = False,
) -> None:
    """Wait for the first heartbeat of ``node`` (it is spinning, so it is ready), with
    ``listening``: for one that says it listens (the controller, once its commands match)."""

    def up() -> bool:
        diag = monitor.node_diag(node)
        return diag is not None and (not listening or diag.get("listening") == "true")

    def ready() -> bool:
        monitor.spin_for(0.05)
        stop.check()
        return up() or group.nodes[node].proc.poll() is not None

    wait_until(ready, timeout, step=0.0)
    proc = group.nodes[node]
    if proc.proc.poll() is not None:
        raise _StartFailure(
            f"node {node} exited with status {proc.proc.returncode} at start; log tail:\n"
            f"{proc.tail()}"
        )
    if not up():
        what = "no heartbeat saying it listens" if listening else "no heartbeat"
        raise _StartFailure(f"node {node} sent {what} within {timeout:.0f} s")
