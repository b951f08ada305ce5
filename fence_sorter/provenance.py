"""Who sent a message: the run's key and the tags of its senders (ROS-free).

The nodes of a run share its ``run_id``, which anyone on the domain can read (a node's command
line, any /parcels message). So the run id tells runs apart, not senders: a participant inside
the domain could publish parcels, commands or a clock with the run's id. The run therefore also
has a secret key, drawn per run by the runner and handed to its node processes in their
environment (:data:`RUN_KEY_ENV`; never on a command line, a parameter or the wire). A sender
(the scanner on /parcels, the controller on /fence_commands, the simulator on /run_clock) puts
the tag of each message under that key into its ``auth`` field; a receiver with the key refuses
a message whose tag does not verify and counts it as ``foreign_source``, whatever its run id.

The tag is the first 8 bytes of HMAC-SHA256(key, payload), the payload the message's field
values in a canonical text (:func:`message_payload`: every field but ``auth``, floats exact).
Not its CDR bytes: rclpy's serialisation leaves alignment padding uninitialised, so one
message serialises to different bytes in two processes. Why a tag and not the
publisher's GID of the message info: rclpy 7.1 (Jazzy) gives no ``publisher_gid`` in the
message info, and a GID learned from the graph by node name trusts a name any participant
can take. A node without a key (started by hand) signs nothing and checks only run ids.
"""

from __future__ import annotations

import hashlib
import hmac
import operator
import os
import secrets
import struct
from collections.abc import Mapping

#: the environment variable that carries a run's key (hex) to its node processes
RUN_KEY_ENV = "FENCE_SORTER_RUN_KEY"
#: bytes of a run key
KEY_BYTES = 32


def new_run_key() -> str:
    """A fresh run key, as the hex text of :data:`RUN_KEY_ENV`."""
    return secrets.token_hex(KEY_BYTES)


def run_key(env: Mapping[str, str] | None = None) -> bytes | None:
    """The run's key from the environment, None when there is none; ValueError naming the
    variable when it is not 64 hex digits."""
    text = (os.environ if env is None else env).get(RUN_KEY_ENV, "")
    if not text:
        return None
    try:
        key = bytes.fromhex(text)
    except ValueError:
        key = b""
    if len(key) != KEY_BYTES:
        raise ValueError(f"{RUN_KEY_ENV} must be {2 * KEY_BYTES} hex digits, got {len(text)}")
    return key


def tag(key: bytes, payload: bytes) -> int:
    """The 64-bit tag of ``payload`` under ``key`` (never 0: 0 means unsigned)."""
    digest = hmac.new(key, payload, hashlib.sha256).digest()
    return int.from_bytes(digest[:8], "little") or 1


def verify(key: bytes, payload: bytes, given: int) -> bool:
    """True when ``given`` is the tag of ``payload`` under ``key`` (constant time)."""
    return hmac.compare_digest(
        tag(key, payload).to_bytes(8, "little"), int(given).to_bytes(8, "little")
    )


def _leaves(msg, prefix: str = "") -> list[str]:
    """Dotted paths of a message's scalar fields (nested messages walked), ``auth`` left out."""
    paths = []
    for name in msg.get_fields_and_field_types():
        if not prefix and name == "auth":
            continue
        value = getattr(msg, name)
        if hasattr(value, "get_fields_and_field_types"):
            paths += _leaves(value, f"{prefix}{name}.")
        else:
            paths.append(f"{prefix}{name}")
    return paths


_GETTERS: dict[type, operator.attrgetter] = {}


def message_payload(msg) -> bytes:
    """What a message's tag covers: the values of every field but ``auth`` (a fence_sorter_msgs
    message with that field), nested fields flattened, as the ``repr`` of one tuple: exact
    for floats (shortest round-trip text, NaN as ``nan``), ints and strings."""
    getter = _GETTERS.get(type(msg))
    if getter is None:
        paths = _leaves(msg)
        getter = _GETTERS[type(msg)] = operator.attrgetter(paths[0], *paths[1:])
    values = getter(msg)
    return repr(tuple(v if isinstance(v, (int, float, str)) else list(v) for v in values)).encode()


def clock_payload(sec: int, nanosec: int, run_id: int) -> bytes:
    """What a /run_clock message's tag covers: its time and run id."""
    return struct.pack("<iIQ", int(sec), int(nanosec), int(run_id))


#: the KeyValue of a DiagnosticStatus that carries its tag (a decimal text)
STATUS_TAG_KEY = "auth"


def status_payload(sec: int, nanosec: int, name: str, message: str, level: int, values) -> bytes:
    """What a /diagnostics status's tag covers: its array's stamp, name, message, level and
    every (key, value) but :data:`STATUS_TAG_KEY`, in order."""
    pairs = [(str(k), str(v)) for k, v in values if k != STATUS_TAG_KEY]
    return repr((int(sec), int(nanosec), str(name), str(message), int(level), pairs)).encode()


#: the string parameter through which a change at run time carries its tag, ``SEQ:TAG``: a
#: node with the run's key takes a change of its parameters only with this one beside it in
#: the same atomic request, SEQ above every one it took before
CHANGE_AUTH_PARAM = "run_change_auth"


def change_value_text(value) -> str:
    """A parameter value as the tag of a change covers it (an array as a list)."""
    if hasattr(value, "tolist"):
        value = value.tolist()
    elif not isinstance(value, (bool, int, float, str, list)):
        value = list(value)
    return repr(value)


def change_payload(node: str, seq: int, changes) -> bytes:
    """What the tag of a change at run time covers: the node's fully qualified name, the
    sequence number and every (name, value) set, sorted by name."""
    pairs = sorted((str(n), change_value_text(v)) for n, v in changes)
    return repr((str(node), int(seq), pairs)).encode()


def change_auth(key: bytes, node: str, seq: int, changes) -> str:
    """The :data:`CHANGE_AUTH_PARAM` value of a change: ``SEQ:TAG``."""
    return f"{int(seq)}:{tag(key, change_payload(node, seq, changes))}"


def change_refusal(key: bytes, node: str, last_seq: int, auth: str | None, changes) -> str:
    """Why a keyed node refuses a change (empty: it takes it): no tag, a malformed one, a
    sequence number not above ``last_seq`` (a replay) or a tag that does not verify."""
    names = ", ".join(sorted(str(n) for n, _ in changes)) or CHANGE_AUTH_PARAM
    if auth is None:
        return (
            f"{names}: a change in a run needs the run's key "
            "(fence-sorter param set --key-file <the run's log directory>/run.key)"
        )
    seq_text, _, tag_text = str(auth).partition(":")
    if not (seq_text.isdigit() and tag_text.isdigit()):
        return f"{names}: {CHANGE_AUTH_PARAM} must be SEQ:TAG, got {auth!r}"
    if int(seq_text) <= last_seq:
        return (
            f"{names}: {CHANGE_AUTH_PARAM} sequence {seq_text} is not above {last_seq} (a replay)"
        )
    payload = change_payload(node, int(seq_text), changes)
    if not verify(key, payload, int(tag_text) % 2**64):
        return f"{names}: the tag of the change does not verify under the run's key"
    return ""
