"""An exclusive lock on a sweep's output directory, held while a sweep writes into it.

The lock is the file ``DIR/_sweep.lock``, holding the owner's pid, host, start time and a unique
token as JSON. On POSIX the exclusion itself is an advisory ``flock`` on that file, which the
kernel drops when the owner dies however it dies (SIGKILL included): a lock file nobody holds is
stale and is simply taken over. Where ``flock`` is unavailable (Windows, some network file
systems) the file is created exclusively, and a lock whose pid no longer runs on this host is stale
and taken over.

Temporary files carry the owner's host, pid and token in their names (:func:`tmp_name`), so that
clean-up removes only one's own debris or that of a dead owner (:func:`is_dead_debris`).
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import time
import uuid
from pathlib import Path
from typing import Any

from ..errors import SweepError

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

__all__ = ["DirLock", "LOCK_NAME", "pid_alive", "tmp_name", "is_dead_debris"]

LOCK_NAME = "_sweep.lock"
_HOST = socket.gethostname().replace("-", "_") or "host"


def pid_alive(pid: int) -> bool:
    """Whether a process ``pid`` runs on this host (a process of another user counts)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OSError:
        return False
    return True


def tmp_name(prefix: str, token: str, suffix: str) -> str:
    """``{prefix}{host}-{pid}-{token}{suffix}``: a temporary file of this process."""
    return f"{prefix}{_HOST}-{os.getpid()}-{token}{suffix}"


def is_dead_debris(name: str, prefix: str, own_token: str) -> bool:
    """Whether the temporary file ``name`` (made by :func:`tmp_name`) belongs to this process's
    ``own_token`` or to a process of this host that no longer runs. Names of other hosts, and
    names that do not parse, are left alone."""
    rest = name[len(prefix) :]
    parts = rest.split("-", 3)
    if len(parts) < 3:
        return False
    host, pid_s, token = parts[0], parts[1], parts[2]
    if token.startswith(own_token) and own_token:
        return True
    if host != _HOST or not pid_s.isdigit():
        return False
    return not pid_alive(int(pid_s))


class _NoFlock(Exception):
    """``flock`` is not supported where the directory lives."""


class DirLock:
    """``with DirLock(dir):`` — exclusive use of ``dir`` by this process, or a
    :class:`~capalloc_rs.errors.SweepError` naming the running owner (pid, host, start time)."""

    def __init__(self, directory: Path) -> None:
        self.path = directory / LOCK_NAME
        self.token = uuid.uuid4().hex[:12]
        self.took_over: dict[str, Any] | None = None  # the stale owner this lock replaced
        self._fd: int | None = None

    def _info(self) -> dict[str, Any]:
        return {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "token": self.token,
        }

    def _read(self, fd: int | None = None) -> dict[str, Any]:
        try:
            if fd is not None:
                os.lseek(fd, 0, os.SEEK_SET)
                raw = os.read(fd, 4096)
            else:
                raw = self.path.read_bytes()[:4096]
            d = json.loads(raw.decode("utf-8"))
            return d if isinstance(d, dict) else {}
        except (OSError, ValueError):
            return {}

    def _busy(self, owner: dict[str, Any]) -> SweepError:
        return SweepError(
            f"{self.path.parent} is in use by another sweep (pid {owner.get('pid', '?')} on "
            f"{owner.get('host', '?')}, started {owner.get('started', '?')}); wait for it to "
            f"finish or write to another directory (if no such sweep runs, delete {self.path})"
        )

    def acquire(self) -> None:
        if fcntl is not None:
            try:
                self._acquire_flock()
                return
            except _NoFlock:  # a file system without flock (some network mounts)
                pass
        self._acquire_excl()

    def _acquire_flock(self) -> None:
        for _ in range(100):
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:  # held by a running process
                owner = self._read(fd)
                os.close(fd)
                raise self._busy(owner) from None
            except OSError:
                if os.fstat(fd).st_size == 0:  # only we open-create it empty (see _acquire_excl)
                    with contextlib.suppress(OSError):
                        self.path.unlink()
                os.close(fd)
                raise _NoFlock from None
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except OSError:
                same = False
            if not same:  # the previous owner removed the file meanwhile: lock the new one
                os.close(fd)
                continue
            old = self._read(fd)
            if old:
                self.took_over = old
            os.ftruncate(fd, 0)
            os.lseek(fd, 0, os.SEEK_SET)
            os.write(fd, json.dumps(self._info()).encode())
            with contextlib.suppress(OSError):
                os.fsync(fd)
            self._fd = fd
            return
        raise SweepError(f"cannot lock {self.path}: it keeps being replaced")  # pragma: no cover

    def _acquire_excl(self) -> None:
        # The lock file appears with its content at once (a hard link of a written temporary
        # file; link fails if the name exists), so an empty lock file is never someone's lock.
        tmp = self.path.with_name(f".{LOCK_NAME}.{os.getpid()}.{self.token}")
        tmp.write_text(json.dumps(self._info()))
        try:
            for _ in range(100):
                try:
                    os.link(tmp, self.path)
                except FileExistsError:
                    owner = self._read()
                    pid = owner.get("pid")
                    if (
                        owner.get("host") == socket.gethostname()
                        and isinstance(pid, int)
                        and not pid_alive(pid)
                    ):
                        self.took_over = owner
                        with contextlib.suppress(OSError):
                            self.path.unlink()
                        continue
                    raise self._busy(owner) from None
                self._fd = os.open(self.path, os.O_RDONLY)
                return
            raise SweepError(f"cannot lock {self.path}")  # pragma: no cover
        finally:
            with contextlib.suppress(OSError):
                tmp.unlink()

    def release(self) -> None:
        if self._fd is None:
            return
        fd, self._fd = self._fd, None
        with contextlib.suppress(OSError):
            if self._read(fd).get("token") == self.token:
                self.path.unlink()  # before unlocking: a waiting process then re-opens a new file
        with contextlib.suppress(OSError):
            os.close(fd)  # drops the flock

    def __enter__(self) -> DirLock:
        self.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
