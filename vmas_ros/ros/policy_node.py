"""``policy_node``: an exported policy as a ROS 2 node, for sim_node or real robots.

It loads ``<stem>.json`` + ``<stem>.onnx`` (``vmas_ros.policy.OnnxPolicy``),
builds every agent's observation from ROS messages through an observation
adapter (default: sim_node's ``<agent>/observation``), and publishes, at
``rate_hz`` or (``act_on: scan``) as soon as every robot's new scan is in
(``policy_trigger.py``), either ``<agent>/action``
(std_msgs/Float32MultiArray, the raw action vector sim_node takes) or, with
``output: cmd_vel``, ``<agent>/cmd_vel``: a body-frame twist (REP 103) as
geometry_msgs/Twist or, with ``use_stamped_cmd_vel``, TwistStamped (Jazzy's
diff_drive_controller).
How an action becomes a twist (rotation by the odometry's heading, a point
ahead of a diff-drive base's wheel axis, limits) is in ``policy_commands.py``.

An input older than ``observation_timeout`` (wall-clock age since it
arrived) is not acted on: a robot whose sensors stopped must not keep
receiving commands computed from the past. An agent without a usable
observation, or without fresh finite odometry when its command needs the
heading, gets nothing (sim_node's ``cmd_vel_timeout``, or the robot's own
command timeout, then stops it), and a throttled warning names the robot and
what is wrong (``policy_inputs.py``). A publisher of the wrong message type on
an input topic (which ROS never delivers) is named once in a warning, with the
type expected (``topic_audit.py``, as sim_node does for its commands).
"""
from __future__ import annotations

if __name__ == "__main__":  # run as a program: a signal during the heavy imports below must end it cleanly
    from vmas_ros.ros.signal_guard import guard

    guard("policy_node")

import sys  # noqa: E402 - after the guard on purpose
import time
from typing import Any, Dict, List, Optional, Tuple

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from vmas_ros.adapters import load_adapter
from vmas_ros.simulator.env_snapshot import unique_names
from vmas_ros.ros.lifecycle import ConfigError
from vmas_ros.ros.params import POLICY_PARAMS, PolicyNodeParams, run_checked
from vmas_ros.ros.policy_commands import CommandLimiter, body_commands, needs_heading, resolve_action_kind
from vmas_ros.ros.policy_inputs import AgentInputs
from vmas_ros.ros.policy_outputs import ActionOutput, CmdVelOutput
from vmas_ros.ros.policy_trigger import ScanTrigger, scan_topics
from vmas_ros.ros.topic_audit import TopicAudit

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
#: accepts reliable and best-effort publishers (sensor drivers often publish best effort)
ACCEPT_ANY = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
WARN_PERIOD = 2.0


class PolicyNode(Node):
    """Runs one exported policy for all its agents, at a fixed rate or when new scans arrive."""

    def __init__(self, **overrides: Any) -> None:
        super().__init__("policy_node")
        self.params = POLICY_PARAMS.declare(self, PolicyNodeParams, overrides)
        POLICY_PARAMS.log_refusals(self, lambda: self.params)
        self.policy = self._load_policy()
        self.agent_names = unique_names(self.policy.agents)
        try:
            self.adapter = load_adapter(self.params.adapter, self.agent_names, self.policy.observation_size,
                                        self.params.kwargs(), self.policy.metadata.get("scenario_kwargs") or {})
            topics = dict(self.adapter.topics())
        except ValueError as error:
            raise ConfigError(f"adapter: {error}") from None
        self.action_kind, why = resolve_action_kind(self.params.action_kind, self.policy.metadata)
        odom_topics = None
        if self.params.output == "cmd_vel" and needs_heading(self.action_kind):
            from nav_msgs.msg import Odometry

            odom_topics = [self.params.odom_topic.replace("{agent}", a) for a in self.agent_names]
            for topic in odom_topics:
                if topics.setdefault(topic, Odometry) is not Odometry:
                    raise ConfigError(f"odom_topic: {topic} is read by the adapter as {topics[topic].__name__}, "
                                      f"not nav_msgs/Odometry")
        #: topics whose last message stands until replaced (goals): never too old to act on
        self.standing = set(getattr(self.adapter, "standing_topics", lambda: ())())
        self.trigger_topics = self._trigger_topics(topics)
        self.inputs = AgentInputs(self.agent_names, topics, odom_topics, lambda: self.params.observation_timeout)
        self.latest: Dict[str, Tuple[Any, float]] = {}  # topic -> (message, monotonic arrival)
        inputs = [self.create_subscription(msg_type, topic, lambda msg, t=topic: self._on_message(t, msg), ACCEPT_ANY)
                  for topic, msg_type in topics.items()]
        # a publisher of another type on an input never matches: ROS drops it silently, so name it
        self.topic_audit = TopicAudit.of_inputs(self, inputs, "policy_node")
        self.output = self._build_output()
        self.limiter = CommandLimiter(len(self.agent_names), period=1.0 / self.params.rate_hz,
                                      memory=max(self.params.observation_timeout, 2.0 / self.params.rate_hz))
        self._set_limits()
        self._warned: Dict[str, float] = {}
        self._started = time.monotonic()
        self.published = 0
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.trigger: Optional[ScanTrigger] = None
        if self.trigger_topics:
            self.trigger = ScanTrigger(self, self.trigger_topics, self._tick, lambda: 1.0 / self.params.rate_hz,
                                       lambda: self.params.observation_timeout, time.monotonic)
            # with no scans at all nothing acts, so nothing would say what is missing: this does
            self._idle = self.create_timer(WARN_PERIOD, self._check_idle)
            when = self.trigger.describe()
        else:
            self._timer = self.create_timer(1.0 / self.params.rate_hz, self._tick)
            when = f"at {self.params.rate_hz} Hz"
        given = self.params.kwargs()
        adapter = f" (adapter {self.params.adapter}, adapter_kwargs {given})" if given else ""
        self.get_logger().info(
            f"policy_node: {self.policy!r} for {self.agent_names}, reading {sorted(topics)}{adapter}, "
            f"publishing {self.output.type_name} on <agent>/{self.output.topic} {when}" + self._command_note(why)
        )

    def _command_note(self, why: str) -> str:
        if self.params.output != "cmd_vel":
            return ""
        p = self.params
        frame = (f"world-frame velocity actions rotated into each robot's body frame by the heading in "
                 f"{p.odom_topic.replace('{agent}', '<agent>')}" if self.action_kind == "world_velocity" else
                 "actions already in the body frame" if self.action_kind == "body_velocity" else
                 "(speed, turn rate) actions, already in the body frame")
        base = (f"; diff-drive base: linear.x and angular.z, velocities tracked {p.lookahead} m ahead of the "
                f"wheel axis" if p.base == "diff_drive" and self.action_kind != "speed_turn" else
                f"; {p.base} base")
        return f"; commands from {frame} ({self.action_kind}: {why}){base}, scaled by {p.cmd_vel_scale}"

    # ----------------------------------------------------------------- set-up
    def _trigger_topics(self, topics: Dict[str, type]) -> List[str]:
        """``act_on: scan``: the adapter's scan topics, whose arrivals trigger actions (timer: none)."""
        if self.params.act_on != "scan":
            return []
        found = scan_topics(topics)
        if not found:
            adapter = self.params.adapter or "(default: <agent>/observation)"
            raise ConfigError(f"act_on: scan needs scans to act on, but adapter {adapter} reads no "
                              f"sensor_msgs/LaserScan topic (it reads {', '.join(sorted(topics))}); use act_on: timer")
        return found

    def _load_policy(self):
        from vmas_ros.policy.onnx_policy import OnnxPolicy

        try:
            return OnnxPolicy.load(self.params.policy_path)
        except Exception as error:  # JSON, checksum, onnxruntime: all mean "cannot use it"
            raise ConfigError(f"policy_path: cannot load {self.params.policy_path!r}: {error}") from None

    def _build_output(self):
        p = self.params
        if p.output == "action":
            return ActionOutput(self, self.agent_names, self.policy.action_size, RELIABLE)
        if self.policy.action_size < 2:
            raise ConfigError(f"output: cmd_vel needs actions of >= 2 components, the policy has "
                              f"{self.policy.action_size}")
        frames = [p.cmd_vel_frame_id.replace("{agent}", a) for a in self.agent_names]
        return CmdVelOutput(self, self.agent_names, RELIABLE, p.use_stamped_cmd_vel, frames)

    def _set_limits(self) -> None:
        for name in ("max_linear_speed", "max_angular_speed", "max_linear_accel", "max_angular_accel"):
            setattr(self.limiter, name, getattr(self.params, name))

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        if reason := POLICY_PARAMS.refuse_change(parameters, self.params):
            return SetParametersResult(successful=False, reason=reason)  # logged by log_refusals
        for parameter in parameters:
            setattr(self.params, parameter.name, float(parameter.value))
            if parameter.name == "rate_hz":
                if self.trigger is not None:
                    self.trigger.set_period()
                else:
                    self._timer.cancel()
                    self._timer = self.create_timer(1.0 / self.params.rate_hz, self._tick)
                self.limiter.period = 1.0 / self.params.rate_hz
        self._set_limits()
        return SetParametersResult(successful=True)

    # ---------------------------------------------------------------- running
    def _on_message(self, topic: str, msg: Any) -> None:
        self.latest[topic] = (msg, time.monotonic())
        if self.trigger is not None and topic in self.trigger_topics:
            self.trigger.on_scan(topic)  # may act right here, in this callback

    def _check_idle(self) -> None:
        """``act_on: scan`` with no action for a while: judge the inputs (and warn) without acting."""
        if time.monotonic() - self.trigger.last_action >= WARN_PERIOD:
            self._tick(act=False)

    def _warn(self, key: str, text: str) -> None:
        now = time.monotonic()
        if now - self._warned.get(key, 0.0) >= WARN_PERIOD:
            self._warned[key] = now
            self.get_logger().warning(text)

    def fresh_messages(self) -> Dict[str, Any]:
        """Messages not older than ``observation_timeout``, and the last one of each standing topic (goals)."""
        now, limit = time.monotonic(), self.params.observation_timeout
        return {topic: msg for topic, (msg, received) in self.latest.items()
                if now - received <= limit or topic in self.standing}

    def _tick(self, act: bool = True) -> None:
        """Build the observations, name the agents that get no command and (``act``) command the others."""
        if not self.context.ok():
            return
        fresh = self.fresh_messages()
        obs = np.asarray(self.adapter.build(fresh), dtype=np.float32)
        expected = (len(self.agent_names), self.policy.observation_size)
        if obs.shape != expected:
            self._warn("shape", f"adapter built observations of shape {obs.shape}, expected {expected}")
            return
        yaw = self.inputs.headings(fresh)
        reasons = self.inputs.reasons(fresh, self.latest, np.isfinite(obs).all(axis=1), yaw,
                                      getattr(self.adapter, "problems", None) or {}, self.count_publishers)
        if reasons and time.monotonic() - self._started > WARN_PERIOD:  # let discovery finish before naming
            for i, why in reasons.items():
                self._warn(self.agent_names[i], f"no command for {self.agent_names[i]}: {why}")
        usable = np.array([i not in reasons for i in range(len(self.agent_names))])
        if not act or not usable.any():
            return
        actions = self.policy.act(np.where(usable[:, None], obs, 0.0)[None])[0]
        self.publish(actions, usable, yaw)

    def publish(self, actions: np.ndarray, usable: np.ndarray, yaw: np.ndarray) -> None:
        """One message per agent in ``usable`` ``[n]``, from its action ``[n, action_size]``."""
        if self.params.output == "cmd_vel":
            p = self.params
            twist = body_commands(actions, yaw, self.action_kind, p.base, p.cmd_vel_scale, p.lookahead)
            actions = self.limiter.limit(twist, usable, time.monotonic())
        for i in np.flatnonzero(usable):
            self.output.send(i, actions[i])
        self.published += 1


def main(argv: Optional[List[str]] = None) -> int:
    """Entry point of ``ros2 run vmas_ros policy_node`` (and ``policy_node`` on PATH)."""
    return run_checked("policy_node", PolicyNode, argv, POLICY_PARAMS)


if __name__ == "__main__":
    sys.exit(main())
