"""``vmas-ros bag play PATH``: publish a bag's messages again on their topics, with their timing.

Each recorded topic gets a publisher of its type with the QoS it was offered
with when recorded (reliability, durability, depth); messages go out in log
time order, spaced as they were recorded divided by ``--rate``. The payloads
are published as recorded (serialized CDR), without being decoded; a topic
whose message package is not installed here (tf2_msgs has no wheel) is
skipped with a note. A recorded
``/clock`` is played like any topic, so nodes with ``use_sim_time`` follow it.
"""
from __future__ import annotations

import sys
import time
from typing import Callable, Dict, Iterator, Optional, Sequence, Tuple

from vmas_ros.rostools.bag import bag_files, summarize_bag
from vmas_ros.rostools.echo import message_class
from vmas_ros.rostools.graph import ToolError, tool_node

__all__ = ["play", "qos_from_yaml"]


def qos_from_yaml(text: str):
    """The first of the ``offered_qos_profiles`` a recorder wrote (rosbag2's YAML list), as a
    QoSProfile; reliable, volatile, depth 10 where it says nothing usable."""
    import yaml
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    profile = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
    try:
        offered = yaml.safe_load(text) if text else None
    except yaml.YAMLError:
        return profile
    first = offered[0] if isinstance(offered, list) and offered and isinstance(offered[0], dict) else {}
    if first.get("reliability") == "best_effort":
        profile.reliability = ReliabilityPolicy.BEST_EFFORT
    if first.get("durability") == "transient_local":
        profile.durability = DurabilityPolicy.TRANSIENT_LOCAL
    if isinstance(first.get("depth"), int) and first["depth"] > 0:
        profile.depth = first["depth"]
    return profile


def _messages(path, topics: Optional[Sequence[str]]) -> Iterator[Tuple[str, int, bytes]]:
    """(topic, log time ns, CDR payload) of every message of ``topics`` (all when None), in log time order."""
    from mcap.reader import make_reader

    for file in bag_files(path):
        with open(file, "rb") as handle:
            for _, channel, message in make_reader(handle).iter_messages(topics=topics, log_time_order=True):
                yield channel.topic, message.log_time, message.data


def play(path, rate: float = 1.0, topics: Optional[Sequence[str]] = None, delay: float = 0.5,
         progress: bool = True, out: Callable[[str], None] = print) -> int:
    """Play bag ``path`` at ``rate`` times its recorded speed, after ``delay`` seconds in which
    running subscribers discover the new publishers. Returns the number of messages published."""
    from tqdm import tqdm

    if not rate > 0 or not delay >= 0:
        raise ToolError(f"--rate must be > 0 and --delay >= 0, got {rate} and {delay}", 2)
    summary = summarize_bag(path)
    wanted = {name: t for name, t in summary.topics.items() if topics is None or name in topics}
    unknown = sorted(set(topics or ()) - set(summary.topics))
    if unknown:
        raise ToolError(f"{path} has no topic {', '.join(unknown)}; it has {', '.join(sorted(summary.topics))}", 2)
    classes = {}
    for name, topic in sorted(wanted.items()):
        try:
            classes[name] = message_class(topic.type)
        except ToolError as error:
            if topics is not None:  # asked for by name: refuse rather than skip
                raise
            print(f"vmas-ros bag play: skipping {name}: {error}", file=sys.stderr)
    total = sum(wanted[name].count for name in classes)
    with tool_node("vmas_ros_bag_play") as tool:
        publishers: Dict[str, object] = {
            name: tool.node.create_publisher(cls, name, qos_from_yaml(wanted[name].offered_qos_profiles))
            for name, cls in classes.items()
        }
        tool.spin_for(delay)
        sent, first_log, wall_start = 0, None, time.monotonic()
        with tqdm(total=total, desc="bag play", unit="msg", disable=not progress) as bar:
            for topic, log_time, data in _messages(path, list(publishers)):
                if first_log is None:
                    first_log, wall_start = log_time, time.monotonic()
                due = wall_start + (log_time - first_log) / 1e9 / rate
                pause = due - time.monotonic()
                if pause > 0:
                    time.sleep(pause)
                publishers[topic].publish(data)
                sent += 1
                bar.update()
        elapsed = time.monotonic() - wall_start
        from rclpy.duration import Duration

        for publisher in publishers.values():  # reliable messages still in flight reach their readers
            publisher.wait_for_all_acked(Duration(seconds=1.0))
    out(f"played {sent} messages on {len(publishers)} topics in {elapsed:.1f} s")
    return sent
