"""Warnings about commands that can never arrive: unknown agents and wrong message types.

ROS drops such messages silently. A publisher on ``/agent_9/cmd_vel`` when the
scenario has three agents, or a ``TwistStamped`` publisher on a topic the node
subscribes as ``Twist``, simply never matches, and the user sees an agent that
does not move and no error anywhere. ``TopicAudit`` looks at the ROS graph
every few seconds and names each such publisher once, with what was expected.

It only reads the graph (no subscriptions are made), so it costs one graph
query per period and never touches the messages themselves.
"""
from __future__ import annotations

from typing import Dict, Iterable, List, Set, Tuple

#: seconds between two looks at the graph
AUDIT_PERIOD_S = 2.0


class TopicAudit:
    """Looks for publishers on command topics the node does not serve as published.

    Args:
        node: the rclpy node (its graph queries, logger and timers are used).
        expected: fully qualified topic -> ``pkg/msg/Type`` the node subscribes
            there (e.g. ``/agent_0/cmd_vel`` -> ``geometry_msgs/msg/Twist``).
        suffixes: last name parts that mark a command topic (``cmd_vel``, ``action``).
        agents: the valid agent names, listed in the warning.
    """

    def __init__(self, node, expected: Dict[str, str], suffixes: Iterable[str], agents: Iterable[str],
                 period: float = AUDIT_PERIOD_S) -> None:
        self.node = node
        self.expected = dict(expected)
        self.suffixes = tuple(suffixes)
        self.agents = list(agents)
        namespace = node.get_namespace().rstrip("/")
        self.prefix = namespace + "/"
        self.reported: Set[Tuple[str, str]] = set()  # (topic, type) already warned about
        self.timer = node.create_timer(period, self.check)

    @classmethod
    def of_sim_node(cls, node, agent_names: Iterable[str], stamped: bool) -> "TopicAudit":
        """The audit of sim_node's ``<agent>/cmd_vel`` (Twist or TwistStamped) and ``<agent>/action`` topics."""
        namespace, names = node.get_namespace().rstrip("/"), list(agent_names)
        twist = "geometry_msgs/msg/TwistStamped" if stamped else "geometry_msgs/msg/Twist"
        expected = {f"{namespace}/{n}/cmd_vel": twist for n in names}
        expected.update({f"{namespace}/{n}/action": "std_msgs/msg/Float32MultiArray" for n in names})
        return cls(node, expected, ("cmd_vel", "action"), names)

    def problems(self) -> List[Tuple[str, str, str]]:
        """(topic, type, reason) of every publisher on a command topic that the node cannot take."""
        found = []
        for topic, _ in self.node.get_topic_names_and_types():
            parts = topic[len(self.prefix):].split("/") if topic.startswith(self.prefix) else []
            if len(parts) != 2 or parts[1] not in self.suffixes:
                continue
            want = self.expected.get(topic)
            for info in self.node.get_publishers_info_by_topic(topic):
                kind = info.topic_type
                if want is None:
                    found.append((topic, kind, f"there is no agent {parts[0]!r} (agents: {', '.join(self.agents)})"))
                elif kind != want:
                    found.append((topic, kind, f"expected {want}"))
        return found

    def check(self) -> None:
        """Warn once per (topic, type) about publishers whose messages are ignored."""
        try:
            problems = self.problems()
        except Exception:  # the graph may be gone during shutdown: nothing to report then
            return
        for topic, kind, reason in problems:
            if (topic, kind) in self.reported:
                continue
            self.reported.add((topic, kind))
            self.node.get_logger().warning(
                f"ignoring a publisher of {kind} on {topic}: {reason}; its messages never reach an agent"
            )
