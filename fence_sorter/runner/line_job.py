"""``fence-sorter run --line LINE``: a line's nodes as separate processes on an isolated domain.

One ``line_unit`` process per unit of the line file (namespace ``/<unit name>``) and the
``line_owner`` (namespace ``/line``: induction, recirculation, the lockstep clock); the owner
waits until every unit is ready, runs the line to the drain and writes the line summary. The
runner waits for it, then stops every process (Ctrl-C or SIGTERM: at once).

A partial line (``--units 2``, ``--no-owner``) starts only those units (and the owner unless
told not to): the commands of two hosts make one line on one domain, joined over UDP with
``--interface``/``--peers`` (the profile of :mod:`fence_sorter.runner.transport`). The owner's
start gate waits for every unit of the line, wherever it runs; a runner without the owner
waits until its units end with the line (the owner's ``end``). ``--bag DIR``: a recorder
takes every topic of the line (:func:`~fence_sorter.recording.topics.line_topics`: every
unit's namespace and the owner's) into one bag; the owner's start gate waits until it matched
them, and it is stopped last. ``--rerun-url``/``--live-rrd``: the units put their view on the
wire every ``view_period`` of sim time and a ``line_viewer`` beside the owner logs the line's
live Rerun view (:mod:`fence_sorter.nodes.line_viewer`); it ends by itself after the owner's
summary, and the runner waits for it (bounded) before it stops the others.

A unit's process that ends during the run (killed, or taken for down by the owner) is started
again, up to :data:`MAX_RESTARTS` times per unit; the new process rejoins the line at a step
of its clock (the owner goes on without the unit meanwhile, :mod:`fence_sorter.line.lockstep`).
The summary counts the restarts per unit (``restarts``).

Exit codes as ``line-sim``'s: 0 a drained line with every check met (every parcel accounted
for, those lost with a unit that went down among them), 1 a check failed (unbalanced
hand-offs, conservation, a wrong destination, an intrusion with the guard on) or a process
failed, 2 bad input, 3 (a runner without the owner) the line's owner fell silent: its process
or host is gone, 5 the recorder could not write the bag, 130 interrupted.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from fence_sorter.line.line_file import LineSpec, load_line, resolve_line
from fence_sorter.line.lockstep import EXIT_OWNER_GONE
from fence_sorter.physics.params import ParameterError
from fence_sorter.runner.job import (
    EXIT_BAD_INPUT,
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_OK,
    Interrupted,
    StopRequest,
    make_bag_dir,
)
from fence_sorter.runner.processes import (
    FASTDDS_PROFILE,
    ProcessGroup,
    choose_domain,
    clean_shm,
    node_command,
    node_env,
)
from fence_sorter.runner.summary import EXIT_RECORDING
from fence_sorter.runner.transport import (
    HostsTransport,
    TransportError,
    hosts_transport,
    write_profile,
)

__all__ = [
    "EXIT_OWNER_GONE",
    "MAX_RESTARTS",
    "LineRunOptions",
    "LineRunResult",
    "parse_units",
    "run_line_job",
]

LOG_DIR_PREFIX = "fence_sorter_line_"
OWNER = "line_owner"
RECORDER = "recorder"
VIEWER = "line_viewer"
#: sim time between the units' view samples when a live view is asked for [s]
VIEW_PERIOD = 0.05
#: wall time the runner gives the live view to end by itself after the owner [s]
VIEWER_END = 30.0
#: a unit's process is started again at most this many times per run
MAX_RESTARTS = 3
#: --reply-timeout, --owner-timeout: defaults and allowed ranges [s] (wall time)
REPLY_TIMEOUT, REPLY_TIMEOUT_RANGE = 10.0, (1.0, 3600.0)
OWNER_TIMEOUT, OWNER_TIMEOUT_RANGE = 20.0, (1.0, 3600.0)


class _OwnerGone(RuntimeError):
    """A unit of a runner without the owner exited EXIT_OWNER_GONE (one line)."""


@dataclass(frozen=True)
class LineRunOptions:
    line: str
    parcels: int = 10
    seed: int | None = None
    rate: float | None = None
    guard: bool = True
    duration: float | None = None  # --duration: induct for S s of sim time instead of --parcels
    rtf: float = 0.0  # --rtf: the owner paces the line clock at this real-time factor (0: unpaced)
    domain: int | None = None
    log_dir: str | None = None
    keep_logs: bool = False
    timeout: float = 3600.0  # wall-time limit of the whole run [s]
    units: str | None = None  # --units: the units started here (None: all of the line)
    owner: bool = True  # start the line's owner here (--no-owner: another host runs it)
    interface: str | None = None  # IPv4 address: the line talks to other hosts on it
    peers: str | None = None  # the other hosts' IPv4 addresses (comma-separated)
    bag: str | None = None  # --bag: record every topic of the line into this bag directory
    live_rrd: str | None = None  # --live-rrd: the live view saved to this .rrd
    rerun_url: str | None = None  # --rerun-url: the live view streamed to this Rerun viewer
    view_period: float | None = None  # --view-period: the units' view [s of sim time]
    reply_timeout: float = REPLY_TIMEOUT  # --reply-timeout: the owner's wait for a reply [s]
    owner_timeout: float = OWNER_TIMEOUT  # --owner-timeout: a unit's wait for a command [s]

    @property
    def live_view(self) -> bool:
        return self.live_rrd is not None or self.rerun_url is not None

    @property
    def unit_view_period(self) -> float:
        """What the units publish their view at: --view-period, else VIEW_PERIOD with a live
        view here, else 0 (none)."""
        if self.view_period is not None:
            return self.view_period
        return VIEW_PERIOD if self.live_view else 0.0


@dataclass
class LineRunResult:
    code: int
    message: str
    summary: dict


class BadLineInput(ValueError):
    """A bad option or line file (one line, exit 2)."""


def parse_units(text: str | None, names: Sequence[str]) -> tuple[int, ...]:
    """The indices of ``--units`` (comma-separated unit numbers 1..N or unit names, each once);
    ``None``: every unit of the line. BadLineInput names the option and the allowed values."""
    if text is None:
        return tuple(range(len(names)))
    allowed = f"1..{len(names)} or {', '.join(names)}"
    items = [w.strip() for w in text.split(",")]
    if not text.strip() or any(not w for w in items):
        raise BadLineInput(f"--units: give units of the line, comma-separated ({allowed})")
    found: list[int] = []
    for w in items:
        if w in names:
            k = names.index(w)
        elif w.isdigit() and 1 <= int(w) <= len(names):
            k = int(w) - 1
        else:
            raise BadLineInput(f"--units: {w!r} is no unit of the line ({allowed})")
        if k in found:
            raise BadLineInput(f"--units: {w!r} given twice (each unit once: {allowed})")
        found.append(k)
    return tuple(sorted(found))


def _check(
    opts: LineRunOptions,
) -> tuple[LineSpec, Path, tuple[int, ...], HostsTransport | None]:
    if not 1 <= opts.parcels <= 10**6:
        raise BadLineInput(f"--parcels must be in [1, 1000000], got {opts.parcels}")
    if opts.rate is not None and not 1.0 <= opts.rate <= 1e5:
        raise BadLineInput(f"--rate must be in [1, 100000] pcs/h, got {opts.rate}")
    if opts.seed is not None and not 0 <= opts.seed < 2**31:
        raise BadLineInput(f"--seed must be in [0, 2147483647], got {opts.seed}")
    if opts.duration is not None and not 0.0 < opts.duration <= 1e6:
        raise BadLineInput(f"--duration must be in (0, 1e6] s, got {opts.duration}")
    if not 0.0 <= opts.rtf <= 100.0:  # NaN fails too
        raise BadLineInput(f"--rtf must be in [0, 100] (0: unpaced), got {opts.rtf}")
    _check_timeouts(opts)
    try:
        line = load_line(opts.line)
        path = resolve_line(opts.line)
    except (ParameterError, OSError) as exc:
        raise BadLineInput(str(exc)) from None
    units = parse_units(opts.units, [u.name for u in line.units])
    if opts.view_period is not None and not 0.0 <= opts.view_period <= 10.0:  # NaN fails too
        raise BadLineInput(
            f"--view-period must be in [0, 10] s (0: no view), got {opts.view_period}"
        )
    if opts.live_view and not opts.owner:
        raise BadLineInput(
            "--rerun-url and --live-rrd run the live view on the owner's host: they do not go "
            "with --no-owner (give that host's units --view-period)"
        )
    if opts.live_view and opts.view_period == 0.0:
        raise BadLineInput("--view-period 0 publishes no view: the live view needs one > 0")
    if opts.live_rrd is not None:
        rrd = Path(opts.live_rrd)
        if rrd.suffix != ".rrd" or not rrd.resolve().parent.is_dir():
            raise BadLineInput(
                f"--live-rrd must be a .rrd file in an existing directory, got {opts.live_rrd}"
            )
    if opts.bag is not None:
        if not opts.owner:
            raise BadLineInput("--bag records on the owner's host: it does not go with --no-owner")
        try:
            make_bag_dir(opts.bag)
        except ValueError as exc:
            raise BadLineInput(str(exc)) from None
    transport = None
    if (opts.interface is None) != (opts.peers is None):
        raise BadLineInput("--interface and --peers go together (this host's, the others')")
    if opts.interface is not None:
        try:
            transport = hosts_transport(opts.interface, opts.peers)
        except TransportError as exc:
            raise BadLineInput(str(exc)) from None
    return line, path, units, transport


def _check_timeouts(opts: LineRunOptions) -> None:
    """--reply-timeout and --owner-timeout: each within its range; with the owner here, the
    units' wait for a command longer than the owner's wait for a reply (while the owner waits
    for one unit, the others get no command)."""
    lo, hi = REPLY_TIMEOUT_RANGE
    if not lo <= opts.reply_timeout <= hi:
        raise BadLineInput(
            f"--reply-timeout must be in [{lo:g}, {hi:g}] s, got {opts.reply_timeout:g}"
        )
    lo, hi = OWNER_TIMEOUT_RANGE
    if opts.owner:
        lo = max(lo, opts.reply_timeout)
        if not lo < opts.owner_timeout <= hi:
            raise BadLineInput(
                f"--owner-timeout must be in ({lo:g}, {hi:g}] s (above --reply-timeout), got "
                f"{opts.owner_timeout:g}"
            )
    elif not lo <= opts.owner_timeout <= hi:
        raise BadLineInput(
            f"--owner-timeout must be in [{lo:g}, {hi:g}] s, got {opts.owner_timeout:g}"
        )


def run_line_job(
    opts: LineRunOptions, say: Callable[[str], None] = print, stop: StopRequest | None = None
) -> LineRunResult:
    """Run the line once; never leaves a process behind."""
    own = stop is None
    if own:
        stop = StopRequest()
        stop.install()
    try:
        try:
            line, path, units, transport = _check(opts)
            domain = choose_domain(opts.domain)
        except ValueError as exc:  # BadLineInput, DomainError
            return LineRunResult(EXIT_BAD_INPUT, str(exc), {})
        return _run(opts, line, path, units, transport, domain, say, stop)
    finally:
        if own:
            stop.restore()


def _run(
    opts: LineRunOptions,
    line: LineSpec,
    path: Path,
    units: tuple[int, ...],
    transport: HostsTransport | None,
    domain: int,
    say: Callable[[str], None],
    stop: StopRequest,
) -> LineRunResult:
    log_dir = Path(opts.log_dir or tempfile.mkdtemp(prefix=LOG_DIR_PREFIX))
    log_dir.mkdir(parents=True, exist_ok=True)
    profile = FASTDDS_PROFILE if transport is None else write_profile(transport, log_dir)
    env = node_env(domain, log_dir / "ros", profile=profile)
    clean_shm()
    group = ProcessGroup(env, log_dir)
    out = log_dir / "summary.json"
    guard = "true" if opts.guard else "false"
    code, message, summary = EXIT_OK, "done", {}
    here = [line.units[k].name for k in units]
    try:
        stop.check()
        where = "" if transport is None else f", UDP on {transport.address}"
        amount = f"{opts.parcels} parcels"
        if opts.duration is not None:
            amount = f"{opts.duration:g} s of induction"
        pace = "unpaced" if opts.rtf == 0.0 else f"rtf {opts.rtf:g}"
        say(
            f"fence-sorter run --line: {line.name}, units {', '.join(here)} of "
            f"{len(line.units)}{'' if opts.owner else ' (the owner on another host)'}, "
            f"{amount}, {pace}, ROS domain {domain}{where}, logs {log_dir}"
        )
        if opts.bag is not None:
            rec_args = ["-p", f"output_dir:={Path(opts.bag).resolve()}", "-p",
                        "use_sim_time:=true", "-p",
                        f"line_units:={','.join(u.name for u in line.units)}"]  # fmt: skip
            group.start(RECORDER, node_command(RECORDER, rec_args))
        if opts.live_view:  # before the units: subscribed when their first samples go out
            view_args = ["-r", "__ns:=/line", "-p", f"line:={path}"]
            if opts.live_rrd is not None:
                view_args += ["-p", f"rrd:={Path(opts.live_rrd).resolve()}"]
            if opts.rerun_url is not None:
                view_args += ["-p", f"url:={opts.rerun_url}"]
            group.start(VIEWER, node_command(VIEWER, view_args))
        view_period = opts.unit_view_period
        for k in units:
            u = line.units[k]
            group.start(
                u.name,
                node_command(
                    "line_unit",
                    ["-r", f"__ns:=/{u.name}", "-p", f"line:={path}", "-p", f"unit_index:={k}",
                     "-p", f"guard:={guard}", "-p", f"view_period:={float(view_period)!r}",
                     "-p", f"owner_timeout:={float(opts.owner_timeout)!r}"],
                ),
            )  # fmt: skip
        owner = None
        if opts.owner:
            args = ["-r", "__ns:=/line", "-p", f"line:={path}", "-p", f"parcels:={opts.parcels}",
                    "-p", f"guard:={guard}", "-p", f"summary:={out}"]  # fmt: skip
            if opts.seed is not None:
                args += ["-p", f"seed:={opts.seed}"]
            if opts.rate is not None:
                args += ["-p", f"rate:={float(opts.rate)!r}"]
            if opts.bag is not None:
                args += ["-p", "recorder:=true"]
            if opts.duration is not None:
                args += ["-p", f"duration:={float(opts.duration)!r}"]
            args += ["-p", f"real_time_factor:={float(opts.rtf)!r}"]
            args += ["-p", f"reply_timeout:={float(opts.reply_timeout)!r}"]
            owner = group.start(OWNER, node_command(OWNER, args))
        end = time.monotonic() + opts.timeout

        def running() -> bool:
            """With the owner: until it exits; without: until every unit here has ended
            with the line (the owner's ``end``)."""
            if owner is not None:
                return owner.proc.poll() is None
            return len(group.dead()) < len(group.nodes)

        while True:
            stop.check()
            _restart_ended(group, owner is None, say)
            if not running():
                break
            if time.monotonic() > end:
                raise RuntimeError(f"the line did not drain within --timeout {opts.timeout:g} s")
            alive = [n for n in group.nodes.values() if n.proc.poll() is None]
            try:
                (owner or alive[0]).proc.wait(timeout=0.2)
            except subprocess.TimeoutExpired:
                pass
        viewer = group.nodes.get(VIEWER)
        if viewer is not None:  # it ends by itself once the owner's summary is out
            try:
                viewer.proc.wait(timeout=VIEWER_END)
            except subprocess.TimeoutExpired:
                say(f"{VIEWER} did not end within {VIEWER_END:g} s of the owner: stopping it")
        if owner is None:
            code, message = EXIT_OK, "done"
            summary = {"line": line.name, "units_here": here, "owner": "another host"}
        else:
            rc = owner.proc.returncode
            if out.exists():
                summary = json.loads(out.read_text())
            if rc == 0:
                code, message = EXIT_OK, "done"
            elif summary:
                code, message = EXIT_FAILED, "a check of the line failed (see the summary)"
            else:
                code, message = EXIT_FAILED, f"line_owner exited {rc}: {owner.tail(3)}"
        summary["restarts"] = {n: group.restarts.get(n, 0) for n in here}
    except Interrupted as exc:
        code, message = EXIT_INTERRUPTED, f"interrupted ({exc})"
    except _OwnerGone as exc:
        code, message = EXIT_OWNER_GONE, str(exc)
        summary = {"line": line.name, "units_here": here, "owner": "gone"}
    except RuntimeError as exc:
        code, message = EXIT_FAILED, str(exc)
    finally:
        stop.stopping()
        # the recorder last: it takes the others' last messages
        codes = group.stop(order=[OWNER, *here, VIEWER], urgent=stop.urgent)
    if opts.bag is not None and code == EXIT_OK and codes.get(RECORDER) not in (0, None):
        code, message = EXIT_RECORDING, f"the recorder could not write the bag {opts.bag}"
    if opts.live_view and code == EXIT_OK and codes.get(VIEWER) not in (0, None):
        code, message = EXIT_FAILED, f"the live view ({VIEWER}) failed: exit {codes.get(VIEWER)}"
    if code == EXIT_OK and not opts.keep_logs and opts.log_dir is None:
        shutil.rmtree(log_dir, ignore_errors=True)
    else:
        summary["log_dir"] = str(log_dir)
    return LineRunResult(code, message, summary)


def _restart_ended(group: ProcessGroup, no_owner: bool, say: Callable[[str], None]) -> None:
    """Start again every unit's process that ended with a failure, up to MAX_RESTARTS times
    per unit (RuntimeError beyond); without the owner here, a unit that found the owner gone
    ends the run (_OwnerGone)."""
    for n in group.dead():
        rc = n.proc.returncode
        if n.name in (OWNER, VIEWER) or rc == 0:
            continue
        if no_owner and rc == EXIT_OWNER_GONE:
            lines = [x for x in n.tail(5).splitlines() if "no command from the line's owner" in x]
            raise _OwnerGone(lines[-1] if lines else f"{n.name}: the line's owner is gone")
        done = group.restarts.get(n.name, 0)
        if done >= MAX_RESTARTS:
            raise RuntimeError(
                f"{n.name} ended during the run (exit {rc}) after {done} restarts "
                f"(at most {MAX_RESTARTS})"
            )
        say(f"{n.name} ended during the run (exit {rc}); starting it again ({done + 1} of "
            f"at most {MAX_RESTARTS})")  # fmt: skip
        group.restart(n.name)
