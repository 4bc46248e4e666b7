"""Writing MCAP files of ROS 2 messages (CDR, ros2msg schemas) in memory, for atomic output.

`McapSink` collects messages topic by topic (each topic registered with its schema on first
use) into an in-memory MCAP file with the `ros2` profile that Foxglove and rosbags read
without configuration; `getvalue()` finishes it and returns the bytes, which the caller writes
in one atomic step (`semloc.io.write_atomic`), so a failed or interrupted run leaves nothing.
"""

from __future__ import annotations

import io
from typing import Any

from semloc.ros.messages import schema_text, serialize


class McapSink:
    """An MCAP file being built in memory (see the module docstring)."""

    def __init__(self) -> None:
        from mcap.writer import CompressionType, Writer

        self._buffer = io.BytesIO()
        self._writer = Writer(self._buffer, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library="semloc")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, str]] = {}
        self.counts: dict[str, int] = {}

    def write(self, topic: str, typename: str, stamp_ns: int, message: Any) -> None:
        """Add `message` of `typename` on `topic`, logged at `stamp_ns`."""
        channel = self._channel(topic, typename)
        data = serialize(message, typename)
        self._writer.add_message(channel, log_time=stamp_ns, data=data, publish_time=stamp_ns)
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def _channel(self, topic: str, typename: str) -> int:
        if topic in self._channels:
            channel, known = self._channels[topic]
            if known != typename:
                raise ValueError(f"topic {topic} carries {known}, not {typename}")
            return channel
        if typename not in self._schemas:
            text = schema_text(typename).encode()
            self._schemas[typename] = self._writer.register_schema(typename, "ros2msg", text)
        channel = self._writer.register_channel(topic, "cdr", self._schemas[typename])
        self._channels[topic] = (channel, typename)
        return channel

    def getvalue(self) -> bytes:
        """The finished file (call once, after the last message)."""
        self._writer.finish()
        return self._buffer.getvalue()
