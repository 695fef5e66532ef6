"""Where a recording's files go, and rosbag2's ``metadata.yaml`` for a bag folder.

A recording is laid out one of two ways, chosen by its path:

* **a single file** (the path ends in ``.mcap``): the first file is the path
  itself, later split files sit beside it as ``<stem>_1.mcap``,
  ``<stem>_2.mcap``, ... There is no metadata file; each MCAP is complete.
* **a bag folder** (any other path), as ``ros2 bag record -s mcap -o NAME``
  makes it in Jazzy: the folder ``NAME/`` holds ``NAME_0.mcap``,
  ``NAME_1.mcap``, ... and a ``metadata.yaml`` written when the recording
  closes. rosbags' folder ``Reader`` and ``ros2 bag info/play`` open it.

``metadata.yaml`` (rosbag2 metadata version 9) is built from the MCAP files'
own summaries (:func:`metadata_from_files`), never from counters kept on the
side, so that what it says is what the files hold. The same function rebuilds
it for a folder whose recorder died before writing it (``vmas-ros
bag-recover``).
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Sequence, Union

import yaml

from vmas_ros.record._io import _stale_split_files, refuse_symlink, split_path
from vmas_ros.record.schemas import type_hash

__all__ = [
    "METADATA_FILE",
    "BagFolder",
    "RecordingExists",
    "SingleFile",
    "bag_layout",
    "folder_files",
    "metadata_from_files",
    "write_metadata",
]

METADATA_FILE = "metadata.yaml"
#: the rosbag2 metadata version written (Jazzy's): QoS profiles as YAML lists, type hashes, ros_distro
METADATA_VERSION = 9


class RecordingExists(FileExistsError):
    """A recording is already at the path: ``path`` is there, ``what`` says what it is."""

    def __init__(self, path: Path, what: str) -> None:
        super().__init__(f"{path} exists ({what}); choose another path or pass overwrite=True")
        self.path, self.what = path, what


@dataclass(frozen=True)
class SingleFile:
    """A recording to ``path`` (``.mcap``) with its split files beside it."""

    path: Path

    @property
    def bag(self) -> Path:
        """What the user named and opens afterwards."""
        return self.path

    def file_path(self, index: int) -> Path:
        return split_path(self.path, index)

    def prepare(self, overwrite: bool) -> None:
        """Make room for a new recording: refuse (or with ``overwrite`` remove) an old one."""
        refuse_symlink(self.path)  # even with overwrite: a link is not a recording to replace
        present = os.path.lexists(self.path)
        stale = _stale_split_files(self.path)
        if not overwrite and (present or stale):
            raise RecordingExists(self.path if present else stale[0], "an MCAP file")
        for old in ([self.path] if present else []) + stale:
            old.unlink()  # files are created anew (O_EXCL), never opened where they are
        self.path.parent.mkdir(parents=True, exist_ok=True)

    def finish(self, paths: Sequence[Path]) -> None:
        """Nothing to add: every MCAP file carries its own summary."""


_BAG_FILE = re.compile(r".+_\d+\.mcap$")


@dataclass(frozen=True)
class BagFolder:
    """A rosbag2 bag folder ``path`` holding ``<name>_<n>.mcap`` and ``metadata.yaml``."""

    path: Path

    @property
    def bag(self) -> Path:
        return self.path

    def file_path(self, index: int) -> Path:
        return self.path / f"{self.path.name}_{index}.mcap"

    def prepare(self, overwrite: bool) -> None:
        """Create the folder; an existing one is refused, or with ``overwrite`` emptied of its bag files.

        Overwriting removes only what a bag folder holds (``metadata.yaml`` and
        ``*_<n>.mcap``): a folder with anything else in it is refused even then,
        so a mistyped path never deletes unrelated files.
        """
        refuse_symlink(self.path)
        if os.path.lexists(self.path):
            if not self.path.is_dir():
                raise RecordingExists(self.path, "a file, not a bag folder")
            entries = sorted(self.path.iterdir())
            if entries and not overwrite:
                raise RecordingExists(self.path, "a folder that is not empty")
            foreign = [p.name for p in entries if not (p.name == METADATA_FILE or _BAG_FILE.fullmatch(p.name))]
            if foreign:
                raise FileExistsError(
                    f"{self.path} holds files that are not part of a bag ({', '.join(foreign[:3])}); "
                    f"the recorder replaces only bag folders: choose another path"
                )
            for old in entries:
                old.unlink()
        self.path.mkdir(parents=True, exist_ok=True)

    def finish(self, paths: Sequence[Path]) -> None:
        write_metadata(self.path, metadata_from_files(paths))


def bag_layout(path: Union[str, os.PathLike]) -> Union[SingleFile, BagFolder]:
    """The layout a recording to ``path`` gets: a single file for ``*.mcap``, else a bag folder."""
    path = Path(path)
    if path.name in ("", ".", "..", ".mcap"):
        raise ValueError(f"not a recording path: {str(path)!r} (expected NAME.mcap or a bag folder NAME)")
    return SingleFile(path) if path.name.endswith(".mcap") else BagFolder(path)


def folder_files(folder: Path) -> List[Path]:
    """The ``<name>_<n>.mcap`` files of a bag folder, in split order."""
    def index(p: Path) -> int:
        return int(p.name[: -len(".mcap")].rsplit("_", 1)[1])
    return sorted((p for p in folder.iterdir() if _BAG_FILE.fullmatch(p.name)), key=index)


# ------------------------------------------------------------------ metadata
def _time(ns: int) -> Dict[str, int]:
    return {"nanoseconds_since_epoch": int(ns)}


def _duration(ns: int) -> Dict[str, int]:
    return {"nanoseconds": int(ns)}


def metadata_from_files(paths: Sequence[Path]) -> Dict[str, object]:
    """rosbag2 metadata (the ``rosbag2_bagfile_information`` mapping) of the finished MCAP ``paths``.

    Counts, times, topics, types and offered QoS come from each file's summary;
    a file without one (its recorder died) raises ValueError naming it. File
    paths are stored relative to the folder, as rosbag2 does.
    """
    from mcap.reader import make_reader

    topics: Dict[str, Dict[str, object]] = {}  # topic -> entry, in order of first appearance
    files: List[Dict[str, object]] = []
    starts, ends = [], []
    for path in paths:
        with open(path, "rb") as stream:
            try:
                summary = make_reader(stream).get_summary()
            except Exception as error:  # mcap raises several kinds for a cut-off file
                raise ValueError(f"{path} has no readable summary ({error})") from None
        if summary is None or summary.statistics is None:
            raise ValueError(f"{path} has no summary: its recorder did not finish it")
        stats = summary.statistics
        count = stats.message_count
        start = stats.message_start_time if count else 0
        end = stats.message_end_time if count else 0
        if count:
            starts.append(start)
            ends.append(end)
        files.append({"path": path.name, "starting_time": _time(start), "duration": _duration(end - start),
                      "message_count": count})
        for channel_id, channel in sorted(summary.channels.items()):
            schema = summary.schemas.get(channel.schema_id)
            type_name = schema.name if schema is not None else ""
            entry = topics.get(channel.topic)
            if entry is None:
                qos = yaml.safe_load(channel.metadata.get("offered_qos_profiles", "") or "[]") or []
                entry = topics[channel.topic] = {
                    "topic_metadata": {
                        "name": channel.topic, "type": type_name, "serialization_format": channel.message_encoding,
                        "offered_qos_profiles": qos, "type_description_hash": type_hash(type_name),
                    },
                    "message_count": 0,
                }
            elif entry["topic_metadata"]["type"] != type_name:
                raise ValueError(f"{path}: topic {channel.topic} has type {type_name}, "
                                 f"earlier files {entry['topic_metadata']['type']}")
            entry["message_count"] += stats.channel_message_counts.get(channel_id, 0)
    start = min(starts) if starts else 0
    return {
        "version": METADATA_VERSION,
        "storage_identifier": "mcap",
        "duration": _duration(max(ends) - start if ends else 0),
        "starting_time": _time(start),
        "message_count": sum(f["message_count"] for f in files),
        "topics_with_message_count": list(topics.values()),
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [f["path"] for f in files],
        "files": files,
        "custom_data": None,
        "ros_distro": os.environ.get("ROS_DISTRO", "jazzy"),
    }


def write_metadata(folder: Path, info: Dict[str, object]) -> Path:
    """Write ``folder/metadata.yaml`` atomically (a temporary file renamed into place)."""
    target = folder / METADATA_FILE
    tmp = folder / f".{METADATA_FILE}.partial"
    text = yaml.safe_dump({"rosbag2_bagfile_information": info}, sort_keys=False, default_flow_style=False)
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(text)
    os.replace(tmp, target)
    return target
