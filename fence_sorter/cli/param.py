"""``fence-sorter param list|get|set NODE [NAME [VALUE]]``: a node's parameters at run time.

A stand-in for ``ros2 param`` (no ros2cli in the ROS 2 wheels), through the node's parameter
services over rclpy, joining the ROS domain of a run (``--domain``; `fence-sorter run` prints
its domain; default ROS_DOMAIN_ID) with localhost discovery, as ``fence-sorter topic`` does.

- ``list NODE``: every parameter with its type and whether it can change at run time
  (``read-only``: only at start, with ``--param`` or a parameter file).
- ``get NODE NAME``: the current value (``NAME: VALUE`` in YAML; ``--json``: JSON alone).
- ``set NODE NAME VALUE``: VALUE is read as ``--param NODE:NAME=VALUE`` reads it (YAML, an
  integer widens to a double) and, for a fence_sorter node, checked against the same table
  (``fence_sorter/nodes/parameters.py``) before it is sent; the node checks it again and
  either applies it at once or refuses it with the reason, which is printed. A node of a
  run (``fence-sorter run``) holds the run's key and takes a change only with its tag under
  that key: ``--key-file`` names the run's ``run.key`` (in its log directory).

Exit codes: 0 done; 1 the node's parameter services did not answer within ``--timeout``, the
parameter does not exist, or the node refused the value; 2 bad options or a VALUE outside
the parameter's allowed values; 130 interrupted.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import yaml

from fence_sorter import provenance
from fence_sorter.cli.ros_session import DomainSession, domain_options, run_in_session
from fence_sorter.cli.subcommands import add_subcommands, doc_summary
from fence_sorter.jsonsafe import json_safe
from fence_sorter.nodes.parameters import NODE_PARAMETERS, ParamOverrideError, parse_override

#: rcl_interfaces ParameterType -> the name printed by ``list``
TYPE_NAMES = {
    0: "not set",
    1: "bool",
    2: "integer",
    3: "double",
    4: "string",
    5: "byte array",
    6: "bool array",
    7: "integer array",
    8: "double array",
    9: "string array",
}


class ParamError(RuntimeError):
    """The node did not answer, or refused (exit 1)."""


def register(parser: argparse.ArgumentParser) -> None:
    commands = add_subcommands(parser, doc_summary(__doc__), "param_command")
    common = domain_options("the node's parameter services and their answer")
    p_list = commands.add_parser(
        "list",
        parents=[common],
        help="a node's parameters",
        description="A node's parameters, with type and whether they can change at run time.",
    )
    p_list.add_argument("node")
    p_list.set_defaults(func=run_list)
    p_get = commands.add_parser(
        "get", parents=[common], help="a parameter's value", description="A parameter's value."
    )
    p_get.add_argument("node")
    p_get.add_argument("name")
    p_get.add_argument("--json", action="store_true", help="the value as JSON")
    p_get.set_defaults(func=run_get)
    p_set = commands.add_parser(
        "set",
        parents=[common],
        help="set a parameter while the node runs",
        description="Set a parameter while the node runs (applied at once, or refused).",
    )
    p_set.add_argument("node")
    p_set.add_argument("name")
    p_set.add_argument("value")
    p_set.add_argument(
        "--key-file",
        metavar="FILE",
        help="the run's key (run.key in the log directory of `fence-sorter run`): a node of "
        "a run takes a change only with its tag under that key",
    )
    p_set.set_defaults(func=run_set)


def node_path(node: str) -> str:
    """``controller`` -> ``/controller`` (the fully qualified name the services hang under)."""
    return node if node.startswith("/") else f"/{node}"


class _Session(DomainSession):
    """A session on the chosen domain, with clients of one node's services."""

    def __init__(self, domain: int | None, target: str, timeout: float) -> None:
        super().__init__(domain, f"fence_sorter_param_{os.getpid()}")
        self.target = node_path(target)
        self.timeout = timeout

    def call(self, service: str, srv_type, request):
        """``request`` to ``<node>/<service>``; its response, or ParamError after --timeout."""
        client = self.node.create_client(srv_type, f"{self.target}/{service}")
        deadline = time.monotonic() + self.timeout
        try:
            while not client.service_is_ready():
                if time.monotonic() > deadline:
                    raise ParamError(
                        f"node {self.target}: no parameter services on the graph within "
                        f"{self.timeout:g} s (is it running on this domain?)"
                    )
                self.executor.spin_once(timeout_sec=0.05)
            future = client.call_async(request)
            while not future.done():
                if time.monotonic() > deadline:
                    raise ParamError(f"node {self.target}: {service} got no answer")
                self.executor.spin_once(timeout_sec=0.05)
            return future.result()
        finally:
            self.node.destroy_client(client)

    def describe(self, names: list[str]) -> list:
        from rcl_interfaces.srv import DescribeParameters  # lazy: ROS messages

        return list(
            self.call(
                "describe_parameters", DescribeParameters, DescribeParameters.Request(names=names)
            ).descriptors
        )

    def names(self) -> list[str]:
        from rcl_interfaces.srv import ListParameters  # lazy: ROS messages

        return sorted(
            self.call("list_parameters", ListParameters, ListParameters.Request()).result.names
        )

    def get(self, name: str):
        """The value of ``name`` as Python, or ParamError if the node has no such parameter."""
        from rcl_interfaces.srv import GetParameters  # lazy: ROS messages
        from rclpy.parameter import parameter_value_to_python

        values = self.call(
            "get_parameters", GetParameters, GetParameters.Request(names=[name])
        ).values
        if not values or values[0].type == 0:
            raise ParamError(f"node {self.target} has no parameter {name!r}")
        return parameter_value_to_python(values[0])

    def set(self, name: str, value, key: bytes | None = None) -> None:
        """Set ``name``; ParamError with the node's reason if it refuses. With the run's
        ``key``: atomically with its tag (``run_change_auth``), as a keyed node requires."""
        from rcl_interfaces.srv import SetParameters, SetParametersAtomically  # lazy: ROS
        from rclpy.parameter import Parameter

        params = [Parameter(name, value=value)]
        if key is None:
            request = SetParameters.Request(parameters=[params[0].to_parameter_msg()])
            result = self.call("set_parameters", SetParameters, request).results[0]
        else:
            seq = time.time_ns()
            auth = provenance.change_auth(key, self.target, seq, [(name, value)])
            params.append(Parameter(provenance.CHANGE_AUTH_PARAM, value=auth))
            request = SetParametersAtomically.Request(
                parameters=[p.to_parameter_msg() for p in params]
            )
            result = self.call(
                "set_parameters_atomically", SetParametersAtomically, request
            ).result
        if not result.successful:
            raise ParamError(f"node {self.target} refused {name} = {value!r}: {result.reason}")


def _run(args: argparse.Namespace, name: str, body) -> int:
    def session() -> _Session:
        return _Session(args.domain, args.node, args.timeout)

    return run_in_session(args, "param", name, ParamError, session, body)


def run_list(args: argparse.Namespace) -> int:
    def body(s: _Session) -> int:
        names = s.names()
        for name, desc in zip(names, s.describe(names), strict=True):
            kind = TYPE_NAMES.get(desc.type, str(desc.type))
            when = "read-only" if desc.read_only else "settable at run time"
            print(f"{name}: {kind}, {when}")
        return 0

    return _run(args, "list", body)


def run_get(args: argparse.Namespace) -> int:
    def body(s: _Session) -> int:
        value = s.get(args.name)
        if args.json:
            print(json.dumps(json_safe(value)))
        else:
            print(f"{args.name}: {shown(value)}")
        return 0

    return _run(args, "get", body)


def shown(value) -> str:
    """A value as YAML reads it back: a string as it is (quoted where YAML would take it for
    another type), anything else in JSON form (1.0, true, [7, 8])."""
    if isinstance(value, str):
        return value if yaml.safe_load(value or "''") == value else json.dumps(value)
    return json.dumps(json_safe(value))


def typed_value(node: str, name: str, text: str):
    """VALUE as ``--param NODE:NAME=VALUE`` reads it: for a fence_sorter node checked against
    its table (ParamOverrideError naming NODE:NAME and the allowed values), else plain YAML."""
    base = node.rsplit("/", 1)[-1]
    if base in NODE_PARAMETERS:
        return parse_override(f"{base}:{name}={text}")[2]
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return text


def run_set(args: argparse.Namespace) -> int:
    try:
        value = typed_value(args.node, args.name, args.value)
    except ParamOverrideError as exc:
        print(f"fence-sorter param set: {str(exc).removeprefix('--param ')}", file=sys.stderr)
        return 2

    key = None
    if args.key_file is not None:
        try:
            text = Path(args.key_file).read_text(encoding="utf-8").strip()
            key = provenance.run_key({provenance.RUN_KEY_ENV: text})
            if key is None:
                raise ValueError("the file is empty")
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            print(
                f"fence-sorter param set: --key-file must be a run's key file (run.key in "
                f"its log directory), got {args.key_file} ({exc})",
                file=sys.stderr,
            )
            return 2

    def body(s: _Session) -> int:
        s.set(args.name, value, key)
        print(f"{args.name}: {shown(value)} (set)")
        return 0

    return _run(args, "set", body)
