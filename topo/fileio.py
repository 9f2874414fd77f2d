"""File writing shared by every package: atomic writes (write to a temporary file in the target's
folder, flush and fsync it, then rename it into place — a file exists whole or not at all), JSON,
JSON lines and whole folders written that way, JSON lines read back, and an exclusive lock file
(one writer of a folder at a time)."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import socket
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, BinaryIO

TEMP_PREFIX = ".tmp-"
"""Name prefix of the temporary files (readers of a folder skip them)."""


def atomic_write(path: str | Path, write: Callable[[BinaryIO], object]) -> Path:
    """Create ``path``'s folder, call ``write(binary file handle)`` on a temporary file beside
    it and rename that onto ``path``; on any error the temporary file is removed. Returns the
    path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=TEMP_PREFIX, suffix=path.suffix, dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            os.fchmod(fh.fileno(), 0o644)  # mkstemp's 0600 would make outputs private
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (:func:`atomic_write`)."""
    return atomic_write(path, lambda fh: fh.write(data))


def atomic_write_json(path: str | Path, obj: Any, *, allow_nan: bool = True) -> Path:
    """JSON-encode ``obj`` (indented, sorted keys) and write it atomically; returns the path.
    ``allow_nan=False`` refuses NaN/inf (strict JSON) instead of writing ``NaN``."""
    text = json.dumps(obj, indent=2, sort_keys=True, allow_nan=allow_nan) + "\n"
    return atomic_write_bytes(path, text.encode())


def atomic_write_json_lines(path: str | Path, rows: Any, *, sort_keys: bool = False,
                           allow_nan: bool = True) -> Path:
    """Write ``rows`` (JSON-encodable objects) one per line, atomically; returns the path.
    Results files that grow a row at a time are rewritten whole this way, so a crash leaves
    the file as it was before or after, never half a line."""
    text = "".join(json.dumps(r, sort_keys=sort_keys, allow_nan=allow_nan) + "\n" for r in rows)
    return atomic_write_bytes(path, text.encode())


def read_json_lines(path: str | Path) -> list[Any]:
    """The rows of a JSON-lines file (blank lines skipped), or of a file holding one JSON list;
    ``[]`` when ``path`` does not exist (a results file not yet begun).

    Raises:
        json.JSONDecodeError: a line (or the list) is not JSON.
    """
    path = Path(path)
    if not path.exists():
        return []
    text = path.read_text()
    if text.lstrip().startswith("["):
        return json.loads(text)
    return [json.loads(line) for line in text.splitlines() if line.strip()]


def atomic_write_dir(path: str | Path, write: Callable[[Path], object]) -> Path:
    """Create ``path``'s parent, call ``write(folder)`` on an empty temporary folder beside
    ``path`` and move it to ``path``, replacing a folder there (moved aside first, then
    removed); on any error the temporary folder is removed and ``path`` is left as it was.
    Returns the path. (Two renames: a reader can find no folder for an instant, never half
    of one.)"""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=TEMP_PREFIX, dir=path.parent))
    old = None
    try:
        write(tmp)
        if path.exists():
            old = path.parent / f"{TEMP_PREFIX}old-{path.name}-{os.getpid()}"
            os.replace(path, old)
        os.replace(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        if old is not None and not path.exists():
            os.replace(old, path)  # moved aside, not replaced: put it back
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
    return path


class LockHeld(RuntimeError):
    """:func:`exclusive_lock` found its lock file held by another process.

    Attributes:
        path: the lock file.
        holder: what the holder wrote into it (``pid``, ``host``, ``since``), or ``{}`` when it
            had not written it yet.
    """

    def __init__(self, path: Path, holder: dict[str, Any]) -> None:
        who = (f"pid {holder.get('pid')} on {holder.get('host')} since {holder.get('since')}"
               if holder else "a process that is just taking it")
        super().__init__(f"{path} is held by {who}")
        self.path = path
        self.holder = holder


def _read_holder(fd: int) -> dict[str, Any]:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        data = json.loads(os.read(fd, 4096).decode() or "{}")
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


@contextlib.contextmanager
def exclusive_lock(path: str | Path) -> Iterator[Path]:
    """Hold an exclusive lock on the file ``path`` for the ``with`` block, or raise
    :class:`LockHeld` at once (never waits).

    The lock is the kernel's ``flock`` on the file, which the holder writes its pid, host and
    start time into; the file is removed on exit. A holder that dies (even ``kill -9``) releases
    the lock with it, so a left-over file is taken over, not a stale lock. POSIX only (``fcntl``);
    on file systems whose ``flock`` does not work across machines only writers on the same
    machine are excluded.

    Raises:
        LockHeld: another open file description holds the lock (another process, or this one).
    """
    import fcntl

    path = Path(path)
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_holder(fd)
            os.close(fd)
            raise LockHeld(path, holder) from None
        mine = os.fstat(fd)
        try:
            now = os.stat(path)
            same = (now.st_ino, now.st_dev) == (mine.st_ino, mine.st_dev)
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)  # the previous holder removed this file as we opened it: lock the new one
    try:
        os.ftruncate(fd, 0)
        holder = {"pid": os.getpid(), "host": socket.gethostname(),
                  "since": time.strftime("%Y-%m-%d %H:%M:%S")}
        os.write(fd, json.dumps(holder).encode())
        yield path
    finally:
        path.unlink(missing_ok=True)  # while still locked: a waiter that opened it retries
        os.close(fd)
