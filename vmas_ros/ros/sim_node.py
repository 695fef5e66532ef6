"""``sim_node``: the batched simulator as an ordinary ROS 2 node.

It owns one vectorized environment, steps it on a timer and speaks standard
messages for one chosen env of the batch (``env_index``):

publishes  <agent>/pose (PoseStamped), <agent>/odom (Odometry), <agent>/scan
           (LaserScan per lidar), <agent>/goal (PoseStamped, agents with a goal),
           agents/poses and landmarks/poses (PoseArray),
           world/markers (MarkerArray), /clock, and /tf where tf2_msgs exists;
           <agent>/observation and <agent>/reward for learned policies (policy_io.py);
subscribes <agent>/cmd_vel (Twist, or TwistStamped), body frame per REP 103,
           and <agent>/action (the raw action vector);
services   ~/reset (Trigger), ~/pause (SetBool), ~/step (Trigger).

All stamps are simulation time, which advances by the world's dt per step.
No physics lives here: this file converts tensors to messages and back. The
engine hands over the published env after each step as one host vector
(simulator/env_snapshot.py, read through env_snapshot.PublishedEnv), the per-step
state topics are filled in bulk as pre-serialised bytes (publish.py), and
unpaced (real_time_factor 0) the node runs several steps per timer callback.
"""
from __future__ import annotations

if __name__ == "__main__":  # run as a program: a signal during the heavy imports below must end it cleanly
    from vmas_ros.ros.signal_guard import guard

    guard("sim_node")

import sys  # noqa: E402 - after the guard on purpose
import time
from typing import Dict, List, Optional

import torch
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from vmas_ros.envs.make_env import make_env
from vmas_ros.ros import convert, sim_setup
from vmas_ros.simulator import env_snapshot
from vmas_ros.ros.command import CommandGate, command_to_action
from vmas_ros.ros.lifecycle import ConfigError, RecordingStopped
from vmas_ros.ros.message_types import type_name
from vmas_ros.ros.params import SIM_PARAMS, SimParams, resolve_device, run_checked
from vmas_ros.ros.policy_io import AgentTopics, policy_actions, start_policy
from vmas_ros.ros.publish import StatePublisher, StateMessages, StepPhases
from vmas_ros.ros.stepping import StepLoop
from vmas_ros.ros.topic_audit import QosAudit, TopicAudit, quiet_subscription_events
from vmas_ros.scenarios import make_heuristic
from vmas_ros.simulator.compile_default import compile_by_default
from vmas_ros.simulator.heuristic_policy import heuristic_actions
from vmas_ros.simulator.threads import limit_threads_for_small_batches

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Twist, TwistStamped
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import Marker, MarkerArray

from geometry_msgs.msg import TransformStamped

try:  # a full ROS install has tf2_msgs; the PyPI wheels do not
    from tf2_msgs.msg import TFMessage
except ImportError:  # pragma: no cover - depends on the installation
    TFMessage = None

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
#: a best-effort subscriber accepts reliable and best-effort publishers alike
ACCEPT_ANY = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)


def _stamp(nanoseconds: int) -> Time:
    return Time(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)


class SimNode(StepLoop, Node):
    """Steps a vectorized environment and publishes env ``env_index`` as ROS messages."""

    def __init__(self, **overrides) -> None:
        super().__init__("sim_node")
        # control: policy takes the scenario the policy names, unless one was given: rclpy's overrides of
        # this node hold exactly what the command line and parameter files gave it (see sim_setup)
        given = {name: parameter.value for name, parameter in getattr(self, "_parameter_overrides", {}).items()}
        overrides = {**overrides, **sim_setup.parameters_from_policy(overrides, given, self.get_logger())}
        self.params = SIM_PARAMS.declare(self, SimParams, overrides,
                                         cross=("env_index", "control", "lidar_angle_max", "lidar_range_min"))
        SIM_PARAMS.log_refusals(self, lambda: self.params)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._build_env()
        self._build_io()
        self.paused = False
        self.steps = 0
        self._dt_ns = round(self.env.world.dt * 1e9)
        self._commands: Dict[int, tuple] = {}  # agent index -> (vx, vy, wz, wall time)
        self._command_gate = CommandGate(self.get_logger(), self.agent_names)  # NaN/inf/huge: dropped, named
        self.rewards = None
        self._zero_actions: Optional[List[torch.Tensor]] = None  # see _actions
        self.foxglove = self._start_foxglove()
        self.recorder = self._start_recorder()
        self._publish()
        self._timer = self.create_timer(self.params.step_period(self.env.world.dt), self._tick)
        self.get_logger().info(
            f"sim_node: scenario {self.params.scenario} with {self.env.n_agents} agents, "
            f"{self.params.num_envs} envs on {self.env.device}, publishing env {self.params.env_index}; "
            + self._drive_hint()
        )

    def _drive_hint(self) -> str:
        if self.per_agent:
            return f"drive with <agent>/cmd_vel, e.g. /{self.agent_names[0]}/cmd_vel"
        taking = ", ".join(self.agent_names[i] for i in self.cmd_vel_agents) or "none (cmd_vel_agents)"
        return (f"per-agent topics off (per_agent_topics): the swarm is in agents/poses and lidar/points; "
                f"agents taking cmd_vel: {taking}")

    # ----------------------------------------------------------------- parameters
    def _on_set_parameters(self, parameters) -> SetParametersResult:
        if reason := SIM_PARAMS.refuse_change(parameters, self.params):
            return SetParametersResult(successful=False, reason=reason)  # logged by log_refusals
        for parameter in parameters:
            setattr(self.params, parameter.name, parameter.value)
            if parameter.name in ("rate_hz", "real_time_factor"):
                self._timer.cancel()
                self._timer = self.create_timer(self.params.step_period(self.env.world.dt), self._tick)
            if parameter.name == "env_index":
                self._commands.clear()
                self.agent_topics.clear()
        return SetParametersResult(successful=True)

    # ------------------------------------------------------------------ building
    def _build_env(self) -> None:
        p = self.params
        limit_threads_for_small_batches(p.num_envs)
        try:
            device = resolve_device(p.device)
            self.env = make_env(p.scenario, num_envs=p.num_envs, device=device, seed=p.seed,
                                compile_physics=False, **p.kwargs())  # compile_physics: see below
        except (ValueError, TypeError, MemoryError) as error:  # bad kwargs, or a world too large
            raise ConfigError(f"cannot build scenario {p.scenario!r}: {error}") from None
        world = self.env.world
        self.own_lidars = sim_setup.add_node_lidars(world, p)  # add_lidar, robot_lidar
        self.policy = make_heuristic(p.scenario, **p.kwargs())
        self.obs = self.env.reset()
        self._compile_physics(world, device)
        self.lidars = sim_setup.published_lidars(world, self.own_lidars)
        # how the published env is taken after each step is the engine's choice, made here once
        self.snapshot = env_snapshot.PublishedEnv(world, self.lidars)

    def _compile_physics(self, world, device) -> None:
        """The step and its LIDAR casts through torch.compile, as ``compile_physics`` says: ``auto`` (where the
        default mode compiles) on a thread of its own while the node steps eagerly, never pausing; ``true``
        on the first step (a pause of seconds, but every step compiled, as make_env(compile_physics=True))."""
        mode = self.params.compile_mode()
        if mode == "true":
            world.compile_physics()
            self.get_logger().info("compile_physics: true: the first step compiles the step (seconds)")
        elif mode == "auto" and compile_by_default(device, self.params.num_envs):
            world.compile_physics(background=True)
            self.get_logger().info("compile_physics: auto: compiling the step in the background; "
                                   "stepping eagerly until it is ready")
        self._compile_reported = world.background_compiler is None

    def _report_compiled(self) -> None:
        """One log line when the background compile is done (called after each step until then)."""
        world = self.env.world
        compiler = world.background_compiler
        if compiler.released:
            self._compile_reported = True
            if compiler.failed:
                self.get_logger().warning(f"compile_physics: {compiler.failed} of {compiler.compiled + compiler.failed} "
                                          f"compiles failed; those parts stay eager")
            # the world's own step index: make_env + compile_physics(after_steps=N) repeats the switch offline
            self.get_logger().info(f"compile_physics: compiled step in use from step {world.compiled_from_step} "
                                   f"(compiled in {compiler.first_ready_s:.1f} s)")

    def _build_io(self) -> None:
        world = self.env.world
        self.agent_names = env_snapshot.unique_names([a.name for a in world.agents])
        self.scan_geometry = sim_setup.scan_geometry(self.lidars, self.own_lidars, self.params.lidar_range_min)
        self.frame_prefix = self._frame_prefix()
        frame = self.world_frame = self.frame_prefix + self.params.frame_id
        # a swarm's agents go out in aggregated topics only; cmd_vel stays for the agents named
        self.per_agent = self.params.per_agent(len(self.agent_names))
        self.cmd_vel_agents = self._cmd_vel_agents()
        cmd_type = TwistStamped if self.params.use_stamped_cmd_vel else Twist
        for i in self.cmd_vel_agents:
            self.create_subscription(cmd_type, f"{self.agent_names[i]}/cmd_vel", lambda msg, i=i: self._on_cmd_vel(i, msg),
                                     ACCEPT_ANY, event_callbacks=quiet_subscription_events())
        self.markers = MarkerArray()
        for k, entity in enumerate(world.entities):
            marker = Marker()
            convert.shape_marker(marker, entity, k, frame)
            self.markers.markers.append(marker)
        # poses, odometry, scans, pose arrays, markers and /clock: pre-serialised, filled in bulk (publish.py)
        self.state_messages = StateMessages(
            self.agent_names, len(world.landmarks), len(world.entities), self.scan_geometry,
            {i: [s.n_rays for s in ls] for i, ls in self.lidars.items()}, frame, self.markers,
            per_agent=self.per_agent, cloud=not self.per_agent, frame_prefix=self.frame_prefix,
            goals=sim_setup.goal_rows(world, self.env.scenario))
        self._per_env_colours = [k for k, e in enumerate(world.entities) if isinstance(e.color, torch.Tensor)]
        if self._per_env_colours:
            self.state_messages.set_colour_fields(self._per_env_colours)
        self.state_pub = StatePublisher(self, self.state_messages, RELIABLE, publish_clock=self.params.publish_clock)
        if not self.params.publish_clock:
            self.get_logger().info("publish_clock is false: /clock comes from another node; this node's stamps "
                                   "are its own simulation time")
        self.phases: Optional[StepPhases] = None  # set by `vmas-ros bench node` to time each part of a step
        self.tf_pub = None
        if TFMessage is None:
            self.get_logger().info("tf2_msgs is not installed: /tf is not published (poses and odometry are)")
        elif self.per_agent:
            self.tf_pub = self.create_publisher(TFMessage, "/tf", RELIABLE)
        self.agent_topics = AgentTopics(self, self.env, self.agent_names, RELIABLE, ACCEPT_ANY, self._send,
                                        on_action=self._record_received, topics=self.per_agent)
        self.learned = self._load_policy()
        self.topic_audit = TopicAudit.of_sim_node(self, [self.agent_names[i] for i in self.cmd_vel_agents],
                                                  self.params.use_stamped_cmd_vel)
        self.qos_audit = QosAudit(self, [*self.state_pub.publishers, *self.agent_topics.obs_pubs,
                                         *self.agent_topics.reward_pubs])
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_service(SetBool, "~/pause", self._on_pause)
        self.create_service(Trigger, "~/step", self._on_step)

    def _frame_prefix(self) -> str:
        """``frame_prefix``, with ``auto`` as the namespace (``/swarm_a`` -> ``swarm_a/``; the root: none)."""
        if self.params.frame_prefix != "auto":
            return self.params.frame_prefix
        namespace = self.get_namespace().strip("/")
        return f"{namespace}/" if namespace else ""

    def _cmd_vel_agents(self) -> List[int]:
        """Indices of the agents that take ``<agent>/cmd_vel``: all of them with per-agent topics, else
        those ``cmd_vel_agents`` names (refused when one is not an agent of the scenario)."""
        if self.per_agent:
            return list(range(len(self.agent_names)))
        named = self.params.cmd_vel_names()
        unknown = [n for n in named if n not in self.agent_names]
        if unknown:
            shown = ", ".join(self.agent_names[:5]) + (", ..." if len(self.agent_names) > 5 else "")
            raise ConfigError(f"cmd_vel_agents: {', '.join(unknown)} not among the scenario's agents ({shown})")
        return [self.agent_names.index(n) for n in named]

    def _load_policy(self):
        try:
            return start_policy(self.get_logger(), self.params, self.env, self.agent_names)
        except (ValueError, ImportError) as error:
            raise ConfigError(f"policy_path: {error}") from None

    def _record_received(self, topic: str, msg) -> None:
        if self.recorder is not None:  # the bag keeps every command, whichever way it came
            with self.recorder.batch():
                self._record(topic, msg, qos="best_effort")

    def _start_foxglove(self):
        """The live Foxglove server, when ``foxglove_port`` is set (0: off)."""
        p = self.params
        if p.foxglove_port == 0:
            return None
        from vmas_ros.viz.foxglove_bridge import FoxgloveBridge

        try:
            bridge = FoxgloveBridge(  # a swarm: the scene shows every agent, no channels per agent
                host=p.foxglove_host, port=p.foxglove_port, frame_id=self.world_frame,
                frame_prefix=self.frame_prefix,
                agent_names=self.agent_names if self.per_agent else (), on_twist=self._on_foxglove_twist,
            )
        except (RuntimeError, OSError) as error:
            from vmas_ros.ros.port_owner import listener_of

            holder = listener_of(p.foxglove_port)
            used = f"; the port is in use by {holder}: give this node a foxglove_port of its own" if holder else ""
            raise ConfigError(f"cannot start the Foxglove server on {p.foxglove_host}:{p.foxglove_port}: "
                              f"{error}{used}") from None
        if p.foxglove_host not in ("127.0.0.1", "localhost", "::1"):
            self.get_logger().warning(
                f"Foxglove server listens on {p.foxglove_host}: anyone who reaches that address can watch "
                f"and drive the simulation"
            )
        from vmas_ros.viz.foxglove_layout import layout_command

        agents = self.agent_names if self.per_agent else self.agent_names[:1]
        command = layout_command(self.frame_prefix, p.frame_id, agents)
        self.get_logger().info(f"Foxglove: open {bridge.url} in Foxglove (layout: "
                               f"{'config/foxglove_layout.json' if command is None else 'make it with: ' + command})")
        return bridge

    def _start_recorder(self):
        """A bag of everything published and received, when ``record_path`` is set."""
        p = self.params
        self._recording_failure = None
        if not p.record_path:
            return None
        from vmas_ros.record import McapRecorder, RecordingExists, RecordingInUse

        try:
            recorder = McapRecorder(
                p.record_path, topics=p.recorded_topics(), overwrite=p.record_overwrite,
                max_bytes=int(p.record_max_mb * 1e6) or None, max_duration_s=p.record_max_duration_s or None,
                on_failure=self._on_recording_failure,
            )
        except RecordingInUse as error:
            raise ConfigError(f"record_path: {error.path} is being recorded by {error.holder}; give this node "
                              f"a record_path of its own") from None
        except RecordingExists as error:
            raise ConfigError(f"record_path: {error.path} exists ({error.what}); choose another path or set "
                              f"record_overwrite:=true to replace it") from None
        except (OSError, ValueError) as error:
            raise ConfigError(f"cannot record to {p.record_path!r}: {error}") from None
        kind = "MCAP file" if p.record_path.endswith(".mcap") else "rosbag2 bag folder"
        self.get_logger().info(f"recording to {recorder.bag} ({kind})")
        return recorder

    def _on_recording_failure(self, failure) -> None:
        # any thread that wrote (the step, a subscription, Foxglove's): the step acts on it
        self._recording_failure = failure

    def _check_recording(self) -> None:
        """After a write error: go on without the bag, or stop (``record_on_error``); said in one line."""
        failure, self._recording_failure = self._recording_failure, None
        if failure is None:
            return
        self.recorder = None
        if self.params.record_on_error == "stop":
            raise RecordingStopped(f"{failure} (record_on_error: stop)")
        self.get_logger().error(f"{failure}; the simulation goes on without recording (record_on_error: continue)")

    def _record(self, topic: str, message, qos: str = "reliable", stamp_ns: Optional[int] = None) -> None:
        """Write ``message`` to the bag, stamped ``stamp_ns`` (default: now in simulation time)."""
        if self.recorder is not None:
            stamp_ns = self.sim_time_ns if stamp_ns is None else stamp_ns
            self.recorder.write(self._topic(topic), type_name(type(message)), message, stamp_ns, qos=qos)

    def _topic(self, name: str) -> str:
        return name if name.startswith("/") else f"/{name}"

    def _on_foxglove_twist(self, agent_index: int, vx: float, vy: float, wz: float) -> None:
        # runs on the Foxglove server's thread: one dict assignment, read by the step
        if self._command_gate.refuse(agent_index, (vx, vy, wz), "Foxglove"):
            return
        self._commands[agent_index] = (vx, vy, wz, time.monotonic())
        if self.recorder is not None:
            twist = Twist()
            twist.linear.x, twist.linear.y, twist.angular.z = vx, vy, wz
            self._record_received(f"{self.agent_names[agent_index]}/cmd_vel", twist)

    def destroy_node(self):
        if getattr(self, "foxglove", None) is not None:
            self.foxglove.close()
        recorder = getattr(self, "recorder", None)
        if recorder is not None:
            recorder.close()  # the bag is finished and readable after SIGINT/SIGTERM
            if recorder.failure is None:
                self.get_logger().info(f"bag closed: {recorder.describe()}")
            else:  # finishing it failed (disk full, the folder vanished): said once
                self.get_logger().error(str(recorder.failure))
        return super().destroy_node()

    # ------------------------------------------------------------------ commands
    def _on_cmd_vel(self, agent_index: int, msg) -> None:
        twist = msg.twist if isinstance(msg, TwistStamped) else msg
        values = (twist.linear.x, twist.linear.y, twist.angular.z)
        topic = f"{self.get_namespace().rstrip('/')}/{self.agent_names[agent_index]}/cmd_vel"
        if self._command_gate.refuse(agent_index, values, topic):
            return
        self._commands[agent_index] = (*values, time.monotonic())
        self._record_received(f"{self.agent_names[agent_index]}/cmd_vel", msg)

    def _actions(self) -> List[torch.Tensor]:
        env, p = self.env, self.params
        if p.control == "heuristic":
            actions = heuristic_actions(self.policy, env, self.obs)
        elif p.control == "policy":
            actions = policy_actions(self.learned, self.obs, self.agent_topics.bounds)
        else:  # zero: the same zero tensors every step (never written: a command writes into a copy)
            if self._zero_actions is None:
                self._zero_actions = [torch.zeros(env.num_envs, env.get_agent_action_size(a), device=env.device)
                                      for a in env.agents]
            actions = list(self._zero_actions)
        now = time.monotonic()
        for i, entry in list(self._commands.items()):
            vx, vy, wz, received = entry
            if now - received > p.cmd_vel_timeout:
                # stale: the fallback drives this agent (unless a newer command just arrived)
                if self._commands.get(i) is entry:
                    del self._commands[i]
                continue
            agent = env.agents[i]
            row = command_to_action(agent, env.world, p.env_index, (vx, vy), wz)
            actions[i] = actions[i].clone()
            actions[i][p.env_index, : row.numel()] = row
        return self.agent_topics.apply(actions, p.env_index, p.cmd_vel_timeout, self._commands)

    # ---------------------------------------------------------------------- step
    # (the step loop and its publishing: stepping.StepLoop)
    def _send(self, publisher, message) -> None:
        publisher.publish(message)
        if self.recorder is not None:
            self._step_records.append((publisher.topic_name, type_name(type(message)), message))

    def _record_payload(self, topic: str, kind: str, payload: bytes) -> None:
        self._step_records.append((topic, kind, payload))

    def _publish_tf(self, snap, stamp_ns: int) -> None:
        """/tf where tf2_msgs exists; without it, only the bag gets /tf (serialised from its definition)."""
        self._tf_bytes = None
        if not self.per_agent or (self.tf_pub is None and self.recorder is None):
            return  # a swarm's frames would cost a message per agent each step: agents/poses has them
        stamp, n_landmarks = _stamp(stamp_ns), len(self.env.world.landmarks)
        transforms = []
        for i, name in enumerate(self.agent_names):
            x, y, yaw = snap.pos[n_landmarks + i, 0], snap.pos[n_landmarks + i, 1], snap.rot[n_landmarks + i]
            tf = TransformStamped()
            tf.header.stamp, tf.header.frame_id = stamp, self.world_frame
            tf.child_frame_id = f"{self.frame_prefix}{name}/base_link"
            tf.transform.translation.x, tf.transform.translation.y = float(x), float(y)
            r = tf.transform.rotation
            r.x, r.y, r.z, r.w = env_snapshot.yaw_to_quaternion(float(yaw))
            transforms.append(tf)
        if transforms and self.tf_pub is not None:
            self._send(self.tf_pub, TFMessage(transforms=transforms))
        elif transforms:
            from vmas_ros.record import serialize_tf_message

            self._tf_bytes = serialize_tf_message(transforms)

    @property
    def sim_time_ns(self) -> int:
        """Simulation time as an exact integer: steps x dt (no float drift over long runs)."""
        return self.steps * self._dt_ns

    # ------------------------------------------------------------------ services
    def _on_reset(self, request, response):
        self.obs, self.rewards = self.env.reset(), None  # no reward until the next step
        self._commands.clear()
        self.agent_topics.clear()
        self._publish()
        response.success, response.message = True, f"reset {self.env.num_envs} envs"
        return response

    def _on_pause(self, request, response):
        self.paused = bool(request.data)
        response.success, response.message = True, "paused" if self.paused else "running"
        return response

    def _on_step(self, request, response):
        if not self.paused:
            response.success, response.message = False, "not paused: call ~/pause with data=true first"
            return response
        self.step_once()
        response.success, response.message = True, f"stepped to t={self.sim_time_ns / 1e9:.3f} s"
        return response


def main(argv: Optional[List[str]] = None) -> int:
    """Entry point of ``ros2 run vmas_ros sim_node`` (and ``sim_node`` on PATH)."""
    return run_checked("sim_node", SimNode, argv, SIM_PARAMS)


if __name__ == "__main__":
    sys.exit(main())
