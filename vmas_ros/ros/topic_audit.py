"""Warnings about commands that can never arrive: unknown agents and wrong message types.

ROS drops such messages silently. A publisher on ``/agent_9/cmd_vel`` when the
scenario has three agents, or a ``TwistStamped`` publisher on a topic the node
subscribes as ``Twist``, simply never matches, and the user sees an agent that
does not move and no error anywhere. ``TopicAudit`` looks at the ROS graph
every few seconds and names each such publisher once, with what was expected.

It only reads the graph (no subscriptions are made), so it costs one graph
query per period and never touches the messages themselves. sim_node audits
its command topics (``of_sim_node``: unknown agents and wrong types);
policy_node audits the inputs its adapter subscribes (``of_inputs``: wrong
types only, since an adapter may read any topic).
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
        suffixes: last name parts that mark a command topic (``cmd_vel``, ``action``);
            a publisher on ``<agent>/<suffix>`` for an agent not in ``expected`` is
            reported too. Empty: only the topics in ``expected`` are audited.
        agents: the valid agent names, listed in the warning.
        consequence: the end of the warning, what the user loses.
    """

    def __init__(self, node, expected: Dict[str, str], suffixes: Iterable[str], agents: Iterable[str],
                 period: float = AUDIT_PERIOD_S, consequence: str = "its messages never reach an agent") -> None:
        self.node = node
        self.expected = dict(expected)
        self.suffixes = tuple(suffixes)
        self.agents = list(agents)
        self.consequence = consequence
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

    @classmethod
    def of_inputs(cls, node, subscriptions: Iterable, what: str) -> "TopicAudit":
        """The audit of ``subscriptions`` (rclpy Subscription objects): a publisher of another type on
        one of their topics is named once; ``what`` (e.g. "policy_node") ends the warning."""
        expected = {sub.topic_name: type_name_of(sub.msg_type) for sub in subscriptions}
        return cls(node, expected, (), (), consequence=f"{what} never receives its messages")

    def problems(self) -> List[Tuple[str, str, str]]:
        """(topic, type, reason) of every publisher on an audited topic that the node cannot take."""
        found = []
        for topic, _ in self.node.get_topic_names_and_types():
            want = self.expected.get(topic)
            parts = topic[len(self.prefix):].split("/") if topic.startswith(self.prefix) else []
            if want is None and (len(parts) != 2 or parts[1] not in self.suffixes):
                continue
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
            self.node.get_logger().warning(f"ignoring a publisher of {kind} on {topic}: {reason}; {self.consequence}")


def type_name_of(message_class: type) -> str:
    """``pkg/msg/Name`` of a message class, as the ROS graph reports types (e.g. std_msgs/msg/String)."""
    return f"{message_class.__module__.split('.')[0]}/msg/{message_class.__name__}"
