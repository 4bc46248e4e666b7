"""A server of Foxglove's WebSocket protocol (https://github.com/foxglove/ws-protocol, spec v1)
on the `websockets` library, for the live view (`semloc.pictures.live`).

It accepts both names of the protocol, `foxglove.websocket.v1` (Foxglove Studio 1.x,
Lichtblick, `@foxglove/ws-protocol`) and `foxglove.sdk.v1` (the Foxglove app and SDK, which
speak the same messages under the new name), and keeps the latest message of each channel: a
client that subscribes at any time receives it at once (stamped with the time it subscribed, so
that its clock does not go back), then every newer one.

`FoxgloveServer(host, port)` serves from a thread of its own; `add_channel(topic, schema_name,
schema, encoding)` advertises a channel (before or after clients connect); `publish(channel,
payload)` is safe from any thread.  A client that reads slower than the messages come gets the
newest of each subscription, never a growing queue.  No capabilities are advertised: clients
only subscribe and unsubscribe.
"""

from __future__ import annotations

import asyncio
import base64
import itertools
import json
import logging
import struct
import threading
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # websockets is imported when a server starts: importing this needs no extra
    from websockets.asyncio.server import Server, ServerConnection

SUBPROTOCOLS = ("foxglove.websocket.v1", "foxglove.sdk.v1")
"""The protocol's names, the older first: both are the same messages (spec v1)."""
MESSAGE_DATA = 0x01
"""The binary opcode of a message: opcode, u32 subscription id, u64 log time (ns), payload."""


@dataclass(frozen=True)
class Channel:
    """One advertised channel."""

    id: int
    topic: str
    schema_name: str
    schema: bytes
    encoding: str
    schema_encoding: str

    def advertised(self) -> dict[str, Any]:
        """The channel in an `advertise` message (a binary schema is base64, as the spec says)."""
        binary = self.schema_encoding in ("protobuf", "flatbuffer")
        schema = base64.b64encode(self.schema).decode() if binary else self.schema.decode()
        return {"id": self.id, "topic": self.topic, "encoding": self.encoding,
                "schemaName": self.schema_name, "schema": schema,
                "schemaEncoding": self.schema_encoding}  # fmt: skip


@dataclass(eq=False)
class Client:
    """One connection: its subscriptions and what waits to be sent to it (JSON messages in
    order, then the newest message of each subscription)."""

    connection: ServerConnection
    subscriptions: dict[int, int] = field(default_factory=dict)  # subscription id -> channel id
    texts: list[str] = field(default_factory=list)
    pending: dict[int, bytes] = field(default_factory=dict)  # subscription id -> frame
    ready: asyncio.Event = field(default_factory=asyncio.Event)

    def say(self, message: dict[str, Any]) -> None:
        """A JSON message, after those already waiting."""
        self.texts.append(json.dumps(message))
        self.ready.set()

    def queue(self, channel: int, log_time: int, payload: bytes) -> None:
        """The newest message of `channel`, for every subscription of it."""
        for sid, cid in self.subscriptions.items():
            if cid == channel:
                self.queue_one(sid, log_time, payload)

    def queue_one(self, sid: int, log_time: int, payload: bytes) -> None:
        """A message for subscription `sid` (last in line, replacing an older one not sent)."""
        self.pending.pop(sid, None)
        self.pending[sid] = struct.pack("<BIQ", MESSAGE_DATA, sid, log_time) + payload
        self.ready.set()

    async def send_all(self) -> None:
        """Send what waits, as it comes, until the connection closes."""
        from websockets.exceptions import ConnectionClosed

        try:
            while True:
                await self.ready.wait()
                self.ready.clear()
                while self.texts or self.pending:
                    if self.texts:
                        await self.connection.send(self.texts.pop(0))
                    else:
                        await self.connection.send(self.pending.pop(next(iter(self.pending))))
        except ConnectionClosed:
            pass


class FoxgloveServer:
    """A Foxglove WebSocket server on its own thread (see the module docstring)."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, name: str = "semloc") -> None:
        self.name, self.session = name, str(time.time_ns())
        self.channels: dict[int, Channel] = {}
        self.latest: dict[int, bytes] = {}
        self.clients: set[Client] = set()
        self._ids = itertools.count(1)
        self._loop = asyncio.new_event_loop()
        self._server: Server | None = None
        started = threading.Event()
        failure: list[BaseException] = []
        self._thread = threading.Thread(target=self._run, args=(host, port, started, failure),
                                        name="foxglove-server", daemon=True)  # fmt: skip
        self._thread.start()
        started.wait()
        if failure:
            raise failure[0]
        assert self._server is not None
        self.port: int = self._server.sockets[0].getsockname()[1]

    # the caller's side ------------------------------------------------------------------------
    def add_channel(self, topic: str, schema_name: str, schema: bytes, encoding: str = "protobuf",
                    schema_encoding: str | None = None) -> int:  # fmt: skip
        """Advertise a channel; returns its id."""
        channel = Channel(next(self._ids), topic, schema_name, schema, encoding,
                          schema_encoding or encoding)  # fmt: skip
        self._call(self._advertise, channel)
        return channel.id

    def publish(self, channel: int, payload: bytes, log_time: int | None = None) -> None:
        """Send `payload` on `channel` to its subscribers and keep it for later ones."""
        self._call(self._publish, channel, time.time_ns() if log_time is None else log_time,
                   payload)  # fmt: skip

    def close(self) -> None:
        """Stop serving and close every connection."""
        if self._thread.is_alive():
            asyncio.run_coroutine_threadsafe(self._stop(), self._loop).result(timeout=10)
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(timeout=10)

    def _call(self, function: Any, *args: Any) -> None:
        if self._loop.is_closed():
            raise RuntimeError("the Foxglove server is closed")
        self._loop.call_soon_threadsafe(function, *args)

    # the server's thread ----------------------------------------------------------------------
    def _run(self, host: str, port: int, started: threading.Event,
             failure: list[BaseException]) -> None:  # fmt: skip
        asyncio.set_event_loop(self._loop)
        try:
            self._server = self._loop.run_until_complete(self._start(host, port))
        except BaseException as exc:  # an address in use: the caller's error
            failure.append(exc)
            started.set()
            self._loop.close()
            return
        started.set()
        self._loop.run_forever()
        self._loop.close()

    async def _start(self, host: str, port: int) -> Server:
        from websockets.asyncio.server import serve

        return await serve(self._serve, host, port, subprotocols=list(SUBPROTOCOLS),
                           logger=logging.getLogger("semloc.foxglove"))  # fmt: skip

    async def _stop(self) -> None:
        assert self._server is not None
        self._server.close()
        await self._server.wait_closed()

    def _advertise(self, channel: Channel) -> None:
        self.channels[channel.id] = channel
        for client in self.clients:
            client.say({"op": "advertise", "channels": [channel.advertised()]})

    def _publish(self, channel: int, log_time: int, payload: bytes) -> None:
        self.latest[channel] = payload
        for client in self.clients:
            client.queue(channel, log_time, payload)

    async def _serve(self, connection: ServerConnection) -> None:
        from websockets.exceptions import ConnectionClosed

        client = Client(connection)
        client.say({"op": "serverInfo", "name": self.name, "capabilities": [],
                    "supportedEncodings": [], "metadata": {}, "sessionId": self.session})  # fmt: skip
        client.say(
            {"op": "advertise", "channels": [c.advertised() for c in self.channels.values()]}
        )
        self.clients.add(client)
        sender = asyncio.create_task(client.send_all())
        try:
            async for message in connection:
                if isinstance(message, str):
                    self._receive(client, message)
        except ConnectionClosed:
            pass
        finally:
            self.clients.discard(client)
            sender.cancel()

    def _receive(self, client: Client, text: str) -> None:
        """A client's JSON message: subscribe and unsubscribe; anything else is answered with a
        warning status."""
        try:
            message = json.loads(text)
            op = message["op"]
            if op == "subscribe":
                for sub in message["subscriptions"]:
                    self._subscribe(client, int(sub["id"]), int(sub["channelId"]))
            elif op == "unsubscribe":
                for sid in message["subscriptionIds"]:
                    client.subscriptions.pop(int(sid), None)
                    client.pending.pop(int(sid), None)
            else:
                self._status(client, 1, f"semloc's live view does not support '{op}'")
        except (ValueError, KeyError, TypeError) as exc:
            self._status(client, 2, f"malformed message: {exc!r}")

    def _subscribe(self, client: Client, sid: int, channel: int) -> None:
        if channel not in self.channels:
            self._status(client, 1, f"no channel {channel}")
            return
        client.subscriptions[sid] = channel
        if channel in self.latest:  # the latest message at once, stamped now: a viewer's clock
            client.queue_one(sid, time.time_ns(), self.latest[channel])  # never goes back

    @staticmethod
    def _status(client: Client, level: int, text: str) -> None:
        client.say({"op": "status", "level": level, "message": text})
