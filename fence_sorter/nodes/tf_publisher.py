"""TF and the robot description of the sorter, published by the simulator.

robot_state_publisher's conventions, without it (no wheel provides it): the URDF
(``urdf/fence_sorter.urdf`` of the package, with the scene's belt width and fence length) as
std_msgs/String on /robot_description (reliable, transient local); the URDF's fixed joints on
/tf_static in one message (transient local); /tf with the fence (joint ``fence_drive``, the drive
angle alpha_w of /joint_states) and one frame ``parcel_<id>`` per parcel on the belt at its
C_s pose of /load_states, both stamped with the snapshot's sim time. Frames hang off the fixed
frame (``frame_id``, default ``sorter``).

A line over DDS (:class:`LineTfPublisher`, published by the line's owner): one URDF whose root
link ``line`` is the line frame, each unit's sorter URDF (its scene's fence, the line's belt
width) with every link and joint named ``<unit>/...`` and mounted on ``line`` by the fixed
joint ``<unit>/mount`` at :func:`~fence_sorter.line.routing.unit_origin` (a left unit: half a
turn about X); /tf_static holds every fixed joint of it. The units do not publish their fence
angles, so the joints ``<unit>/fence_drive`` have no /tf.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

from geometry_msgs.msg import TransformStamped
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

from fence_sorter.line.line_file import LineSpec
from fence_sorter.line.one_fence import LineConfig
from fence_sorter.line.routing import unit_origin
from fence_sorter.line.types import FenceSnapshot, LineSnapshot, ParcelSnapshot
from fence_sorter.nodes.convert import FRAME_ID
from fence_sorter.nodes.convert import _stamp as stamp_header  # the stamps of /load_states
from fence_sorter.nodes.qos import topic_qos
from fence_sorter.physics.fence import FenceParams
from fence_sorter.recording import topics
from fence_sorter.resources import data_path

URDF_FILE = ("urdf", "fence_sorter.urdf")
LINE_FRAME = "line"
FENCE_JOINT = "fence_drive"
FENCE_FRAME = "fence"
PARCEL_FRAME = "parcel_{}"


def _floats(text: str | None) -> list[float]:
    return [float(v) for v in (text or "0 0 0").split()]


def _set(element: ET.Element, attr: str, index: int, value: float) -> None:
    values = _floats(element.get(attr))
    values[index] = value
    element.set(attr, " ".join(f"{v:.9g}" for v in values))


def robot_description(
    belt_width: float, fence_length: float, fence_height: float, frame_id: str = FRAME_ID
) -> str:
    """The package's URDF with this line's belt width s, fence length R_z and height [m]; its
    root link (the fixed frame) named ``frame_id``."""
    root = ET.parse(data_path(*URDF_FILE)).getroot()
    links = {e.get("name"): e for e in root.iter("link")}
    joints = {e.get("name"): e for e in root.iter("joint")}
    links[FRAME_ID].set("name", frame_id)
    for parent in root.iter("parent"):
        if parent.get("link") == FRAME_ID:
            parent.set("link", frame_id)

    def box(link: str) -> ET.Element:
        return links[link].find("visual/geometry/box")

    for link, mount in (("belt", "belt_mount"), ("scan_line", "scan_line_mount")):
        _set(box(link), "size", 1, belt_width)
        _set(joints[mount].find("origin"), "xyz", 1, 0.5 * belt_width)
    chute_half_width = 0.5 * _floats(box("chute").get("size"))[1]
    _set(joints["chute_mount"].find("origin"), "xyz", 1, belt_width + chute_half_width)
    fence_origin = links[FENCE_FRAME].find("visual/origin")
    _set(box(FENCE_FRAME), "size", 0, fence_length)
    _set(box(FENCE_FRAME), "size", 2, fence_height)
    _set(fence_origin, "xyz", 0, 0.5 * fence_length)
    _set(fence_origin, "xyz", 2, 0.5 * fence_height)
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode")


def _quaternion_rpy(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of URDF's fixed-axis roll, pitch, yaw."""
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


def _transform(
    t: float, parent: str, child: str, xyz: tuple[float, float, float], q: tuple[float, ...]
) -> TransformStamped:
    msg = TransformStamped()
    stamp_header(msg.header, t, parent)
    msg.child_frame_id = child
    tr, rot = msg.transform.translation, msg.transform.rotation
    tr.x, tr.y, tr.z = (float(v) for v in xyz)
    rot.x, rot.y, rot.z, rot.w = (float(v) for v in q)
    return msg


def static_transforms(urdf: str, t: float = 0.0) -> list[TransformStamped]:
    """The URDF's fixed joints as transforms parent link -> child link."""
    out = []
    for joint in ET.fromstring(urdf).iter("joint"):
        if joint.get("type") != "fixed":
            continue
        origin = joint.find("origin")
        xyz = _floats(origin.get("xyz") if origin is not None else None)
        rpy = _floats(origin.get("rpy") if origin is not None else None)
        parent, child = joint.find("parent").get("link"), joint.find("child").get("link")
        out.append(_transform(t, parent, child, tuple(xyz), _quaternion_rpy(*rpy)))
    return out


def _yaw(angle: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, math.sin(0.5 * angle), math.cos(0.5 * angle))


def fence_transform(fence: FenceSnapshot, t: float, frame_id: str) -> TransformStamped:
    """The fence frame: rotated by the drive angle alpha_w about the axis z (joint fence_drive)."""
    return _transform(t, frame_id, FENCE_FRAME, (0.0, 0.0, 0.0), _yaw(fence.drive_angle))


def parcel_transform(p: ParcelSnapshot, t: float, frame_id: str) -> TransformStamped:
    """Frame ``parcel_<id>``: C_s on the belt (z = 0) and the load's yaw, as its LoadState pose."""
    return _transform(
        t, frame_id, PARCEL_FRAME.format(int(p.parcel_id)), (p.x, p.y, 0.0), _yaw(p.yaw)
    )


class TfPublisher:
    """/robot_description and /tf_static once (transient local), /tf per state snapshot."""

    def __init__(self, node, line: LineConfig, frame_id: str = FRAME_ID) -> None:
        self.frame_id = frame_id
        fence_height = (line.fence or FenceParams()).height  # a stiff fence: the default height
        self.description = robot_description(
            line.conveyor.width, line.fence_length, fence_height, frame_id
        )
        self.pub_description = node.create_publisher(
            String, topics.ROBOT_DESCRIPTION, topic_qos(topics.ROBOT_DESCRIPTION)
        )
        self.pub_static = node.create_publisher(
            TFMessage, topics.TF_STATIC, topic_qos(topics.TF_STATIC)
        )
        self.pub_tf = node.create_publisher(TFMessage, topics.TF, topic_qos(topics.TF))

    def publish_static(self, t: float) -> None:
        """The description and every fixed frame (the URDF's root is the fixed frame)."""
        self.pub_description.publish(String(data=self.description))
        self.pub_static.publish(TFMessage(transforms=static_transforms(self.description, t)))

    def publish(self, snap: LineSnapshot) -> None:
        """The fence and every parcel on the belt at the snapshot's sim time."""
        t = snap.t
        transforms = [fence_transform(snap.fence, t, self.frame_id)]
        transforms += [parcel_transform(p, t, self.frame_id) for p in snap.parcels]
        self.pub_tf.publish(TFMessage(transforms=transforms))


def line_description(line: LineSpec) -> str:
    """The URDF of a line: root link ``line``, each unit's sorter (:func:`robot_description`
    with its scene's fence length and height) prefixed ``<unit>/`` (links, joints, materials)
    and mounted by the fixed joint ``<unit>/mount`` at the unit's origin."""
    root = ET.Element("robot", name=line.name)
    ET.SubElement(root, "link", name=LINE_FRAME)
    for u in line.units:
        sc = u.scenario
        height = (sc.fence or FenceParams()).height
        unit = ET.fromstring(robot_description(line.width, sc.length, height))
        prefix = f"{u.name}/"
        for e in unit.iter():
            if e.tag in ("link", "joint", "material") and e.get("name"):
                e.set("name", prefix + e.get("name"))
            elif e.tag in ("parent", "child"):
                e.set("link", prefix + e.get("link"))
        xyz, rpy = unit_origin(u.position, u.mirrored, line.width)
        mount = ET.SubElement(root, "joint", name=f"{prefix}mount", type="fixed")
        ET.SubElement(mount, "parent", link=LINE_FRAME)
        ET.SubElement(mount, "child", link=f"{prefix}{FRAME_ID}")
        ET.SubElement(
            mount, "origin", xyz=" ".join(f"{v:.9g}" for v in xyz),
            rpy=" ".join(f"{v:.17g}" for v in rpy),
        )  # fmt: skip
        root.extend(list(unit))
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode")


class LineTfPublisher:
    """A line's /robot_description and /tf_static, once (transient local; sim time 0)."""

    def __init__(self, node, line: LineSpec) -> None:
        self.description = line_description(line)
        self.pub_description = node.create_publisher(
            String, topics.ROBOT_DESCRIPTION, topic_qos(topics.ROBOT_DESCRIPTION)
        )
        self.pub_static = node.create_publisher(
            TFMessage, topics.TF_STATIC, topic_qos(topics.TF_STATIC)
        )
        self.pub_description.publish(String(data=self.description))
        self.pub_static.publish(TFMessage(transforms=static_transforms(self.description, 0.0)))
