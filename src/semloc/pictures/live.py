"""A live Foxglove view of a localization, in Foxglove's own schemas (protobuf, from
`foxglove-sdk`), served over Foxglove's WebSocket protocol by `semloc.pictures.foxglove_ws`
(both `foxglove.websocket.v1` and `foxglove.sdk.v1`; the `viz` extra), so Foxglove, Lichtblick
and any client of the protocol show it without plugins.

`FoxgloveView(global_map, port)` starts a server (Foxglove or Lichtblick: *Open connection* ->
`ws://localhost:PORT`; the layout `docs/foxglove_layout.json` arranges the panels) and
`update(stamp_ns, result, local_map, T_odom_sensor)` publishes one answer.  Each channel keeps
its latest message: a viewer that subscribes at any time, also after the run, gets the latest
of every channel at once.

- `/semloc/map` (`foxglove.SceneUpdate`, frame `map`): the map's objects as label-coloured
  boxes with their labels;
- `/semloc/local` (`SceneUpdate`): the local objects placed by the best hypothesis (green
  when `localized`, orange when not) and a line from each matched one to its map partner;
  with coverage, entity `missing`: the map objects the answer counts missing (in view of the
  recent looks, detected by nobody: `Support.missing_ids`) as magenta boxes labelled
  `missing ID`;
- `/semloc/hypotheses` (`SceneUpdate`): where each of the best hypotheses puts the local
  frame's origin, with its rank and confidence, and, when the answer is ambiguous, its "look
  there next" suggestions (`semloc.pictures.looks`), one entity `next_look/N` each: for each
  rank the suggestion separates, a cyan arrow from the sensor (placed by the best hypothesis)
  to the spot to look at, labelled `look N: LABEL ID if #RANK`;
- `/semloc/pose` (`foxglove.PoseInFrame`, frame `map`): the sensor's pose when `localized`;
- `/tf` (`foxglove.FrameTransform`): `map` -> `odom` when `localized`;
- `/semloc/status` (`foxglove.Log`): status, confidence and reason of each answer, the best
  suggestion of an ambiguous one, and with coverage how many map objects in view were
  missing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from semloc.maps import ObjectMap
from semloc.pictures.colors import label_colors, rgb
from semloc.pictures.foxglove_ws import FoxgloveServer
from semloc.pictures.looks import LOOK_RGB, look_arrows
from semloc.results import Result

STATUS_RGB = {"localized": (0.1, 0.8, 0.2), "ambiguous": (1.0, 0.7, 0.0), "failed": (0.9, 0.1, 0.1)}
HYPOTHESES = 5
MISSING_RGB = (1.0, 0.0, 1.0)
"""Magenta: the map objects an answer counts missing (no label colour is this loud)."""


@dataclass(frozen=True)
class Box:
    """A box to draw: its pose in the map (4 x 4), size (m) and label."""

    T: np.ndarray
    size: np.ndarray
    text: str


def missing_boxes(result: Result, global_map: ObjectMap) -> list[Box]:
    """The map objects the answer counts missing (`Support.missing_ids`), as boxes 10 cm
    larger than the map's (so they show around them), labelled `missing ID`."""
    ids = () if result.support is None else result.support.missing_ids or ()
    boxes = []
    for gid in ids:
        obj = global_map.get(gid)
        T = np.eye(4)
        T[:3, 3] = obj.position
        if obj.rotation is not None:
            T[:3, :3] = obj.rotation
        size = (obj.size if obj.size is not None else np.full(3, 0.2)) + 0.1
        boxes.append(Box(T, size, f"missing {gid}"))
    return boxes


def _quaternion(R: np.ndarray) -> tuple[float, float, float, float]:
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return float(x), float(y), float(z), float(w)


TOPICS = {"/semloc/map": "SceneUpdate", "/semloc/local": "SceneUpdate",
          "/semloc/hypotheses": "SceneUpdate", "/semloc/pose": "PoseInFrame",
          "/tf": "FrameTransform", "/semloc/status": "Log"}  # fmt: skip
"""The view's channels and their `foxglove.` schemas."""


class FoxgloveView:
    """The live view of one localization (see the module docstring)."""

    def __init__(self, global_map: ObjectMap, port: int = 8765, host: str = "127.0.0.1",
                 map_frame: str = "map", odom_frame: str = "odom") -> None:  # fmt: skip
        import foxglove.messages

        self.m = foxglove.messages
        self.global_map, self.map_frame, self.odom_frame = global_map, map_frame, odom_frame
        self.colors = {k: rgb(v) for k, v in label_colors(global_map.labels).items()}
        self.server = FoxgloveServer(host, port)
        self.port = self.server.port
        self.channels: dict[str, int] = {}
        for topic, name in TOPICS.items():
            schema = getattr(self.m, name).get_schema()
            self.channels[topic] = self.server.add_channel(topic, schema.name, schema.data,
                                                           encoding=schema.encoding)  # fmt: skip
        self.publish_map()

    def close(self) -> None:
        self.server.close()

    def _log(self, topic: str, message: Any) -> None:
        self.server.publish(self.channels[topic], message.encode())

    # messages -------------------------------------------------------------------------------
    def _pose(self, T: np.ndarray) -> Any:
        m = self.m
        x, y, z, w = _quaternion(T[:3, :3])
        return m.Pose(position=m.Vector3(x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])),
                      orientation=m.Quaternion(x=x, y=y, z=z, w=w))  # fmt: skip

    def _color(self, rgb_: tuple, a: float) -> Any:
        return self.m.Color(r=float(rgb_[0]), g=float(rgb_[1]), b=float(rgb_[2]), a=a)

    def _at(self, xyz: np.ndarray) -> Any:
        T = np.eye(4)
        T[:3, 3] = xyz
        return self._pose(T)

    def publish_map(self) -> None:
        """The map's objects (kept for every viewer that subscribes later)."""
        m, entities = self.m, []
        for obj in self.global_map:
            T = np.eye(4)
            T[:3, 3] = obj.position
            if obj.rotation is not None:
                T[:3, :3] = obj.rotation
            size = obj.size if obj.size is not None else np.full(3, 0.2)
            colour = tuple(c / 255 for c in self.colors.get(obj.label, (128, 128, 128)))
            label = obj.position + [0.0, 0.0, float(size[2]) / 2 + 0.15]
            entities.append(m.SceneEntity(
                frame_id=self.map_frame, id=f"map/{obj.id}",
                cubes=[m.CubePrimitive(pose=self._pose(T), size=m.Vector3(
                    x=float(size[0]), y=float(size[1]), z=float(size[2])),
                    color=self._color(colour, 0.45))],
                texts=[self._text(label, obj.label, 12.0, self._color((1, 1, 1), 0.9))],
            ))  # fmt: skip
        self._log("/semloc/map", m.SceneUpdate(entities=entities))

    def update(self, stamp_ns: int, result: Result, local_map: ObjectMap,
               T_odom_sensor: np.ndarray | None = None) -> None:  # fmt: skip
        """Publish one answer (see the module docstring)."""
        self._log("/semloc/local", self._local_scene(result, local_map))
        self._log("/semloc/hypotheses", self._hypotheses_scene(result, T_odom_sensor))
        if result.pose_is_answer:
            m, pose = self.m, result.pose
            T_odom_sensor = np.eye(4) if T_odom_sensor is None else T_odom_sensor
            self._log("/semloc/pose", m.PoseInFrame(frame_id=self.map_frame,
                                                    pose=self._pose(pose @ T_odom_sensor)))  # fmt: skip
            x, y, z, w = _quaternion(pose[:3, :3])
            self._log("/tf", m.FrameTransform(
                parent_frame_id=self.map_frame, child_frame_id=self.odom_frame,
                translation=m.Vector3(x=float(pose[0, 3]), y=float(pose[1, 3]), z=float(pose[2, 3])),
                rotation=m.Quaternion(x=x, y=y, z=z, w=w)))  # fmt: skip
        self._log("/semloc/status", self._status(result))

    def _local_scene(self, result: Result, local_map: ObjectMap) -> Any:
        """The local objects placed by the best hypothesis, lines to their map partners."""
        m, best = self.m, result.best
        missing = self._missing_entity(result)
        if best is None or best.pose is None:
            return m.SceneUpdate(
                entities=[m.SceneEntity(frame_id=self.map_frame, id="local"), missing]
            )
        colour = self._color(STATUS_RGB[result.status], 1.0)
        placed = {o.id: best.pose[:3, :3] @ o.position + best.pose[:3, 3] for o in local_map}
        spheres = [m.SpherePrimitive(pose=self._at(p), size=m.Vector3(x=0.15, y=0.15, z=0.15),
                                     color=colour) for p in placed.values()]  # fmt: skip
        where = {o.id: o.position for o in self.global_map}
        points = [self._point(v) for g, lid in best.pairs if g in where and lid in placed
                  for v in (where[g], placed[lid])]  # fmt: skip
        lines = [m.LinePrimitive(type=m.LinePrimitiveLineType.LineList, thickness=0.02,
                                 points=points, color=colour)] if points else []  # fmt: skip
        return m.SceneUpdate(entities=[m.SceneEntity(frame_id=self.map_frame, id="local",
                                                     spheres=spheres, lines=lines), missing])  # fmt: skip

    def _missing_entity(self, result: Result) -> Any:
        """The map objects the answer counts missing, as boxes a little larger than the map's
        (an empty entity replaces the previous answer's)."""
        m = self.m
        colour = self._color(MISSING_RGB, 0.8)
        cubes, texts = [], []
        for box in missing_boxes(result, self.global_map):
            size = m.Vector3(x=float(box.size[0]), y=float(box.size[1]), z=float(box.size[2]))
            cubes.append(m.CubePrimitive(pose=self._pose(box.T), color=colour, size=size))
            above = box.T[:3, 3] + [0.0, 0.0, float(box.size[2]) / 2 + 0.3]
            texts.append(self._text(above, box.text, 12.0, colour))
        return m.SceneEntity(frame_id=self.map_frame, id="missing", cubes=cubes, texts=texts)

    def _hypotheses_scene(self, result: Result, T_odom_sensor: np.ndarray | None) -> Any:
        """The best hypotheses' origins with rank and confidence, and the next-look arrows
        (everything of the previous answer deleted first)."""
        m, entities = self.m, []
        for h in result.hypotheses[:HYPOTHESES]:
            if h.pose is None:
                continue
            conf = "" if h.confidence is None else f" {h.confidence:.2f}"
            entities.append(m.SceneEntity(
                frame_id=self.map_frame, id=f"hypothesis/{h.rank}",
                spheres=[m.SpherePrimitive(pose=self._at(h.pose[:3, 3]), size=m.Vector3(
                    x=0.3, y=0.3, z=0.3), color=self._color((0.3, 0.5, 1.0), 0.8))],
                texts=[self._text(h.pose[:3, 3] + [0, 0, 0.4], f"#{h.rank}{conf}", 14.0)],
            ))  # fmt: skip
        colour = self._color(LOOK_RGB, 1.0)
        arrows = look_arrows(result, T_odom_sensor)
        for order in sorted({a.order for a in arrows}):
            mine = [a for a in arrows if a.order == order]
            entities.append(m.SceneEntity(
                frame_id=self.map_frame, id=f"next_look/{order}",
                arrows=[self._arrow(a.start, a.end, colour) for a in mine],
                texts=[self._text(a.end + [0, 0, 0.4], a.text, 12.0, colour) for a in mine],
            ))  # fmt: skip
        deletions = [m.SceneEntityDeletion(type=m.SceneEntityDeletionType.All)]
        return m.SceneUpdate(deletions=deletions, entities=entities)

    def _status(self, result: Result) -> Any:
        """The answer's status line, with the best suggestion of an ambiguous one."""
        m = self.m
        conf = "" if result.confidence is None else f" {result.confidence:.2f}"
        text = f"{result.status}{conf} {result.reason}".rstrip()
        if result.next_look:
            look = result.next_look[0]
            ranks = ", ".join(f"#{r}" for r in look.separates)
            text += f"; look at {look.label} {look.global_id} (tells {ranks})"
        support = result.support
        if support is not None and support.n_expected is not None:
            text += f"; {support.n_missing} of {support.n_expected} map objects in view missing"
        level = m.LogLevel.Info if result.status == "localized" else m.LogLevel.Warning
        return m.Log(level=level, name="semloc", message=text)

    def _point(self, v: np.ndarray) -> Any:
        return self.m.Point3(x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def _text(self, xyz: np.ndarray, text: str, size: float, colour: Any = None) -> Any:
        return self.m.TextPrimitive(pose=self._at(xyz), billboard=True, font_size=size,
                                    scale_invariant=True, text=text,
                                    color=colour or self._color((1, 1, 1), 1.0))  # fmt: skip

    def _arrow(self, start: np.ndarray, end: np.ndarray, colour: Any) -> Any:
        """An arrow from `start` to `end` (Foxglove's arrows point along their pose's +x)."""
        from scipy.spatial.transform import Rotation

        direction = np.asarray(end, dtype=float) - start
        length = float(np.linalg.norm(direction))
        T = np.eye(4)
        T[:3, 3] = start
        if length > 1e-9:
            T[:3, :3] = Rotation.align_vectors([direction], [[1.0, 0.0, 0.0]])[0].as_matrix()
        head = min(0.4, 0.3 * length)
        return self.m.ArrowPrimitive(pose=self._pose(T), shaft_length=length - head,
                                     shaft_diameter=0.06, head_length=head, head_diameter=0.2,
                                     color=colour)  # fmt: skip
