"""A live Foxglove view of a localization, over Foxglove's WebSocket protocol (`foxglove-sdk`,
the `viz` extra), in Foxglove's own schemas, so the Foxglove app shows it without plugins.

`FoxgloveView(global_map, port)` starts a server (Foxglove: *Open connection* ->
`ws://localhost:PORT`; the layout `docs/foxglove_layout.json` arranges the panels) and
`update(stamp_ns, result, local_map, T_odom_sensor)` publishes one answer:

- `/semloc/map` (`foxglove.SceneUpdate`, frame `map`): the map's objects as label-coloured
  boxes with their labels; sent again to each viewer that subscribes;
- `/semloc/local` (`SceneUpdate`): the local objects placed by the best hypothesis (green
  when `localized`, orange when not) and a line from each matched one to its map partner;
- `/semloc/hypotheses` (`SceneUpdate`): where each of the best hypotheses puts the local
  frame's origin, with its rank and confidence;
- `/semloc/pose` (`foxglove.PoseInFrame`, frame `map`): the sensor's pose when `localized`;
- `/tf` (`foxglove.FrameTransform`): `map` -> `odom` when `localized`;
- `/semloc/status` (`foxglove.Log`): status, confidence and reason of each answer.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from semloc.maps import ObjectMap
from semloc.pictures.colors import label_colors, rgb
from semloc.results import Result

STATUS_RGB = {"localized": (0.1, 0.8, 0.2), "ambiguous": (1.0, 0.7, 0.0), "failed": (0.9, 0.1, 0.1)}
HYPOTHESES = 5


def _quaternion(R: np.ndarray) -> tuple[float, float, float, float]:
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return float(x), float(y), float(z), float(w)


class FoxgloveView:
    """The live view of one localization (see the module docstring)."""

    def __init__(self, global_map: ObjectMap, port: int = 8765, host: str = "127.0.0.1",
                 map_frame: str = "map", odom_frame: str = "odom") -> None:  # fmt: skip
        import foxglove
        from foxglove.channels import (
            FrameTransformChannel,
            LogChannel,
            PoseInFrameChannel,
            SceneUpdateChannel,
        )

        # a viewer that goes away is not an error of the run (the SDK logs it as one)
        logging.getLogger("foxglove.websocket").setLevel(logging.CRITICAL)
        self.m = foxglove.messages
        self.global_map, self.map_frame, self.odom_frame = global_map, map_frame, odom_frame
        self.colors = {k: rgb(v) for k, v in label_colors(global_map.labels).items()}
        self.context = foxglove.Context()
        view = self

        class Listener(foxglove.ServerListener):
            def on_subscribe(self, client: Any, channel: Any) -> None:
                if channel.topic == "/semloc/map":
                    view.publish_map()

        channel = {"context": self.context}
        self.map_channel = SceneUpdateChannel("/semloc/map", **channel)
        self.local_channel = SceneUpdateChannel("/semloc/local", **channel)
        self.hypotheses_channel = SceneUpdateChannel("/semloc/hypotheses", **channel)
        self.pose_channel = PoseInFrameChannel("/semloc/pose", **channel)
        self.tf_channel = FrameTransformChannel("/tf", **channel)
        self.status_channel = LogChannel("/semloc/status", **channel)
        self.server = foxglove.start_server(name="semloc", host=host, port=port,
                                            context=self.context, server_listener=Listener())  # fmt: skip
        self.port = self.server.port

    def close(self) -> None:
        self.server.stop()

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
        """The map's objects (once per viewer that subscribes)."""
        m, entities = self.m, []
        for obj in self.global_map:
            T = np.eye(4)
            T[:3, 3] = obj.position
            if obj.rotation is not None:
                T[:3, :3] = obj.rotation
            size = obj.size if obj.size is not None else np.full(3, 0.2)
            colour = tuple(c / 255 for c in self.colors.get(obj.label, (128, 128, 128)))
            label = self._at(obj.position + [0.0, 0.0, float(size[2]) / 2 + 0.15])
            entities.append(m.SceneEntity(
                frame_id=self.map_frame, id=f"map/{obj.id}",
                cubes=[m.CubePrimitive(pose=self._pose(T), size=m.Vector3(
                    x=float(size[0]), y=float(size[1]), z=float(size[2])),
                    color=self._color(colour, 0.45))],
                texts=[m.TextPrimitive(pose=label, billboard=True, font_size=12.0,
                                       scale_invariant=True, color=self._color((1, 1, 1), 0.9),
                                       text=obj.label)],
            ))  # fmt: skip
        self.map_channel.log(m.SceneUpdate(entities=entities))

    def update(self, stamp_ns: int, result: Result, local_map: ObjectMap,
               T_odom_sensor: np.ndarray | None = None) -> None:  # fmt: skip
        """Publish one answer (see the module docstring)."""
        m = self.m
        best = result.best
        colour = self._color(STATUS_RGB[result.status], 1.0)
        entities = [m.SceneEntity(frame_id=self.map_frame, id="local")]
        if best is not None and best.pose is not None:
            placed = {o.id: best.pose[:3, :3] @ o.position + best.pose[:3, 3] for o in local_map}
            spheres = [m.SpherePrimitive(pose=self._at(p), size=m.Vector3(x=0.15, y=0.15, z=0.15),
                                         color=colour) for p in placed.values()]  # fmt: skip
            where = {o.id: o.position for o in self.global_map}
            points = [m.Point3(x=float(v[0]), y=float(v[1]), z=float(v[2]))
                      for g, l in best.pairs if g in where and l in placed
                      for v in (where[g], placed[l])]  # fmt: skip
            lines = [m.LinePrimitive(type=m.LinePrimitiveLineType.LineList, thickness=0.02,
                                     points=points, color=colour)] if points else []  # fmt: skip
            entities = [m.SceneEntity(frame_id=self.map_frame, id="local", spheres=spheres,
                                      lines=lines)]  # fmt: skip
        self.local_channel.log(m.SceneUpdate(entities=entities))
        marks = []
        for h in result.hypotheses[:HYPOTHESES]:
            if h.pose is None:
                continue
            conf = "" if h.confidence is None else f" {h.confidence:.2f}"
            marks.append(m.SceneEntity(
                frame_id=self.map_frame, id=f"hypothesis/{h.rank}",
                spheres=[m.SpherePrimitive(pose=self._at(h.pose[:3, 3]), size=m.Vector3(
                    x=0.3, y=0.3, z=0.3), color=self._color((0.3, 0.5, 1.0), 0.8))],
                texts=[m.TextPrimitive(pose=self._at(h.pose[:3, 3] + [0, 0, 0.4]), billboard=True,
                                       font_size=14.0, scale_invariant=True,
                                       color=self._color((1, 1, 1), 1.0), text=f"#{h.rank}{conf}")],
            ))  # fmt: skip
        deletions = [m.SceneEntityDeletion(type=m.SceneEntityDeletionType.All)]
        self.hypotheses_channel.log(m.SceneUpdate(deletions=deletions, entities=marks))
        if result.pose_is_answer:
            T_odom_sensor = np.eye(4) if T_odom_sensor is None else T_odom_sensor
            self.pose_channel.log(m.PoseInFrame(frame_id=self.map_frame,
                                                pose=self._pose(result.pose @ T_odom_sensor)))  # fmt: skip
            x, y, z, w = _quaternion(result.pose[:3, :3])
            t = result.pose[:3, 3]
            self.tf_channel.log(m.FrameTransform(
                parent_frame_id=self.map_frame, child_frame_id=self.odom_frame,
                translation=m.Vector3(x=float(t[0]), y=float(t[1]), z=float(t[2])),
                rotation=m.Quaternion(x=x, y=y, z=z, w=w)))  # fmt: skip
        conf = "" if result.confidence is None else f" {result.confidence:.2f}"
        level = m.LogLevel.Info if result.status == "localized" else m.LogLevel.Warning
        self.status_channel.log(m.Log(level=level, name="semloc",
                                      message=f"{result.status}{conf} {result.reason}".rstrip()))  # fmt: skip
