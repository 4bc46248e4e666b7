"""What a ROS 2 subscriber sees of `semloc ros2 node`: types written by hand from the .msg files,
readers that accept classic CDR (XCDR1) only, DDS on loopback.

    PYTHONPATH=src python benchmarks/ros2_wire_check.py [--keyframes 24]

A simulated walk's bag is played (`semloc ros2 play`) into a `semloc ros2 node` process; this
process subscribes `/semloc/status` (std_msgs/String), `/semloc/pose`
(geometry_msgs/PoseWithCovarianceStamped) and `/tf` (tf2_msgs/TFMessage) with its own types,
declared here field by field from the ROS 2 message definitions (not from semloc's), and a
data-representation QoS of XCDR1 alone, as a reader of `rmw_cyclonedds_cpp` has.  Printed:
messages per topic and a sample of each; a mismatch in names, layouts or representation shows
as nothing received.  The test suite checks the same (and more: Cyclone DDS's own
`cyclonedds ls / typeof / subscribe`, poses equal to `bag localize --jsonl`) in
`tests/ros2/test_interop.py`, with its own copy of these types.
"""

import argparse
import json
import os
import random
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault(
    "CYCLONEDDS_URI",
    '<CycloneDDS><Domain><General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
    "<AllowMulticast>false</AllowMulticast></General><Discovery><Peers>"
    '<Peer address="127.0.0.1"/></Peers></Discovery></Domain></CycloneDDS>',
)

import cyclonedds.idl.types as t  # noqa: E402
from cyclonedds.core import Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.sub import DataReader, InvalidSample  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402


# builtin_interfaces/msg/Time, std_msgs/msg/Header, std_msgs/msg/String
@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: t.int32
    nanosec: t.uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class String(IdlStruct, typename="std_msgs::msg::dds_::String_"):
    data: str


# geometry_msgs/msg/{Point, Quaternion, Pose, PoseWithCovariance, PoseWithCovarianceStamped}
@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: t.float64
    y: t.float64
    z: t.float64


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: t.float64
    y: t.float64
    z: t.float64
    w: t.float64


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point
    orientation: Quaternion


@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose
    covariance: t.array[t.float64, 36]


@dataclass
class PoseWithCovarianceStamped(
    IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"
):
    header: Header
    pose: PoseWithCovariance


# geometry_msgs/msg/{Vector3, Transform, TransformStamped}, tf2_msgs/msg/TFMessage
@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: t.float64
    y: t.float64
    z: t.float64


@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3
    rotation: Quaternion


@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header
    child_frame_id: str
    transform: Transform


@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: t.sequence[TransformStamped]


XCDR1_ONLY = Qos(
    Policy.Reliability.Reliable(duration(seconds=1)),
    Policy.History.KeepLast(1000),
    Policy.DataRepresentation(use_cdrv0_representation=True),
)


def main(argv: "list[str] | None" = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--keyframes", type=int, default=24)
    args = parser.parse_args(argv)
    domain = random.randrange(100, 200)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    semloc = [sys.executable, "-m", "semloc"]
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder)
        subprocess.run([*semloc, "simulate", str(out), "--bag", "--no-snapshots", "--size",
                        "small", "--keyframes", str(args.keyframes)], env=env, check=True,
                       capture_output=True)  # fmt: skip
        participant = DomainParticipant(domain)
        readers = {
            name: DataReader(participant, Topic(participant, f"rt{name}", kind), qos=XCDR1_ONLY)
            for name, kind in (("/semloc/status", String),
                               ("/semloc/pose", PoseWithCovarianceStamped), ("/tf", TFMessage))
        }  # fmt: skip
        node = subprocess.Popen([*semloc, "ros2", "node", "--map",
                                 str(out / "global_reconstruction.json"), "--domain", str(domain)],
                                env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
        try:
            time.sleep(3.0)
            subprocess.run([*semloc, "ros2", "play", str(out / "walk.mcap"), "--domain",
                            str(domain)], env=env, check=True, capture_output=True)  # fmt: skip
            time.sleep(1.0)
            got = {n: [m for m in r.take(N=1000) if not isinstance(m, InvalidSample)]
                   for n, r in readers.items()}  # fmt: skip
        finally:
            node.terminate()
            node.wait(30)
    for name, messages in got.items():
        print(f"{name}: {len(messages)} messages")
    if got["/semloc/status"]:
        last = json.loads(got["/semloc/status"][-1].data)
        print("  last status:", {k: last[k] for k in ("stamp", "status", "confidence")})
    if got["/semloc/pose"]:
        pose = got["/semloc/pose"][-1]
        p = pose.pose.pose.position
        print(f"  last pose: frame {pose.header.frame_id}, ({p.x:.3f}, {p.y:.3f}, {p.z:.3f})")
    if got["/tf"]:
        frames = {(f.header.frame_id, f.child_frame_id) for m in got["/tf"] for f in m.transforms}
        print("  /tf frames:", sorted(frames))
    return 0 if all(got.values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
