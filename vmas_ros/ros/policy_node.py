"""``policy_node``: an exported policy as a ROS 2 node, for sim_node or real robots.

It loads ``<stem>.json`` + ``<stem>.onnx`` (``vmas_ros.policy.OnnxPolicy``),
builds every agent's observation from ROS messages through an observation
adapter (default: sim_node's ``<agent>/observation``), and publishes at
``rate_hz`` either ``<agent>/action`` (std_msgs/Float32MultiArray, the raw
action vector sim_node takes) or, with ``output: cmd_vel``,
``<agent>/cmd_vel`` (geometry_msgs/Twist: linear.x/y = ``cmd_vel_scale`` x
the action's first two components, for velocity-controlled robots).

An observation older than ``observation_timeout`` (wall-clock age since it
arrived) is not acted on: a robot whose sensors stopped must not keep
receiving commands computed from the past. Agents without a usable
observation get nothing (sim_node's ``cmd_vel_timeout`` then stops them), and
a throttled warning names them. A publisher of the wrong message type on an
input topic (which ROS never delivers) is named once in a warning, with the
type expected (``topic_audit.py``, as sim_node does for its commands).
"""
from __future__ import annotations

if __name__ == "__main__":  # run as a program: a signal during the heavy imports below must end it cleanly
    from vmas_ros.ros.startup import guard

    guard("policy_node")

import sys  # noqa: E402 - after the guard on purpose
import time
from typing import Any, Dict, List, Optional, Tuple

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from vmas_ros.ros.adapters import load_adapter
from vmas_ros.ros.convert import unique_names
from vmas_ros.ros.lifecycle import ConfigError
from vmas_ros.ros.params import POLICY_PARAMS, PolicyNodeParams, run_checked
from vmas_ros.ros.topic_audit import TopicAudit

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
#: accepts reliable and best-effort publishers (sensor drivers often publish best effort)
ACCEPT_ANY = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
WARN_PERIOD = 2.0


class PolicyNode(Node):
    """Runs one exported policy for all its agents at a fixed rate."""

    def __init__(self, **overrides: Any) -> None:
        super().__init__("policy_node")
        self.params = POLICY_PARAMS.declare(self, PolicyNodeParams, overrides)
        POLICY_PARAMS.log_refusals(self, lambda: self.params)
        self.policy = self._load_policy()
        self.agent_names = unique_names(self.policy.agents)
        try:
            self.adapter = load_adapter(self.params.adapter, self.agent_names, self.policy.observation_size,
                                        self.params.kwargs())
            topics = dict(self.adapter.topics())
        except ValueError as error:
            raise ConfigError(f"adapter: {error}") from None
        self.latest: Dict[str, Tuple[Any, float]] = {}  # topic -> (message, monotonic arrival)
        inputs = [self.create_subscription(msg_type, topic, lambda msg, t=topic: self._on_message(t, msg), ACCEPT_ANY)
                  for topic, msg_type in topics.items()]
        # a publisher of another type on an input never matches: ROS drops it silently, so name it
        self.topic_audit = TopicAudit.of_inputs(self, inputs, "policy_node")
        self._build_outputs()
        self._warned: Dict[str, float] = {}
        self.published = 0
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._timer = self.create_timer(1.0 / self.params.rate_hz, self._tick)
        self.get_logger().info(
            f"policy_node: {self.policy!r} for {self.agent_names}, reading {sorted(topics)}, "
            f"publishing <agent>/{self.params.output} at {self.params.rate_hz} Hz"
        )

    # ----------------------------------------------------------------- set-up
    def _load_policy(self):
        from vmas_ros.policy.onnx_policy import OnnxPolicy

        try:
            return OnnxPolicy.load(self.params.policy_path)
        except Exception as error:  # JSON, checksum, onnxruntime: all mean "cannot use it"
            raise ConfigError(f"policy_path: cannot load {self.params.policy_path!r}: {error}") from None

    def _build_outputs(self) -> None:
        if self.params.output == "cmd_vel":
            from geometry_msgs.msg import Twist

            if self.policy.action_size < 2:
                raise ConfigError(f"output: cmd_vel needs actions of >= 2 components, the policy has "
                                  f"{self.policy.action_size}")
            self.messages = [Twist() for _ in self.agent_names]
            self.publishers_ = [self.create_publisher(Twist, f"{n}/cmd_vel", RELIABLE) for n in self.agent_names]
        else:
            from std_msgs.msg import Float32MultiArray, MultiArrayDimension

            size = self.policy.action_size
            self.messages = []
            for _ in self.agent_names:
                msg = Float32MultiArray()
                msg.layout.dim = [MultiArrayDimension(label="action", size=size, stride=size)]
                msg.data = [0.0] * size
                self.messages.append(msg)
            self.publishers_ = [self.create_publisher(Float32MultiArray, f"{n}/action", RELIABLE)
                                for n in self.agent_names]

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        if reason := POLICY_PARAMS.refuse_change(parameters, self.params):
            return SetParametersResult(successful=False, reason=reason)  # logged by log_refusals
        for parameter in parameters:
            setattr(self.params, parameter.name, float(parameter.value))
            if parameter.name == "rate_hz":
                self._timer.cancel()
                self._timer = self.create_timer(1.0 / self.params.rate_hz, self._tick)
        return SetParametersResult(successful=True)

    # ---------------------------------------------------------------- running
    def _on_message(self, topic: str, msg: Any) -> None:
        self.latest[topic] = (msg, time.monotonic())

    def _warn(self, key: str, text: str) -> None:
        now = time.monotonic()
        if now - self._warned.get(key, 0.0) >= WARN_PERIOD:
            self._warned[key] = now
            self.get_logger().warning(text)

    def fresh_messages(self) -> Tuple[Dict[str, Any], List[str]]:
        """Messages not older than ``observation_timeout``, and the topics that are stale."""
        now, limit = time.monotonic(), self.params.observation_timeout
        fresh, stale = {}, []
        for topic, (msg, received) in self.latest.items():
            if now - received <= limit:
                fresh[topic] = msg
            else:
                stale.append(topic)
        return fresh, stale

    def _tick(self) -> None:
        if not self.context.ok():
            return
        fresh, stale = self.fresh_messages()
        if stale:
            self._warn("stale", f"not acting on observations older than {self.params.observation_timeout} s: "
                                f"{', '.join(sorted(stale))}")
        obs = np.asarray(self.adapter.build(fresh), dtype=np.float32)
        expected = (len(self.agent_names), self.policy.observation_size)
        if obs.shape != expected:
            self._warn("shape", f"adapter built observations of shape {obs.shape}, expected {expected}")
            return
        usable = np.isfinite(obs).all(axis=1)
        if not usable.all():
            missing = [n for n, ok in zip(self.agent_names, usable) if not ok]
            self._warn("missing", f"no usable observation for {', '.join(missing)}: waiting for "
                                  f"{', '.join(sorted(set(self.adapter.topics()) - set(fresh))) or 'valid data'}")
        if not usable.any():
            return
        actions = self.policy.act(np.where(usable[:, None], obs, 0.0)[None])[0]
        self.publish(actions, usable)

    def publish(self, actions: np.ndarray, usable: np.ndarray) -> None:
        """One message per agent with a usable observation."""
        scale = self.params.cmd_vel_scale
        for i, ok in enumerate(usable):
            if not ok:
                continue
            msg = self.messages[i]
            if self.params.output == "cmd_vel":
                msg.linear.x, msg.linear.y = float(actions[i, 0]) * scale, float(actions[i, 1]) * scale
            else:
                np.frombuffer(msg.data, dtype=np.float32)[:] = actions[i]
            self.publishers_[i].publish(msg)
        self.published += 1


def main(argv: Optional[List[str]] = None) -> int:
    """Entry point of ``ros2 run vmas_ros policy_node`` (and ``policy_node`` on PATH)."""
    return run_checked("policy_node", PolicyNode, argv, POLICY_PARAMS)


if __name__ == "__main__":
    sys.exit(main())
