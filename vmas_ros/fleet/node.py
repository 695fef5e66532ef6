"""``robot_fleet``: N simulated robots, each behind Jazzy's diff_drive_controller interface.

Per robot (names from ``robot_names``, default ``agent_0``... as sim_node's agents):

* subscribes ``<robot>/cmd_vel``: geometry_msgs/TwistStamped (``use_stamped_cmd_vel:
  false``: Twist), body frame, best-effort QoS so reliable and best-effort
  publishers both reach it;
* publishes ``<robot>/odom`` (nav_msgs/Odometry: pose in ``odom_frame``, shared
  by all robots, twist in ``<robot>/base_link``), ``<robot>/scan``
  (sensor_msgs/LaserScan in ``<robot>/base_link``) and, with one goal per
  robot, ``<robot>/goal`` (PoseStamped);

and for the fleet ``agents/poses`` (the true poses) and ``goals_topic`` (every
goal) as PoseArrays, and the ``~/reset`` service (std_srvs/Trigger: end the
episode, start the next). Stamps are the node clock's (wall time).

The node only moves data: the simulation is :class:`vmas_ros.fleet.world.FleetWorld`
(numpy, no ROS), stepped by a wall-clock timer at ``rate_hz``. Nothing here
imports torch or vmas_ros's engine.
"""
from __future__ import annotations

if __name__ == "__main__":  # run as a program: a signal during the imports below must end it cleanly
    from vmas_ros.ros.signal_guard import guard

    guard("robot_fleet")

import sys  # noqa: E402 - after the guard on purpose
import time
from typing import Any, Dict, List, Optional

import numpy as np
from geometry_msgs.msg import PoseArray, PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan
from std_srvs.srv import Trigger

from vmas_ros.fleet import episodes as episode_plan
from vmas_ros.fleet import messages
from vmas_ros.fleet.commands import command_problem
from vmas_ros.fleet.params import CROSS_CHECKED, FLEET_PARAMS, FleetParams
from vmas_ros.fleet.summary import document, write_atomic
from vmas_ros.fleet.world import FleetWorld
from vmas_ros.ros.lifecycle import ConfigError
from vmas_ros.ros.topic_audit import TopicAudit

NAME = "robot_fleet"
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
#: accepts reliable and best-effort publishers (teleops and drivers use either)
ACCEPT_ANY = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
#: seconds between two warnings of one kind (a publisher of bad commands at 100 Hz must not flood the log)
WARN_PERIOD = 2.0
#: goals are published this often, and at every episode start
GOAL_PERIOD_S = 1.0
#: seconds between the last episode's end and the exit: the reply of ~/reset and the last messages get out
EXIT_GRACE_S = 0.3


class FleetNode(Node):
    """The fleet's ROS side: subscriptions to commands, timers that step and publish, ``~/reset``."""

    def __init__(self, **overrides: Any) -> None:
        super().__init__(NAME)
        self.params = p = FLEET_PARAMS.declare(self, FleetParams, overrides, cross=CROSS_CHECKED)
        self.names = p.names_list()
        try:
            planned = episode_plan.plan(p)
        except ValueError as error:
            raise ConfigError(str(error)) from None
        # two streams, so that turning scans on or off does not change the odometry's noise
        odom_seed, scan_seed = np.random.SeedSequence(p.seed).spawn(2)
        self.odom_rng, self.scan_rng = np.random.default_rng(odom_seed), np.random.default_rng(scan_seed)
        self._warned: Dict[str, float] = {}
        self._closed = False
        self._finished_at: Optional[float] = None
        self.world = FleetWorld(p, planned, time.monotonic())
        if p.summary_path:
            try:
                self._write_summary()
            except OSError as error:
                raise ConfigError(f"summary_path {p.summary_path!r} cannot be written: {error}") from None
        self._build_topics(any(e.per_robot_goals for e in planned))
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.fleet_timers = [self.create_timer(1.0 / p.rate_hz, self._step),
                             self.create_timer(1.0 / p.odom_rate_hz, self._publish_odometry),
                             self.create_timer(GOAL_PERIOD_S, self._publish_goals)]
        if p.scan_rate_hz > 0:
            self.fleet_timers.append(self.create_timer(1.0 / p.scan_rate_hz, self._publish_scans))
        self.world.resume(time.monotonic())  # the first episode's clock starts now, not while the node was built
        self.waiting = p.wait_for_commands  # see _step
        self._publish_goals()
        self.get_logger().info(self._describe(len(planned)))

    # ----------------------------------------------------------------- set-up
    def _build_topics(self, with_goals: bool) -> None:
        p = self.params
        command_type = TwistStamped if p.use_stamped_cmd_vel else Twist
        self.command_subscriptions = [
            self.create_subscription(command_type, f"{name}/cmd_vel",
                                     lambda msg, i=i: self._on_command(i, msg), ACCEPT_ANY)
            for i, name in enumerate(self.names)]
        # a publisher of the other Twist type never matches and ROS drops it silently: name it
        self.topic_audit = TopicAudit.of_inputs(self, self.command_subscriptions, NAME)
        self.odom_publishers = [self.create_publisher(Odometry, f"{name}/odom", RELIABLE) for name in self.names]
        self.odom_messages = [messages.odometry(p.odom_frame, f"{name}/base_link", p.odom_noise_position,
                                                p.odom_noise_yaw, p.odom_noise_velocity) for name in self.names]
        scans = p.scan_rate_hz > 0
        self.scan_publishers = [self.create_publisher(LaserScan, f"{name}/scan", RELIABLE)
                                for name in self.names] if scans else []
        self.scan_messages = [messages.laser_scan(f"{name}/base_link", p.scan_rays, p.scan_angle_min,
                                                  p.scan_angle_max, p.scan_range_min, p.scan_range_max,
                                                  p.scan_rate_hz) for name in self.names]
        self.goal_publishers = ([self.create_publisher(PoseStamped, f"{name}/goal", RELIABLE) for name in self.names]
                                if with_goals else [])
        self.goals_publisher = self.create_publisher(PoseArray, p.goals_topic, RELIABLE)
        self.poses_publisher = self.create_publisher(PoseArray, "agents/poses", RELIABLE)

    def _describe(self, planned: int) -> str:
        """The start-up line: what the node expects and offers, so a user can check a wiring at a glance."""
        p = self.params
        command = "geometry_msgs/TwistStamped" if p.use_stamped_cmd_vel else "geometry_msgs/Twist"
        episodes = f"{planned} episode{'s' if planned > 1 else ''}"
        length = f"of {p.episode_seconds:g} s" if p.episode_seconds > 0 else "ended by ~/reset"
        scans = (f"<robot>/scan (sensor_msgs/LaserScan, {p.scan_rays} rays, frame <robot>/base_link) at "
                 f"{p.scan_rate_hz:g} Hz" if p.scan_rate_hz > 0 else "no scans")
        return (f"{NAME}: {len(self.names)} {p.drive} robots ({', '.join(self.names)}); expects {command} on "
                f"<robot>/cmd_vel (body frame <robot>/base_link: x forward, y left; reliable or best effort; "
                f"dropped after {p.cmd_vel_timeout:g} s); publishes <robot>/odom (nav_msgs/Odometry, pose in "
                f"'{p.odom_frame}', twist in <robot>/base_link) at {p.odom_rate_hz:g} Hz, {scans}, goals on "
                f"'{p.goals_topic}' and true poses on 'agents/poses' in '{p.odom_frame}'; {episodes} {length}"
                + (f"; summary in {p.summary_path}" if p.summary_path else ""))

    # ---------------------------------------------------------------- inputs
    def _warn(self, key: str, text: str) -> None:
        now = time.monotonic()
        if now - self._warned.get(key, -WARN_PERIOD) >= WARN_PERIOD:
            self._warned[key] = now
            self.get_logger().warning(text)

    def _on_command(self, robot: int, msg) -> None:
        twist = msg.twist if self.params.use_stamped_cmd_vel else msg
        values = (twist.linear.x, twist.linear.y, twist.linear.z, twist.angular.x, twist.angular.y, twist.angular.z)
        problem = command_problem(values)
        if problem is not None:
            self._warn(f"command:{robot}", f"dropped a command for {self.names[robot]} ({problem})")
            return
        self.world.command(robot, (twist.linear.x, twist.linear.y, twist.angular.z), time.monotonic())

    def _on_reset(self, request, response):
        if self.world.finished:
            response.success, response.message = False, "the last episode has ended: the node is exiting"
            return response
        record = self.world.end_episode("reset")
        self._episode_ended(record)
        response.success = True
        response.message = (f"episode {record['index']} ended; "
                            + ("that was the last: the node exits" if self.world.finished
                               else f"episode {self.world.tracker.index} started"))
        return response

    # --------------------------------------------------------------- running
    def _step(self) -> None:
        if not self.context.ok():
            return
        now = time.monotonic()
        if self.waiting:
            if not all(self.count_publishers(sub.topic_name) for sub in self.command_subscriptions):
                self.world.resume(now)  # the robots stand and the episode's clock does not run
                return
            self.waiting = False
            self.get_logger().info(f"{NAME}: every robot's cmd_vel has a publisher: episode 0 starts")
        for record in self.world.step(now):
            self._episode_ended(record)
        if self.world.finished and self.params.exit_after_last:
            if self._finished_at is None:
                self._finished_at = now
            elif now - self._finished_at >= EXIT_GRACE_S:
                self.get_logger().info(f"{NAME}: the last of {len(self.world.episodes)} planned episodes has ended: "
                                       "exiting")
                self.context.try_shutdown()

    def _episode_ended(self, record: dict) -> None:
        self.get_logger().info(self._episode_line(record))
        if self.params.summary_path:
            try:
                self._write_summary()
            except OSError as error:
                self._warn("summary", f"cannot write the summary to {self.params.summary_path}: {error}")
        if not self.world.finished:
            self._publish_goals()

    def _episode_line(self, record: dict) -> str:
        n, planned = len(self.names), len(self.world.episodes)
        parts = [f"{NAME}: episode {record['index']} ({record['plan_index'] + 1} of {planned}) ended by "
                 f"{record['ended_by']} after {record['duration']:.2f} s"]
        times = record["time_to_goal"]
        if times is not None:
            reached = sum(t is not None for t in times)
            every = record["all_reached_time"]
            parts.append(f"{reached}/{n} robots reached their goals"
                         + (f" (all by {every:.2f} s)" if every is not None else ""))
        collisions = record["collisions"]
        parts.append(f"{collisions['robot_robot']} robot-robot and {collisions['robot_wall']} wall collisions")
        if record["coverage"] is not None:
            parts.append(f"coverage {record['coverage']:.3f} m")
        return ", ".join(parts)

    def _write_summary(self) -> None:
        world = self.world
        write_atomic(self.params.summary_path, document(self.params.as_dict(), self.names, len(world.episodes),
                                                        world.records, world.complete))

    # --------------------------------------------------------------- outputs
    def _publish_odometry(self) -> None:
        if not self.context.ok():
            return
        stamp = self.get_clock().now().to_msg()
        report = self.world.odometry(self.odom_rng)  # [n, 6]
        for publisher, msg, row in zip(self.odom_publishers, self.odom_messages, report):
            publisher.publish(messages.fill_odometry(msg, stamp, row))
        self.poses_publisher.publish(messages.pose_array(self.params.odom_frame, stamp, self.world.state.pose))

    def _publish_scans(self) -> None:
        if not self.context.ok():
            return
        stamp = self.get_clock().now().to_msg()
        ranges = self.world.scan(self.scan_rng)  # [n, R]
        for publisher, msg, row in zip(self.scan_publishers, self.scan_messages, ranges):
            publisher.publish(messages.fill_scan(msg, stamp, row))

    def _publish_goals(self) -> None:
        if not self.context.ok() or self.world.finished:
            return
        frame, stamp = self.params.odom_frame, self.get_clock().now().to_msg()
        episode = self.world.episode
        self.goals_publisher.publish(messages.pose_array(frame, stamp, episode.goals))
        if episode.per_robot_goals and self.goal_publishers:
            for publisher, (x, y) in zip(self.goal_publishers, episode.goals):
                publisher.publish(messages.goal(frame, stamp, x, y))

    # ------------------------------------------------------------------ stop
    def destroy_node(self) -> None:
        """Record the running episode (ended by ``shutdown``) and write the summary, then leave ROS."""
        if not self._closed:
            self._closed = True
            record = self.world.close()
            if record is not None:
                print(self._episode_line(record), file=sys.stderr, flush=True)
            if self.params.summary_path:
                try:
                    self._write_summary()
                except OSError as error:
                    print(f"{NAME}: cannot write the summary to {self.params.summary_path}: {error}",
                          file=sys.stderr, flush=True)
        super().destroy_node()


# -------------------------------------------------------------------- start
def asks_for_help(argv: List[str]) -> bool:
    """Whether the command line asks for ``-h``/``--help`` before any ``--ros-args``."""
    args = argv[1:]
    own = args[:args.index("--ros-args")] if "--ros-args" in args else args
    return "-h" in own or "--help" in own


def main(argv: Optional[List[str]] = None) -> int:
    """Entry point of ``robot_fleet`` and ``python -m vmas_ros.fleet.node``; returns the exit code.

    ``--help`` lists the parameters. Refused parameters and a malformed
    ``--ros-args`` exit with code 2, a signal with 0 (see :mod:`vmas_ros.ros.lifecycle`).
    """
    from vmas_ros.ros.lifecycle import EXIT_CONFIG, run_node

    args = list(sys.argv if argv is None else argv)
    if asks_for_help(args):
        print(f"usage: {NAME} [--help] [--ros-args -p name:=value ... | --params-file FILE]\n\n"
              f"{FLEET_PARAMS.help()}")
        return 0
    try:
        return run_node(NAME, FleetNode, args)
    except Exception as error:  # rclpy.init refusing --ros-args: a user's input error, not a crash
        text = str(error)
        if type(error).__name__ != "RCLError" or "failed to initialize rcl" not in text:
            raise
        print(f"{NAME}: refused arguments: {text.split(', at ')[0]}", file=sys.stderr)
        return EXIT_CONFIG


if __name__ == "__main__":
    sys.exit(main())
