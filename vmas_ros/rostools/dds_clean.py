"""Find and remove the Fast DDS shared-memory segments that a killed process left half made.

Fast DDS, the ROS 2 middleware the wheels bring, keeps its shared-memory
transport in files under ``/dev/shm`` named ``fastrtps_*``. With
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` every participant on the machine,
whatever its domain, probes the same numbered ports (``fastrtps_port7000``,
``fastrtps_port7001``, ...) to find a free one.

Each segment starts with a four-byte state word (boost.interprocess's managed
segment header): 0 not started, 1 being set up, 2 ready, 3 corrupted. A process
killed (SIGKILL, OOM) between creating the file and marking it ready leaves 0
or 1 behind for good. Every later participant that opens that port then waits
for it to become ready, forever, inside Fast DDS: a node hangs at start-up with
no output, and no timeout in Python reaches it.

Setting a segment up takes microseconds, so one that has stayed unready for
``min_age_s`` seconds has no live creator and is safe to remove. Ready
segments, and the ``_el`` lock files beside them, are never touched: Fast DDS
cleans those itself once their owner is gone.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import List, Optional

__all__ = ["SHM_DIR", "stuck_segments", "remove_stuck_segments", "clean"]

SHM_DIR = Path("/dev/shm")
#: the state word's values (boost.interprocess): a segment in one of these for long is abandoned
UNREADY_STATES = (0, 1)
DEFAULT_MIN_AGE_S = 2.0


def _state(path: Path) -> Optional[int]:
    """The segment's state word, 0 for a file shorter than it (its creator died before sizing it);
    None when the file went away meanwhile."""
    try:
        with open(path, "rb") as segment:
            head = segment.read(4)
    except OSError:
        return None
    return int.from_bytes(head, "little") if len(head) == 4 else 0


def stuck_segments(directory: Path = SHM_DIR, min_age_s: float = DEFAULT_MIN_AGE_S,
                   now: Optional[float] = None) -> List[Path]:
    """Fast DDS segments under ``directory`` that are still unready ``min_age_s`` seconds after
    their file was last changed, sorted by name. A missing ``directory`` (no /dev/shm) has none."""
    if min_age_s < 0:
        raise ValueError(f"min_age_s must be >= 0 seconds, got {min_age_s}")
    now = time.time() if now is None else now
    stuck = []
    for path in sorted(Path(directory).glob("fastrtps_*")):
        if path.name.endswith("_el") or not path.is_file():
            continue
        try:
            age = now - path.stat().st_mtime
        except OSError:
            continue
        if age >= min_age_s and _state(path) in UNREADY_STATES:
            stuck.append(path)
    return stuck


def remove_stuck_segments(directory: Path = SHM_DIR, min_age_s: float = DEFAULT_MIN_AGE_S) -> List[Path]:
    """Remove :func:`stuck_segments`; returns the ones removed (another cleaner may race us)."""
    removed = []
    for path in stuck_segments(directory, min_age_s):
        try:
            path.unlink()
        except FileNotFoundError:
            continue
        removed.append(path)
    return removed


def clean(directory: Path = SHM_DIR, min_age_s: float = DEFAULT_MIN_AGE_S, dry_run: bool = False) -> List[Path]:
    """``vmas-ros dds-clean``: report (and unless ``dry_run``, remove) the stuck segments."""
    found = stuck_segments(directory, min_age_s) if dry_run else remove_stuck_segments(directory, min_age_s)
    verb = "would remove" if dry_run else "removed"
    if not found:
        print(f"no stuck Fast DDS segments under {directory}")
    for path in found:
        print(f"{verb} {path} (left unready by a process that was killed)")
    return found
