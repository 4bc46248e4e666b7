"""Playing a recorded bag onto the DDS wire, as `ros2 bag play` would, without ROS.

`play(bag, wire)` publishes every message of the bag's topics whose type semloc knows
(`semloc.ros.messages.typestore()`: ROS 2 Humble and vision_msgs 4) on `rt/<topic>` with ROS 2
type names, in log-time order, at the recorded pace times `rate` (0: as fast as possible),
reliable with a deep history, so a subscriber that keeps up loses nothing.  Topics of other
types are left out and counted.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from semloc.ros import messages as msgs
from semloc.ros.bag import opened
from semloc.ros2.node import Wire


def play(
    bag: Path,
    wire: Wire,
    rate: float = 1.0,
    stop: Callable[[], bool] = lambda: False,
    wait_for_readers_s: float = 2.0,
    published: Callable[[str, int], None] | None = None,
) -> dict[str, int]:
    """Publish the bag's messages (see the module docstring); messages published per topic.
    `published(topic, log_time)` is called after each message is written."""
    counts: dict[str, int] = {}
    with opened(bag) as reader:
        connections = [c for c in reader.connections if msgs.known(c.msgtype)]
        skipped = {c.topic for c in reader.connections} - {c.topic for c in connections}
        for topic in sorted(skipped):
            counts[f"{topic} (type not known, left out)"] = 0
        writers = {c.topic: wire.writer(c.topic, c.msgtype) for c in connections}
        _wait_for_readers(list(writers.values()), wait_for_readers_s)
        first_log, started = None, time.monotonic()
        for connection, log_time, raw in reader.messages(connections=connections):
            if stop():
                break
            if first_log is None:
                first_log = log_time
            if rate > 0:
                due = started + (log_time - first_log) / 1e9 / rate
                time.sleep(max(0.0, due - time.monotonic()))
            message = msgs.deserialize(raw, connection.msgtype)
            wire.publish(connection.topic, connection.msgtype, message)
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
            if published is not None:
                published(connection.topic, log_time)
    return counts


def _wait_for_readers(writers: list, seconds: float) -> None:
    """Give subscribers that are starting up a moment to be discovered (volatile topics send
    nothing to a reader that joins later)."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if all(w.get_matched_subscriptions() for w in writers):
            return
        time.sleep(0.01)
