"""The fleet stepped in time, episode after episode: the whole simulation, with no ROS in it.

:class:`FleetWorld` owns the state (:class:`~vmas_ros.fleet.kinematics.MotionState`,
arrays ``[n, ...]``), the command buffer, the contact counter and the
running episode's tracker. The node calls :meth:`FleetWorld.step` from a
wall-clock timer with ``time.monotonic()``; tests call it with times of their
own, so every behaviour here is checked without ROS and without waiting.

One step: the commands due at its start (latency, timeout) -> kinematics (limiter, lag,
integration) -> discs pushed apart and kept inside the walls -> contact
onsets and goals noted -> the episode ends if its time is up (or, with
``end_on_goals``, once every robot stands on its goal). A step never
crosses the end of an episode: the last one is shortened to land on it, so
durations are exact.
"""
from __future__ import annotations

from typing import List, Optional, Sequence

import numpy as np

from vmas_ros.fleet import kinematics
from vmas_ros.fleet.commands import CommandBuffer
from vmas_ros.fleet.contacts import Arena, ContactCounter, separate
from vmas_ros.fleet.episodes import Episode
from vmas_ros.fleet.raycast import cast, ray_angles, readings
from vmas_ros.fleet.summary import EpisodeTracker

__all__ = ["FleetWorld", "MAX_STEP_S"]

#: the longest step integrated at once, s: a process stopped for a while (a debugger, SIGSTOP) resumes
#: with one step of this instead of teleporting its robots through each other
MAX_STEP_S = 0.1


class FleetWorld:
    """``n`` robots running through ``episodes`` as robot_fleet's parameter values ``params`` describe.

    ``records`` collects every finished episode's summary entry; ``finished``
    turns true after the last episode when ``params.exit_after_last`` (with it
    false the episodes start over from the first).
    """

    def __init__(self, params, episodes: Sequence[Episode], now: float) -> None:
        self.params = params
        self.episodes = list(episodes)
        self.n = params.n_robots
        self.model = kinematics.DriveModel.from_params(params)
        self.arena = Arena(params.arena_half_x, params.arena_half_y)
        self.radius = params.robot_radius
        self.commands = CommandBuffer(self.n, params.command_latency, params.cmd_vel_timeout)
        self.angles = ray_angles(params.scan_rays, params.scan_angle_min, params.scan_angle_max)  # [R]
        self.records: List[dict] = []
        self.finished = False
        self.episode_number = 0  # episodes started so far, counting repeats
        self.last_time = now
        self._start(0)

    # ---------------------------------------------------------------- episodes
    @property
    def episode(self) -> Episode:
        return self.tracker.episode

    def _start(self, index: int) -> None:
        """Robots teleported to episode ``index``'s start, at rest, with no command in flight."""
        episode = self.episodes[index]
        self.index = index
        self.state = kinematics.MotionState.at_rest(episode.robots)
        self.commands.clear()
        self.contacts = ContactCounter.at(self.state.pose[:, :2], self.radius, self.arena)
        self.tracker = EpisodeTracker(self.episode_number, index, episode, self.params.goal_radius)
        self.episode_number += 1

    def end_episode(self, ended_by: str) -> dict:
        """End the running episode (``time``, ``goals``, ``reset``) and start the next; returns its record."""
        record = self.tracker.record(self.state.pose, ended_by)
        self.records.append(record)
        following = self.index + 1
        if following < len(self.episodes):
            self._start(following)
        elif self.params.exit_after_last:
            self.finished = True
        else:
            self._start(0)
        return record

    def close(self) -> Optional[dict]:
        """The node stops: record the running episode as ended by ``shutdown`` (None when none runs)."""
        if self.finished:
            return None
        self.finished = True
        record = self.tracker.record(self.state.pose, "shutdown")
        self.records.append(record)
        return record

    @property
    def complete(self) -> bool:
        """Whether every planned episode ran to its end (by time, its goals or ``~/reset``)."""
        ended = [r for r in self.records if r["ended_by"] != "shutdown"]
        return len(ended) >= len(self.episodes)

    # ------------------------------------------------------------------ motion
    def command(self, robot: int, twist: Sequence[float], now: float) -> None:
        """Robot ``robot`` received body-frame ``(vx, vy, wz)`` at ``now`` (monotonic s)."""
        self.commands.push(robot, twist, now)

    def resume(self, now: float) -> None:
        """Go on from ``now`` (monotonic s): the time since the last step is not integrated."""
        self.last_time = now

    def step(self, now: float) -> List[dict]:
        """Advance to ``now`` (monotonic s); returns the records of the episodes that ended."""
        if self.finished:
            return []
        start = self.last_time
        dt = min(max(now - start, 0.0), MAX_STEP_S)
        self.last_time = now
        limit = self.params.episode_seconds
        if limit > 0:
            dt = min(dt, max(limit - self.tracker.elapsed, 0.0))
        ended = []
        if dt > 0:
            self._advance(dt, start)
        if self.params.end_on_goals and self.tracker.all_at_goal:
            ended.append(self.end_episode("goals"))
        elif limit > 0 and self.tracker.elapsed >= limit - 1e-9:
            ended.append(self.end_episode("time"))
        return ended

    def _advance(self, dt: float, start: float) -> None:
        # the commands in force when the step starts act over it: none acts before it is due
        target = self.commands.target(start)  # [n, 3]
        state = kinematics.step(self.state, target, dt, self.model)
        positions, touching, at_wall = separate(state.pose[:, :2], self.radius, self.arena)
        state.pose[:, :2] = positions
        self.state = state
        robot_onsets, wall_onsets = self.contacts.update(touching, at_wall)
        self.tracker.advance(dt, state.pose, robot_onsets, wall_onsets)

    # ------------------------------------------------------------------ sensing
    def scan(self, rng: Optional[np.random.Generator] = None) -> np.ndarray:
        """Every robot's LaserScan ranges ``[n, R]`` (float32, REP 117) at the current state."""
        p = self.params
        distances = cast(self.state.pose, self.angles, self.radius, self.arena, p.scan_range_max)
        return readings(distances, p.scan_range_min, p.scan_range_max, p.scan_noise, p.scan_dropout, rng)

    def odometry(self, rng: np.random.Generator) -> np.ndarray:
        """``[n, 6]``: x, y, yaw, vx, vy, wz as the odometry reports them, with its noise.

        The true state is untouched: the noise is drawn for this report only.
        A diff-drive base reports no sideways velocity, noisy or not.
        """
        p = self.params
        noise = rng.normal(size=(self.n, 6)) * np.array(
            [p.odom_noise_position, p.odom_noise_position, p.odom_noise_yaw,
             p.odom_noise_velocity, p.odom_noise_velocity if self.model.holonomic else 0.0, 0.0])
        report = np.concatenate([self.state.pose, self.state.velocity], axis=1) + noise
        report[:, 2] = kinematics.wrap_angle(report[:, 2])
        return report
