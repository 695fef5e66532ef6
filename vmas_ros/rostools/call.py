"""``vmas-ros call SERVICE [true|false]``: call a ``std_srvs`` Trigger or SetBool service.

These are the services sim_node offers (``reset``, ``pause``, ``step``), and
the common ones of other ROS 2 nodes. The reply's ``success`` decides the exit
code, so scripts can tell a refusal from an answer.
"""
from __future__ import annotations

from typing import Callable, Optional

from vmas_ros.rostools.graph import ToolError, call_service, resolve_name, service_type, tool_node

__all__ = ["call", "SUPPORTED"]

SUPPORTED = ("std_srvs/srv/Trigger", "std_srvs/srv/SetBool", "std_srvs/srv/Empty")
_BOOLS = {"true": True, "1": True, "on": True, "false": False, "0": False, "off": False}


def call(service: str, value: Optional[str] = None, timeout: float = 10.0, namespace: str = "/",
         out: Callable[[str], None] = print) -> bool:
    """Call ``service`` (SetBool with ``value`` ``true``/``false``) and print its reply.

    Returns the reply's ``success`` (True for Empty); raises :class:`ToolError`
    for a missing service, an unsupported type or a bad ``value``.
    """
    from std_srvs.srv import Empty, SetBool, Trigger

    name = resolve_name(service, namespace)
    with tool_node("vmas_ros_call") as tool:
        kind = service_type(tool, name, timeout)
        if kind not in SUPPORTED:
            raise ToolError(f"{name} is a {kind} service; vmas-ros call supports {', '.join(SUPPORTED)} "
                            f"(with a full ROS install: ros2 service call)", 2)
        if kind == "std_srvs/srv/SetBool":
            if value is None or value.lower() not in _BOOLS:
                raise ToolError(f"{name} is a SetBool service: give true or false, got {value!r}", 2)
            request = SetBool.Request(data=_BOOLS[value.lower()])
            srv_type = SetBool
        elif value is not None:
            raise ToolError(f"{name} is a {kind.rsplit('/', 1)[-1]} service and takes no value, got {value!r}", 2)
        else:
            srv_type = Trigger if kind == "std_srvs/srv/Trigger" else Empty
            request = srv_type.Request()
        response = call_service(tool, srv_type, name, request, timeout)
    if srv_type is Empty:
        out(f"{name}: done")
        return True
    out(f"{name}: success={response.success} message={response.message!r}")
    return bool(response.success)
