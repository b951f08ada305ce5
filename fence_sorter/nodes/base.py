"""Common machinery of the fence_sorter nodes: parameters, diagnostic heartbeat, clean shutdown.

Every executable is a small :class:`FenceSorterNode` subclass that lists its parameters as
:class:`ParamSpec` entries (its table in :mod:`fence_sorter.nodes.parameters`, ROS-free, so
`fence-sorter run` checks overrides against the same table) and a
module-level ``main()`` that calls :func:`run_node`.
"""

from __future__ import annotations

import inspect
import signal
import sys
import time
from array import array
from collections.abc import Sequence

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import SubscriptionEventCallbacks, UnsupportedEventTypeError
from rclpy.exceptions import ParameterException
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from fence_sorter import __version__, provenance
from fence_sorter.nodes.parameters import COMMON_PARAMETERS, ParamSpec
from fence_sorter.nodes.qos import topic_qos
from fence_sorter.nodes.sources import STARTED_KEY, PinnedClock, authentic, sign_diagnostics
from fence_sorter.recording.topics import DIAGNOSTICS

#: the signature of a subscription callback that takes rclpy's message info too
_MSG_AND_INFO = inspect.Signature(
    [inspect.Parameter(n, inspect.Parameter.POSITIONAL_ONLY) for n in ("msg", "info")]
)


def make_executor(events: bool, context=None) -> Executor:
    """rclpy's EventsExecutor (``events``) or SingleThreadedExecutor. Measured on the unpaced
    suite (``fence-sorter run --parcels 100 --rtf 0``, CPU over 4 s): scanner 37 -> 21 %,
    controller 35 -> 19 % of a core, for the same work."""
    if events:
        from rclpy.experimental import EventsExecutor  # lazy: ~0.1 s more, events_executor only

        return EventsExecutor(context=context)
    return SingleThreadedExecutor(context=context)


class FenceSorterNode(Node):
    """Base class of the fence_sorter nodes.

    Subclasses set ``NODE_NAME``, ``PARAMETERS`` and ``STATUS``; they may override
    :meth:`validate_parameters` to refuse parameter changes that the ranges cannot express, and
    :meth:`apply_parameters` to put an accepted change to work. A parameter that is not
    ``read_only`` in its :class:`ParamSpec` is one the node applies when it is set; rcl refuses
    a change of any other.
    """

    NODE_NAME: str = "fence_sorter"
    PARAMETERS: tuple[ParamSpec, ...] = ()
    #: status text and level carried by the heartbeat while the node does its work
    STATUS: str = "running"
    STATUS_LEVEL: bytes = DiagnosticStatus.OK
    #: with the run's key and sim time, take sim time from /run_clock (fence_sorter.provenance)
    PINNED_CLOCK: bool = True

    def __init__(self, **kwargs: object) -> None:
        super().__init__(self.NODE_NAME, **kwargs)
        self.take_errors = 0  # messages lost to rclpy take failures (see spin_node)
        #: this process's start (wall clock, ns): a restarted node's heartbeats, stamped from
        #: sim time 0 until its clock arrives, are newer than the last process's
        self.started_ns = time.time_ns()
        specs = COMMON_PARAMETERS + self.PARAMETERS
        self.param_specs = {spec.name: spec for spec in specs}
        self.parameter_changes = 0  # accepted changes at run time (heartbeat parameter_changes)
        names = [spec.name for spec in specs]
        if len(set(names)) != len(names):
            raise ValueError(f"{self.NODE_NAME}: duplicate parameter names in {names}")
        for spec in specs:
            self.declare_parameter(spec.name, spec.default, spec.descriptor())
        # Initial values (defaults, --params-file, -p overrides) pass the same validation as
        # later changes.
        reason = self.validate_parameters([self.get_parameter(name) for name in names])
        if reason:
            raise ParameterException(reason, "initial values")
        # the run's key (fence_sorter.provenance): tags on what this node sends, checks on what
        # it takes in, on every change of its parameters at run time, and its sim time from
        # /run_clock
        try:
            self.run_key = provenance.run_key()
        except ValueError as exc:
            raise ParameterException(str(exc), provenance.RUN_KEY_ENV) from None
        self.change_seq = 0  # the sequence number of the last keyed change taken
        self.parameter_changes_refused = 0
        self.parameter_change_log: list[str] = []  # "t=<sim s> NAME=VALUE, ..." taken
        self.parameter_refusals: list[str] = []  # the reasons of the refused, last few
        if self.run_key is not None:
            self.declare_parameter(
                provenance.CHANGE_AUTH_PARAM,
                "",
                ParameterDescriptor(
                    description="SEQ:TAG of a change at run time under the run's key "
                    "(set by fence-sorter param set --key-file, beside the change)"
                ),
            )
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.pinned_clock: PinnedClock | None = None
        if (
            self.PINNED_CLOCK
            and self.run_key is not None
            and self.get_parameter("use_sim_time").value
        ):
            self.pinned_clock = PinnedClock(self, self.run_key)

        self._diagnostics_pub = self.create_publisher(
            DiagnosticArray, DIAGNOSTICS, topic_qos(DIAGNOSTICS)
        )
        # The heartbeat runs on the steady clock: it must beat even before /clock arrives when
        # the node runs with use_sim_time:=true.
        self._heartbeat_timer = self.create_timer(
            float(self.get_parameter("heartbeat_period").value),
            self._on_heartbeat_timer,
            clock=Clock(clock_type=ClockType.STEADY_TIME),
        )
        self.get_logger().info(f"{self.NODE_NAME} {__version__}: {self.STATUS}")

    def parameter_values(self) -> dict:
        """This node's own parameters (``PARAMETERS``) by name, as they are now."""
        return {spec.name: self.get_parameter(spec.name).value for spec in self.PARAMETERS}

    def validate_parameters(self, parameters: Sequence[Parameter]) -> str | None:
        """Return a reason to refuse ``parameters``, or None to accept them."""
        del parameters
        return None

    def apply_parameters(self, parameters: Sequence[Parameter]) -> None:
        """Put accepted run-time changes to work (called after :meth:`validate_parameters`
        accepted them, before rcl stores them)."""
        del parameters

    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        """A change at run time: each value against its table entry (the check of
        ``--param``: type, an integer widens to a double, range), then the node's own checks
        across parameters; refused with the reason, else applied."""
        if self.pinned_clock is not None and any(p.name == "use_sim_time" for p in parameters):
            return SetParametersResult(
                successful=False, reason="use_sim_time is fixed in a run with a key (/run_clock)"
            )
        seq = None
        if self.run_key is not None:
            auth = [p.value for p in parameters if p.name == provenance.CHANGE_AUTH_PARAM]
            changes = [(p.name, p.value) for p in parameters if p.name in self.param_specs]
            reason = provenance.change_refusal(
                self.run_key,
                self.get_fully_qualified_name(),
                self.change_seq,
                auth[0] if len(auth) == 1 else None,
                changes,
            )
            if reason:
                self.parameter_changes_refused += 1
                self.parameter_refusals = [*self.parameter_refusals[-4:], reason]
                self.get_logger().warning(f"refused a change of parameters: {reason}")
                return SetParametersResult(successful=False, reason=reason)
            seq = int(str(auth[0]).partition(":")[0])
        for param in parameters:
            spec = self.param_specs.get(param.name)
            if spec is None:
                continue  # rcl's own (use_sim_time, ...): rcl checks them
            if spec.read_only:
                return SetParametersResult(
                    successful=False, reason=f"{param.name} is read-only (set at start only)"
                )
            value = param.value
            try:
                spec.coerce(list(value) if isinstance(value, array) else value)
            except ValueError as exc:
                return SetParametersResult(
                    successful=False, reason=f"{param.name} {exc}, got {param.value!r}"
                )
        reason = self.validate_parameters(parameters)
        if reason:
            return SetParametersResult(successful=False, reason=reason)
        self.apply_parameters(parameters)
        self.parameter_changes += 1
        if seq is not None:
            self.change_seq = seq
        now = self.get_clock().now().nanoseconds * 1e-9
        changed = ", ".join(
            f"{p.name}={provenance.change_value_text(p.value)}"
            for p in parameters
            if p.name in self.param_specs
        )
        self.parameter_change_log.append(f"t={now:.3f} s {changed}")
        return SetParametersResult(successful=True)

    def create_intake_subscription(
        self,
        msg_type,
        topic: str,
        callback,
        qos,
        intake,
        with_info: bool = False,
        on_matched=None,
    ):
        """A subscription whose callback sees only what ``intake`` (a
        :class:`fence_sorter.nodes.intake.TopicIntake`) admits (the run's id, the sender's tag
        under the run's key, the rate), with the middleware's message-lost event counted in it
        where the RMW provides that event. ``with_info``: the callback takes ``(msg, info)``,
        rclpy's message info (``received_timestamp``: ns on the system clock when the
        middleware received it). ``on_matched``: called with rclpy's matched status when a
        publisher is matched or unmatched, where the RMW reports it."""

        key = self.run_key

        def admitted(msg) -> None:
            if intake.admit(msg.run_id, lambda: authentic(msg, key)):
                callback(msg)

        def admitted_with_info(*args) -> None:
            # rclpy's SingleThreadedExecutor calls (msg, info); its EventsExecutor (9.1) passes
            # the (msg, info) tuple as one argument
            msg, info = args if len(args) == 2 else args[0]
            if intake.admit(msg.run_id, lambda: authentic(msg, key)):
                callback(msg, info)

        # rclpy picks the message-info call by the callback's signature: two arguments
        admitted_with_info.__signature__ = _MSG_AND_INFO
        if with_info:
            admitted = admitted_with_info

        events = {"message_lost": intake.on_message_lost}
        if on_matched is not None:
            events["matched"] = on_matched
        while True:
            try:
                return self.create_subscription(
                    msg_type,
                    topic,
                    admitted,
                    qos,
                    event_callbacks=SubscriptionEventCallbacks(**events),
                )
            except UnsupportedEventTypeError:
                kind = "matched" if "matched" in events else "message_lost"
                self.get_logger().warning(f"{topic}: the RMW reports no {kind} events")
                del events[kind]
                if not events:
                    return self.create_subscription(msg_type, topic, admitted, qos)

    def heartbeat_status(self) -> DiagnosticStatus:
        """Return the DiagnosticStatus this node reports on every heartbeat."""
        return DiagnosticStatus(
            level=self.STATUS_LEVEL,
            name=f"fence_sorter/{self.get_name()}",
            message=self.STATUS,
            hardware_id="fence_sorter",
            values=[
                KeyValue(key="version", value=__version__),
                KeyValue(key="node", value=self.get_fully_qualified_name()),
                KeyValue(key=STARTED_KEY, value=str(self.started_ns)),
                KeyValue(key="take_errors", value=str(self.take_errors)),
                *(
                    KeyValue(key=k, value=v)
                    for k, v in (self.pinned_clock.values() if self.pinned_clock else {}).items()
                ),
                KeyValue(key="parameter_changes", value=str(self.parameter_changes)),
                KeyValue(
                    key="parameter_changes_refused", value=str(self.parameter_changes_refused)
                ),
                KeyValue(key="parameter_change_log", value="; ".join(self.parameter_change_log)),
                KeyValue(key="parameter_refusals", value=" | ".join(self.parameter_refusals)),
            ],
        )

    def heartbeat_stamp(self):
        """Stamp of the heartbeat: the node's clock (sim time with use_sim_time)."""
        return self.get_clock().now().to_msg()

    def heartbeat_message(self) -> DiagnosticArray:
        """One DiagnosticArray with this node's status."""
        msg = DiagnosticArray()
        msg.header.stamp = self.heartbeat_stamp()
        msg.status = [self.heartbeat_status()]
        return msg

    def _on_heartbeat_timer(self) -> None:
        """A heartbeat, or, when this node's sim time lags the run's clock (a long callback
        kept the executor from the clock), one with the next clock message: stamped from the
        lagging time it would follow later-stamped heartbeats of other nodes, out of stamp
        order on /diagnostics."""
        pinned = self.pinned_clock
        if pinned is not None and pinned.behind(time.monotonic()):
            pinned.on_next = self.publish_heartbeat
            return
        self.publish_heartbeat()

    def publish_heartbeat(self) -> bool:
        """Publish :meth:`heartbeat_message` on /diagnostics; False if this node holds it back."""
        self._diagnostics_pub.publish(sign_diagnostics(self.heartbeat_message(), self.run_key))
        return True


#: more take failures than this in one run: something is really broken, stop
MAX_TAKE_ERRORS = 100


def spin_node(node: FenceSorterNode, executor: Executor | None = None) -> None:
    """Spin ``node`` until shutdown, through rare take failures instead of dying on the first.

    Under heavy load rclpy's ``take_message`` occasionally raises ``RuntimeError: Unable to
    convert call argument '0' to Python object`` for a message that arrived (seen here once in
    some thirty suite runs on a loaded 2-core machine; ros/joint_state_publisher#117 reports the
    same under load). Such a failure is logged and counted (``take_errors`` in the node's
    diagnostics), that one message is lost, and the node spins on; more than
    :data:`MAX_TAKE_ERRORS` re-raise. Ctrl-C, SIGTERM and shutdown end the spin as usual.
    """
    if executor is None:
        executor = make_executor(bool(node.get_parameter("events_executor").value))
        executor.add_node(node)
    announced = False
    while rclpy.ok():
        if not announced and node._diagnostics_pub.get_subscription_count() > 0:
            # a first heartbeat as soon as a listener (the runner's monitor) has matched and
            # the node sends one (the scanner: once /clock runs), not a heartbeat_period
            # later: the run's nodes are up up to 1 s sooner
            announced = node.publish_heartbeat()
        try:
            executor.spin_once(timeout_sec=0.1)
        except (KeyboardInterrupt, ExternalShutdownException):
            raise
        except RuntimeError as exc:  # rclpy's RCLError is one too
            if not rclpy.ok():
                break
            node.take_errors += 1
            node.get_logger().error(
                f"a message could not be taken ({type(exc).__name__}: {exc}); "
                f"{node.take_errors} so far, going on"
            )
            if node.take_errors > MAX_TAKE_ERRORS:
                raise


def run_node(node_class: type[FenceSorterNode], args: Sequence[str] | None = None) -> int:
    """Init rclpy, spin one node (:func:`spin_node`) until Ctrl-C, SIGTERM or external
    shutdown; return the exit code.

    rclpy's own signal handlers (SIGINT and SIGTERM) shut the context down, which ends the spin
    with ExternalShutdownException. On SIGINT rclpy then calls the Python handler it found,
    which by default raises KeyboardInterrupt at whatever bytecode the main thread is in: once
    inside an rclpy Task's constructor, whose half-built object then printed "Exception ignored
    in Task.__del__" with a traceback at exit. Python's SIGINT handler is therefore a no-op
    here; a KeyboardInterrupt that still slips through ends the spin as well.
    """
    signal.signal(signal.SIGINT, lambda *_: None)
    rclpy.init(args=list(args) if args is not None else None)
    node: FenceSorterNode | None = None
    try:
        node = node_class()
        spin_node(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ParameterException as exc:
        print(f"{node_class.NODE_NAME}: invalid parameter: {exc}", file=sys.stderr)
        return 1
    except Exception:  # RCLError: a signal shut the context down during construction or spin
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
