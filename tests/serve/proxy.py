"""A small HTTP/1.1 proxy for tests: forwards each request to a server and can drop the answer
of chosen requests on the way back (the request was served, the client sees the connection
close), and strip a base path, as a reverse proxy in front of the service would."""

from __future__ import annotations

import http.client
import socket
import threading
import urllib.parse
from collections.abc import Callable


class DroppingProxy:
    """Forwards to `target` (http://host:port); the answer to a request for which
    `drop(method, path)` is true is dropped, `times` times in all.  A request path starting
    with `prefix` is forwarded without it."""

    def __init__(
        self,
        target: str,
        drop: Callable[[str, str], bool] = lambda method, path: False,
        times: int = 1,
        prefix: str = "",
    ) -> None:
        parts = urllib.parse.urlsplit(target)
        self.target = (parts.hostname, parts.port)
        self.drop, self.left, self.prefix = drop, times, prefix
        self.dropped: list[str] = []
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.url = f"http://127.0.0.1:{self.listener.getsockname()[1]}{prefix}"
        self._lock = threading.Lock()
        threading.Thread(target=self._accept, daemon=True).start()

    def close(self) -> None:
        self.listener.close()

    def _accept(self) -> None:
        while True:
            try:
                client, _ = self.listener.accept()
            except OSError:
                return
            threading.Thread(target=self._serve, args=(client,), daemon=True).start()

    def _serve(self, client: socket.socket) -> None:
        upstream = http.client.HTTPConnection(*self.target, timeout=120)
        reader = client.makefile("rb")
        try:
            self._exchange(client, reader, upstream)
        except OSError:
            pass
        finally:
            reader.close()
            client.close()
            upstream.close()

    def _exchange(self, client: socket.socket, reader, upstream) -> None:
        """Requests of one client connection, until it closes or an answer is dropped."""
        while True:
            request = _read_request(reader)
            if request is None:
                return
            method, path, headers, body = request
            if self.prefix and path.startswith(self.prefix):
                path = path[len(self.prefix) :] or "/"
            upstream.request(method, path, body, headers)
            answer = upstream.getresponse()
            data = answer.read()
            with self._lock:
                dropping = self.left > 0 and self.drop(method, path)
                if dropping:
                    self.left -= 1
                    self.dropped.append(f"{method} {path} {answer.status}")
            if dropping:
                return  # served, but the answer never reaches the client
            head = [f"HTTP/1.1 {answer.status} {answer.reason}"]
            head += [f"{k}: {v}" for k, v in answer.getheaders()
                     if k.lower() not in ("content-length", "transfer-encoding")]  # fmt: skip
            head.append(f"Content-Length: {len(data)}")
            client.sendall(("\r\n".join(head) + "\r\n\r\n").encode("latin-1") + data)


def _read_request(reader) -> tuple[str, str, dict[str, str], bytes] | None:
    line = reader.readline()
    if not line.strip():
        return None
    method, path, _ = line.decode("latin-1").split(" ", 2)
    headers: dict[str, str] = {}
    while (header := reader.readline()) not in (b"\r\n", b"\n", b""):
        name, _, value = header.decode("latin-1").partition(":")
        headers[name.strip()] = value.strip()
    length = int(headers.get("Content-Length", "0"))
    return method, path, headers, reader.read(length) if length else b""
