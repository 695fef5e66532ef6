"""What policy_node publishes per agent: the raw action, or a body-frame Twist / TwistStamped.

``ActionOutput`` sends ``<agent>/action`` (std_msgs/Float32MultiArray, what
sim_node's ``<agent>/action`` takes). ``CmdVelOutput`` sends ``<agent>/cmd_vel``
as geometry_msgs/Twist, or as geometry_msgs/TwistStamped (stamped now, with a
``header.frame_id`` per agent) for bases that take only that, such as Jazzy's
diff_drive_controller. Messages are made once per agent and refilled.
"""
from __future__ import annotations

from typing import List, Sequence

import numpy as np


class ActionOutput:
    """``<agent>/action`` for each agent: the policy's action vector as is."""

    topic = "action"

    def __init__(self, node, agents: Sequence[str], action_size: int, qos) -> None:
        from std_msgs.msg import Float32MultiArray, MultiArrayDimension

        self.type_name = "std_msgs/Float32MultiArray"
        self.messages = []
        for _ in agents:
            msg = Float32MultiArray()
            msg.layout.dim = [MultiArrayDimension(label="action", size=action_size, stride=action_size)]
            msg.data = [0.0] * action_size
            self.messages.append(msg)
        self.publishers = [node.create_publisher(Float32MultiArray, f"{a}/action", qos) for a in agents]

    def send(self, index: int, action: np.ndarray) -> None:
        """Publish agent ``index``'s action ``[action_size]``."""
        msg = self.messages[index]
        np.frombuffer(msg.data, dtype=np.float32)[:] = action
        self.publishers[index].publish(msg)


class CmdVelOutput:
    """``<agent>/cmd_vel`` for each agent: a body-frame twist (REP 103), stamped or not."""

    topic = "cmd_vel"

    def __init__(self, node, agents: Sequence[str], qos, stamped: bool, frame_ids: List[str]) -> None:
        from geometry_msgs.msg import Twist, TwistStamped

        self.node, self.stamped = node, stamped
        kind = TwistStamped if stamped else Twist
        self.type_name = f"geometry_msgs/{kind.__name__}"
        self.messages = [kind() for _ in agents]
        if stamped:
            for msg, frame in zip(self.messages, frame_ids):
                msg.header.frame_id = frame
        self.publishers = [node.create_publisher(kind, f"{a}/cmd_vel", qos) for a in agents]

    def send(self, index: int, twist: np.ndarray) -> None:
        """Publish agent ``index``'s twist ``[3]``: (linear.x, linear.y, angular.z)."""
        msg = self.messages[index]
        if self.stamped:
            msg.header.stamp = self.node.get_clock().now().to_msg()
            body = msg.twist
        else:
            body = msg
        body.linear.x, body.linear.y, body.angular.z = (float(v) for v in twist)
        self.publishers[index].publish(msg)
