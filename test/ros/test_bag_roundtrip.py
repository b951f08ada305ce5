"""Every fence_sorter_msgs message through a rosbag2 MCAP bag and back, read three ways.

Written with rosbags (types registered from msg_defs/), read back with rosbags' Reader,
with AnyReader (which uses only the definitions embedded in the bag) and with the independent
mcap + mcap_ros2 decoder. No ROS needed; the message definitions are the same .msg files that
rosidl builds into fence_sorter_msgs.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys.store import Typestore

from fence_sorter.recording.msgtypes import (
    MSG_DIR_ENV,
    MsgDefsNotFoundError,
    find_msg_dir,
    make_typestore,
    message_names,
    msg_files,
    msgtype_name,
)
from fence_sorter.recording.samples import (
    MessageDict,
    diff_values,
    from_mcap_ros2,
    from_rosbags,
    sample_values,
    to_rosbags,
)

REPO_MSG_DIR = Path(__file__).resolve().parents[2] / "msg_defs" / "msg"
SEEDS = (1, 2)  # two messages per type, to check order and distinct values


def topic_of(name: str) -> str:
    return f"/test/{name.lower()}"


@pytest.fixture(scope="module")
def typestore() -> Typestore:
    return make_typestore()


@pytest.fixture(scope="module")
def expected(typestore: Typestore) -> dict[str, list[MessageDict]]:
    return {
        name: [sample_values(typestore, msgtype_name(name), seed) for seed in SEEDS]
        for name in message_names()
    }


@pytest.fixture(scope="module")
def bag(
    typestore: Typestore,
    expected: dict[str, list[MessageDict]],
    tmp_path_factory: pytest.TempPathFactory,
) -> Path:
    path = tmp_path_factory.mktemp("bags") / "all_types"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        stamp = 1_000_000_000
        for name, samples in expected.items():
            msgtype = msgtype_name(name)
            conn = writer.add_connection(topic_of(name), msgtype, typestore=typestore)
            for values in samples:
                data = typestore.serialize_cdr(to_rosbags(typestore, msgtype, values), msgtype)
                writer.write(conn, stamp, data)
                stamp += 1_000_000
    return path


def test_msg_defs_are_the_registered_types(typestore: Typestore) -> None:
    names = message_names()
    assert names == [
        "FenceCommand",
        "FenceState",
        "HandOff",
        "LoadState",
        "Parcel",
        "RunClock",
        "SortEvent",
        "SortOutcome",
    ]
    for name in names:
        assert msgtype_name(name) in typestore.types
    assert find_msg_dir() == REPO_MSG_DIR  # the checkout wins over installed copies


@pytest.mark.ros
def test_installed_msg_files_equal_msg_defs(monkeypatch: pytest.MonkeyPatch) -> None:
    """The interface package installs the same .msg files; the type store accepts them."""
    installed = Path(sys.prefix) / "share" / "fence_sorter_msgs" / "msg"
    if not installed.is_dir():
        pytest.fail(f"{installed} missing: run scripts/bootstrap.sh")
    for name, path in msg_files(REPO_MSG_DIR).items():
        copy = installed / path.name
        assert copy.read_text() == path.read_text(), name
    monkeypatch.setenv(MSG_DIR_ENV, str(installed))
    assert find_msg_dir() == installed
    assert sorted(make_typestore().fielddefs) == sorted(make_typestore(REPO_MSG_DIR).fielddefs)


def test_missing_msg_dir_is_a_precise_error(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv(MSG_DIR_ENV, str(tmp_path))
    with pytest.raises(MsgDefsNotFoundError, match=str(tmp_path)):
        find_msg_dir()


def test_rosbags_reader_reads_back_every_field(
    bag: Path, typestore: Typestore, expected: dict[str, list[MessageDict]]
) -> None:
    got: dict[str, list[MessageDict]] = {name: [] for name in expected}
    with Reader(bag) as reader:
        assert reader.message_count == len(expected) * len(SEEDS)
        for conn, _, rawdata in reader.messages():
            name = conn.msgtype.rsplit("/", 1)[1]
            assert conn.topic == topic_of(name)
            msg = typestore.deserialize_cdr(rawdata, conn.msgtype)
            got[name].append(from_rosbags(typestore, msg))
    assert diff_values(expected, got) == []


def test_anyreader_reads_back_with_embedded_definitions(
    bag: Path, expected: dict[str, list[MessageDict]]
) -> None:
    got: dict[str, list[MessageDict]] = {name: [] for name in expected}
    with AnyReader([bag]) as reader:
        for conn, _, rawdata in reader.messages(connections=reader.connections):
            msg = reader.deserialize(rawdata, conn.msgtype)
            got[conn.msgtype.rsplit("/", 1)[1]].append(from_rosbags(reader.typestore, msg))
    assert diff_values(expected, got) == []


def test_mcap_ros2_decodes_the_bag_independently(
    bag: Path, expected: dict[str, list[MessageDict]]
) -> None:
    files = sorted(bag.glob("*.mcap"))
    assert len(files) == 1
    got: dict[str, list[MessageDict]] = {name: [] for name in expected}
    with files[0].open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for schema, channel, _, decoded in reader.iter_decoded_messages():
            assert schema.encoding == "ros2msg"
            assert channel.message_encoding == "cdr"
            name = schema.name.rsplit("/", 1)[1]
            got[name].append(from_mcap_ros2(decoded))
    assert diff_values(expected, got) == []
