"""Relocalization answers as ROS 2 messages, for Foxglove / RViz without configuration.

`AnswerTopics` writes, into an `McapSink`:

- `/semloc/pose` (geometry_msgs/PoseWithCovarianceStamped, frame `map`): the pose of the
  detections' frame in the map, with the covariance of the answer's fit
  (`semloc.ros.frames.covariance`), when the answer is `localized`;
- `/tf` (tf2_msgs/TFMessage): `map` -> odometry frame when localized, and the odometry frame
  -> the detections' frame at every answer;
- `/semloc/status` (std_msgs/String): the localize JSON at every answer with its `stamp` and
  `n_local` (`semloc.schema.StatusAnswer`): its latest step only and its best three
  hypotheses; its `prior` is the prior in effect on the odometry frame's origin (null: none);
- `/semloc/map` (visualization_msgs/MarkerArray, once): the map's objects as label-coloured
  boxes with their labels;
- `/semloc/matches` (MarkerArray, every answer): the best hypothesis's local objects placed in
  the map, a line from each to its map partner, an arrow from each moved object's map
  place to where it is now, and, when the answer is ambiguous, its "look there next"
  suggestions (namespace `next look`, `semloc.pictures.looks`): for each rank a suggestion
  separates, a cyan arrow from the sensor (placed by the best hypothesis) to the spot to look
  at, labelled `look N: LABEL ID if #RANK`.  (The ROS 2 node publishes
  this topic as `/semloc/markers`.)
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from semloc import schema
from semloc.maps import ObjectMap
from semloc.pictures.colors import label_colors, rgb
from semloc.pictures.looks import LOOK_RGB, look_arrows
from semloc.results import Result
from semloc.ros import messages as msgs
from semloc.ros.frames import covariance
from semloc.ros.mcap_out import McapSink

POSE_TOPIC = "/semloc/pose"
TF_TOPIC = "/tf"
STATUS_TOPIC = "/semloc/status"
MAP_TOPIC = "/semloc/map"
MATCHES_TOPIC = "/semloc/matches"
OUTPUT_TOPICS = {POSE_TOPIC: msgs.POSE, TF_TOPIC: msgs.TF, STATUS_TOPIC: msgs.STRING,
                 MAP_TOPIC: msgs.MARKERS, MATCHES_TOPIC: msgs.MARKERS}  # fmt: skip
"""The topics `semloc bag localize` writes and their message types."""

TOP_HYPOTHESES = 3
"""How many of the best hypotheses `/semloc/status` lists."""
STATUS_COLORS = {"localized": (0.1, 0.8, 0.2), "ambiguous": (1.0, 0.7, 0.0),
                 "failed": (0.9, 0.1, 0.1)}  # fmt: skip


@dataclass
class Frames:
    """The frame names: the map's, the odometry's and the detections'."""

    map: str = "map"
    odom: str = "odom"
    sensor: str = "odom"


class AnswerTopics:
    """Writes the answers of one run into `sink` (see the module docstring)."""

    def __init__(self, sink: McapSink, global_map: ObjectMap, frames: Frames) -> None:
        self.sink, self.global_map, self.frames = sink, global_map, frames
        self.colors = {k: rgb(v) for k, v in label_colors(global_map.labels).items()}
        self._map_written = False

    def write(
        self, stamp: int, result: Result, T_odom_sensor: np.ndarray, local: ObjectMap
    ) -> None:
        """The messages of one answer at `stamp` (ns); `local`: the local objects so far."""
        if not self._map_written:
            self.sink.write(MAP_TOPIC, msgs.MARKERS, stamp, self.map_markers(stamp))
            self._map_written = True
        f = self.frames
        transforms = []
        if result.pose_is_answer:
            T_map_sensor = result.pose @ T_odom_sensor
            self.sink.write(
                POSE_TOPIC, msgs.POSE, stamp, self.pose(stamp, result, T_map_sensor, local)
            )
            transforms.append(msgs.transform(result.pose, stamp, f.map, f.odom))
        if f.sensor != f.odom:
            transforms.append(msgs.transform(T_odom_sensor, stamp, f.odom, f.sensor))
        if transforms:
            self.sink.write(TF_TOPIC, msgs.TF, stamp, msgs.new(msgs.TF, transforms=transforms))
        self.sink.write(STATUS_TOPIC, msgs.STRING, stamp, msgs.new(msgs.STRING,
                        data=json.dumps(status(stamp, result, len(local)), allow_nan=False)))  # fmt: skip
        self.sink.write(
            MATCHES_TOPIC, msgs.MARKERS, stamp,
            self.match_markers(stamp, result, local, T_odom_sensor),
        )  # fmt: skip

    def pose(self, stamp: int, result: Result, T_map_sensor: np.ndarray, local: ObjectMap) -> Any:
        best = result.best
        assert best is not None
        index = {o.id: o for o in local}
        centres = np.array([index[lid].position for _, lid in best.pairs if lid in index])
        with_cov = msgs.new("geometry_msgs/msg/PoseWithCovariance", pose=msgs.pose(T_map_sensor),
                            covariance=covariance(best, centres).reshape(36))  # fmt: skip
        return msgs.new(msgs.POSE, header=msgs.header(stamp, self.frames.map), pose=with_cov)

    def map_markers(self, stamp: int) -> Any:
        markers = []
        for i, obj in enumerate(self.global_map):
            T = np.eye(4)
            T[:3, 3] = obj.position
            if obj.rotation is not None:
                T[:3, :3] = obj.rotation
            size = obj.size if obj.size is not None else np.full(3, 0.2)
            color = self._color(self.colors.get(obj.label, (128, 128, 128)), 0.5)
            markers.append(self._marker(stamp, "map objects", i, 1, T, np.maximum(size, 0.01),
                                        color, text=obj.id))  # fmt: skip
            T_text = T.copy()
            T_text[:3, :3] = np.eye(3)
            T_text[2, 3] += float(size[2]) / 2 + 0.15
            markers.append(self._marker(stamp, "map labels", i, 9, T_text, (0, 0, 0.15),
                                        (1.0, 1.0, 1.0, 0.9), text=obj.label))  # fmt: skip
        return msgs.new(msgs.MARKERS, markers=markers)

    def match_markers(self, stamp: int, result: Result, local: ObjectMap,
                      T_odom_sensor: np.ndarray | None = None) -> Any:  # fmt: skip
        markers = [msgs.new("visualization_msgs/msg/Marker", header=msgs.header(stamp, self.frames.map),
                            action=3)]  # fmt: skip  # DELETEALL: the last answer's go
        markers += self.look_markers(stamp, result, T_odom_sensor)
        best = result.best
        if best is None or best.pose is None:
            return msgs.new(msgs.MARKERS, markers=markers)
        placed = {o.id: best.pose[:3, :3] @ o.position + best.pose[:3, 3] for o in local}
        where = {o.id: o.position for o in self.global_map}
        color = (*STATUS_COLORS[result.status], 1.0)
        for i, (_, xyz) in enumerate(sorted(placed.items())):
            T = np.eye(4)
            T[:3, 3] = xyz
            markers.append(self._marker(stamp, "local objects", i, 2, T, (0.15, 0.15, 0.15), color))
        lines = [(where[g], placed[lid]) for g, lid in best.pairs if g in where and lid in placed]
        if lines:
            markers.append(self._marker(stamp, "pairs", 0, 5, np.eye(4), (0.02, 0, 0), color,
                                        points=[p for line in lines for p in line]))  # fmt: skip
        for i, moved in enumerate(result.changes.moved):
            if moved.global_id in where and moved.local_id in placed:
                ends = [where[moved.global_id], placed[moved.local_id]]
                markers.append(self._marker(stamp, "moved", i, 0, np.eye(4), (0.04, 0.08, 0.1),
                                            (1.0, 0.2, 0.8, 1.0), points=ends))  # fmt: skip
        return msgs.new(msgs.MARKERS, markers=markers)

    def look_markers(self, stamp: int, result: Result, T_odom_sensor: np.ndarray | None) -> list:
        """The next-look arrows of an ambiguous answer, each with its label above its end."""
        markers, color = [], (*LOOK_RGB, 1.0)
        for i, arrow in enumerate(look_arrows(result, T_odom_sensor)):
            markers.append(self._marker(stamp, "next look", 2 * i, 0, np.eye(4), (0.06, 0.2, 0.4),
                                        color, points=[arrow.start, arrow.end]))  # fmt: skip
            T_text = np.eye(4)
            T_text[:3, 3] = arrow.end + [0.0, 0.0, 0.4]
            markers.append(self._marker(stamp, "next look", 2 * i + 1, 9, T_text, (0, 0, 0.25),
                                        color, text=arrow.text))  # fmt: skip
        return markers

    def _marker(self, stamp: int, ns: str, i: int, kind: int, T: np.ndarray, scale: Any,
                color: tuple, text: str = "", points: list | None = None) -> Any:  # fmt: skip
        rgba = msgs.new("std_msgs/msg/ColorRGBA", r=float(color[0]), g=float(color[1]),
                        b=float(color[2]), a=float(color[3]))  # fmt: skip
        return msgs.new(
            "visualization_msgs/msg/Marker", header=msgs.header(stamp, self.frames.map), ns=ns,
            id=i, type=kind, action=0, pose=msgs.pose(T), scale=msgs.vector(scale), color=rgba,
            text=text, points=[msgs.point(p) for p in points or []],
        )  # fmt: skip

    @staticmethod
    def _color(rgb255: tuple[int, int, int], alpha: float) -> tuple[float, float, float, float]:
        return rgb255[0] / 255, rgb255[1] / 255, rgb255[2] / 255, alpha


def status(stamp: int, result: Result, n_local: int) -> dict[str, Any]:
    """The JSON of `/semloc/status` for one answer at `stamp` (ns): `schema.StatusAnswer`,
    with the latest step and the best `TOP_HYPOTHESES` hypotheses only (a message at every
    answer)."""
    answer = result.to_model(schema.StatusAnswer, 1, stamp=stamp / 1e9, n_local=n_local)
    answer.hypotheses = answer.hypotheses[:TOP_HYPOTHESES]
    return answer.model_dump(by_alias=True)
