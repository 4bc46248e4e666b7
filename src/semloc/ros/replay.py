"""Replaying a recorded run through a `StreamLocalizer`: each detection message put into the
odometry frame, fused, localized; the answers with their stamps.

Frames: with odometry, a detection message in the odometry's moving (child) frame is placed by
the odometry pose at its stamp (interpolated; none within `MAX_GAP_S`: the message is skipped
and counted), one already in the odometry frame is used as it is, any other frame is a
`BagError`.  Without odometry every message must be in one frame, which is then the local
(odometry) frame.

With a camera-info topic, each update says what the camera covered (`semloc.ros.camera`):
negative evidence for the Localizer.

Pose estimates (the run's `--initialpose` topic) replay as the live node takes them: each sets
the prior on the odometry frame's origin (`semloc.ros.initialpose.estimate_prior`, with the
odometry at its stamp) from the first detection message recorded at or after it; one it cannot
use (another frame than `map_frame`, before any odometry, a bad covariance) is left out and
counted in `run.warnings`.  Each answer carries the prior in effect.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from semloc import schema
from semloc.priors import Prior
from semloc.results import Result
from semloc.ros.bag import MAX_GAP_S, BagError, Odometry, Run
from semloc.ros.camera import CameraError
from semloc.ros.initialpose import UnusableEstimate, estimate_prior
from semloc.ros.stream import DetectionFrame, StreamLocalizer

NO_ODOMETRY = f"detection messages without odometry within {MAX_GAP_S:g} s"


@dataclass(frozen=True)
class Answer:
    """One answer of a replay: the message's stamp (ns) and frame, the odometry frame, the pose
    of the message's frame in it, and the Localizer's result."""

    stamp: int
    frame: str
    odom_frame: str
    T_odom_sensor: np.ndarray
    result: Result
    prior: Prior | None = None
    """The prior in effect (on the odometry frame's origin), None: none."""


def replay(run: Run, stream: StreamLocalizer, map_frame: str = "map") -> Iterator[Answer]:
    """The answers of `run` (see the module docstring); `run.skipped` counts what was left out."""
    odometry = run.odometry()
    trajectory = None if odometry is None else odometry.trajectory
    camera = run.camera()
    estimates = run.estimates()
    applied = 0  # estimates applied so far
    fixed: str | None = None
    stamps: list[int] = []  # of the messages left out for want of odometry
    placed = 0
    for log_time, frame in run.timed_frames():
        while applied < len(estimates) and estimates[applied][0] <= log_time:
            try:
                prior = estimate_prior(estimates[applied][1], map_frame, trajectory)
                stream.localizer.set_prior(prior)
            except UnusableEstimate as exc:
                run.warnings[exc.why] = run.warnings.get(exc.why, 0) + 1
            applied += 1
        if odometry is None:
            fixed = fixed if fixed is not None else frame.frame
            if frame.frame != fixed:
                raise BagError(
                    f"{run.path}: detections change frame from '{fixed}' to '{frame.frame}'; "
                    "give --odom to connect them"
                )
            pose: np.ndarray | None = np.eye(4)
        else:
            pose = sensor_pose(run, frame, odometry)
        if pose is None:
            run.skipped[NO_ODOMETRY] = run.skipped.get(NO_ODOMETRY, 0) + 1
            stamps.append(frame.stamp)
            continue
        placed += 1
        coverage = None
        if camera is not None:
            try:
                coverage = camera.at(pose, frame.frame)
            except CameraError as exc:
                raise BagError(f"{run.path}: --camera-info: {exc}") from None
        result = stream.step(frame, pose, coverage)
        if result is not None:
            odom_frame = frame.frame if odometry is None else odometry.frame
            yield Answer(frame.stamp, frame.frame, odom_frame, pose, result,
                         stream.localizer.prior)  # fmt: skip
    if odometry is not None and stamps and not placed:
        known = odometry.trajectory.stamps
        raise BagError(
            f"{run.path}: no detection message has odometry within {MAX_GAP_S:g} s (detections "
            f"at {min(stamps) / 1e9:.1f}-{max(stamps) / 1e9:.1f} s, odometry at "
            f"{known[0] / 1e9:.1f}-{known[-1] / 1e9:.1f} s)"
        )


def sensor_pose(run: Run, frame: DetectionFrame, odometry: Odometry) -> np.ndarray | None:
    """The pose of the message's frame in the odometry frame at its stamp (None: no odometry
    near it); BagError for a frame the odometry does not give."""
    if frame.frame == odometry.frame:
        return np.eye(4)
    if frame.frame == odometry.child:
        return odometry.trajectory.at(frame.stamp)
    raise BagError(
        f"{run.path}: detections are in frame '{frame.frame}', the odometry gives "
        f"'{odometry.frame}' -> '{odometry.child}'; they must be in one of those frames"
    )


def answer_json(answer: Answer) -> dict[str, Any]:
    """One line of `--jsonl` (`schema.BagLine`): `{"stamp": seconds, "result": the localize
    JSON}`; its `steps` hold this update's step only (the earlier ones are on the lines
    before), its `prior` is the prior in effect (null: none)."""
    line = schema.BagLine(stamp=answer.stamp / 1e9, result=answer.result.to_model(last_steps=1))
    return line.model_dump(by_alias=True)
