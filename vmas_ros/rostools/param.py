"""``vmas-ros param list|get|set|describe NODE [NAME [VALUE]]``: a node's parameters.

Works with any ROS 2 node through its parameter services
(``rcl_interfaces``), as ``ros2 param`` does. ``set`` reads VALUE as YAML
(``1`` an integer, ``1.5`` a double, ``true`` a bool, ``[1, 2]`` an array,
anything else a string) and, where the parameter is declared as a double,
takes an integer as that double. The node may refuse a value; its reason is
printed and the exit code is 1.
"""
from __future__ import annotations

import difflib
from typing import Callable, List, Optional

from vmas_ros.rostools.graph import ToolError, call_service, resolve_name, tool_node

__all__ = ["describe_parameter", "get_parameter", "list_parameters", "parse_value", "set_parameter"]


def _type_name(code: int) -> str:
    """``rcl_interfaces/ParameterType`` code -> its name as ros2 prints it (``integer array``)."""
    from rcl_interfaces.msg import ParameterType

    for attribute in dir(ParameterType):
        if attribute.startswith("PARAMETER_") and getattr(ParameterType, attribute) == code:
            return attribute[len("PARAMETER_"):].lower().replace("_", " ")
    return str(code)


def parse_value(text: str):
    """A parameter value from the command line, read as YAML the way ``ros2 param set`` reads it."""
    import yaml

    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        return text
    return text if value is None or isinstance(value, dict) else value


def _names(tool, node: str, timeout: float) -> List[str]:
    from rcl_interfaces.srv import ListParameters

    response = call_service(tool, ListParameters, f"{node}/list_parameters", ListParameters.Request(), timeout)
    return sorted(response.result.names)


def _unknown(node: str, name: str, names: List[str]) -> ToolError:
    close = difflib.get_close_matches(name, names, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else f"; it has: {', '.join(names)}"
    return ToolError(f"{node} has no parameter {name!r}{hint}")


def _descriptor(tool, node: str, name: str, timeout: float):
    from rcl_interfaces.msg import ParameterType
    from rcl_interfaces.srv import DescribeParameters

    response = call_service(tool, DescribeParameters, f"{node}/describe_parameters",
                            DescribeParameters.Request(names=[name]), timeout)
    if not response.descriptors or response.descriptors[0].type == ParameterType.PARAMETER_NOT_SET:
        raise _unknown(node, name, _names(tool, node, timeout))
    return response.descriptors[0]


def list_parameters(node: str, timeout: float = 10.0, namespace: str = "/",
                    out: Callable[[str], None] = print) -> List[str]:
    """Print the names of ``node``'s parameters, sorted, one per line."""
    node = resolve_name(node, namespace)
    with tool_node("vmas_ros_param") as tool:
        names = _names(tool, node, timeout)
    for name in names:
        out(name)
    return names


def get_parameter(node: str, name: str, timeout: float = 10.0, namespace: str = "/",
                  out: Callable[[str], None] = print):
    """Print and return the value of ``node``'s parameter ``name``."""
    from rcl_interfaces.msg import ParameterType
    from rcl_interfaces.srv import GetParameters
    from rclpy.parameter import parameter_value_to_python

    node = resolve_name(node, namespace)
    with tool_node("vmas_ros_param") as tool:
        response = call_service(tool, GetParameters, f"{node}/get_parameters", GetParameters.Request(names=[name]),
                                timeout)
        if not response.values or response.values[0].type == ParameterType.PARAMETER_NOT_SET:
            raise _unknown(node, name, _names(tool, node, timeout))
    value = parameter_value_to_python(response.values[0])
    out(f"{name}: {value!r}")
    return value


def set_parameter(node: str, name: str, text: str, timeout: float = 10.0, namespace: str = "/",
                  out: Callable[[str], None] = print):
    """Set ``node``'s parameter ``name`` to ``text`` (read as YAML); returns the value sent.

    Raises :class:`ToolError` naming the node's reason when it refuses.
    """
    from rcl_interfaces.msg import ParameterType
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter

    node = resolve_name(node, namespace)
    value = parse_value(text)
    with tool_node("vmas_ros_param") as tool:
        descriptor = _descriptor(tool, node, name, timeout)
        if descriptor.type == ParameterType.PARAMETER_DOUBLE and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)  # a double given as 1
        try:
            message = Parameter(name, value=value).to_parameter_msg()
        except TypeError as error:
            raise ToolError(f"{text!r} is not a parameter value: {error}", 2) from error
        request = SetParameters.Request(parameters=[message])
        result = call_service(tool, SetParameters, f"{node}/set_parameters", request, timeout).results[0]
    if not result.successful:
        raise ToolError(f"{node} refused {name}={value!r}: {result.reason or 'no reason given'}")
    out(f"set {name} to {value!r}")
    return value


def describe_parameter(node: str, name: str, timeout: float = 10.0, namespace: str = "/",
                       out: Callable[[str], None] = print) -> Optional[object]:
    """Print what ``node`` says about parameter ``name``: type, description, ranges, read-only."""
    node = resolve_name(node, namespace)
    with tool_node("vmas_ros_param") as tool:
        d = _descriptor(tool, node, name, timeout)
    out(f"Parameter name: {name}")
    out(f"  Type: {_type_name(d.type)}")
    if d.description:
        out(f"  Description: {d.description}")
    if d.additional_constraints:
        out(f"  Constraints: {d.additional_constraints}")
    for kind, ranges in (("Integer range", d.integer_range), ("Floating point range", d.floating_point_range)):
        for r in ranges:
            step = f", step {r.step:g}" if r.step else ""
            out(f"  {kind}: {r.from_value:g} to {r.to_value:g}{step}")
    out(f"  Read only: {d.read_only}")
    return d
