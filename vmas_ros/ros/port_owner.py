"""Which process listens on a TCP port of this host: the "other user" a refused port is named after.

Read from Linux's ``/proc``: the listening sockets in ``/proc/net/tcp`` and
``tcp6`` give the socket's inode, and the process whose ``/proc/<pid>/fd``
holds that socket is its owner. Processes of other users cannot be looked
into; then, and on other systems, the answer is None and the caller says
less.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Optional, Set

__all__ = ["listener_of"]

_LISTEN = "0A"  # TCP state code of a listening socket in /proc/net/tcp
_MAX_DESCRIPTION = 300


def _listening_inodes(port: int) -> Set[str]:
    inodes: Set[str] = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if len(fields) > 9 and fields[3] == _LISTEN and int(fields[1].rsplit(":", 1)[1], 16) == port:
                inodes.add(fields[9])
    return inodes


def listener_of(port: int) -> Optional[str]:
    """``pid N (command line)`` of the process listening on ``port``, or None if that cannot be known."""
    inodes = _listening_inodes(port)
    if not inodes:
        return None
    wanted = {f"socket:[{inode}]" for inode in inodes}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fds = os.listdir(entry / "fd")
            if not any(os.readlink(entry / "fd" / fd) in wanted for fd in fds):
                continue
            command = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode("utf-8", "replace").strip()
        except OSError:
            continue
        return f"pid {entry.name} ({command})"[:_MAX_DESCRIPTION]
    return None
