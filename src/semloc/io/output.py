"""Atomic output: files written all or none, and sets of files moved into a folder all or none.

`write_files` writes each regular file to a temporary file beside it and renames them into
place only when all are written (SIGINT and SIGTERM held during the renames); `staged_folder`
builds a set of files in a temporary folder beside its target and moves them in at the end.
On an error or an interrupt nothing half-written is left.
"""

from __future__ import annotations

import os
import secrets
import shutil
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from semloc.io.interrupts import signals_held
from semloc.maps import MapError


def write_atomic(path: str | os.PathLike[str], data: bytes | str) -> Path:
    """Write `data` to `path` atomically (`write_files` with one file); returns the path."""
    write_files([(Path(path), data)])
    return Path(path)


def write_files(files: list[tuple[Path, bytes | str]]) -> list[Path]:
    """Write several files all or none; the last one should be the index that names the others.

    Each regular file is written to a temporary file in its own folder (mode 0666 less the
    umask, like a plain write); only when all are written are they renamed into place, in order,
    with SIGINT and SIGTERM held.  A target that exists and is not a regular file (`/dev/full`,
    `/dev/stdout`, a FIFO) is written as a stream, never renamed over, before the renames: a
    stream that fails leaves the regular files as they were.  The folders must exist.
    `MapError` naming the file on any problem.
    """
    staged: list[tuple[str, Path]] = []
    streams: list[tuple[Path, bytes]] = []
    try:
        for path, data in files:
            path = Path(path)
            payload = data.encode() if isinstance(data, str) else data
            if _is_stream(path):
                streams.append((path, payload))
                continue
            # named and listed for clean-up before it exists: an interrupt at any moment
            # (signal masks hold only this thread) leaves nothing behind
            tmp = _temporary_name(path, ".tmp")
            staged.append((tmp, path))
            _write_new(tmp, path, payload)
        for path, payload in streams:
            _write_stream(path, payload)
        with signals_held():
            while staged:
                tmp, path = staged[0]
                try:
                    os.replace(tmp, path)
                except OSError as exc:
                    raise MapError(f"{path}: cannot write ({exc.strerror or exc})") from None
                staged.pop(0)
    finally:
        for tmp, _ in staged:
            if os.path.exists(tmp):
                os.unlink(tmp)
    return [Path(path) for path, _ in files]


def _write_stream(path: Path, payload: bytes) -> None:
    try:
        with open(path, "wb") as handle:
            handle.write(payload)
    except OSError as exc:
        raise MapError(f"{path}: cannot write ({exc.strerror or exc})") from None


def _is_stream(path: Path) -> bool:
    """Whether `path` is an existing non-regular file; `MapError` for a folder or no folder."""
    try:
        info = path.stat()
    except FileNotFoundError:
        if not path.parent.is_dir():
            raise MapError(f"{path}: folder {path.parent} does not exist") from None
        return False
    except OSError as exc:
        raise MapError(f"{path}: cannot write ({exc.strerror or exc})") from None
    if stat.S_ISDIR(info.st_mode):
        raise MapError(f"{path}: is a folder, not a file")
    return not stat.S_ISREG(info.st_mode)


def _temporary_name(path: Path, suffix: str) -> str:
    """A name for a new temporary file or folder beside `path` (hidden, random)."""
    return str(path.parent / f".{path.name[:100]}.{secrets.token_hex(6)}{suffix}")


def _write_new(tmp: str, path: Path, payload: bytes) -> None:
    """Create `tmp` (mode 0666 less the umask, like a plain write) with `payload`, on disk when
    it returns; `MapError` naming `path` on a problem."""
    try:
        handle = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        with os.fdopen(handle, "wb") as stream:
            stream.write(payload)
            stream.flush()
            os.fsync(stream.fileno())
    except OSError as exc:
        raise MapError(f"{path}: cannot write ({exc.strerror or exc})") from None


@contextmanager
def staged_folder(out: str | os.PathLike[str], index: str | None = None) -> Iterator[Path]:
    """A temporary folder beside `out` to write a set of files into, moved into `out` at the end.

    When the block ends normally, a missing `out` is the staged folder renamed (one atomic
    step); into an existing `out` the files move one by one with SIGINT/SIGTERM held, the file
    named `index` last.  On an error or an interrupt the staged folder is removed and `out` is
    left as it was: all files or none.  Missing parent folders of `out` are created.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise MapError(f"{out}: exists and is not a folder")
    stage = Path(_temporary_name(out, ".partial"))  # named before it exists (see write_files)
    try:
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
            os.mkdir(stage, 0o777)  # less the umask, like a plain folder
        except OSError as exc:
            raise MapError(f"{out}: cannot create the folder ({exc.strerror or exc})") from None
        yield stage
        with signals_held():
            _move_into(stage, out, index)
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def _move_into(stage: Path, out: Path, index: str | None) -> None:
    try:
        if not out.exists():
            os.rename(stage, out)
            return
        files = sorted(p for p in stage.rglob("*") if not p.is_dir())
        files.sort(key=lambda p: p.relative_to(stage).as_posix() == index)
        for source in files:
            target = out / source.relative_to(stage)
            target.parent.mkdir(parents=True, exist_ok=True)
            os.replace(source, target)
    except OSError as exc:
        raise MapError(
            f"{out}: cannot move the results into place ({exc.strerror or exc})"
        ) from None
