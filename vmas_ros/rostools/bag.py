"""``vmas-ros bag info PATH``: what a bag holds, read from its MCAP files.

PATH is a single ``.mcap`` file or a rosbag2 bag folder (``metadata.yaml``
beside ``<name>_0.mcap``, ...; the files the metadata lists, or every
``.mcap`` in the folder when it has none). The figures come from the files'
own summaries, so they are right even where ``metadata.yaml`` is missing. A
file without a summary (its recorder was killed) is named, with the command
that repairs it.
"""
from __future__ import annotations

import datetime as _dt
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Dict, List, Optional

from vmas_ros.rostools.graph import ToolError

__all__ = ["BagSummary", "TopicSummary", "bag_files", "bag_info", "summarize_bag"]


@dataclass
class TopicSummary:
    """One topic of a bag: its message type, how many messages, and the QoS it was offered with."""

    name: str
    type: str
    count: int
    serialization_format: str = "cdr"
    offered_qos_profiles: str = ""


@dataclass
class BagSummary:
    """A bag's files, total size, time span (ns since the epoch of the log times) and topics."""

    files: List[str]
    size_bytes: int
    start_ns: Optional[int]
    end_ns: Optional[int]
    topics: Dict[str, TopicSummary] = field(default_factory=dict)

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics.values())

    @property
    def duration_ns(self) -> int:
        return 0 if self.start_ns is None else self.end_ns - self.start_ns


def bag_files(path) -> List[Path]:
    """The MCAP files of bag ``path`` (a file, or a bag folder), in recording order."""
    path = Path(path)
    if path.is_file():
        return [path]
    if not path.is_dir():
        raise ToolError(f"no bag at {path}: expected an .mcap file or a bag folder")
    metadata = path / "metadata.yaml"
    if metadata.is_file():
        import yaml

        try:
            info = yaml.safe_load(metadata.read_text(encoding="utf-8"))["rosbag2_bagfile_information"]
            listed = [path / name for name in info["relative_file_paths"]]
        except (yaml.YAMLError, KeyError, TypeError) as error:
            raise ToolError(f"{metadata} is not rosbag2 metadata ({error}); `vmas-ros bag-recover {path}` "
                            f"rebuilds it from the files") from error
        missing = [str(p) for p in listed if not p.is_file()]
        if missing:
            raise ToolError(f"{metadata} lists files that are not there: {', '.join(missing)}")
        return listed
    found = sorted(path.glob("*.mcap"), key=_split_index)
    if not found:
        raise ToolError(f"{path} is a folder without metadata.yaml or .mcap files: not a bag")
    return found


def _split_index(path: Path):
    """``name_12.mcap`` sorts after ``name_2.mcap``."""
    stem, _, index = path.stem.rpartition("_")
    return (stem, int(index)) if index.isdigit() else (path.stem, -1)


def summarize_bag(path) -> BagSummary:
    """The :class:`BagSummary` of bag ``path``, from its files' MCAP summaries."""
    from mcap.reader import make_reader

    files = bag_files(path)
    summary = BagSummary([str(f) for f in files], sum(f.stat().st_size for f in files), None, None)
    for file in files:
        with open(file, "rb") as handle:
            try:
                found = make_reader(handle).get_summary()
            except Exception as error:  # mcap raises several kinds for a damaged file
                found, problem = None, error
            else:
                problem = "it has no summary"
        if found is None or found.statistics is None:
            raise ToolError(f"{file} cannot be summarised ({problem}): its recorder did not close it; "
                            f"`vmas-ros bag-recover {path}` rebuilds a readable bag")
        stats = found.statistics
        if stats.message_count:
            starts = [t for t in (summary.start_ns, stats.message_start_time) if t is not None]
            ends = [t for t in (summary.end_ns, stats.message_end_time) if t is not None]
            summary.start_ns, summary.end_ns = min(starts), max(ends)
        for channel_id, channel in found.channels.items():
            schema = found.schemas.get(channel.schema_id)
            topic = summary.topics.setdefault(channel.topic, TopicSummary(
                channel.topic, schema.name if schema else "", 0, channel.message_encoding,
                channel.metadata.get("offered_qos_profiles", "")))
            topic.count += stats.channel_message_counts.get(channel_id, 0)
    return summary


def _when(ns: Optional[int]) -> str:
    if ns is None:
        return "-"
    stamp = _dt.datetime.fromtimestamp(ns / 1e9, tz=_dt.timezone.utc)
    return f"{stamp:%Y-%m-%d %H:%M:%S.%f} UTC ({ns / 1e9:.9f})"


def bag_info(path, as_json: bool = False, out: Callable[[str], None] = print) -> BagSummary:
    """Print bag ``path``'s files, size, duration, start, end, message count and topics (as
    ``ros2 bag info`` lays them out, or as JSON with ``as_json``)."""
    summary = summarize_bag(path)
    if as_json:
        document = asdict(summary)
        document["topics"] = [asdict(t) for t in summary.topics.values()]
        document.update(message_count=summary.message_count, duration_ns=summary.duration_ns)
        out(json.dumps(document, indent=2))
        return summary
    width = max((len(t.name) for t in summary.topics.values()), default=0)
    out(f"Files:             {', '.join(summary.files)}")
    out(f"Bag size:          {summary.size_bytes / 2**20:.1f} MiB")
    out("Storage id:        mcap")
    out(f"Duration:          {summary.duration_ns / 1e9:.3f} s")
    out(f"Start:             {_when(summary.start_ns)}")
    out(f"End:               {_when(summary.end_ns)}")
    out(f"Messages:          {summary.message_count}")
    for i, topic in enumerate(sorted(summary.topics.values(), key=lambda t: t.name)):
        label = "Topic information: " if i == 0 else " " * 19
        out(f"{label}Topic: {topic.name:<{width}} | Type: {topic.type} | Count: {topic.count} | "
            f"Serialization Format: {topic.serialization_format}")
    return summary
