"""The nodes' parameters as plain data (no ROS): one table per node.

Each node declares its parameters from its table here (:meth:`ParamSpec.descriptor`, in
``fence_sorter.nodes.base``), and ``fence-sorter run`` checks ``--param NODE:KEY=VALUE`` against
the same tables before any node starts (:func:`parse_override`): name, type (an integer widens
to a double) and range.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass

import yaml

from fence_sorter.capacity.constraints import ConstraintProfile
from fence_sorter.recording.topics import TOPIC_TYPES
from fence_sorter.scene import DEFAULT_SCENE

ParamValue = bool | int | float | str | list[str] | list[float] | list[int]

#: the damage limits of an outcome when the simulator is given none (the paper's (10), (11))
_LIMITS = ConstraintProfile()
#: the highest CPU number of this machine (the simulator's ``loop_cpu`` range)
LAST_CPU = (os.cpu_count() or 1) - 1


class ParamOverrideError(ValueError):
    """A ``NODE:KEY=VALUE`` override that the node would refuse (one line)."""


@dataclass(frozen=True)
class ParamSpec:
    """One node parameter: name, default, description (with unit) and constraints."""

    name: str
    default: ParamValue
    description: str
    read_only: bool = False
    min_value: float | int | None = None
    max_value: float | int | None = None

    @property
    def kind(self) -> str:
        """'bool', 'int', 'double', 'string' or 'T[]' for a list of T (ROS parameter types)."""
        return _kind(self.default)

    def allowed(self) -> str:
        """The allowed values in words, e.g. 'a double in [0.0, 100.0]'."""
        kind = {"int": "an integer", "double": "a double", "bool": "true or false"}.get(
            self.kind, f"a {self.kind}"
        )
        if self.min_value is not None and self.max_value is not None:
            return f"{kind} in [{self.min_value:g}, {self.max_value:g}]"
        return kind

    def coerce(self, value: object) -> ParamValue:
        """``value`` as this parameter's type (an integer widens to a double), in range;
        ValueError (naming the allowed values) otherwise."""
        kind = self.kind
        if kind == "string":
            return value if isinstance(value, str) else _text(value)
        if kind.endswith("[]"):
            if not isinstance(value, list) or any(_kind(v) != kind[:-2] for v in value):
                if not (kind == "double[]" and isinstance(value, list)):
                    raise ValueError(f"must be {self.allowed()}")
            if kind == "double[]":
                return [self._number(v) for v in value]
            return value
        if kind == "bool":
            if not isinstance(value, bool):
                raise ValueError(f"must be {self.allowed()}")
            return value
        number = self._number(value)
        if kind == "int":
            if isinstance(value, float):
                raise ValueError(f"must be {self.allowed()}")
            number = int(number)
        if self.min_value is not None and self.max_value is not None:
            if not self.min_value <= number <= self.max_value:
                raise ValueError(f"must be {self.allowed()}")
        return number

    def _number(self, value: object) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float) or math.isnan(value):
            raise ValueError(f"must be {self.allowed()}")
        return float(value) if self.kind.startswith("double") else value

    def descriptor(self):
        """The rcl_interfaces ParameterDescriptor that declares this parameter (imports
        rclpy: for the nodes only)."""
        from rcl_interfaces.msg import (  # lazy: ROS messages; the runner checks without ROS
            FloatingPointRange,
            IntegerRange,
            ParameterDescriptor,
        )
        from rclpy.parameter import Parameter  # lazy: rclpy; the table is ROS-free for the runner

        param_type = Parameter.Type.from_parameter_value(self.default)
        desc = ParameterDescriptor(
            name=self.name,
            type=param_type.value,
            description=self.description,
            read_only=self.read_only,
        )
        if self.min_value is not None and self.max_value is not None:
            if param_type is Parameter.Type.DOUBLE:
                desc.floating_point_range = [
                    FloatingPointRange(
                        from_value=float(self.min_value), to_value=float(self.max_value), step=0.0
                    )
                ]
            elif param_type is Parameter.Type.INTEGER:
                desc.integer_range = [
                    IntegerRange(
                        from_value=int(self.min_value), to_value=int(self.max_value), step=0
                    )
                ]
            else:
                raise ValueError(f"parameter {self.name!r}: a range needs a number default")
        return desc


def _kind(value: object) -> str:
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int):
        return "int"
    if isinstance(value, float):
        return "double"
    if isinstance(value, list):
        return f"{_kind(value[0]) if value else 'string'}[]"
    return "string"


def _text(value: object) -> str:
    return json.dumps(value) if not isinstance(value, str) else value


#: the run identity of the nodes that exchange /parcels and /fence_commands (scanner,
#: controller, simulator): ``fence-sorter run`` draws one per run and gives it to all three
RUN_ID_PARAMETER = ParamSpec(
    "run_id",
    0,
    "Id of the run this node belongs to: stamped on its /parcels and /fence_commands, and "
    "messages with another id are refused and counted as foreign; 0: none (takes any)",
    read_only=True,
    min_value=0,
    max_value=2**63 - 1,
)

COMMON_PARAMETERS: tuple[ParamSpec, ...] = (
    ParamSpec(
        "heartbeat_period",
        1.0,
        "Period of the diagnostic heartbeat on /diagnostics [s] (steady clock)",
        read_only=True,
        min_value=0.05,
        max_value=60.0,
    ),
    ParamSpec(
        "events_executor",
        True,
        "Spin with rclpy's EventsExecutor (rclpy.experimental): a fraction of the "
        "SingleThreadedExecutor's CPU per callback, which counts at the thousands of /clock "
        "messages per second of an unpaced run; false: SingleThreadedExecutor",
        read_only=True,
    ),
)

SIMULATOR_PARAMETERS: tuple[ParamSpec, ...] = (
    RUN_ID_PARAMETER,
    ParamSpec(
        "scene",
        DEFAULT_SCENE,
        "Scene (name in config/scenes or YAML path): conveyor, fence, contact and solver "
        "of the line (its parcel and drive are only used to warm the JIT up)",
        read_only=True,
    ),
    ParamSpec("frame_id", "sorter", "Fixed frame of the sorter (REP-103, z up)", read_only=True),
    ParamSpec(
        "real_time_factor",
        1.0,
        "Sim time advanced per wall second [-]; 0: unpaced, as fast as possible",
        min_value=0.0,
        max_value=100.0,
    ),
    ParamSpec(
        "physics_rate",
        1000.0,
        "Pacing loop rate [Hz] (wall clock); each cycle advances 1/physics_rate x rtf of sim",
        read_only=True,
        min_value=10.0,
        max_value=10000.0,
    ),
    ParamSpec(
        "publish_rate",
        50.0,
        "Rate of /clock, /fence_state, /joint_states, /load_states [Hz] (in cycles: wall "
        "Hz when paced, sim Hz when unpaced)",
        read_only=True,
        min_value=1.0,
        max_value=1000.0,
    ),
    ParamSpec(
        "marker_rate",
        10.0,
        "Rate of /markers [Hz] (same clock as publish_rate); 0: no markers",
        read_only=True,
        min_value=0.0,
        max_value=100.0,
    ),
    ParamSpec(
        "max_catch_up",
        0.1,
        "Largest sim time one late cycle may advance to catch up [s]; beyond it sim time "
        "slips behind the wall clock",
        read_only=True,
        min_value=0.001,
        max_value=10.0,
    ),
    ParamSpec(
        "spin_margin",
        0.0004,
        "Largest busy-wait before each deadline [s]; below it the wait follows the recent "
        "oversleep of time.sleep (at least 50 us)",
        read_only=True,
        min_value=0.0,
        max_value=0.005,
    ),
    ParamSpec(
        "lookahead",
        0.05,
        "Sim time the running solves may be stepped ahead of the line clock in each paced "
        "cycle's spare wall time [s], so the costly stretch of an impact is spread over "
        "the cycles before it is due; 0: off (each cycle does all of its physics)",
        read_only=True,
        min_value=0.0,
        max_value=1.0,
    ),
    ParamSpec(
        "prefetch_reserve",
        0.0002,
        "Wall time left free before the next cycle's busy-wait when stepping ahead [s] (one "
        "solver step may overrun the budget by its own cost)",
        read_only=True,
        min_value=0.0,
        max_value=0.01,
    ),
    ParamSpec(
        "line_end_x",
        3.0,
        "x0 where parcels leave the line (rear passing it) [m]",
        read_only=True,
        min_value=-10.0,
        max_value=100.0,
    ),
    ParamSpec(
        "r_s_min",
        -0.5,
        "Smallest R_s a command may ask for [m] (paper range (3))",
        read_only=True,
        min_value=-10.0,
        max_value=10.0,
    ),
    ParamSpec(
        "r_s_max",
        2.0,
        "Largest R_s a command may ask for [m]; a divert parcel whose front passes it with "
        "no accepted command is NO_COMMAND (point of no return)",
        read_only=True,
        min_value=-10.0,
        max_value=10.0,
    ),
    ParamSpec(
        "scan_line_x",
        -3.0,
        "The scanner's scan line [m]: a parcel's scan_position_x must lie within "
        "scan_line_tolerance of it",
        read_only=True,
        min_value=-100.0,
        max_value=100.0,
    ),
    ParamSpec(
        "scan_line_tolerance",
        0.5,
        "Largest distance of a parcel's scan_position_x from scan_line_x [m]",
        read_only=True,
        min_value=0.0,
        max_value=200.0,
    ),
    ParamSpec(
        "realtime_priority",
        50,
        "SCHED_FIFO priority of the pacing thread, the process's other threads one below "
        "(1-99; needs CAP_SYS_NICE or an rtprio limit, otherwise a warning and normal "
        "scheduling); 0: normal scheduling",
        read_only=True,
        min_value=0,
        max_value=99,
    ),
    ParamSpec(
        "command_wait",
        1.0,
        "Unpaced runs (lockstep): a parcel to divert without a command is held before its "
        "front reaches r_s_min until its command arrives, for at most this long in wall "
        "time [s]; 0: off (commands may then come too late at high speed)",
        read_only=True,
        min_value=0.0,
        max_value=60.0,
    ),
    ParamSpec(
        "loop_cpu",
        -1,
        "CPU the pacing loop's process is pinned to, this node's own threads kept off it "
        "(-1: not pinned). `fence-sorter run` sets it to the last CPU and keeps the other "
        "nodes off it too, so their work does not evict the loop's caches while it sleeps",
        read_only=True,
        min_value=-1,
        max_value=LAST_CPU,
    ),
    ParamSpec(
        "scan_lead",
        1.0,
        "Unpaced runs: sim time stays within this much of the scanner's progress "
        "(/scan_progress) and waits at its start for the first report, so a scanner "
        "behind the fast /clock cannot publish parcels past their hold point [s]; 0: off "
        "(for a parcel source that does not report progress)",
        read_only=True,
        min_value=0.0,
        max_value=100.0,
    ),
    ParamSpec(
        "warm_up",
        True,
        "Run one short stroke before starting so the compiled kernel is loaded",
        read_only=True,
    ),
    ParamSpec(
        "keep_cpus_awake",
        False,
        "Paced runs: one SCHED_IDLE busy process per CPU keeps the CPUs from halting "
        "between deadlines (on a VM whose guest idles with HLT, a sleeping loop otherwise "
        "wakes when the host runs its vCPU again); they yield to any other work",
        read_only=True,
    ),
    ParamSpec(
        "cycle_trace",
        "",
        "Write the paced loop's per-cycle timing (deadline, wake, end of each phase, what "
        "the cycle did) to this .npz at shutdown, to diagnose deadline misses (last 600000 "
        "cycles); empty: none",
        read_only=True,
    ),
    ParamSpec(
        "rrd_path",
        "",
        "Save a Rerun recording (.rrd) of the run here (logged in a child process from the "
        "snapshots published at publish_rate); empty: none",
        read_only=True,
    ),
    ParamSpec(
        "rrd_url",
        "",
        "Also stream to a Rerun viewer listening at this gRPC url (e.g. "
        "rerun+http://127.0.0.1:9876/proxy); empty: none",
        read_only=True,
    ),
    ParamSpec(
        "w_dop",
        _LIMITS.w_dop,
        "(10) admissible impact speed w_dop each outcome's impact_speed_margin is taken "
        "against [m/s] (as the controller's)",
        read_only=True,
        min_value=1e-6,
        max_value=100.0,
    ),
    ParamSpec(
        "a_ndop",
        _LIMITS.a_ndop,
        "(11) admissible acceleration a_Ndop each outcome's accel_margin is taken against "
        "[m/s^2] (as the controller's)",
        read_only=True,
        min_value=1e-6,
        max_value=1e5,
    ),
    ParamSpec(
        "rrd_scan_line_x",
        -3.0,
        "x0 of the scan line drawn in the Rerun view [m] (drawing only)",
        read_only=True,
        min_value=-100.0,
        max_value=100.0,
    ),
)

SCANNER_PARAMETERS: tuple[ParamSpec, ...] = (
    RUN_ID_PARAMETER,
    ParamSpec("frame_id", "sorter", "Fixed frame of the sorter (REP-103, z up)", True),
    ParamSpec("scene", "", "Scene YAML (belt speed and width); empty: default", True),
    ParamSpec("stream", "", "Stream config (YAML) or CSV manifest; empty: default", True),
    ParamSpec("seed", -1, "Seed of a random stream; -1: the file's", True, -1, 2**31 - 1),
    ParamSpec(
        "scan_line_x", -3.0, "Scan line along the belt, frame sorter [m]", True, -100.0, 0.0
    ),
    ParamSpec("parcels", 0, "Parcels to inject; 0: use duration", True, 0, 10**7),
    ParamSpec(
        "duration", 0.0, "Inject parcels arriving within [s]; 0: use parcels", True, 0.0, 1e6
    ),
    ParamSpec(
        "rate",
        0.0,
        "Arrival rate of a stream config's parcel mix [pcs/h], replacing its spacing; 0: the "
        "stream's own",
        True,
        0.0,
        1e5,
    ),
    ParamSpec("start_delay", 0.5, "Sim time before the first parcel [s]", True, 0.0, 1e4),
    ParamSpec(
        "start_gate",
        "simulator,controller",
        "Nodes (names, comma-separated) that must be in the ROS graph with a subscription on "
        "every topic they need before the stream starts (recorder: every suite topic; "
        "simulator: /parcels, /fence_commands, /scan_progress; any other: /parcels); "
        "empty: start at once",
        True,
    ),
    ParamSpec(
        "tick_period",
        0.005,
        "Period of the scan check on the wall clock [s] (with use_sim_time the check runs "
        "on every /clock update instead)",
        True,
        1e-4,
        1.0,
    ),
)

#: the controller's planner: each of these may change during a run (the next parcels are
#: planned with the new settings, fence_sorter.nodes.controller)
PLANNER_PARAMETERS: tuple[ParamSpec, ...] = (
    ParamSpec("alpha_k_deg", 40.0, "Fence angle alpha_k of every stroke [deg]", False, 1.0, 89.0),
    ParamSpec("t1_min", 0.2, "Shortest working time t1, range (5) [s]", False, 0.02, 10.0),
    ParamSpec("t1_max", 1.5, "Longest working time t1, range (5) [s]", False, 0.02, 10.0),
    ParamSpec("t1_step", 0.1, "Candidate step of t1 [s]", False, 0.001, 10.0),
    ParamSpec("r_s_min", -0.4, "Smallest R_s, range (3) [m]", False, -5.0, 5.0),
    ParamSpec("r_s_max", 1.0, "Largest R_s, range (3) [m]", False, -5.0, 5.0),
    ParamSpec("r_s_step", 0.2, "Candidate step of R_s [m]", False, 0.001, 10.0),
    ParamSpec("w_dop", 2.4, "(10) admissible impact speed w_dop [m/s]", False, 1e-6, 100.0),
    ParamSpec("a_ndop", 300.0, "(11) admissible acceleration a_Ndop [m/s^2]", False, 1e-6, 1e5),
    ParamSpec("ydot_dop", 2.5, "(12) admissible exit speed ydot_dop [m/s]", False, 1e-6, 100.0),
    ParamSpec(
        "active_constraints", [7, 8, 9, 10, 11, 12], "Constraints that count, of (7)-(12)", False
    ),
    ParamSpec("pitch_gap", 0.1, "Gap Delta between loads in Delta_c (2) [m]", False, 0.0, 10.0),
    ParamSpec(
        "fence_model", "scene", "Fence the planner simulates: scene (the plant's) | stiff", False
    ),
    ParamSpec(
        "max_evaluations",
        60,
        "Safety cap of twin evaluations per parcel (the deadline ends planning first)",
        False,
        1,
        1000,
    ),
    ParamSpec(
        "deadline_margin",
        0.02,
        "Wall time kept before a command's deadline [s]",
        False,
        0.0,
        10.0,
    ),
    ParamSpec(
        "min_planning_time",
        0.2,
        "Least wall time a command's deadline gives the planner [s] (an unpaced simulator "
        "holds a parcel for its command)",
        False,
        0.0,
        10.0,
    ),
    ParamSpec(
        "uncertainty_mass",
        0.05,
        "Relative half-width of a parcel's mass a stroke is verified over",
        False,
        0.0,
        0.5,
    ),
    ParamSpec(
        "uncertainty_mu",
        0.05,
        "Half-width of mu1 and mu2 a stroke is verified over",
        False,
        0.0,
        0.5,
    ),
    ParamSpec(
        "uncertainty_size",
        0.005,
        "Half-width of A and B a stroke is verified over [m]",
        False,
        0.0,
        0.1,
    ),
    ParamSpec(
        "decision_table",
        "",
        "Starting strokes per load class, tried first (config/decision_table.yaml, made by "
        "python -m benchmarks paper-sweep decision-table); empty: none",
        False,
    ),
    ParamSpec(
        "start_margin",
        0.1,
        "Command out this long before the front is at R_s [s]",
        False,
        0.0,
        10.0,
    ),
    ParamSpec("busy_margin", 0.05, "Idle time between two strokes [s]", False, 0.0, 10.0),
    ParamSpec("quantum_size", 0.05, "Class bin of sizes and cog offsets [m]", False, 1e-4, 1.0),
    ParamSpec("quantum_mass", 0.2, "Class bin of mass (relative, log steps)", False, 1e-3, 10.0),
    ParamSpec("quantum_gap", 0.05, "Class bin of the lateral gap [m]", False, 1e-4, 1.0),
    ParamSpec("quantum_yaw_deg", 5.0, "Class bin of the yaw [deg]", False, 1e-3, 90.0),
    ParamSpec(
        "min_exit_speed",
        0.3,
        "(8) reserve: cross y0 = s at least this fast [m/s]",
        False,
        0.0,
        100.0,
    ),
    ParamSpec("quantum_mu", 0.05, "Class bin of mu1 and mu2", False, 1e-4, 1.0),
)

CONTROLLER_PARAMETERS: tuple[ParamSpec, ...] = (
    RUN_ID_PARAMETER,
    ParamSpec("scene", "", "Scene YAML (belt, fence, contact); empty: default", True),
    ParamSpec("frame_id", "sorter", "Fixed frame of the sorter (REP-103, z up)", True),
    ParamSpec(
        "scan_line_x",
        -3.0,
        "The scanner's scan line [m]: a parcel's scan_position_x must lie within "
        "scan_line_tolerance of it",
        False,
        -100.0,
        100.0,
    ),
    ParamSpec(
        "scan_line_tolerance",
        0.5,
        "Largest distance of a parcel's scan_position_x from scan_line_x [m]",
        False,
        0.0,
        200.0,
    ),
    *PLANNER_PARAMETERS,
    ParamSpec("warmup_stream", "", "Stream whose parcel classes warm the cache", True),
    ParamSpec("warmup_parcels", 400, "Parcels drawn for the warm-up", True, 0, 100000),
    ParamSpec(
        "wait_for_command_subscribers",
        1,
        "Listen to /parcels once /fence_commands has this many subscribers",
        True,
        0,
        100,
    ),
    ParamSpec("warmup_time", 8.0, "Wall-time budget of the warm-up [s]", True, 0.0, 600.0),
)

RECORDER_PARAMETERS: tuple[ParamSpec, ...] = (
    ParamSpec(
        "output_dir",
        "",
        "The bag directory if missing or empty, else the directory that receives a new "
        "run_<UTC time> bag; empty: a new $ROS_HOME/bags/run_<UTC time> (~/.ros/bags)",
        read_only=True,
    ),
    ParamSpec("storage", "mcap", "rosbag2 storage: mcap or sqlite3", read_only=True),
    ParamSpec("topics", list(TOPIC_TYPES), "Topics to record", read_only=True),
    ParamSpec(
        "line_units",
        "",
        "A line's unit names, comma-separated: record the line's topics (every unit's "
        "namespace, the owner's) instead of topics; empty: not a line",
        read_only=True,
    ),
    ParamSpec(
        "max_segment_duration",
        10.0,
        "A segment is closed (complete, readable) after this long [s] (wall clock)",
        read_only=True,
        min_value=0.1,
        max_value=3600.0,
    ),
    ParamSpec(
        "max_segment_size_mb",
        64.0,
        "A segment is closed when its messages reach this size [MiB]",
        read_only=True,
        min_value=0.01,
        max_value=100000.0,
    ),
    ParamSpec(
        "flush_period",
        0.5,
        "The open segment's pending messages are written to its file (a complete MCAP "
        "chunk) at least this often [s] (wall clock): a SIGKILL loses at most this much "
        "plus the 0.2 s a message is held for log-time order",
        read_only=True,
        min_value=0.01,
        max_value=60.0,
    ),
    ParamSpec(
        "compression",
        "zstd",
        "MCAP chunk compression: zstd or none (sqlite3: none)",
        read_only=True,
    ),
    ParamSpec(
        "custom_data_file",
        "",
        "A JSON object file of strings whose entries go into the bag's metadata custom_data "
        "(fence-sorter run --sensors: the calibration truth); empty: none",
        read_only=True,
    ),
)

SENSORS_PARAMETERS: tuple[ParamSpec, ...] = (
    RUN_ID_PARAMETER,
    ParamSpec(
        "scene",
        DEFAULT_SCENE,
        "Scene (name in config/scenes or YAML path) the simulator runs: its fence gives the "
        "strain gauge's root moment per tip deflection (a stiff fence has no gauge)",
        read_only=True,
    ),
    ParamSpec(
        "sensors",
        "camera60",
        "Sensors file (name in config/sensors or YAML path): rate, noise, dropouts, latency "
        "and camera frame of the drive encoder, the camera and the strain gauge",
        read_only=True,
    ),
    ParamSpec("seed", 0, "Seed of the sensors' noise and dropouts", True, 0, 2**31 - 1),
    ParamSpec(
        "max_state_gap",
        0.01,
        "Longest sim time between two states of the fence or of a parcel across which the "
        "sensors interpolate [s]; the samples of a longer gap are dropped and counted",
        True,
        1e-4,
        10.0,
    ),
    ParamSpec(
        "max_pending",
        10000,
        "Camera frames held for their latency at most; beyond it a frame is dropped and "
        "counted (camera_dropped_overload)",
        True,
        1,
        10**7,
    ),
)


FOXGLOVE_PARAMETERS: tuple[ParamSpec, ...] = (
    ParamSpec(
        "host",
        "127.0.0.1",
        "Address the Foxglove WebSocket server binds (an IP address or localhost); "
        "127.0.0.1: this machine only (docs/design/security.md)",
        read_only=True,
    ),
    ParamSpec(
        "port",
        8765,
        "TCP port of the Foxglove WebSocket server; 0: a free one (logged)",
        True,
        0,
        65535,
    ),
    ParamSpec("topics", list(TOPIC_TYPES), "Topics served to Foxglove", read_only=True),
    ParamSpec(
        "client_backlog",
        1024,
        "Outgoing messages held per client; beyond it the oldest are dropped, each one "
        "counted per client and topic on /diagnostics",
        True,
        16,
        1_000_000,
    ),
)

#: a unit of a line over DDS (fence_sorter.nodes.line_unit; its namespace: /<unit name>)
LINE_UNIT_PARAMETERS: tuple[ParamSpec, ...] = (
    ParamSpec("line", "two_units", "Line file (name in config/lines or YAML path)", True),
    ParamSpec(
        "unit_index", 0, "Index of this unit in the line file's units (0: the first)", True, 0, 999
    ),
    ParamSpec("guard", True, "The swept-sector guard of the unit's planner", True),
    ParamSpec(
        "dt", 0.01, "Step of the line clock [s] (the owner's; must match)", True, 0.001, 0.1
    ),
    ParamSpec(
        "owner_timeout",
        20.0,
        "Wall time without a command from the line's owner, once the line runs, after which "
        "the unit takes the owner for gone and exits 3 [s]",
        True,
        1.0,
        3600.0,
    ),
    ParamSpec(
        "view_period",
        0.0,
        "Sim time between the unit's view samples on fence_state and load_states (for the "
        "line's live view) [s]; 0: none published",
        True,
        0.0,
        10.0,
    ),
)

#: the live Rerun view of a line over DDS (fence_sorter.nodes.line_viewer, namespace /line)
LINE_VIEWER_PARAMETERS: tuple[ParamSpec, ...] = (
    ParamSpec("line", "two_units", "Line file (name in config/lines or YAML path)", True),
    ParamSpec("rrd", "", "Save the live view to this .rrd file ('': no file)", True),
    ParamSpec(
        "url",
        "",
        "Stream the live view to the Rerun viewer listening at this URL, e.g. "
        "rerun+http://127.0.0.1:9876/proxy ('': no viewer)",
        True,
    ),
    ParamSpec(
        "flush_every",
        5,
        "Samples buffered before they are sent to the sinks (a viewer follows in steps of "
        "this many view periods)",
        True,
        1,
        10_000,
    ),
    ParamSpec(
        "drain_time",
        0.5,
        "Once the line's summary came: wall time without a view message after which the "
        "view is closed and the node exits 0 [s]",
        True,
        0.05,
        60.0,
    ),
)

#: the owner of a line over DDS: induction, recirculation, the lockstep clock
#: (fence_sorter.nodes.line_owner, namespace /line)
LINE_OWNER_PARAMETERS: tuple[ParamSpec, ...] = (
    ParamSpec("line", "two_units", "Line file (name in config/lines or YAML path)", True),
    ParamSpec("parcels", 10, "Parcels of the stream", True, 1, 1_000_000),
    ParamSpec("seed", -1, "Seed of the stream; -1: the stream file's own", True, -1, 2**31 - 1),
    ParamSpec(
        "rate", 0.0, "Induction rate [pcs/h]; 0: the stream file's own", True, 0.0, 100_000.0
    ),
    ParamSpec(
        "duration",
        0.0,
        "Induct the stream's parcels arriving within this sim time [s] instead of `parcels`; "
        "0: `parcels`",
        True,
        0.0,
        1e6,
    ),
    ParamSpec("guard", True, "The units' swept-sector guard (must match the units')", True),
    ParamSpec("dt", 0.01, "Step of the line clock [s]", True, 0.001, 0.1),
    ParamSpec(
        "real_time_factor",
        0.0,
        "Pace the line clock at this real-time factor (Pacer deadlines every dt / rtf of wall "
        "time); 0: unpaced, as fast as the units answer",
        True,
        0.0,
        100.0,
    ),
    ParamSpec(
        "reply_timeout",
        10.0,
        "Wall time a unit may take to answer one command before the line takes it for down "
        "and goes on without it [s]",
        True,
        0.1,
        3600.0,
    ),
    ParamSpec(
        "start_timeout",
        60.0,
        "Wall time every unit has to match its topics and say it is ready [s]",
        True,
        0.1,
        3600.0,
    ),
    ParamSpec("summary", "", "Write the line summary (JSON) to this file; empty: stdout", True),
    ParamSpec(
        "warm_up",
        True,
        "Warm each unit's planner from the stream before the run (as line-sim does)",
        True,
    ),
    ParamSpec(
        "recorder",
        False,
        "The start gate also waits until the recorder matched every lockstep topic (--bag)",
        True,
    ),
)

#: node name -> every parameter it declares (the common ones first)
NODE_PARAMETERS: dict[str, tuple[ParamSpec, ...]] = {
    "simulator": COMMON_PARAMETERS + SIMULATOR_PARAMETERS,
    "scanner": COMMON_PARAMETERS + SCANNER_PARAMETERS,
    "controller": COMMON_PARAMETERS + CONTROLLER_PARAMETERS,
    "recorder": COMMON_PARAMETERS + RECORDER_PARAMETERS,
    "sensors": COMMON_PARAMETERS + SENSORS_PARAMETERS,
    "foxglove": COMMON_PARAMETERS + FOXGLOVE_PARAMETERS,
}


def parse_override(item: str, nodes: tuple[str, ...] | None = None) -> tuple[str, str, ParamValue]:
    """``NODE:KEY=VALUE`` -> (node, key, value as the node declares it). VALUE is read as a
    ROS ``-p`` value is (YAML); ParamOverrideError names NODE:KEY and the allowed values."""
    known = tuple(nodes or NODE_PARAMETERS)
    node, sep, kv = item.partition(":")
    key, eq, text = kv.partition("=")
    if not sep or not eq or not key or node not in known:
        raise ParamOverrideError(
            f"--param {item!r} must be NODE:KEY=VALUE with NODE one of {', '.join(known)}"
        )
    specs = {s.name: s for s in NODE_PARAMETERS[node]}
    if key not in specs:
        raise ParamOverrideError(
            f"--param {node}:{key}: {node} has no parameter {key!r} "
            f"(it has: {', '.join(sorted(specs))})"
        )
    try:
        value = yaml.safe_load(text) if text.strip() else ""
    except yaml.YAMLError:
        value = text
    if isinstance(value, str):  # rcl reads 1e-6 as a double, YAML 1.1 as a string
        for number in (int, float):
            try:
                value = number(value)
                break
            except ValueError:
                pass
    if specs[key].kind == "string":
        value = text
    try:
        return node, key, specs[key].coerce(value)
    except ValueError as exc:
        raise ParamOverrideError(f"--param {node}:{key} {exc}, got {text!r}") from None


def ros_value(value: ParamValue) -> str:
    """``value`` as the text of a ROS ``-p KEY:=VALUE`` that reads back as the same type
    (a double keeps its point, a string is quoted)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ("inf" if value > 0 else "-inf")
    return json.dumps(value)
