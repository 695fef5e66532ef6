"""Warnings about messages that can never arrive: unknown agents, wrong message types, QoS asked but not offered.

ROS drops such messages silently. A publisher on ``/agent_9/cmd_vel`` when the
scenario has three agents, or a ``TwistStamped`` publisher on a topic the node
subscribes as ``Twist``, simply never matches, and the user sees an agent that
does not move and no error anywhere. ``TopicAudit`` looks at the ROS graph
every few seconds and names each such publisher once, with what was expected.

It only reads the graph (no subscriptions are made), so it costs one graph
query per period and never touches the messages themselves. sim_node audits
its command topics (``of_sim_node``: unknown agents and wrong types);
policy_node audits the inputs its adapter subscribes (``of_inputs``: wrong
types only, since an adapter may read any topic). ``QosAudit`` does the same
for the subscribers of sim_node's own topics.
"""
from __future__ import annotations

import abc
from typing import Dict, Iterable, List, Set, Tuple

from vmas_ros.ros.message_types import type_name

#: seconds between two looks at the graph
AUDIT_PERIOD_S = 2.0


class _GraphAudit(abc.ABC):
    """Reads the ROS graph every ``period`` seconds and warns once about each problem found."""

    def __init__(self, node, period: float) -> None:
        self.node = node
        self.reported: Set[tuple] = set()  # problems already warned about
        self.timer = node.create_timer(period, self.check)

    @abc.abstractmethod
    def problems(self) -> List[tuple]:
        """Every problem in the graph now, each a tuple that names it."""

    @abc.abstractmethod
    def warning(self, problem: tuple) -> str:
        """The warning for ``problem``."""

    def check(self) -> None:
        """Warn once per problem (a timer callback)."""
        try:
            problems = self.problems()
        except Exception:  # the graph may be gone during shutdown: nothing to report then
            return
        for problem in problems:
            if problem in self.reported:
                continue
            self.reported.add(problem)
            self.node.get_logger().warning(self.warning(problem))


class TopicAudit(_GraphAudit):
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
        super().__init__(node, period)
        self.expected = dict(expected)
        self.suffixes = tuple(suffixes)
        self.agents = list(agents)
        self.consequence = consequence
        namespace = node.get_namespace().rstrip("/")
        self.prefix = namespace + "/"

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
        expected = {sub.topic_name: type_name(sub.msg_type) for sub in subscriptions}
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

    def warning(self, problem: tuple) -> str:
        topic, kind, reason = problem
        return f"ignoring a publisher of {kind} on {topic}: {reason}; {self.consequence}"


def quiet_publisher_events():
    """Event callbacks for a publisher without rclpy's default QoS/type event handlers.

    Every handler is a waitable that each executor round walks in Python: with
    one per sim_node topic, they made each round of the unpaced node several
    times dearer, and the unpaced node runs many rounds while it steps.
    What they would warn about is audited instead, every few seconds
    (:meth:`QosAudit.check` for the published topics, :class:`TopicAudit` for
    the subscribed ones, whose best-effort QoS accepts any publisher).
    """
    from rclpy.event_handler import PublisherEventCallbacks

    return PublisherEventCallbacks(use_default_callbacks=False)


def quiet_subscription_events():
    """The same for a subscription (see :func:`quiet_publisher_events`)."""
    from rclpy.event_handler import SubscriptionEventCallbacks

    return SubscriptionEventCallbacks(use_default_callbacks=False)


class QosAudit(_GraphAudit):
    """Warns once about subscribers of the node's topics that ask for more than the node offers.

    A subscriber requesting reliable delivery from a best-effort publisher, or
    transient-local durability from a volatile one, is matched by DDS but gets
    nothing; rclpy's default publisher event handlers would say so, but cost
    every executor round (see :func:`quiet_publisher_events`), so the graph
    is read every ``period`` seconds instead.
    """

    def __init__(self, node, publishers: Iterable, period: float = AUDIT_PERIOD_S) -> None:
        super().__init__(node, period)
        self.publishers = list(publishers)

    def problems(self) -> List[Tuple[str, str, str]]:
        """(topic, subscriber node, reason) of every subscriber on an audited topic that receives nothing."""
        from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

        found = []
        for publisher in self.publishers:
            offered = publisher.qos_profile
            for info in self.node.get_subscriptions_info_by_topic(publisher.topic_name):
                wanted = info.qos_profile
                reason = None
                if wanted.reliability == ReliabilityPolicy.RELIABLE and offered.reliability == ReliabilityPolicy.BEST_EFFORT:
                    reason = "it requests reliable delivery and the topic is best effort"
                elif (wanted.durability == DurabilityPolicy.TRANSIENT_LOCAL
                      and offered.durability != DurabilityPolicy.TRANSIENT_LOCAL):
                    reason = "it requests transient-local durability and the topic is volatile"
                if reason is not None:
                    found.append((publisher.topic_name, f"{info.node_namespace.rstrip('/')}/{info.node_name}", reason))
        return found

    def warning(self, problem: tuple) -> str:
        topic, subscriber, reason = problem
        return f"the subscriber {subscriber} of {topic} receives nothing: {reason}"
