"""One recorder per recording path: an advisory lock held while it records.

Two recorders given one path (two sim_nodes on a host with the same
``record_path``) would write over each other's files, and with overwrite the
second would delete the first's bag under it. :class:`PathClaim` takes an
exclusive ``flock`` on a lock file named after the path's absolute form, in
the temporary directory (not beside the bag: a killed recorder must leave
nothing there but the bag), before anything is touched, and keeps it until
the recording is closed; a second recorder on the same host is refused with
the first one's description (process ID and command line), read from the
lock file. The kernel drops the lock when its process dies, so a crashed
recorder never blocks the next one. Where ``fcntl`` is missing (Windows)
there is no claim.
"""
from __future__ import annotations

import hashlib
import os
import sys
import tempfile
from pathlib import Path
from typing import Optional

try:
    import fcntl
except ImportError:  # pragma: no cover - not on POSIX
    fcntl = None

__all__ = ["PathClaim", "RecordingInUse", "describe_this_process", "lock_path_of"]

#: how much of the holder's description is kept (a command line can be long)
_MAX_DESCRIPTION = 300


class RecordingInUse(RuntimeError):
    """Another live recorder holds the path; ``holder`` says which process."""

    def __init__(self, path: Path, holder: str) -> None:
        super().__init__(f"{path} is being recorded by {holder}")
        self.path, self.holder = Path(path), holder


def describe_this_process() -> str:
    """``pid N (command line)``: what a refused recorder is told about the holder."""
    command = " ".join(sys.argv) if sys.argv and sys.argv[0] else sys.executable
    return f"pid {os.getpid()} ({command})"[:_MAX_DESCRIPTION]


def lock_path_of(path: Path) -> Path:
    """The lock file of a recording path: one per absolute path (links resolved), per user."""
    absolute = os.path.realpath(os.path.abspath(path))
    digest = hashlib.sha256(absolute.encode("utf-8", "surrogateescape")).hexdigest()[:32]
    user = getattr(os, "getuid", lambda: "user")()
    return Path(tempfile.gettempdir()) / f"vmas_ros_recording_locks_{user}" / f"{digest}.lock"


class PathClaim:
    """Hold ``<path>.lock`` exclusively until :meth:`release`; raises :class:`RecordingInUse` if held."""

    def __init__(self, path: Path, holder: Optional[str] = None) -> None:
        self.lock_path = lock_path_of(path)
        self._fd: Optional[int] = None
        if fcntl is None:
            return
        self.lock_path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        fd = os.open(self.lock_path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            other = os.read(fd, 4 * _MAX_DESCRIPTION).decode("utf-8", "replace").strip()
            os.close(fd)
            raise RecordingInUse(Path(path), other or "another process") from None
        os.ftruncate(fd, 0)
        os.write(fd, (holder or describe_this_process()).encode("utf-8", "replace"))
        self._fd = fd

    def release(self) -> None:
        """Remove the lock file and drop the lock (idempotent)."""
        fd, self._fd = self._fd, None
        if fd is None:
            return
        try:
            self.lock_path.unlink()
        except OSError:
            pass
        os.close(fd)
