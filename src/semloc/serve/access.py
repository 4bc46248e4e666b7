"""Who may do what: the token file, rights per map, and the request rates.

The token file (JSON, or YAML for .yaml/.yml):

    {"tokens": [{"token": "s3cret", "maps": {"office": ["read", "localize"], "*": ["read"]}},
                {"sha256": "<hex digest of a token>", "maps": {"*": ["read", "localize", "write"]}}]}

Only SHA-256 digests are kept in memory.  Rights: `read` (maps, versions, the page),
`localize` (one-shot localization and sessions), `write` (uploads and change reports).  The
entries of one token for a map and for `*` add up.  A token without any right on a map does
not see it (the service answers 404, as for a map that does not exist); a token that sees a
map but lacks the right gets 403; no token or an unknown one gets 401.

`Gate.admit(token, address)` says who asks, within their rate: a known token's requests count
against its own bucket; a failed login (no token, or an unknown one) counts against the bucket
of failed logins of the address it came from, so that guessing tokens goes no faster than the
rate, and a device with a valid token behind the same address is not held up by it.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import yaml

RIGHTS = ("read", "localize", "write")
ANY_MAP = "*"


class TokenFileError(ValueError):
    """The token file cannot be used (the message names the file and the problem)."""


def digest(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


@dataclass(frozen=True)
class Grant:
    """The rights of one token: map id (or `*`) -> rights."""

    name: str  # a short, non-secret name for logs and rate limits (the digest's first digits)
    maps: dict[str, frozenset[str]]

    def rights(self, map_id: str) -> frozenset[str]:
        return self.maps.get(map_id, frozenset()) | self.maps.get(ANY_MAP, frozenset())

    def sees(self, map_id: str) -> bool:
        return bool(self.rights(map_id))


class Access:
    """The grants of a token file; `Access.open()` lets everyone do everything (loopback use)."""

    def __init__(self, grants: dict[str, Grant] | None) -> None:
        self._grants = grants  # digest -> grant; None: no tokens needed

    @classmethod
    def open(cls) -> Access:
        return cls(None)

    @property
    def required(self) -> bool:
        return self._grants is not None

    def grant(self, token: str | None) -> Grant | None:
        """The grant of `token` (None if unknown or missing); everyone's without a token file."""
        if self._grants is None:
            return Grant("anyone", {ANY_MAP: frozenset(RIGHTS)})
        if not token:
            return None
        wanted = digest(token)
        for known, grant in self._grants.items():
            if hmac.compare_digest(known, wanted):
                return grant
        return None

    @classmethod
    def from_file(cls, path: str | Path) -> Access:
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise TokenFileError(f"{path}: cannot read the token file ({exc})") from None
        try:
            data = (
                yaml.safe_load(text)
                if path.suffix.lower() in (".yaml", ".yml")
                else json.loads(text)
            )
        except (ValueError, yaml.YAMLError) as exc:
            raise TokenFileError(f"{path}: not valid JSON/YAML ({str(exc)[:80]})") from None
        return cls(_grants(path, data))


def _grants(path: Path, data: object) -> dict[str, Grant]:
    if not isinstance(data, dict) or not isinstance(data.get("tokens"), list):
        raise TokenFileError(f'{path}: must hold {{"tokens": [...]}}')
    grants: dict[str, Grant] = {}
    for i, entry in enumerate(data["tokens"]):
        where = f"{path}: tokens[{i}]"
        if not isinstance(entry, dict):
            raise TokenFileError(f"{where} must be an object")
        token, hashed = entry.get("token"), entry.get("sha256")
        if (token is None) == (hashed is None):
            raise TokenFileError(f"{where} needs exactly one of 'token' and 'sha256'")
        if token is not None and (not isinstance(token, str) or len(token) < 8):
            raise TokenFileError(f"{where}: 'token' must be a string of at least 8 characters")
        if hashed is not None and (
            not isinstance(hashed, str)
            or len(hashed) != 64
            or any(c not in "0123456789abcdef" for c in hashed.lower())
        ):
            raise TokenFileError(f"{where}: 'sha256' must be 64 hexadecimal digits")
        key = digest(token) if token is not None else hashed.lower()
        if key in grants:
            raise TokenFileError(f"{where}: the same token occurs twice")
        grants[key] = Grant(key[:8], _maps(where, entry.get("maps")))
    return grants


def _maps(where: str, maps: object) -> dict[str, frozenset[str]]:
    if not isinstance(maps, dict) or not maps:
        raise TokenFileError(f"{where}: 'maps' must be an object of map id -> rights")
    out = {}
    for map_id, rights in maps.items():
        if not isinstance(rights, list) or not all(r in RIGHTS for r in rights):
            raise TokenFileError(
                f"{where}: rights of {map_id!r} must be a list of {', '.join(RIGHTS)}"
            )
        out[str(map_id)] = frozenset(rights)
    return out


class RateLimiter:
    """A token bucket per client: `rate` requests a second on average, bursts of `burst`."""

    def __init__(self, rate: float, burst: float | None = None) -> None:
        self.rate = rate
        self.burst = burst if burst is not None else max(1.0, 2 * rate)
        self._buckets: dict[str, tuple[float, float]] = {}  # client -> (level, when)
        self._lock = threading.Lock()

    def allow(self, client: str) -> bool:
        if self.rate <= 0:
            return True
        now = time.monotonic()
        with self._lock:
            level, when = self._buckets.get(client, (self.burst, now))
            level = min(self.burst, level + (now - when) * self.rate)
            allowed = level >= 1.0
            self._buckets[client] = (level - 1.0 if allowed else level, now)
            if len(self._buckets) > 100_000:  # forget full buckets (idle clients)
                self._buckets = {k: v for k, v in self._buckets.items() if v[0] < self.burst}
            return allowed


class Refused(Exception):
    """A request refused before its rights are looked at: `reason` is "unauthorized" (no token
    or an unknown one) or "too many requests" (past the rate); the web layer picks the
    status."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason, self.detail = reason, detail


class Gate:
    """Who asks, within their rate: `rate` requests a second per token (per address without
    token file), and as many failed logins a second per address (0: no limits)."""

    def __init__(self, access: Access, rate: float) -> None:
        self.access, self.rate = access, rate
        self._requests = RateLimiter(rate)
        self._failures = RateLimiter(rate)

    def admit(self, token: str | None, address: str) -> Grant:
        """The grant of `token`; `Refused` without a valid one or past the rate."""
        grant = self.access.grant(token)
        if grant is None:
            if not self._failures.allow(address):
                raise Refused("too many requests",
                              f"more than {self.rate:g} failed logins a second from {address}")  # fmt: skip
            raise Refused("unauthorized", "a valid token is needed (Authorization: Bearer)")
        client = grant.name if self.access.required else address
        if not self._requests.allow(client):
            raise Refused("too many requests", f"more than {self.rate:g} requests a second")
        return grant
