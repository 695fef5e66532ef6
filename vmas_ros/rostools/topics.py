"""``vmas-ros topics``: the topics (and services) of the ROS graph, as ``ros2 topic list -t`` prints them."""
from __future__ import annotations

from typing import Callable, Dict, List

from vmas_ros.rostools.graph import tool_node

__all__ = ["graph_names", "list_topics"]


def graph_names(wait: float = 3.0, services: bool = False) -> Dict[str, List[str]]:
    """Name -> types of every topic (or service) seen after ``wait`` seconds of discovery.

    Discovery has no end a tool could wait for, and a participant whose first
    announcements were missed is seen only at a periodic later one, hence the
    default wait.
    """
    with tool_node("vmas_ros_topics") as tool:
        tool.spin_for(wait)
        node = tool.node
        names = node.get_service_names_and_types() if services else node.get_topic_names_and_types()
        return {name: list(types) for name, types in names}


def list_topics(wait: float = 3.0, services: bool = False, show_types: bool = True,
                out: Callable[[str], None] = print) -> Dict[str, List[str]]:
    """Print one ``name [type]`` line per topic (or service), sorted; returns what was printed."""
    names = graph_names(wait, services)
    for name in sorted(names):
        out(f"{name} [{', '.join(names[name])}]" if show_types else name)
    return names
