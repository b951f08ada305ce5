"""``python -m benchmarks line-scale``: the lines it generates from four_units' pattern are
valid line files with the units where the pattern puts them; with ``--hosts 2`` each line's
units split in two halves, the owner's first, and the links told apart by host; bad options
exit 2 with one line naming the option and its allowed range (nothing is run), and so does
``--hosts 2`` where two hosts cannot be made."""

from __future__ import annotations

import pytest
import yaml

from benchmarks import cli as cli_main
from benchmarks.commands import line_scale
from benchmarks.commands.line_scale import line_of, links_by_host, split
from fence_sorter.line.line_file import load_line


@pytest.mark.parametrize("n", [1, 2, 8])
def test_a_generated_line_has_n_units_5_m_apart_each_serving_two_destinations(
    tmp_path, n: int
) -> None:
    path = tmp_path / f"units_{n}.yaml"
    path.write_text(yaml.safe_dump(line_of(n), sort_keys=False))
    line = load_line(str(path))  # the line file's own checks: zones apart and on the belt
    four = load_line("four_units")
    assert [u.name for u in line.units] == [f"unit_{k + 1}" for k in range(n)]
    assert [u.position for u in line.units] == [3.0 + 5.0 * k for k in range(n)]
    assert [u.side for u in line.units] == [four.units[k % 4].side for k in range(n)]
    served = [d for u in line.units for d in u.destinations]
    assert sorted(served) == sorted(f"D{j + 1}" for j in range(2 * n))  # each once
    assert line.length == pytest.approx(line.units[-1].position + 6.0)


@pytest.mark.parametrize(
    ("option", "value", "allowed", "more"),
    [("--units", "0,2", "[1, 16]", ()), ("--units", "a", "unit counts", ()),
     ("--parcels", "0", "[1, 10000]", ()), ("--rtf", "-1", "[0, 100]", ()),
     ("--hosts", "3", "1 or 2", ()), ("--units", "1,2", "[2, 16]", ("--hosts", "2")),
     ("--rtf", "1", "unpaced", ("--hosts", "2"))],
)  # fmt: skip
def test_bad_option_exits_2_naming_it(tmp_path, capsys, option, value, allowed, more) -> None:
    out = tmp_path / "x.md"
    assert cli_main.main(["line-scale", option, value, *more, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and option in err[0] and allowed in err[0]
    assert not out.exists()


@pytest.mark.parametrize(
    ("n", "a", "b"), [(2, "1", "2"), (3, "1", "2,3"), (4, "1,2", "3,4"), (8, "1,2,3,4", "5,6,7,8")]
)
def test_two_hosts_split_a_line_in_halves_the_owner_s_host_first(n, a, b) -> None:
    assert split(n) == (a, b)
    # the owner's links (the induction's, to the recirculation) are host A's
    names = [f"unit_{k + 1}" for k in range(n)]
    links = [f"induction>{names[0]}", *(f"{x}>unit_{k + 2}" for k, x in enumerate(names[:-1])),
             f"{names[-1]}>recirculation"]  # fmt: skip
    across, within = links_by_host({k: {"n": 1} for k in [*links, "all"]}, n)
    last_a = f"unit_{n // 2}"
    assert sorted(across) == sorted([f"{last_a}>unit_{n // 2 + 1}", f"{names[-1]}>recirculation"])
    assert sorted(within) == sorted(set(links) - set(across))


def test_two_hosts_without_root_or_ip_exit_2_with_one_line(tmp_path, capsys, monkeypatch) -> None:
    why = "two hosts need root and the ip command (network namespaces, veth)"
    monkeypatch.setattr(line_scale, "why_not", lambda: why)
    out = tmp_path / "x.md"
    assert cli_main.main(["line-scale", "--hosts", "2", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"benchmarks: error: --hosts 2: {why}"]
    assert not out.exists()


def test_two_hosts_skip_unless_root_says_so_in_one_line_and_exits_0(
    tmp_path, capsys, monkeypatch
) -> None:
    monkeypatch.setattr(line_scale.os, "geteuid", lambda: 1000)
    out = tmp_path / "x.md"
    argv = ["line-scale", "--hosts", "2", "--skip-unless-root", "--out", str(out)]
    assert cli_main.main(argv) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["line-scale: --hosts 2 skipped: network namespaces need root"]
    assert not out.exists()
