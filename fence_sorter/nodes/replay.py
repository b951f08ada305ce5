"""Replay of a recorded bag over DDS (``fence-sorter replay``): every message republished raw
(CDR as recorded) with its original timing scaled by ``rate``, /clock included, so nodes run
with ``use_sim_time:=true`` follow the recorded sim time. A topic recorded in another version
of its type (a field added since) is republished field by field into the current type.

Timing: message k goes out at wall ``start + (t_k - t_0) / rate`` (t = bag timestamp, the
recorder's reception time), paced on the steady clock. QoS per topic as recorded (reliable or
best effort, fence_sorter.recording.topics; reliable ones offered transient local, see
:func:`offered`); unknown topics are published reliable. The node ends once its reliable
subscribers have acknowledged every message (at most ``ACK_WAIT``).
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import rclpy
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from fence_sorter.nodes.qos import RELIABLE_QOS, topic_qos
from fence_sorter.nodes.recorder import message_class
from fence_sorter.recording.bagread import BagContents, BagMessage
from fence_sorter.recording.topics import REPLAY_DEPTH, TOPICS

NODE_NAME = "replay"
ACK_WAIT = 10.0  # [s] the longest wait for reliable subscribers to acknowledge the last messages


@dataclass
class ReplayResult:
    published: Counter = field(default_factory=Counter)
    wall_time: float = 0.0
    bag_time: float = 0.0  # span of the bag timestamps replayed [s]
    max_lateness: float = 0.0  # [s]
    unacknowledged: list[str] = field(default_factory=list)  # topics not acked within ACK_WAIT


def _fields(obj) -> list[str]:
    """Field names of a rosbags message (a dataclass) or of an rclpy message class."""
    if hasattr(obj, "get_fields_and_field_types"):
        return list(obj.get_fields_and_field_types())
    # a rosbags dataclass lists the type's constants (UPPER_CASE) and __msgtype__ too
    names = getattr(obj, "__dataclass_fields__", {})
    return [n for n in names if not n.startswith("__") and not n.isupper()]


def _copy_into(cls, src):
    """An rclpy message of ``cls`` with the fields ``src`` (a rosbags message) has by name;
    the others keep their defaults (a field the recording's version did not have)."""
    out = cls()
    types = cls.get_fields_and_field_types()
    for name in types:
        if not hasattr(src, name):
            continue
        value = getattr(src, name)
        current = getattr(out, name)
        if hasattr(current, "get_fields_and_field_types"):
            setattr(out, name, _copy_into(type(current), value))
        elif isinstance(value, (list, tuple)) and value and _fields(value[0]):
            pkg, _, kind = types[name].removeprefix("sequence<").partition(">")[0].partition("/")
            inner = message_class(f"{pkg}/msg/{kind}")
            setattr(out, name, [_copy_into(inner, v) for v in value])
        elif hasattr(value, "tolist"):
            setattr(out, name, value.tolist())
        else:
            setattr(out, name, value)
    return out


def offered(qos):
    """The recorded ``qos``, transient local when reliable: a subscriber asking for transient
    local gets every message from the first, even when its side of the match completes after
    the replay has started (a volatile reader drops what arrives before); volatile
    subscribers are matched and served as before."""
    if qos.reliability != ReliabilityPolicy.RELIABLE:
        return qos
    return QoSProfile(
        history=qos.history,
        depth=qos.depth,
        reliability=qos.reliability,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


def replay(
    contents: BagContents,
    rate: float = 1.0,
    topics: Iterable[str] | None = None,
    wait_for_subscribers: float = 0.0,
    say: Callable[[str], None] = print,
    on_publish: Callable[[BagMessage], None] | None = None,
    ready: Callable[[], bool] | None = None,
    domain: int | None = None,
) -> ReplayResult:
    """Publish the bag's messages over DDS on ROS domain ``domain`` (None: the current
    ROS_DOMAIN_ID); returns counts.

    ``wait_for_subscribers`` > 0: wait up to that long [s] for at least one subscriber on a
    replayed topic before starting (so a node started just before does not miss the start);
    ``ready``: a further condition that ends that wait (a Foxglove client subscribed).
    ``on_publish`` sees every message right after it is published (``replay --foxglove``).
    """
    if not rate > 0:
        raise ValueError(f"--rate must be > 0, got {rate}")
    wanted = set(topics) if topics else None
    msgs = [m for m in contents.messages if wanted is None or m.topic in wanted]
    msgs.sort(key=lambda m: m.t_ns)
    result = ReplayResult()
    if not msgs:
        return result
    rclpy.init(**({} if domain is None else {"domain_id": domain}))
    node = rclpy.create_node(NODE_NAME)
    try:
        pubs = {}
        convert: dict[str, type] = {}  # topics recorded in another version of their type
        for topic in sorted({m.topic for m in msgs}):
            first = next(m for m in msgs if m.topic == topic)
            cls = message_class(first.msgtype)
            if _fields(first.msg) != _fields(cls):
                convert[topic] = cls
                had, has = _fields(first.msg), _fields(cls)
                missing = ", ".join(n for n in has if n not in had) or "none"
                gone = ", ".join(n for n in had if n not in has) or "none"
                say(
                    f"{topic}: recorded as another version of {first.msgtype} (without "
                    f"{missing}; dropped: {gone}): republished field by field, the fields it "
                    "lacks at their defaults"
                )
            qos = topic_qos(topic, REPLAY_DEPTH) if topic in TOPICS else RELIABLE_QOS
            pubs[topic] = node.create_publisher(cls, topic, offered(qos))
        if wait_for_subscribers > 0:
            deadline = time.monotonic() + wait_for_subscribers
            while (
                time.monotonic() < deadline
                and not any(p.get_subscription_count() for p in pubs.values())
                and not (ready is not None and ready())
            ):
                time.sleep(0.05)
        t0 = msgs[0].t_ns
        result.bag_time = (msgs[-1].t_ns - t0) * 1e-9
        say(
            f"replaying {len(msgs)} messages on {len(pubs)} topics, {result.bag_time:.1f} s of "
            f"bag at rate {rate:g}"
        )
        start = time.monotonic()
        for m in msgs:
            due = start + (m.t_ns - t0) * 1e-9 / rate
            now = time.monotonic()
            if due > now:
                time.sleep(due - now)
            else:
                result.max_lateness = max(result.max_lateness, now - due)
            cls = convert.get(m.topic)
            pubs[m.topic].publish(m.raw if cls is None else _copy_into(cls, m.msg))
            result.published[m.topic] += 1
            if on_publish is not None:
                on_publish(m)
        result.wall_time = time.monotonic() - start
        # the node goes only once its reliable subscribers have acknowledged every message
        # (a repair of the tail can take a heartbeat period on a loaded machine)
        result.unacknowledged = sorted(
            t for t, p in pubs.items() if not p.wait_for_all_acked(Duration(seconds=ACK_WAIT))
        )
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return result
