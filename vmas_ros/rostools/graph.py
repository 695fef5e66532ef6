"""What the ROS tools share: a node per tool kept for the process, names resolved as ``ros2`` does, waiting.

Names follow ROS 2's rules: ``/a/b`` is absolute; ``a/b`` is relative and
resolves against the tool's namespace (``--namespace``, default ``/``), so
``echo agent_0/pose`` reads ``/agent_0/pose`` and, with ``--namespace
/swarm1``, ``/swarm1/agent_0/pose``.
"""
from __future__ import annotations

import atexit
import contextlib
import re
import threading
import time
from typing import Callable, Dict, Iterator, Optional, Set, TypeVar

__all__ = ["ToolError", "ToolNode", "call_service", "frame_prefix_error", "resolve_name", "service_type", "tool_node"]

T = TypeVar("T")

#: ROS 2 name tokens: letters, digits and underscores, not starting with a digit
_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


class ToolError(Exception):
    """A refusal a tool reports as one line on stderr (exit code :attr:`exit_code`)."""

    def __init__(self, message: str, exit_code: int = 1) -> None:
        super().__init__(message)
        self.exit_code = exit_code


def resolve_name(name: str, namespace: str = "/") -> str:
    """The fully qualified form of topic or service ``name`` seen from ``namespace``.

    ``/x/y`` stays as it is; ``x/y`` becomes ``<namespace>/x/y``. Raises
    :class:`ToolError` (exit code 2) for a name ROS 2 would refuse, naming it.
    """
    for what, value in (("name", name), ("namespace", namespace)):
        tokens = value.strip("/").split("/") if value.strip("/") else []
        if (what == "name" and not tokens) or not all(_TOKEN.fullmatch(t) for t in tokens) or "//" in value:
            raise ToolError(f"{value!r} is not a valid ROS 2 {what}: expected tokens of letters, digits and "
                            f"underscores separated by '/', e.g. 'agent_0/pose' or '/swarm1/agent_0/pose'", 2)
    if name.startswith("/"):
        return "/" + name.strip("/")
    base = "/" + namespace.strip("/")
    return (base.rstrip("/") + "/" + name.strip("/")) if base != "/" else "/" + name.strip("/")


def frame_prefix_error(value: str) -> Optional[str]:
    """Why ``value`` is not a frame name prefix (sim_node's ``frame_prefix``), or None when it is.

    ``auto`` and ``''`` are accepted; otherwise letters, digits, ``_`` and ``/``
    not starting with ``/`` and without ``//`` (e.g. ``robot_a/``). Shared by
    the node's parameter check and ``vmas-ros foxglove-layout``, so both refuse
    the same values with the same words.
    """
    if value == "auto" or value == "":
        return None
    if value.startswith("/") or not all(c.isalnum() or c in "_/" for c in value) or "//" in value:
        return (f"frame_prefix {value!r} is not a frame name prefix: expected 'auto', '' or letters, digits, "
                f"'_' and '/' not starting with '/', e.g. 'robot_a/'")
    return None


class ToolNode:
    """An rclpy node in a context of its own, with the executor that spins it.

    Its own context lets a tool run inside a process that already uses rclpy
    (a test, a notebook) without touching that process's default context.
    """

    def __init__(self, name: str, namespace: str = "/") -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        self.context = rclpy.Context()
        # Python's own Ctrl-C handling (KeyboardInterrupt), not rclpy's shutdown of every context
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self.context, namespace=namespace,
                                      start_parameter_services=False, enable_rosout=False)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.lock = threading.Lock()  # one tool call at a time spins this node

    def entities(self) -> Set[object]:
        """The node's publishers, subscriptions and service clients now."""
        node = self.node
        return {*node.publishers, *node.subscriptions, *node.clients}

    def destroy_created_since(self, before: Set[object]) -> None:
        """Destroy the publishers, subscriptions and clients not in ``before``."""
        node = self.node
        for publisher in [p for p in node.publishers if p not in before]:
            node.destroy_publisher(publisher)
        for subscription in [s for s in node.subscriptions if s not in before]:
            node.destroy_subscription(subscription)
        for client in [c for c in node.clients if c not in before]:
            node.destroy_client(client)

    def spin_once(self, timeout: float) -> None:
        """Run at most one ready callback, waiting up to ``timeout`` seconds for one."""
        self.executor.spin_once(timeout_sec=timeout)

    def spin_for(self, seconds: float) -> None:
        """Spin for ``seconds``: discovery and callbacks go on meanwhile."""
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            self.spin_once(min(0.05, left))

    def wait_until(self, found: Callable[[], Optional[T]], timeout: float, period: float = 0.05) -> Optional[T]:
        """Spin until ``found()`` returns something other than None, or ``timeout`` seconds pass
        (then the last None)."""
        deadline = time.monotonic() + timeout
        while True:
            value = found()
            if value is not None or time.monotonic() >= deadline:
                return value
            self.spin_once(min(period, max(0.0, deadline - time.monotonic())))

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()


_SHARED: Dict[str, ToolNode] = {}
_SHARED_LOCK = threading.Lock()


@contextlib.contextmanager
def tool_node(name: str) -> Iterator[ToolNode]:
    """This process's :class:`ToolNode` named ``name``, for the length of one tool call.

    The node outlives the call and serves the process's next call of the same
    tool: peers often see a new DDS participant only at their next periodic
    announcement, seconds later, so a test or a notebook that runs tools again
    and again would wait that long every time. What the call created
    (publishers, subscriptions, service clients) is destroyed on the way out,
    whatever happens, so no call sees another's leftovers. Calls from several
    threads take turns.
    """
    with _SHARED_LOCK:
        tool = _SHARED.get(name)
        if tool is None or not tool.context.ok():
            tool = _SHARED[name] = ToolNode(name)
    with tool.lock:
        before = tool.entities()
        try:
            yield tool
        finally:
            tool.destroy_created_since(before)


@atexit.register
def _close_shared() -> None:
    with _SHARED_LOCK:
        for tool in _SHARED.values():
            tool.close()
        _SHARED.clear()


def call_service(tool: ToolNode, srv_type, name: str, request, timeout: float):
    """Call service ``name`` once and return its response; ToolError if it does not answer in
    ``timeout`` seconds (not there, or too busy)."""
    client = tool.node.create_client(srv_type, name)
    try:
        if tool.wait_until(lambda: True if client.service_is_ready() else None, timeout) is None:
            raise ToolError(f"service {name} is not available (waited {timeout:g} s; `vmas-ros topics --services` "
                            f"lists the services there are)")
        future = client.call_async(request)
        if tool.wait_until(lambda: True if future.done() else None, timeout) is None:
            raise ToolError(f"service {name} did not answer within {timeout:g} s")
        return future.result()
    finally:
        tool.node.destroy_client(client)


def service_type(tool: ToolNode, name: str, timeout: float) -> str:
    """The type of service ``name`` (``pkg/srv/Name``) once it shows in the graph; ToolError if not."""
    found = tool.wait_until(lambda: (dict(tool.node.get_service_names_and_types()).get(name) or [None])[0], timeout)
    if found is None:
        raise ToolError(f"no service {name} appeared within {timeout:g} s (is its node running, with the same "
                        f"ROS_DOMAIN_ID? `vmas-ros topics --services` lists the services there are)")
    return found
