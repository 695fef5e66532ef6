"""ROS 2 message type names, as the ROS graph, bags and Foxglove spell them."""
from __future__ import annotations

__all__ = ["type_name"]


def type_name(message_class: type) -> str:
    """``pkg/msg/Name`` of a message class (e.g. ``sensor_msgs/msg/LaserScan`` for ``sensor_msgs.msg.LaserScan``).

    rclpy generates each class in ``<pkg>.msg._<name>``, so the package is the
    first part of the class's module.
    """
    return f"{message_class.__module__.split('.')[0]}/msg/{message_class.__name__}"
