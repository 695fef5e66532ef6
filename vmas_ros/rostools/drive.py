"""``vmas-ros drive AGENT``: publish a velocity command on ``<agent>/cmd_vel`` for a while.

A publisher's first messages are lost while DDS discovery has not yet matched
it to the subscriber, so the command waits until the topic has a subscriber
before its clock starts: ``--seconds`` is the time the agent is driven. It
publishes the type the subscriber asks for (``geometry_msgs/Twist``, or
``TwistStamped`` for a node with ``use_stamped_cmd_vel``), ends with a zero
command so the agent stops, and reports what it sent. When nothing listens it
says why: no node at all, or no such agent (naming the agents that are there).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable, List, Optional

from vmas_ros.rostools.graph import ToolError, ToolNode, resolve_name, tool_node

__all__ = ["DriveReport", "drive"]

TWIST = "geometry_msgs/msg/Twist"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
#: once other agents' cmd_vel subscribers are seen in the asked agent's namespace, how long to
#: wait for the asked one before calling it missing (discovery announces a node's topics
#: together, within a fraction of this; another node's agents say nothing about this one's)
MISSING_AFTER_S = 1.0
#: after the publisher matched, time for the subscriber's side of the match to complete (DDS
#: matches the two ends separately; a best-effort reader drops what arrives before its side)
SETTLE_S = 0.5
#: zero commands sent at the end: cmd_vel is best effort, and one lost zero would leave the agent
#: on its last command until the node's cmd_vel_timeout
STOP_REPEATS = 3


@dataclass
class DriveReport:
    """What a drive did: ``sent`` commands (the final zero one not counted) on ``topic``."""

    topic: str
    message_type: str
    sent: int
    subscribers: int
    seconds: float

    def __str__(self) -> str:
        kind = self.message_type.rsplit("/", 1)[-1]
        plural = "" if self.subscribers == 1 else "s"
        return (f"sent {self.sent} {kind}s to {self.topic} ({self.subscribers} subscriber{plural}) "
                f"over {self.seconds:.1f} s, then a zero {kind}")


def _check_finite(**values: float) -> None:
    for name, value in values.items():
        if not math.isfinite(value):
            raise ToolError(f"--{name} must be a finite number, got {value}", 2)


def _cmd_vel_listeners(tool: ToolNode) -> List[str]:
    """Every ``.../cmd_vel`` topic someone subscribes to, sorted."""
    node = tool.node
    return sorted(name for name, _ in node.get_topic_names_and_types()
                  if name.endswith("/cmd_vel") and node.count_subscribers(name) > 0)


def _sibling_prefix(topic: str) -> str:
    """The namespace that ``topic``'s agent shares with its node's other agents:
    ``/swarm_a/agent_0/cmd_vel`` gives ``/swarm_a/``, ``/agent_0/cmd_vel`` gives ``/``."""
    return topic.rsplit("/", 2)[0] + "/"


def _find_listener(tool: ToolNode, topic: str, agent: str, wait: float) -> str:
    """The message type the subscriber of ``topic`` takes, once one is seen; ToolError if none.

    The agent is called missing only after its siblings (other cmd_vel listeners in the same
    namespace) have been seen for :data:`MISSING_AFTER_S`: several simulators in one graph are
    discovered one after another, so another namespace's agents prove nothing about this one."""
    others_seen_at: Optional[float] = None
    siblings = _sibling_prefix(topic)

    def found():
        nonlocal others_seen_at
        if tool.node.count_subscribers(topic) > 0:
            types = dict(tool.node.get_topic_names_and_types()).get(topic)
            if types:
                return types[0]
        if others_seen_at is None and any(name.startswith(siblings) for name in _cmd_vel_listeners(tool)):
            others_seen_at = time.monotonic()
        if others_seen_at is not None and time.monotonic() - others_seen_at > MISSING_AFTER_S:
            return ""  # the node is there, this agent is not
        return None

    message_type = tool.wait_until(found, wait)
    if message_type is None or message_type == "":
        listeners = _cmd_vel_listeners(tool)
        if listeners:
            agents = ", ".join(name[: -len("/cmd_vel")].lstrip("/") for name in listeners)
            raise ToolError(f"no agent {agent!r}: nothing subscribes to {topic}; the agents that listen are {agents}")
        raise ToolError(f"nothing subscribed to {topic} within {wait:g} s: is sim_node running, with the same "
                        f"ROS_DOMAIN_ID? (`vmas-ros topics` lists what there is)")
    if message_type not in (TWIST, TWIST_STAMPED):
        raise ToolError(f"{topic} takes {message_type}; drive publishes {TWIST} or {TWIST_STAMPED}")
    return message_type


def drive(agent: str = "agent_0", vx: float = 0.0, vy: float = 0.0, wz: float = 0.0, seconds: float = 2.0,
          rate_hz: float = 20.0, wait: float = 10.0, namespace: str = "/",
          out: Callable[[str], None] = print) -> DriveReport:
    """Drive ``agent`` at body-frame velocity (``vx``, ``vy``) m/s and yaw rate ``wz`` rad/s for
    ``seconds`` of wall time, ``rate_hz`` commands per second, after waiting up to ``wait`` seconds
    for a subscriber. Prints (through ``out``) and returns the :class:`DriveReport`."""
    _check_finite(vx=vx, vy=vy, wz=wz)
    if not (math.isfinite(seconds) and seconds >= 0):
        raise ToolError(f"--seconds must be a finite number >= 0, got {seconds}", 2)
    if not (math.isfinite(rate_hz) and rate_hz > 0) or not (math.isfinite(wait) and wait > 0):
        raise ToolError(f"--rate and --wait must be finite numbers > 0, got {rate_hz} and {wait}", 2)
    from geometry_msgs.msg import Twist, TwistStamped
    from rclpy.duration import Duration

    topic = resolve_name(f"{agent.rstrip('/')}/cmd_vel", namespace)
    with tool_node("vmas_ros_drive") as tool:
        message_type = _find_listener(tool, topic, agent, wait)
        stamped = message_type == TWIST_STAMPED
        publisher = tool.node.create_publisher(TwistStamped if stamped else Twist, topic, 10)
        if tool.wait_until(lambda: publisher.get_subscription_count() or None, wait) is None:
            raise ToolError(f"{topic} has a subscriber, but it did not match this publisher within {wait:g} s "
                            f"(incompatible QoS?)")
        tool.spin_for(SETTLE_S)

        def command(x: float, y: float, z: float):
            twist = Twist()
            twist.linear.x, twist.linear.y, twist.angular.z = float(x), float(y), float(z)
            if not stamped:
                return twist
            message = TwistStamped()
            message.header.stamp = tool.node.get_clock().now().to_msg()
            message.twist = twist
            return message

        sent, period = 0, 1.0 / rate_hz
        start = time.monotonic()
        end = start + seconds
        while time.monotonic() < end:
            publisher.publish(command(vx, vy, wz))
            sent += 1
            next_at = start + sent * period
            while time.monotonic() < min(next_at, end):
                tool.spin_once(max(0.0, min(next_at, end) - time.monotonic()))
        driven = time.monotonic() - start
        for _ in range(STOP_REPEATS):
            publisher.publish(command(0.0, 0.0, 0.0))
            tool.spin_for(period)
        publisher.wait_for_all_acked(Duration(seconds=1.0))
        report = DriveReport(topic, message_type, sent, publisher.get_subscription_count(), driven)
    out(str(report))
    return report
