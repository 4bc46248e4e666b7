"""`semloc bag info` and `semloc bag localize`: recorded ROS 2 runs (rosbag2 folders with
sqlite3 or MCAP storage, bare .mcap / .db3 files) in, answers as MCAP (and JSON lines) out.

Needs the `semloc[ros]` extra (rosbags, mcap; no ROS installation).  The work is in
`semloc.ros`; this module checks the options, the files and the extra, and prints.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Annotated

import typer
from pydantic import ValidationError
from rich.table import Table

from semloc.cli.app import app, console, err_console, fail, first_error
from semloc.cli.extras import need
from semloc.cli.files import (
    check_finite,
    check_output,
    check_separate,
    map_paths,
    read_config,
    read_label_map,
)
from semloc.cli.options import (
    CameraRangeOption,
    NearOption,
    RadiusOption,
    prior_option,
    topic_option,
)
from semloc.cli.render import support_line
from semloc.io import load_map, write_files
from semloc.localizer import LocalizerConfig
from semloc.pictures.display import for_rich
from semloc.ros.answers import OUTPUT_TOPICS, AnswerTopics, Frames
from semloc.ros.bag import Run, opened, topics
from semloc.ros.initialpose import TOPIC as INITIALPOSE_TOPIC
from semloc.ros.mcap_out import McapSink
from semloc.ros.replay import Answer, answer_json, replay
from semloc.ros.stream import StreamLocalizer

bag_app = typer.Typer(
    help="ROS 2 bags and MCAP: localize a recorded run, list a bag's topics (the ros extra).",
    no_args_is_help=True,
)
app.add_typer(bag_app, name="bag")

BagArgument = Annotated[
    Path,
    typer.Argument(
        metavar="BAG", help="A rosbag2 folder (sqlite3 or MCAP storage), or a .mcap / .db3 file."
    ),
]


@bag_app.command("info")
def info(bag: BagArgument) -> None:
    """List BAG's topics: type, messages, and which option of `bag localize` reads each."""
    need("bag info", "ros")
    found, duration = topics(bag)
    title = f"{for_rich(bag, None)}: {duration:.1f} s"
    table = Table(title=title, title_justify="left", box=None)
    for column, names in (("topic", [t.name for t in found]), ("type", [t.msgtype for t in found])):
        table.add_column(column, no_wrap=True, min_width=max(map(len, names), default=4))
    table.add_column("messages", justify="right")
    table.add_column("use")
    for topic in found:
        table.add_row(topic.name, topic.msgtype, str(topic.count), topic.use or "")
    console.print(table)
    usable = [t for t in found if t.use == "--detections"]
    if not usable:
        console.print("no vision_msgs/msg/Detection3DArray topic: nothing to localize with")


@bag_app.command("localize")
def localize(
    bag: BagArgument,
    map_file: Annotated[Path, typer.Option("--map", help="The global map (semloc JSON).")],
    detections: Annotated[
        str, typer.Option(help="Topic of vision_msgs/msg/Detection3DArray messages.")
    ],
    output: Annotated[
        Path, typer.Option("--output", "-o", help="MCAP file to write the answers to.")
    ],
    odom: Annotated[
        str | None,
        typer.Option(help="Topic of nav_msgs/msg/Odometry placing the detections' frame."),
    ] = None,
    points: Annotated[
        str | None,
        typer.Option(
            help="Topic of sensor_msgs/msg/PointCloud2 with the detections' points "
            "(fields x, y, z, detection = index in the array of the same stamp)."
        ),
    ] = None,
    jsonl: Annotated[
        Path | None,
        typer.Option(help='Also write each answer as a JSON line {"stamp", "result"}.'),
    ] = None,
    gamma: Annotated[float | None, typer.Option(help="Merge threshold of the clustering.")] = None,
    config: Annotated[
        Path | None,
        typer.Option(help="Settings file, JSON or .yaml (`semloc config --dump`)."),
    ] = None,
    label_map: Annotated[
        Path | None,
        typer.Option("--label-map", help="Labels mapped before comparing (JSON or .yaml)."),
    ] = None,
    map_frame: Annotated[str, typer.Option(help="Frame id of the map in the output.")] = "map",
    initialpose: Annotated[
        str,
        typer.Option(
            help="geometry_msgs/PoseWithCovarianceStamped topic of robot pose estimates in the "
            "map (RViz's 2D Pose Estimate), read when the bag has it: each sets the prior from "
            "the next detection message on; 'none' reads none."
        ),
    ] = INITIALPOSE_TOPIC,
    near: NearOption = None,
    radius: RadiusOption = None,
    camera_info: Annotated[
        str | None,
        typer.Option(
            "--camera-info",
            help="sensor_msgs/msg/CameraInfo topic of the camera that made the detections: each "
            "message then says what the camera covered (its field of view, placed by the "
            "bag's /tf_static), and map objects in plain view that were not detected count "
            "against a place.",
        ),
    ] = None,
    camera_range: CameraRangeOption = 5.0,
) -> None:
    """Localize a recorded run and write the answers as MCAP for Foxglove.

    BAG's detections are fused into local objects, relocalized in the map after each message.

    Output: /semloc/pose (when localized), /tf, /semloc/status (JSON), /semloc/map, /semloc/matches.

    Both outputs are written at the end, both or neither.  --near/--radius: a position prior
    on the odometry frame's origin (the local frame), until a pose estimate on --initialpose.
    """
    check_finite(gamma=gamma)
    prior = prior_option(near, radius)
    need("bag localize", "ros")
    check_output(output)
    if jsonl is not None:
        check_output(jsonl, "--jsonl")
    settings = read_config(config)
    if gamma is not None:
        settings["gamma"] = gamma
    if label_map is not None:
        settings["label_map"] = read_label_map(label_map)
    try:
        cfg = LocalizerConfig(**settings)
    except ValidationError as exc:
        fail(f"invalid settings: {first_error(exc)}")
    global_map = load_map(map_file)
    check_separate(
        {"--output": [output], "--jsonl": [jsonl] if jsonl else []},
        {**_bag_files(bag), **map_paths(map_file, global_map, "the --map")},
    )
    start = time.perf_counter()
    with opened(bag) as reader:
        run = Run(reader, bag, detections, odom, points, topic_option(initialpose),
                  camera_info, camera_range)  # fmt: skip
        if odom is None:
            _warn_moving_frame(run)
        stream = StreamLocalizer(global_map, cfg, use_points=points is not None)
        stream.localizer.set_prior(prior)
        sink = McapSink()
        writer: AnswerTopics | None = None
        lines, last = [], None
        for answer in replay(run, stream, map_frame):
            if writer is None:
                frames = Frames(map_frame, answer.odom_frame, answer.frame)
                writer = AnswerTopics(sink, global_map, frames)
            writer.write(answer.stamp, answer.result, answer.T_odom_sensor, stream.local_map())
            if jsonl is not None:
                lines.append(json.dumps(answer_json(answer), allow_nan=False) + "\n")
            last = answer
    seconds = time.perf_counter() - start
    files = [] if jsonl is None else [(jsonl, "".join(lines))]
    write_files([*files, (output, sink.getvalue())])
    _report(run, last, stream, seconds, output, jsonl, sink.counts)


def _warn_moving_frame(run: Run) -> None:
    """One line on stderr when the detections' frame is one an odometry topic of the bag
    moves but --odom was not given: the objects would be fused as if the sensor stood still
    (the answer is then ambiguous or wrong, for no visible reason)."""
    frame = run.first_frame()
    topic = None if frame is None else run.odometry_moving(frame)
    if topic is not None:
        err_console.print(
            f"[bold yellow]warning:[/] the detections are in frame {for_rich(frame, None)}, "
            f"which {for_rich(topic, None)} moves; without --odom they are taken as fixed in "
            f"one frame: give --odom {for_rich(topic, None)}",
            soft_wrap=True,
        )


def _bag_files(bag: Path) -> dict[Path, str]:
    """The bag and, for a folder, its files: the inputs an output must not overwrite."""
    files = {bag: "the bag"}
    if bag.is_dir():
        files.update({p: "a file of the bag" for p in bag.iterdir() if p.is_file()})
    return files


def _report(
    run: Run,
    last: Answer | None,
    stream: StreamLocalizer,
    seconds: float,
    output: Path,
    jsonl: Path | None,
    counts: dict[str, int],
) -> None:
    """What the run did: messages left out, the last answer, the files written."""
    for why, count in run.skipped.items():
        console.print(f"skipped {count} {why}")
    for why, count in run.warnings.items():
        err_console.print(f"[bold yellow]warning:[/] skipped {count} {why}", soft_wrap=True)
    if last is None:
        console.print("no local object was published: no answer")
    else:
        result = last.result
        conf = "" if result.confidence is None else f", confidence {result.confidence:.2f}"
        console.print(
            f"{stream.updates} answers, {len(stream.local_map())} local objects; last answer: "
            f"{result.status}{conf} {result.reason}".rstrip()
        )
        looks = support_line(result)
        if looks:
            console.print(looks)
    shown = ", ".join(f"{t} {counts.get(t, 0)}" for t in OUTPUT_TOPICS)
    console.print(f"wrote {for_rich(output, None)} ({shown}) in {seconds:.1f} s")
    if jsonl is not None:
        console.print(f"wrote {for_rich(jsonl, None)}")
