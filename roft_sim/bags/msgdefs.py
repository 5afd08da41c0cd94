"""The ROS 2 message definitions a bag embeds, as rosbag2 writes them into an MCAP schema.

A schema of the ``ros2msg`` encoding is the type's ``.msg`` text followed, for every type it
uses (depth first, each once), by a line of 80 ``=``, a line ``MSG: <package>/<Type>`` and that
type's text. The texts below are the fields of the ROS 2 (Humble to Rolling) definitions in
``common_interfaces`` and ``rcl_interfaces``, comments left out (a reader parses fields and
constants only; the type hashes do not depend on comments). The tests check every definition
against the ones ``rosbags`` ships for ROS 2.
"""

from __future__ import annotations

import re

__all__ = ["MESSAGE_DEFINITIONS", "schema_text", "dependencies"]

MESSAGE_DEFINITIONS: dict[str, str] = {
    "builtin_interfaces/msg/Time": "int32 sec\nuint32 nanosec\n",
    "std_msgs/msg/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "sensor_msgs/msg/Image": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n"
        "uint8 is_bigendian\nuint32 step\nuint8[] data\n"
    ),
    "sensor_msgs/msg/RegionOfInterest": (
        "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"
    ),
    "sensor_msgs/msg/CameraInfo": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\n"
        "float64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\n"
        "uint32 binning_y\nRegionOfInterest roi\n"
    ),
    "geometry_msgs/msg/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/msg/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/msg/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/msg/Pose": "Point position\nQuaternion orientation\n",
    "geometry_msgs/msg/PoseStamped": "std_msgs/Header header\nPose pose\n",
    "geometry_msgs/msg/Twist": "Vector3 linear\nVector3 angular\n",
    "geometry_msgs/msg/TwistStamped": "std_msgs/Header header\nTwist twist\n",
    "geometry_msgs/msg/Transform": "Vector3 translation\nQuaternion rotation\n",
    "geometry_msgs/msg/TransformStamped": (
        "std_msgs/Header header\nstring child_frame_id\nTransform transform\n"
    ),
    "tf2_msgs/msg/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
}
"""``.msg`` text of every type used, by full name (``package/msg/Type``)."""

_PRIMITIVES = frozenset(
    ("bool", "byte", "char", "float32", "float64", "string", "wstring")
    + tuple(f"{sign}int{bits}" for sign in ("", "u") for bits in (8, 16, 32, 64))
)
_FIELD = re.compile(r"^([A-Za-z0-9_/]+)(?:\[[0-9<=]*\])?\s+\w+")
_SEPARATOR = "=" * 80


def dependencies(datatype: str) -> list[str]:
    """The types ``datatype`` uses, directly or not, depth first, each once (full names).

    Raises:
        KeyError: a type that is not in :data:`MESSAGE_DEFINITIONS`.
    """
    out: list[str] = []

    def visit(name: str) -> None:
        package = name.split("/")[0]
        for line in MESSAGE_DEFINITIONS[name].splitlines():
            m = _FIELD.match(line.strip())
            if m is None or m.group(1) in _PRIMITIVES:
                continue
            used = m.group(1)
            full = used.replace("/", "/msg/") if "/" in used else f"{package}/msg/{used}"
            if full not in out:
                out.append(full)
                visit(full)

    visit(datatype)
    return out


def schema_text(datatype: str) -> str:
    """The ``ros2msg`` schema of ``datatype`` (e.g. ``sensor_msgs/msg/Image``): its definition,
    then each dependency after a separator line and a ``MSG: package/Type`` line, as rosbag2
    writes it."""
    parts = [MESSAGE_DEFINITIONS[datatype]]
    for dep in dependencies(datatype):
        parts.append(f"{_SEPARATOR}\nMSG: {dep.replace('/msg/', '/')}\n{MESSAGE_DEFINITIONS[dep]}")
    return "".join(parts)
