"""``vmas-ros echo TOPIC``: print a topic's messages, as ``ros2 topic echo`` does."""
from __future__ import annotations

import importlib
import math
import time
from typing import Any, Callable

from vmas_ros.rostools.graph import ToolError, resolve_name, tool_node

__all__ = ["echo", "message_class", "to_yaml"]


def message_class(type_name: str):
    """``pkg/msg/Name`` -> the message class (what ros2cli does with rosidl_runtime_py)."""
    package, kind, name = type_name.split("/")
    try:
        return getattr(importlib.import_module(f"{package}.{kind}"), name)
    except (ImportError, AttributeError) as error:
        raise ToolError(f"{type_name} is not installed in this Python ({error}); "
                        f"install the package that defines it to read it") from error


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


def echo(topic: str, count: int = 1, timeout: float = 10.0, namespace: str = "/",
         out: Callable[[str], None] = print) -> int:
    """Print ``count`` messages of ``topic`` (resolved against ``namespace``), each followed by
    ``---``. Returns how many were printed; raises :class:`ToolError` when the topic does not
    appear, or no message arrives, within ``timeout`` seconds."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    if count < 1 or not timeout > 0:
        raise ToolError(f"--count must be >= 1 and --timeout > 0, got {count} and {timeout}", 2)
    name = resolve_name(topic, namespace)
    deadline = time.monotonic() + timeout
    with tool_node("vmas_ros_echo") as tool:
        types = tool.wait_until(lambda: dict(tool.node.get_topic_names_and_types()).get(name), timeout)
        if types is None:
            raise ToolError(f"no topic {name} appeared within {timeout:g} s (is the publisher running, with the "
                            f"same ROS_DOMAIN_ID? `vmas-ros topics` lists what there is)")
        received: list = []
        # best effort accepts both reliable and best-effort publishers
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        tool.node.create_subscription(message_class(types[0]), name, received.append, qos)
        printed = 0

        def printed_enough():
            nonlocal printed
            while received and printed < count:
                out(to_yaml(received.pop(0)))
                out("---")
                printed += 1
            return True if printed >= count else None

        tool.wait_until(printed_enough, max(0.0, deadline - time.monotonic()))
        if not printed:
            raise ToolError(f"no message on {name} ({types[0]}) within {timeout:g} s")
        return printed
