"""The topics of the node suite in one place: names, message types and QoS (ROS-free).

Every node, the recorder, the run's monitor, analysis, replay and the Rerun logging take their
topic names from here, and :mod:`fence_sorter.nodes.qos` builds the rclpy profiles from the
:class:`QosSpec` of each topic, so a publisher, its subscribers, the bag's offered QoS and the
replay agree. History depths are the named constants below.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

CLOCK = "/clock"
#: the simulator's sim time under the run's key (fence_sorter_msgs/RunClock): the nodes of a
#: run with a key take their time from it, not from /clock (fence_sorter/provenance.py)
RUN_CLOCK = "/run_clock"
PARCELS = "/parcels"
#: the scanner's progress (rosgraph_msgs/Clock: every parcel due by this sim time is out)
SCAN_PROGRESS = "/scan_progress"
FENCE_COMMANDS = "/fence_commands"
FENCE_STATE = "/fence_state"
LOAD_STATES = "/load_states"
SORT_OUTCOMES = "/sort_outcomes"
#: full-rate sorting events (SortEvent): one per stroke, at the solver's resolution
SORT_EVENTS = "/sort_events"
JOINT_STATES = "/joint_states"
MARKERS = "/markers"
DIAGNOSTICS = "/diagnostics"
#: measured topics a real sorter can record (docs/guide/calibration.md): drive encoder (>= 200 Hz),
#: overhead camera poses of the parcels (25-120 Hz), fence root bending moment (>= 1 kHz)
DRIVE_ENCODER = "/sensors/drive_encoder"
CAMERA_POSES = "/sensors/camera/parcel_poses"
FENCE_ROOT_MOMENT = "/sensors/fence_root/moment"
TF = "/tf"
TF_STATIC = "/tf_static"
ROBOT_DESCRIPTION = "/robot_description"

#: high-rate state (fence, loads): the newest samples count; best effort
STATE_DEPTH = 5
#: reliable events (outcomes, diagnostics, progress): samples kept while a reader is slow
EVENT_DEPTH = 100
#: /clock, /joint_states, /markers: reliable keep-last as robot_state_publisher and RViz ask
CLOCK_DEPTH = 10
#: /parcels and /fence_commands: history kept for late joiners (transient local). The scanner
#: keeps its whole stream when it is longer; readers keep this many
STREAM_HISTORY_DEPTH = 10000
#: /tf: what tf2's TransformListener asks for (reliable, volatile)
TF_DEPTH = 100
#: the recorder's subscriptions: history kept while its executor is busy (the writer thread
#: has its own queue)
RECORDER_DEPTH = 1000
#: the Foxglove node's subscriptions: history kept while its executor is busy
FOXGLOVE_DEPTH = 1000
#: replay's publishers (it publishes as fast as the bag's pace asks)
REPLAY_DEPTH = 1000


@dataclass(frozen=True)
class QosSpec:
    """A topic's QoS: reliable or best effort, keep-last ``depth``, transient local or
    volatile."""

    reliable: bool
    depth: int
    transient_local: bool = False
    keep_all: bool = False  # keep every sample until taken (depth unused)

    def with_depth(self, depth: int) -> QosSpec:
        return replace(self, depth=int(depth))


STATE_QOS = QosSpec(reliable=False, depth=STATE_DEPTH)
EVENT_QOS = QosSpec(reliable=True, depth=EVENT_DEPTH)
CLOCK_QOS = QosSpec(reliable=True, depth=CLOCK_DEPTH)
STREAM_QOS = QosSpec(reliable=True, depth=STREAM_HISTORY_DEPTH, transient_local=True)
#: what the nodes take in from outside (subscriptions of /parcels and /fence_commands):
#: keep-all, so a flood is refused and counted by the node (nodes/intake.py) instead of
#: overwriting samples it has not taken yet; transient local, for the history
INPUT_QOS = QosSpec(reliable=True, depth=1, transient_local=True, keep_all=True)
#: static descriptions (/tf_static, /robot_description): late joiners get the last one
LATCHED_QOS = QosSpec(reliable=True, depth=1, transient_local=True)
TF_QOS = QosSpec(reliable=True, depth=TF_DEPTH)


@dataclass(frozen=True)
class Topic:
    name: str
    msgtype: str
    qos: QosSpec


#: every topic of the suite, in recording order
TOPICS: dict[str, Topic] = {
    t.name: t
    for t in (
        Topic(CLOCK, "rosgraph_msgs/msg/Clock", CLOCK_QOS),
        Topic(PARCELS, "fence_sorter_msgs/msg/Parcel", STREAM_QOS),
        Topic(SCAN_PROGRESS, "rosgraph_msgs/msg/Clock", EVENT_QOS),
        Topic(FENCE_COMMANDS, "fence_sorter_msgs/msg/FenceCommand", STREAM_QOS),
        Topic(FENCE_STATE, "fence_sorter_msgs/msg/FenceState", STATE_QOS),
        Topic(LOAD_STATES, "fence_sorter_msgs/msg/LoadState", STATE_QOS),
        Topic(SORT_OUTCOMES, "fence_sorter_msgs/msg/SortOutcome", EVENT_QOS),
        Topic(SORT_EVENTS, "fence_sorter_msgs/msg/SortEvent", EVENT_QOS),
        Topic(JOINT_STATES, "sensor_msgs/msg/JointState", CLOCK_QOS),
        Topic(MARKERS, "visualization_msgs/msg/MarkerArray", CLOCK_QOS),
        Topic(DIAGNOSTICS, "diagnostic_msgs/msg/DiagnosticArray", EVENT_QOS),
        Topic(TF, "tf2_msgs/msg/TFMessage", TF_QOS),
        Topic(TF_STATIC, "tf2_msgs/msg/TFMessage", LATCHED_QOS),
        Topic(ROBOT_DESCRIPTION, "std_msgs/msg/String", LATCHED_QOS),
    )
}
#: topic -> (type, reliable), as the recorder and the bag tests look them up
TOPIC_TYPES: dict[str, tuple[str, bool]] = {
    t.name: (t.msgtype, t.qos.reliable) for t in TOPICS.values()
}
SUITE_TOPICS = list(TOPICS)

#: the topics each node of the suite subscribes to: the scanner starts its stream once every
#: node it waits for has these subscriptions in the ROS graph (nodes/scanner.py)
NODE_SUBSCRIPTIONS: dict[str, tuple[str, ...]] = {
    "simulator": (PARCELS, FENCE_COMMANDS, SCAN_PROGRESS),
    "controller": (PARCELS,),
    "recorder": tuple(SUITE_TOPICS),
    "sensors": (FENCE_STATE, LOAD_STATES, PARCELS),
    "foxglove": tuple(SUITE_TOPICS),
}
#: the measured topics a real sorter's sensors publish (docs/guide/calibration.md), published in a
#: run by the sensors node (``fence-sorter run --sensors``) and recorded with the suite's
#: topics then: reliable, so a calibration bag holds every sample the sensors took
MEASURED_QOS = QosSpec(reliable=True, depth=EVENT_DEPTH)
MEASURED: dict[str, Topic] = {
    t.name: t
    for t in (
        Topic(DRIVE_ENCODER, "sensor_msgs/msg/JointState", MEASURED_QOS),
        Topic(CAMERA_POSES, "fence_sorter_msgs/msg/LoadState", MEASURED_QOS),
        Topic(FENCE_ROOT_MOMENT, "geometry_msgs/msg/WrenchStamped", MEASURED_QOS),
    )
}
#: measured topics: topic -> (type, reliable)
MEASURED_TOPICS: dict[str, tuple[str, bool]] = {
    t.name: (t.msgtype, t.qos.reliable) for t in MEASURED.values()
}
#: every topic a node of fence_sorter publishes or records
ALL_TOPICS: dict[str, Topic] = {**TOPICS, **MEASURED}

#: a line over DDS (fence_sorter.nodes.line_owner, line_unit): the lockstep topics are
#: reliable and keep-all (nothing is dropped silently; the line_unit module's LINE_QOS)
LINE_QOS = QosSpec(reliable=True, depth=1, keep_all=True)
#: the induction's hand-offs to the first unit (the owner's namespace is /line)
LINE_INDUCTION = "/line/handoffs"
#: the owner's line summary (std_msgs/String, JSON), once at the end of the run: what the
#: live run printed, kept in the bag beside the records it is computed from
LINE_SUMMARY = "/line/summary"
LINE_SUMMARY_QOS = QosSpec(reliable=True, depth=1, transient_local=True)
#: the owner's set-up (std_msgs/String, JSON), once at its start: the line file's name and
#: text and the run's configuration (parcels, seed, rate, guard, clock step, warm-up), what a
#: bag's analysis needs to replay the owner
LINE_SETUP = "/line/setup"


def line_unit_topics(unit: str) -> tuple[str, str, str]:
    """A unit's lockstep topics: its commands, its replies, its downstream hand-offs."""
    return f"/{unit}/commands", f"/{unit}/replies", f"/{unit}/handoffs"


def line_topics(units: list[str] | tuple[str, ...]) -> dict[str, Topic]:
    """Every topic of a line over DDS with units named ``units``, in recording order: the
    line clock, the owner's set-up, the induction's hand-offs, each unit's commands, replies
    and hand-offs, the static frames and model of every unit, the owner's summary, and
    /diagnostics."""
    out = [
        Topic(CLOCK, "rosgraph_msgs/msg/Clock", CLOCK_QOS),
        Topic(LINE_SETUP, "std_msgs/msg/String", LINE_SUMMARY_QOS),
        Topic(LINE_INDUCTION, "fence_sorter_msgs/msg/HandOff", LINE_QOS),
    ]
    for u in units:
        commands, replies, handoffs = line_unit_topics(u)
        out += [
            Topic(commands, "std_msgs/msg/String", LINE_QOS),
            Topic(replies, "std_msgs/msg/String", LINE_QOS),
            Topic(handoffs, "fence_sorter_msgs/msg/HandOff", LINE_QOS),
        ]
    out += [
        Topic(TF_STATIC, "tf2_msgs/msg/TFMessage", LATCHED_QOS),
        Topic(ROBOT_DESCRIPTION, "std_msgs/msg/String", LATCHED_QOS),
        Topic(LINE_SUMMARY, "std_msgs/msg/String", LINE_SUMMARY_QOS),
        Topic(DIAGNOSTICS, "diagnostic_msgs/msg/DiagnosticArray", EVENT_QOS),
    ]
    return {t.name: t for t in out}
