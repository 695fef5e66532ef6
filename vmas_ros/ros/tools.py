"""Small stand-ins for ``ros2 topic echo`` and a keyboard-free teleop.

The PyPI ROS wheels have no ``ros2`` CLI, so ``vmas-ros echo`` and
``vmas-ros drive`` give a new user the same first steps: see what sim_node
publishes and drive an agent with ``geometry_msgs/Twist``. With a full ROS
install, ``ros2 topic echo`` and ``teleop_twist_keyboard`` work as usual.
"""
from __future__ import annotations

import importlib
import math
import sys
import time
from typing import Any, Optional


def message_class(type_name: str):
    """``pkg/msg/Name`` -> the message class (what ros2cli does with rosidl_runtime_py)."""
    package, _, name = type_name.split("/")
    return getattr(importlib.import_module(f"{package}.msg"), name)


def to_yaml(message: Any, indent: int = 0, max_items: int = 32) -> str:
    """Readable YAML-like text of a message, long arrays cut to ``max_items``."""
    pad = "  " * indent
    lines = []
    for field in message.get_fields_and_field_types():
        value = getattr(message, field)
        if hasattr(value, "get_fields_and_field_types"):
            lines.append(f"{pad}{field}:")
            lines.append(to_yaml(value, indent + 1, max_items))
        elif isinstance(value, (list, tuple)) or hasattr(value, "tolist"):
            items = list(value)
            if items and hasattr(items[0], "get_fields_and_field_types"):
                lines.append(f"{pad}{field}: [{len(items)} messages]")
            else:
                shown = ", ".join(_scalar(v) for v in items[:max_items])
                more = f", ... ({len(items)} items)" if len(items) > max_items else ""
                lines.append(f"{pad}{field}: [{shown}{more}]")
        else:
            lines.append(f"{pad}{field}: {_scalar(value)}")
    return "\n".join(lines)


def _scalar(value: Any) -> str:
    if isinstance(value, float):
        return ".inf" if math.isinf(value) and value > 0 else f"{value:.6g}"
    return repr(value) if isinstance(value, str) else str(value)


def echo(topic: str, count: int = 1, timeout: float = 10.0) -> int:
    """Print ``count`` messages of ``topic``; exit code 1 if none arrived in ``timeout`` s."""
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    rclpy.init()
    node = rclpy.create_node("vmas_ros_echo")
    try:
        deadline = time.monotonic() + timeout
        type_name: Optional[str] = None
        while type_name is None and time.monotonic() < deadline:
            types = dict(node.get_topic_names_and_types())
            type_name = types.get(topic, [None])[0]
            rclpy.spin_once(node, timeout_sec=0.1)
        if type_name is None:
            print(f"no topic {topic!r} appeared within {timeout} s (is sim_node running with the same ROS_DOMAIN_ID?)",
                  file=sys.stderr)
            return 1
        received = []
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        node.create_subscription(message_class(type_name), topic, received.append, qos)
        printed = 0
        while printed < count and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
            while received and printed < count:
                print(to_yaml(received.pop(0)))
                print("---")
                printed += 1
        return 0 if printed else 1
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def drive(agent: str, vx: float, vy: float, wz: float, seconds: float, rate_hz: float = 20.0) -> int:
    """Publish a Twist on ``/<agent>/cmd_vel`` at ``rate_hz`` for ``seconds``, then a zero Twist."""
    import rclpy
    from geometry_msgs.msg import Twist

    for name, value in (("vx", vx), ("vy", vy), ("wz", wz), ("seconds", seconds)):
        if not math.isfinite(value):
            print(f"{name} must be finite, got {value}", file=sys.stderr)
            return 2
    rclpy.init()
    node = rclpy.create_node("vmas_ros_drive")
    publisher = node.create_publisher(Twist, f"/{agent}/cmd_vel", 10)
    twist = Twist()
    twist.linear.x, twist.linear.y, twist.angular.z = float(vx), float(vy), float(wz)
    try:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            publisher.publish(twist)
            rclpy.spin_once(node, timeout_sec=1.0 / rate_hz)
        publisher.publish(Twist())
        return 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
