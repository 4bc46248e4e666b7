"""ROS 2 messages on the DDS wire without ROS: Cyclone DDS types made from the message
definitions semloc already uses for bags.

A ROS 2 node is, on the wire, a DDS participant that names its topics `rt/<topic>` and its
types `<pkg>::msg::dds_::<Type>_`, with the fields of the `.msg` definition in order, in
classic CDR (XCDR1, final types, as `rmw_cyclonedds_cpp` writes them).  `idl_type(typename)`
builds that Cyclone DDS type from the definition in `semloc.ros.messages.typestore()` (ROS 2
Humble, plus vision_msgs 4), so a bag and the wire carry the same layout by construction.
`to_wire(message, typename)` turns a message of that store into its wire type; the wire
types' fields have the message's names, so code that reads messages reads both.
"""

from __future__ import annotations

import os
import types
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np

from semloc.ros import messages as msgs

LOOPBACK = (
    '<CycloneDDS><Domain><General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
    "<AllowMulticast>false</AllowMulticast></General><Discovery><Peers>"
    '<Peer address="127.0.0.1"/></Peers><ParticipantIndex>auto</ParticipantIndex>'
    "<MaxAutoParticipantIndex>40</MaxAutoParticipantIndex></Discovery></Domain></CycloneDDS>"
)
"""Cyclone DDS on this machine only: the loopback interface, no multicast, peer 127.0.0.1."""
NETWORKS = ("loopback", "default")
ON_LOOPBACK = (
    "DDS stays on this machine (loopback): CYCLONEDDS_URI is not set; set it for the robot's "
    "network, or pass --network default for Cyclone DDS's defaults (docs/ros2.md)"
)


def choose_network(network: str) -> str | None:
    """Configure Cyclone DDS's network before this process's first participant.  A
    `CYCLONEDDS_URI` that is set is honoured, never overridden; without one, `loopback` keeps
    DDS on this machine (returns the notice to show) and `default` leaves Cyclone DDS's
    defaults (multicast discovery on the machine's network)."""
    if network not in NETWORKS:
        raise ValueError(f"network must be one of {', '.join(NETWORKS)}, got {network!r}")
    if os.environ.get("CYCLONEDDS_URI") or network == "default":
        return None
    os.environ["CYCLONEDDS_URI"] = LOOPBACK
    return ON_LOOPBACK


_BASE = {
    "bool": "bool", "byte": "uint8", "char": "uint8", "uint8": "uint8", "int8": "int8",
    "int16": "int16", "uint16": "uint16", "int32": "int32", "uint32": "uint32",
    "int64": "int64", "uint64": "uint64", "float32": "float32", "float64": "float64",
}  # fmt: skip
"""ROS 2 base types and the Cyclone DDS IDL types of the same size."""


def topic_name(topic: str) -> str:
    """The DDS topic of a ROS 2 topic: `/semloc/pose` -> `rt/semloc/pose`."""
    return "rt/" + topic.lstrip("/")


def dds_typename(typename: str) -> str:
    """`geometry_msgs/msg/Pose` -> `geometry_msgs::msg::dds_::Pose_`."""
    package, kind, name = typename.split("/")
    return f"{package}::{kind}::dds_::{name}_"


@cache
def idl_type(typename: str) -> type:
    """The Cyclone DDS type of a ROS 2 message type of the store (built once)."""
    from cyclonedds.idl import IdlStruct

    store = msgs.typestore()
    annotations = {name: _annotation(desc) for name, desc in store.get_msgdef(typename).fields}
    cls = types.new_class(
        typename.split("/")[-1],
        (IdlStruct,),
        {"typename": dds_typename(typename)},
        lambda namespace: namespace.update({"__annotations__": annotations}),
    )
    return dataclass(cls)


def _annotation(desc: tuple) -> Any:
    import cyclonedds.idl.types as t
    from rosbags.interfaces import Nodetype

    kind, detail = desc
    if kind == Nodetype.BASE:
        name = detail[0]
        return str if name == "string" else (bool if name == "bool" else getattr(t, _BASE[name]))
    if kind == Nodetype.NAME:
        return idl_type(detail)
    if kind == Nodetype.ARRAY:
        inner, length = detail
        return t.array[_annotation(inner), length]
    if kind == Nodetype.SEQUENCE:
        return t.sequence[_annotation(detail[0])]
    raise ValueError(f"unsupported field kind {kind}")


def to_wire(message: Any, typename: str) -> Any:
    """The wire type's instance of a message of the store (or of a wire instance)."""
    from rosbags.interfaces import Nodetype

    store = msgs.typestore()
    values = {}
    for name, (kind, detail) in store.get_msgdef(typename).fields:
        value = getattr(message, name)
        if kind == Nodetype.NAME:
            values[name] = to_wire(value, detail)
        elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            inner = detail[0]
            if inner[0] == Nodetype.NAME:
                values[name] = [to_wire(v, inner[1]) for v in value]
            else:
                values[name] = np.asarray(value).tolist() if len(value) else []
        else:
            values[name] = value.item() if isinstance(value, np.generic) else value
    return idl_type(typename)(**values)
