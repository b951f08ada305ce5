"""Sensors node: what a real sorter's drive encoder, overhead camera and fence root strain gauge
publish, measured from the twin's published state (``fence-sorter run --sensors FILE``).

It subscribes to the simulator's /fence_state (drive angle alpha_w, tip deflection), its
/load_states (each parcel's centre of gravity and yaw) and the scanner's /parcels (the centre
of gravity offsets that place the geometric centre a camera sees), and publishes the measured
topics (/sensors/drive_encoder, /sensors/camera/parcel_poses, /sensors/fence_root/moment) with
the rates, noise, dropouts and camera frame of the sensors file. The sensor model is
:class:`fence_sorter.calibration.sensors.SensorStream` (the noise and dropout functions of
``fence-sorter emulate``) and the messages are those of :mod:`fence_sorter.calibration.bag`
(serialised there, published raw), so a run's calibration bag and an emulated one read alike.

Time is the simulator's: the stamps of its states (the node needs no /clock). Every sample is
stamped with its capture time, an instant k / rate of its sensor, the truth interpolated
between the states around it (``fence-sorter run --sensors`` sets the simulator's
publish_rate to the highest sensor rate, at most 250 Hz of sim time). Latency is delayed
publication in sim time: a camera frame goes out once the state stream has reached its capture
time + ``camera.latency``; the encoder samples go out at once, the gauge's one state later.
Every sample not published is counted on /diagnostics (``*_dropped_*``,
in the run's summary under "dropped"): ``camera_dropped_dropout`` (the dropout model),
``*_dropped_state_gap`` (the state stream had a gap longer than ``max_state_gap``: the
node fell behind or the middleware lost states), ``camera_dropped_overload`` (more than
``max_pending`` frames held), ``camera_dropped_unknown_parcel`` (no valid /parcels message for
it), ``states_dropped_out_of_order``; the middleware's lost states are counted as
``fence_state.lost`` and ``load_states.lost``.
"""

from __future__ import annotations

import math
import sys
from collections import Counter
from collections.abc import Sequence

from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from rclpy.event_handler import SubscriptionEventCallbacks
from sensor_msgs.msg import JointState

from fence_sorter.calibration.bag import camera_msg, encoder_msg, moment_msg
from fence_sorter.calibration.replay import root_moment_factor
from fence_sorter.calibration.sensors import SensorConfigError, SensorStream, load_sensors
from fence_sorter.inputs import InputError, validate_parcel
from fence_sorter.nodes.base import FenceSorterNode, run_node
from fence_sorter.nodes.convert import parcel_from_msg
from fence_sorter.nodes.intake import TopicIntake
from fence_sorter.nodes.parameters import SENSORS_PARAMETERS
from fence_sorter.nodes.qos import INPUT_QOS, topic_qos
from fence_sorter.recording import topics
from fence_sorter.recording.msgtypes import make_typestore
from fence_sorter.scene import load_scene
from fence_sorter.stamps import time_to_sec
from fence_sorter_msgs.msg import FenceState, LoadState, Parcel

#: sim time after its last state when a parcel's state is forgotten [s]
FORGET_AFTER = 1.0


class SensorsNode(FenceSorterNode):
    """The sensors of a sensors file, measuring the twin's published state."""

    NODE_NAME = "sensors"
    STATUS = "measuring"
    PARAMETERS = SENSORS_PARAMETERS

    def __init__(self, **kwargs: object) -> None:
        super().__init__(**kwargs)
        p = self.parameter_values()
        self.config = load_sensors(str(p["sensors"]))  # SensorConfigError: exit 2 in main()
        scene = load_scene(str(p["scene"])).scenario  # SceneError: exit 2 in main()
        self.belt_width = scene.conveyor.width
        factor = root_moment_factor(scene) if scene.fence is not None else None
        self.stream = SensorStream(
            self.config, int(p["seed"]), factor, float(p["max_state_gap"]), int(p["max_pending"])
        )
        self.ts = make_typestore()
        self.known: set[int] = set()
        self.bad_parcels: Counter[str] = Counter()
        self.lost: Counter[str] = Counter()
        self._last_forget = -float("inf")

        self.parcel_intake = TopicIntake("parcels", int(p["run_id"]))
        self.create_intake_subscription(
            Parcel, topics.PARCELS, self._on_parcel, INPUT_QOS, self.parcel_intake
        )
        for msg_type, name, callback in (
            (FenceState, topics.FENCE_STATE, self._on_fence),
            (LoadState, topics.LOAD_STATES, self._on_load),
        ):
            key = name.strip("/")
            self.lost[key] = 0
            self.create_subscription(
                msg_type,
                name,
                callback,
                topic_qos(name, topics.RECORDER_DEPTH),
                event_callbacks=SubscriptionEventCallbacks(
                    message_lost=lambda info, key=key: self._on_lost(key, info)
                ),
            )
        self.pub_encoder = self.create_publisher(
            JointState, topics.DRIVE_ENCODER, topic_qos(topics.DRIVE_ENCODER)
        )
        self.pub_camera = self.create_publisher(
            LoadState, topics.CAMERA_POSES, topic_qos(topics.CAMERA_POSES)
        )
        self.pub_moment = None
        if self.stream.strain is not None:
            self.pub_moment = self.create_publisher(
                WrenchStamped, topics.FENCE_ROOT_MOMENT, topic_qos(topics.FENCE_ROOT_MOMENT)
            )
        cfg = self.config
        self.get_logger().info(
            f"sensors {cfg.name}: encoder {cfg.encoder.rate:g} Hz, camera {cfg.camera.rate:g} "
            f"Hz (latency {cfg.camera.latency:g} s, dropout {cfg.camera.dropout:g}), "
            + (f"gauge {cfg.strain.rate:g} Hz" if self.pub_moment else "no gauge")
        )

    def _on_lost(self, key: str, info) -> None:
        self.lost[key] += int(getattr(info, "total_count_change", 1))

    def _publish(self, publisher, msg, msgtype: str) -> None:
        publisher.publish(bytes(self.ts.serialize_cdr(msg, msgtype)))

    def _on_parcel(self, msg: Parcel) -> None:
        spec = parcel_from_msg(msg)
        try:
            validate_parcel(spec, self.belt_width, self.known)
        except InputError as exc:
            self.bad_parcels[exc.key] += 1
            return
        self.known.add(spec.parcel_id)
        self.stream.parcel(spec.parcel_id, spec.cog_offset_x, spec.cog_offset_y)

    def _on_fence(self, msg: FenceState) -> None:
        t = time_to_sec(msg.header.stamp)
        (enc_t, enc_a), (str_t, str_m) = self.stream.fence_state(
            t, msg.drive_angle, msg.drive_rate, msg.tip_deflection
        )
        joint = topics.MEASURED[topics.DRIVE_ENCODER].msgtype
        for tk, a in zip(enc_t, enc_a, strict=True):
            self._publish(self.pub_encoder, encoder_msg(self.ts, tk, a), joint)
        if self.pub_moment is not None:
            wrench = topics.MEASURED[topics.FENCE_ROOT_MOMENT].msgtype
            for tk, m in zip(str_t, str_m, strict=True):
                self._publish(self.pub_moment, moment_msg(self.ts, tk, m), wrench)
        self._release()
        if t - self._last_forget > FORGET_AFTER:
            self.stream.forget_before(t - FORGET_AFTER)
            self._last_forget = t

    def _on_load(self, msg: LoadState) -> None:
        q, v = msg.pose.orientation, msg.twist
        self.stream.parcel_state(
            msg.parcel_id,
            time_to_sec(msg.header.stamp),
            (msg.pose.position.x, msg.pose.position.y, 2.0 * math.atan2(q.z, q.w)),
            (v.linear.x, v.linear.y, v.angular.z),
        )
        self._release()

    def _release(self) -> None:
        camera = topics.MEASURED[topics.CAMERA_POSES].msgtype
        for f in self.stream.release():
            self._publish(
                self.pub_camera, camera_msg(self.ts, f.t, f.parcel_id, f.x, f.y, f.yaw), camera
            )

    def heartbeat_stamp(self):
        """The state clock (sim time of the newest state): the time base of /diagnostics in a
        run, without following /clock (hundreds of messages per second the node does not need)."""
        t = self.stream.clock if math.isfinite(self.stream.clock) else 0.0
        sec, nanosec = divmod(int(round(t * 1e9)), 10**9)
        return TimeMsg(sec=sec, nanosec=nanosec)

    def heartbeat_status(self) -> DiagnosticStatus:
        status = super().heartbeat_status()
        lo, hi = self.stream.delay_range
        values = {
            "sensors": self.config.name,
            "state_clock_s": f"{self.stream.clock:.4f}",
            # the newest /fence_state and /load_states stamps: the encoder's and gauge's
            # samples follow the first, the camera's frames the second
            "fence_clock_s": f"{self.stream.fence_clock:.4f}",
            "load_clock_s": f"{self.stream.load_clock:.4f}",
            # state clock at a camera frame's publication - its capture time (the latency)
            "camera_delay_min_s": f"{lo:.4f}",
            "camera_delay_max_s": f"{hi:.4f}",
        }
        values.update({k: str(v) for k, v in self.stream.counts.items()})
        values.update({f"{k}.lost": str(v) for k, v in self.lost.items()})
        values.update(self.parcel_intake.values())
        values.update({f"bad_parcels.{k}": str(v) for k, v in sorted(self.bad_parcels.items())})
        status.values.extend(KeyValue(key=k, value=v) for k, v in values.items())
        return status


def main(args: Sequence[str] | None = None) -> int:
    """Run the sensors until Ctrl-C or SIGTERM; exit 2 with one line naming the field and its
    range on a bad sensors file or scene."""
    try:
        return run_node(SensorsNode, args)
    except (SensorConfigError, ValueError) as exc:
        print(f"sensors: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
