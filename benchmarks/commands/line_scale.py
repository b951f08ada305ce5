"""``python -m benchmarks line-scale``: the line over DDS against its number of units.

For each number of units (default 1, 2, 4, 8) a line file with that many units is written
from four_units.yaml's pattern (unit k at X = 3 + 5 k m, the side, scene and overrides of
four_units' unit k mod 4, two destinations per unit with equal shares, the belt 6 m past the
last fence; the rest of four_units as it is), and ``fence-sorter run --line`` runs it on this
host, one process per unit and the owner, in lockstep over DDS:

- unpaced (``--rtf 0``): the line's speed, sim time over the wall time of the clock's loop;
- paced (``--rtf 1`` by default): the line clock's deadline misses and slips (the owner's
  ``PacedSteps``), whether that many units keep real time here;
- both: the hand-offs' transit, DDS writer's source timestamp to the reader's reception, per
  link and over all links (median, p99, max).

With ``--hosts 2`` each line is split over two hosts on this machine: two network namespaces
joined by a veth pair (:mod:`benchmarks.netns`; root and ``ip`` needed, one line and exit 2
otherwise). Host A runs the owner and the first half of the units (``fence-sorter run --line
--units 1..n/2 --interface A --peers B``), host B the other half (``--units n/2+1..n
--no-owner``), as the two-host tests do; only the unpaced run (the line's speed), 2 units or
more. Besides the speed: the hand-offs' transit per link, the links whose ends are on
different hosts (unit_{n/2} -> unit_{n/2+1}, and unit_n -> the owner's recirculation) apart
from those within a host, and the bytes and packets the veth carried each way (its kernel
counters). Both namespaces run on one kernel, so the source timestamp (taken on one host) and
the reception (on the other) are read on the same clock: the transit across the link is
measured, not estimated.

The load average is taken before and after each run (the machine is shared: each figure is
written beside the load it was measured under). Writes the figures as JSON beside ``--out``
(``line-scale.json``; with ``--hosts 2`` ``line-scale-hosts.json``), each with the command
and commit, and ``--out`` (Markdown) from both JSON files: one table per number of hosts.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import yaml

from benchmarks.netns import (
    NotRunnable,
    grown,
    in_ns,
    link_counters,
    two_hosts,
    wait_both,
    why_not,
)
from fence_sorter.verification.machine import git_revision

REPO = Path(__file__).resolve().parents[2]
PATTERN = REPO / "config" / "lines" / "four_units.yaml"


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = "The line over DDS: speed, paced deadline misses, hand-off transit."
    parser.add_argument(
        "--units", default=None, metavar="N1,N2,...", help="default 1,2,4,8; 2,4,8 with --hosts 2"
    )
    parser.add_argument("--parcels", type=int, default=8, metavar="N", help="per run")
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument(
        "--rtf", type=float, default=None,
        help="real-time factor of the paced runs (0: none; default 1; --hosts 2: unpaced only)",
    )  # fmt: skip
    parser.add_argument(
        "--hosts", type=int, default=1, metavar="N",
        help="1: this host; 2: each line split over two network namespaces (root and ip)",
    )  # fmt: skip
    parser.add_argument(
        "--skip-unless-root", action="store_true",
        help="--hosts 2 run by another user: say so in one line and exit 0 (make reports)",
    )  # fmt: skip
    parser.add_argument("--out", default="docs/reports/line-scale.md", metavar="FILE")
    parser.set_defaults(func=run)


def _error(msg: str) -> int:
    print(f"benchmarks: error: {msg}", file=sys.stderr)
    return 2


def line_of(n: int) -> dict:
    """four_units.yaml with ``n`` units in its pattern (see the module's docstring)."""
    base = yaml.safe_load(PATTERN.read_text())
    pattern = base["units"]
    units = []
    for k in range(n):
        u = dict(pattern[k % len(pattern)])
        u.update(
            name=f"unit_{k + 1}",
            position=3.0 + 5.0 * k,
            destinations=[f"D{2 * k + 1}", f"D{2 * k + 2}"],
        )
        units.append(u)
    share = 1.0 / (2 * n)
    base["name"] = f"units_{n}"
    base["units"] = units
    base["induction"]["destinations"] = {f"D{j + 1}": share for j in range(2 * n)}
    base["conveyor"]["length"] = 3.0 + 5.0 * (n - 1) + 6.0
    return base


def run_line(path: Path, parcels: int, seed: int, rtf: float) -> dict:
    """One ``fence-sorter run --line`` to the drain; its summary with the load around it."""
    cmd = _cmd(path, parcels, seed, rtf)
    load0, t0 = os.getloadavg()[0], time.perf_counter()
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, timeout=3600)
    wall = time.perf_counter() - t0
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd[2:])} exited {proc.returncode}: {proc.stderr[-400:]}")
    s = json.loads(proc.stdout)
    return {
        "rtf_target": rtf,
        "sim_time_s": s["sim_time_s"],
        "loop_wall_s": s["wall_time_s"],
        "command_wall_s": wall,
        # CPU of every process of the run (runner, owner, units), start-up and warm-up included
        "cpu_s": (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime),
        "sim_per_wall": s["real_time_factor"],
        "load_before": load0,
        "load_after": os.getloadavg()[0],
        "conservation_ok": s["conservation_ok"],
        "handoffs_balanced": s["handoffs_balanced"],
        "pacing": s["pacing"],
        "handoff_latency": s["handoff_latency"],
    }


def _cpu(run: dict) -> str:
    return "-" if "cpu_s" not in run else f"{run['cpu_s']:.0f}"


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


def _cmd(path: Path, parcels: int, seed: int, rtf: float, *more: str) -> list[str]:
    return [sys.executable, "-m", "fence_sorter.cli.main", "run", "--line", str(path),
            "--parcels", str(parcels), "--seed", str(seed), "--rtf", repr(rtf), "--json",
            *more]  # fmt: skip


def split(n: int) -> tuple[str, str]:
    """``--units`` of host A (the owner's: the first half, unit 1 to n // 2) and of host B."""
    half = n // 2
    return (",".join(str(k) for k in range(1, half + 1)),
            ",".join(str(k) for k in range(half + 1, n + 1)))  # fmt: skip


def host_of(name: str, n: int) -> str:
    """The host of a link's end (``induction`` and ``recirculation``: the owner's, A)."""
    if name in ("induction", "recirculation"):
        return "A"
    return "A" if int(name.rsplit("_", 1)[1]) <= n // 2 else "B"


def links_by_host(latency: dict, n: int) -> tuple[dict, dict]:
    """The summary's ``handoff_latency`` split: (links across the two hosts, links within a
    host), each ``{link: figures}``."""
    across, within = {}, {}
    for link, fig in latency.items():
        if link == "all":
            continue
        a, b = link.split(">")
        (across if host_of(a, n) != host_of(b, n) else within)[link] = fig
    return across, within


def run_line_two_hosts(path: Path, n: int, parcels: int, seed: int) -> dict:
    """One unpaced ``fence-sorter run --line`` split over two hosts (:func:`split`) to the
    drain; host A's summary with the load around it and what the veth carried."""
    units_a, units_b = split(n)
    domain = str(150 + int(uuid.uuid4().hex[:4], 16) % 50)
    with two_hosts() as h, tempfile.TemporaryDirectory(prefix="line_scale_hosts_") as tmp:
        b_cmd = in_ns(h.b, _cmd(path, parcels, seed, 0.0, "--units", units_b, "--no-owner",
                                "--domain", domain, "--interface", h.addr_b, "--peers",
                                h.addr_a, "--timeout", "3000"))  # fmt: skip
        a_cmd = in_ns(h.a, _cmd(path, parcels, seed, 0.0, "--units", units_a, "--domain",
                                domain, "--interface", h.addr_a, "--peers", h.addr_b,
                                "--timeout", "3000"))  # fmt: skip
        c0 = {"a": link_counters(h.a, h.dev_a), "b": link_counters(h.b, h.dev_b)}
        load0, t0 = os.getloadavg()[0], time.perf_counter()
        cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        # B first: A's owner then waits at its start gate for B's units across the link
        procs = [_popen(b_cmd, tmp), _popen(a_cmd, tmp)]
        out_a, err_a, out_b, err_b = wait_both(procs[1], procs[0], 3600, 120)
        wall = time.perf_counter() - t0
        cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        c1 = {"a": link_counters(h.a, h.dev_a), "b": link_counters(h.b, h.dev_b)}
        for side, proc, err in (("A", procs[1], err_a), ("B", procs[0], err_b)):
            if proc.returncode != 0:
                raise RuntimeError(f"host {side}: {' '.join(proc.args[7:])} exited "
                                   f"{proc.returncode}: {err[-400:]}")  # fmt: skip
    s = json.loads(out_a)
    across, within = links_by_host(s["handoff_latency"], n)
    a_rx, b_rx = grown(c0["a"], c1["a"]), grown(c0["b"], c1["b"])
    return {
        "units_a": units_a,
        "units_b": units_b,
        "sim_time_s": s["sim_time_s"],
        "loop_wall_s": s["wall_time_s"],
        "command_wall_s": wall,
        "cpu_s": (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime),
        "sim_per_wall": s["real_time_factor"],
        "load_before": load0,
        "load_after": os.getloadavg()[0],
        "conservation_ok": s["conservation_ok"],
        "handoffs_balanced": s["handoffs_balanced"],
        "handoff_latency": s["handoff_latency"],
        "links_across": across,
        "links_within": within,
        # what each end of the veth received: A's from B, B's from A (Ethernet frames)
        "veth": {
            "b_to_a_bytes": a_rx["rx_bytes"],
            "b_to_a_packets": a_rx["rx_packets"],
            "a_to_b_bytes": b_rx["rx_bytes"],
            "a_to_b_packets": b_rx["rx_packets"],
        },
    }


def _popen(cmd: list[str], cwd: str) -> subprocess.Popen:
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=cwd)  # fmt: skip


def _counts(args: argparse.Namespace) -> list[int] | str:
    """The unit counts of ``--units``, or the one-line error."""
    text = args.units or ("2,4,8" if args.hosts == 2 else "1,2,4,8")
    try:
        counts = [int(n) for n in text.split(",")]
    except ValueError:
        return f"--units must be unit counts separated by commas, got {text!r}"
    low = 2 if args.hosts == 2 else 1
    if not counts or not all(low <= n <= 16 for n in counts):
        more = " (--hosts 2: a unit on each host at least)" if low == 2 else ""
        return f"--units must be in [{low}, 16]{more}, got {text!r}"
    return counts


def run(args: argparse.Namespace) -> int:
    if args.hosts not in (1, 2):
        return _error(f"--hosts must be 1 or 2, got {args.hosts}")
    counts = _counts(args)
    if isinstance(counts, str):
        return _error(counts)
    if not 1 <= args.parcels <= 10_000:
        return _error(f"--parcels must be in [1, 10000], got {args.parcels}")
    if args.hosts == 2 and args.rtf is not None:
        return _error("--rtf: --hosts 2 measures the unpaced line only (no paced runs)")
    rtf = 1.0 if args.rtf is None else args.rtf
    if not 0.0 <= rtf <= 100.0:
        return _error(f"--rtf must be in [0, 100], got {args.rtf}")
    if args.hosts == 2 and args.skip_unless_root and os.geteuid() != 0:
        print("line-scale: --hosts 2 skipped: network namespaces need root", file=sys.stderr)
        return 0
    if args.hosts == 2 and (why := why_not()) is not None:
        return _error(f"--hosts 2: {why}")
    units = ",".join(map(str, counts))
    command = f"python -m benchmarks line-scale --units {units} --parcels {args.parcels} "
    command += f"--seed {args.seed} " + ("--hosts 2" if args.hosts == 2 else f"--rtf {rtf:g}")
    rows: list[dict] = []
    try:
        with tempfile.TemporaryDirectory(prefix="line_scale_") as tmp:
            for n in counts:
                path = Path(tmp) / f"units_{n}.yaml"
                path.write_text(yaml.safe_dump(line_of(n), sort_keys=False))
                row = {"units": n, "cores": os.cpu_count()}
                if args.hosts == 2:
                    row["unpaced"] = run_line_two_hosts(path, n, args.parcels, args.seed)
                else:
                    row["unpaced"] = run_line(path, args.parcels, args.seed, 0.0)
                print(json.dumps({"units": n, "unpaced": row["unpaced"]["sim_per_wall"]}),
                      flush=True)  # fmt: skip
                if args.hosts == 1 and rtf > 0.0:
                    row["paced"] = run_line(path, args.parcels, args.seed, rtf)
                    print(json.dumps({"units": n, "paced": row["paced"]["pacing"]}), flush=True)
                rows.append(row)
    except NotRunnable as exc:
        return _error(f"--hosts 2: {exc}")
    result = {
        "command": command,
        "commit": git_revision(),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "cores": os.cpu_count(),
        "hosts": args.hosts,
        "rows": rows,
    }
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        json_path(out, args.hosts).write_text(json.dumps(result, indent=1) + "\n")
        one, two = (_read(json_path(out, k)) for k in (1, 2))
        text = report(one, two)
        out.write_text(text)
    else:
        text = report(result) if args.hosts == 1 else report(None, result)
    print(text)
    return 0 if all(r["unpaced"]["conservation_ok"] for r in rows) else 1


def json_path(out: Path, hosts: int) -> Path:
    """The JSON file of ``hosts``' figures beside the Markdown report ``out``."""
    return out.with_suffix(".json") if hosts == 1 else out.with_name(f"{out.stem}-hosts.json")


def _read(path: Path) -> dict | None:
    return json.loads(path.read_text()) if path.exists() else None


def report(r: dict | None, hosts: dict | None = None) -> str:
    """The Markdown report: one host's figures (:func:`run`'s, ``r``) and two hosts' ones
    (``hosts``), a table each."""
    text = "# The line over DDS against its number of units\n\n"
    if r is not None:
        text += one_host_table(r)
    if hosts is not None:
        text += ("\n" if r is not None else "") + two_hosts_table(hosts)
    return text


def one_host_table(r: dict) -> str:
    head = [
        "| units | unpaced sim/wall | CPU [s] | load | paced misses | slips | lateness p99 [ms] "
        "| load | hand-off p50 [ms] | p99 [ms] | max [ms] | hand-offs |",
        "|" + " --- |" * 12,
    ]
    for row in r["rows"]:
        u, p = row["unpaced"], row.get("paced")
        lat = (p or u)["handoff_latency"]["all"]
        if p is None:
            paced = "- | - | - | -"
        else:
            pc = p["pacing"]
            paced = (
                f"{pc['deadline_misses']} of {pc['cycles']} ({pc['deadline_miss_share']:.2%}) "
                f"| {pc['catch_up_slips']} | {_ms(pc['lateness_p99_ms'])} "
                f"| {p['load_before']:.1f}-{p['load_after']:.1f}"
            )
        head.append(
            f"| {row['units']} | {_speed(u)} | {_cpu(u)} "
            f"| {u['load_before']:.1f}-{u['load_after']:.1f} "
            f"| {paced} | {_ms(lat.get('p50_ms'))} | {_ms(lat.get('p99_ms'))} "
            f"| {_ms(lat.get('max_ms'))} | {lat['n']} |"
        )
    return (
        f"`{r['command']}` at commit {r['commit']}, {r['date']}, on this {r['cores']}-core "
        "machine shared with other work (load: the 1-minute load average before and after "
        "each run).\n\n"
        "Each line: four_units.yaml's pattern with that many units (one `line_unit` process "
        "each, and the `line_owner`), the same stream and seed, run to the drain with "
        "`fence-sorter run --line`. Unpaced sim/wall: sim time over the wall time of the "
        "owner's clock loop (start-up and warm-up not in it); CPU: the CPU time of every "
        "process of the unpaced run, start-up and warm-up included. Paced: every 10 ms step "
        "of the line clock has a deadline; a miss is a deadline passed before the loop ran "
        "it or a step that ended more than one period after its deadline; a slip drops more "
        "than 0.1 s of lag from the grid. Hand-off transit: the DDS writer's source "
        "timestamp to the reader's reception, over every link of the paced run (of the "
        "unpaced one without it), one clock on one host.\n\n" + "\n".join(head) + "\n"
    )


def _speed(u: dict) -> str:
    return f"{u['sim_per_wall']:.2f}x ({u['sim_time_s']:.1f} s in {u['loop_wall_s']:.1f} s)"


def _fig(f: dict) -> str:
    """A link's transit figures: p50 / p99 / max [ms] (hand-offs)."""
    if not f.get("n"):
        return "- (0)"
    return f"{_ms(f['p50_ms'])} / {_ms(f['p99_ms'])} / {_ms(f['max_ms'])} ({f['n']})"


def _within(links: dict) -> str:
    """The links within a host together: the range of their medians, the largest p99 and
    max [ms], and the hand-offs over all of them."""
    figs = [f for f in links.values() if f.get("n")]
    if not figs:
        return "- (0)"
    p50 = [f["p50_ms"] for f in figs]
    lo, hi = _ms(min(p50)), _ms(max(p50))
    return (
        f"{lo if lo == hi else f'{lo}-{hi}'} / {_ms(max(f['p99_ms'] for f in figs))} / "
        f"{_ms(max(f['max_ms'] for f in figs))} ({sum(f['n'] for f in figs)})"
    )


def two_hosts_table(r: dict) -> str:
    head = [
        "| units (A + B) | unpaced sim/wall | CPU [s] | load | across: unit > unit "
        "| across: last unit > recirculation | within a host | veth A>B | veth B>A |",
        "|" + " --- |" * 9,
    ]
    for row in r["rows"]:
        u, n = row["unpaced"], row["units"]
        across = u["links_across"]
        middle = next(k for k in across if not k.endswith(">recirculation"))
        back = next(k for k in across if k.endswith(">recirculation"))
        v, sim = u["veth"], u["sim_time_s"]
        head.append(
            f"| {n} ({n // 2} + {n - n // 2}) | {_speed(u)} | {_cpu(u)} "
            f"| {u['load_before']:.1f}-{u['load_after']:.1f} "
            f"| {middle}: {_fig(across[middle])} | {_fig(across[back])} "
            f"| {_within(u['links_within'])} "
            f"| {v['a_to_b_packets'] / sim:.0f} pkt/s, {v['a_to_b_bytes'] / sim / 1e3:.0f} kB/s "
            f"| {v['b_to_a_packets'] / sim:.0f} pkt/s, {v['b_to_a_bytes'] / sim / 1e3:.0f} kB/s |"
        )
    return (
        "## The line over two hosts\n\n"
        f"`{r['command']}` at commit {r['commit']}, {r['date']}, on this {r['cores']}-core "
        "machine shared with other work (load: the 1-minute load average before and after "
        "each run).\n\n"
        "The same lines, stream and seed, each split over two hosts: two network namespaces "
        "of this machine joined by a veth pair (`benchmarks/netns.py`), host A running the "
        "owner and units 1 to n/2 (`fence-sorter run --line L --units ... --interface A "
        "--peers B`), host B the other units (`--units ... --no-owner --interface B --peers "
        "A`); unpaced only. Every command and reply of B's units and the two links whose "
        "ends are on different hosts (the middle unit to the next, the last unit to the "
        "owner's recirculation) cross the veth as UDP. Hand-off transit: p50 / p99 / max "
        "[ms] (hand-offs), the DDS writer's source timestamp to the reader's reception; both "
        "namespaces run on one kernel, one clock, so a transit across the link is measured "
        "as one within a host is. Within a host: every other link (the induction's to "
        "unit_1, and the links between two units of one host), the range of their medians, "
        "their largest p99 and max. veth: what each end's kernel counters received "
        "(Ethernet frames, headers included) per second of sim time.\n\n" + "\n".join(head) + "\n"
    )
