"""config/foxglove_layout.json, the Foxglove layout of a run: every panel of its configuration is
in the layout tree and every panel in the tree is configured; every topic it names is a topic
of the suite, and every field a plot draws is a number of that topic's message type (the type
store filled from msg_defs/, as the bags and the Foxglove node's schemas are)."""

from __future__ import annotations

import json

from rosbags.typesys.store import Nodetype

from fence_sorter.recording.msgtypes import make_typestore
from fence_sorter.recording.topics import TOPICS
from fence_sorter.resources import data_path

NUMBERS = {"float64", "float32", "int8", "uint8", "int16", "uint16", "int32", "uint32"}


def _tree_panels(node) -> set[str]:
    if isinstance(node, str):
        return {node}
    return _tree_panels(node["first"]) | _tree_panels(node["second"])


def test_layout_names_the_suites_topics_and_numeric_fields() -> None:
    layout = json.loads(data_path("config", "foxglove_layout.json").read_text())
    panels = layout["configById"]
    assert _tree_panels(layout["layout"]) == set(panels)
    kinds = sorted(p.split("!")[0] for p in panels)
    assert kinds == ["3D", "Plot", "Plot", "Plot", "Table"]
    ts = make_typestore()
    drawn = []
    for pid, cfg in panels.items():
        if pid.startswith("Plot!"):
            for series in cfg["paths"]:
                topic, _, field = series["value"].partition(".")
                assert topic in TOPICS, series["value"]
                fields = dict(ts.fielddefs[TOPICS[topic].msgtype][1])
                assert field in fields, series["value"]
                nodetype, spec = fields[field]
                assert nodetype == Nodetype.BASE and spec[0] in NUMBERS, series["value"]
                assert series["timestampMethod"] == "headerStamp"
                assert "header" in fields  # the plot's time: the message's sim-time stamp
                drawn.append(series["value"])
        elif pid.startswith("Table!"):
            assert cfg["topicPath"] in TOPICS
        else:
            assert set(cfg["topics"]) <= set(TOPICS) and cfg["followTf"] == "sorter"
    assert drawn == [
        "/load_states.contact_normal_force",
        "/load_states.contact_normal_force_stiff",
        "/fence_state.tip_deflection",
        "/fence_state.drive_angle",
    ]
    assert panels["Table!outcomes"]["topicPath"] == "/sort_outcomes"
    assert set(panels["3D!sorter"]["topics"]) == {"/robot_description", "/markers"}
