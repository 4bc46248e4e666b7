"""`semloc ros2 node | play | echo`: semloc live on a ROS 2 robot's DDS wire, without ROS.

Needs the `semloc[ros2]` extra (Cyclone DDS; rosbags for the message definitions).  The work
is in `semloc.ros2`; this module checks the options and prints.  The DDS domain is `--domain`,
else `ROS_DOMAIN_ID`, else 0; `CYCLONEDDS_URI` configures the network as for any Cyclone DDS
process (semloc never overrides it).
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from pathlib import Path
from typing import Annotated

import typer
from pydantic import ValidationError

from semloc.cli import remote
from semloc.cli.app import app, choices, console, err_console, fail, first_error, foxglove_option
from semloc.cli.extras import need
from semloc.cli.files import read_config
from semloc.cli.options import (
    CameraRangeOption,
    NearOption,
    RadiusOption,
    prior_option,
    topic_option,
)
from semloc.client import Client, ServerError
from semloc.io import load_map
from semloc.localizer import LocalizerConfig
from semloc.pictures.live import FoxgloveView
from semloc.ros import messages as msgs
from semloc.ros.initialpose import TOPIC as INITIALPOSE_TOPIC
from semloc.ros2.node import DEFAULT_RANGE_M, TF_STATIC, LiveNode, NodeSettings, Wire, samples
from semloc.ros2.play import play
from semloc.ros2.remote import RemoteLocalizer
from semloc.ros2.wire import NETWORKS, choose_network

ros2_app = typer.Typer(
    help="Live on a ROS 2 robot without ROS (the ros2 extra): the semloc node, a bag player, "
    "a topic printer, on the DDS wire.",
    no_args_is_help=True,
)
app.add_typer(ros2_app, name="ros2")

KNOWN_TOPICS = {
    "/semloc/pose": "geometry_msgs/msg/PoseWithCovarianceStamped",
    "/semloc/status": "std_msgs/msg/String",
    "/semloc/markers": "visualization_msgs/msg/MarkerArray",
    "/semloc/map": "visualization_msgs/msg/MarkerArray",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/detections": "vision_msgs/msg/Detection3DArray",
    "/odom": "nav_msgs/msg/Odometry",
    "/detections/points": "sensor_msgs/msg/PointCloud2",
    "/initialpose": "geometry_msgs/msg/PoseWithCovarianceStamped",
    "/camera_info": "sensor_msgs/msg/CameraInfo",
    "/tf_static": "tf2_msgs/msg/TFMessage",
}
"""The topics `echo` knows the type of (others need `--type`)."""

FoxgloveOption = foxglove_option()
Network = choices("Network", NETWORKS)
NetworkOption = Annotated[
    Network,
    typer.Option(
        "--network",
        help="Without $CYCLONEDDS_URI: 'loopback' keeps DDS on this machine, 'default' uses "
        "Cyclone DDS's defaults (the machine's network). A set $CYCLONEDDS_URI always wins.",
    ),
]
DomainOption = Annotated[
    int | None,
    typer.Option(
        "--domain",
        min=0,
        max=232,
        help="DDS domain id, 0 to 232 (or $ROS_DOMAIN_ID; without either: 0).",
    ),
]


def _network(network: Network) -> None:
    """Cyclone DDS's network for this process (`semloc.ros2.wire.choose_network`)."""
    try:
        notice = choose_network(network.value)
    except ValueError as exc:
        fail(f"--network: {exc}")
    if notice is not None:
        err_console.print(f"semloc ros2: {notice}", style="yellow", highlight=False)


def _domain(domain: int | None) -> int:
    if domain is not None:
        return domain
    value = os.environ.get("ROS_DOMAIN_ID", "0").strip() or "0"
    if not value.isdigit() or int(value) > 232:
        fail(f"ROS_DOMAIN_ID must be a domain id from 0 to 232, got {value!r}")
    return int(value)


@ros2_app.command("node")
def node(
    map_file: Annotated[
        str,
        typer.Option(
            "--map", help="The global map: a semloc JSON file, or with --server a map id."
        ),
    ],
    detections: Annotated[
        str, typer.Option(help="vision_msgs/Detection3DArray topic to localize.")
    ] = "/detections",
    odom: Annotated[
        str, typer.Option(help="nav_msgs/Odometry topic; 'none' without odometry.")
    ] = "/odom",
    domain: DomainOption = None,
    network: NetworkOption = Network["loopback"],
    config: Annotated[
        Path | None, typer.Option("--config", help="Localizer settings (JSON or YAML).")
    ] = None,
    map_frame: Annotated[str, typer.Option(help="Frame id of the map.")] = "map",
    reliable: Annotated[
        bool,
        typer.Option(
            "--reliable",
            help="Subscribe reliable (matches reliable publishers only); default best-effort, "
            "which matches every publisher.",
        ),
    ] = False,
    server: Annotated[
        str | None,
        typer.Option(help="Localize through this `semloc serve` (a session of map --map)."),
    ] = None,
    token: remote.TokenOption = None,
    foxglove: FoxgloveOption = None,
    points: Annotated[
        str | None,
        typer.Option(
            help="sensor_msgs/PointCloud2 topic with the detections' points (fields x, y, z, "
            "detection = index in the array of the same stamp) [default: none, boxes only]."
        ),
    ] = None,
    initialpose: Annotated[
        str,
        typer.Option(
            help="geometry_msgs/PoseWithCovarianceStamped topic of robot pose estimates in the "
            "map (RViz's 2D Pose Estimate): each sets the prior; 'none' reads none."
        ),
    ] = INITIALPOSE_TOPIC,
    near: NearOption = None,
    radius: RadiusOption = None,
    camera_info: Annotated[
        str | None,
        typer.Option(
            "--camera-info",
            help="sensor_msgs/msg/CameraInfo topic of the camera that made the detections: each "
            "update then says what the camera covered (its field of view, placed by /tf_static), "
            "and map objects in plain view that were not detected count against a place "
            "[default: none, no coverage].",
        ),
    ] = None,
    camera_range: CameraRangeOption = DEFAULT_RANGE_M,
) -> None:
    """Localize a robot's detections live: publish /semloc/pose, /tf, /semloc/status,
    /semloc/markers and /semloc/map on the DDS wire (Ctrl-C ends it).  --near/--radius: a
    position prior on the odometry frame's origin, until a pose estimate on --initialpose.
    --camera-info: each update says what the camera covered (from its first CameraInfo on;
    until then without)."""
    need("ros2 node", "ros2")
    _network(network)
    prior = prior_option(near, radius)
    try:
        cfg = LocalizerConfig(**read_config(config))
    except ValidationError as exc:
        fail(f"invalid settings: {first_error(exc)}")
    localizer = None
    if server is None:
        global_map = load_map(Path(map_file))
    else:
        client = Client(server, token)
        try:
            global_map = client.get_map(map_file)
            session = client.session(map_file, up=(0.0, 0.0, 1.0))
        except (ServerError, OSError) as exc:
            fail(f"--server {server}: {exc}")
        localizer = RemoteLocalizer(session, global_map)
    settings = NodeSettings(
        detections, topic_option(odom), _domain(domain), map_frame, reliable, points,
        topic_option(initialpose), prior, camera_info, camera_range,
    )  # fmt: skip
    view = None
    if foxglove is not None:
        need("ros2 node --foxglove", "viz", modules=("foxglove", "websockets"))
        view = FoxgloveView(global_map, port=foxglove, map_frame=map_frame)
    live = LiveNode(global_map, cfg, settings, localizer=localizer)
    inputs = [detections, settings.odom or "no odometry"] + ([points] if points else [])
    if camera_info is not None:
        inputs += [f"{camera_info} (coverage to {camera_range:g} m)", TF_STATIC]
    console.print(
        f"semloc node on domain {settings.domain}: {' + '.join(inputs)}"
        f" -> /semloc/pose, /tf, /semloc/status, /semloc/markers, /semloc/map ({len(global_map)} "
        "map objects); Ctrl-C ends it"
    )

    def show(answer) -> None:
        result = answer.result
        if view is not None:
            view.update(answer.stamp, result, live.stream.local_map(), answer.T_odom_sensor)
        conf = "" if result.confidence is None else f" {result.confidence:.2f}"
        console.print(f"{answer.stamp / 1e9:.3f} {result.status}{conf} {result.reason}".rstrip())

    try:
        live.spin(lambda: False, show)
    finally:
        if view is not None:
            view.close()


@ros2_app.command("play")
def play_command(
    bag: Annotated[Path, typer.Argument(metavar="BAG", help="A rosbag2 folder or .mcap / .db3.")],
    domain: DomainOption = None,
    network: NetworkOption = Network["loopback"],
    rate: Annotated[
        float, typer.Option(min=0.0, help="Times the recorded pace; 0: as fast as possible.")
    ] = 1.0,
) -> None:
    """Publish BAG's messages on the DDS wire with ROS 2 names, at the recorded pace."""
    need("ros2 play", "ros2")
    _network(network)
    start = time.perf_counter()
    counts = play(bag, Wire(_domain(domain)), rate)
    shown = ", ".join(f"{topic} {n}" for topic, n in counts.items())
    console.print(f"played {shown} in {time.perf_counter() - start:.1f} s")


@ros2_app.command("echo")
def echo(
    topic: Annotated[str, typer.Argument(help="The topic, e.g. /semloc/status.")],
    domain: DomainOption = None,
    network: NetworkOption = Network["loopback"],
    msgtype: Annotated[
        str | None, typer.Option("--type", help="Its message type, e.g. std_msgs/msg/String.")
    ] = None,
    count: Annotated[int | None, typer.Option(min=1, help="Stop after this many.")] = None,
) -> None:
    """Print a topic's messages, one JSON line each (Ctrl-C ends it)."""
    need("ros2 echo", "ros2")
    _network(network)
    typename = msgtype or KNOWN_TOPICS.get(topic)
    if typename is None:
        fail(f"the type of {topic} is not known: give --type (known: {', '.join(KNOWN_TOPICS)})")
    if not msgs.known(typename):
        fail(f"--type {typename}: not a message type semloc knows")
    reader = Wire(_domain(domain)).reader(topic, typename, reliable=False)
    printed = 0
    while count is None or printed < count:
        for message in samples(reader):
            print(json.dumps(dataclasses.asdict(message), default=str), flush=True)
            printed += 1
            if count is not None and printed >= count:
                return
        time.sleep(0.005)
