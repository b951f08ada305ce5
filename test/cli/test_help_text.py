"""The help of the commands of subcommands (``bag``, ``topic``, ``param``) describes them in
whole sentences: the first paragraph of the module's docstring, not its first line."""

from __future__ import annotations

import pytest

from fence_sorter.cli.main import main
from fence_sorter.cli.subcommands import doc_summary


def test_doc_summary_is_the_whole_first_paragraph() -> None:
    doc = """``tool x``: a stand-in for ``x`` (none in the
    wheels), over rclpy.

    More detail.
    """
    assert doc_summary(doc) == "`tool x`: a stand-in for `x` (none in the wheels), over rclpy."


@pytest.mark.parametrize(
    ("argv", "tail"),
    [
        (["topic", "--help"], "as the run's nodes use."),
        (["bag", "info", "--help"], "and the health of each segment."),
        (["param", "--help"], "a node's parameters at run time."),
    ],
)
def test_help_description_is_complete(argv: list[str], tail: str, capsys) -> None:
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 0
    # the description: the paragraph after the usage, up to the argument list
    description = " ".join(capsys.readouterr().out.split("\n\n")[1].split())
    assert description.endswith(tail), description
    assert description.count("(") == description.count(")"), description
