"""buzz_wire: two agents carry a ball on rods up a narrow channel without touching it.

Description
    A "buzz wire" game for two. A ball (disc of radius 0.03) hangs between two
    agents (discs of radius 0.03, mass 1) on two rigid, non-colliding rods of
    length 0.25 each, free to turn at both ends. The ball starts in the lower
    half of a vertical channel 0.25 wide and 2 long (walls at x = +-0.125,
    closed by short floors at y = +-1); the agents are outside the walls, one
    on each side, so the rods cross them. The team must bring the ball to a
    goal in the channel (green) without any agent or the ball touching a wall
    or a floor. ``max_speed_1`` can slow agent 1 down, so that the other has
    to adapt its pace.
Observation (per agent, in this order)
    own position (2), own velocity (2), own position minus the goal's (2):
    6 values. Agents see neither the ball nor each other.
Reward
    Shared: ``pos_shaping_factor`` x the decrease of the ball's distance to
    the goal, plus ``collision_reward`` for every (agent or ball, wall or
    floor) pair that touches. ``info`` reports ``pos_rew`` and ``collision_rew``.
Starting state
    Rods at an angle uniform in [-pi/6, pi/6] (0 without
    ``random_start_angle``), ball x uniform in [-0.03, 0.03] and y in
    [-0.94, -0.03], agents 0.25 from it along the rods (agent 0 on the left),
    goal x uniform in [-0.03, 0.03] and y in [-0.03, 0.94]; all at rest.
Episode termination
    When the ball is within 0.01 of the goal, or when anything touched a wall
    or floor in the last step.
Kwargs
    ``random_start_angle`` (True), ``pos_shaping_factor`` (1),
    ``collision_reward`` (-10), ``max_speed_1`` (None: agent 1 as fast as agent 0).
"""
from __future__ import annotations

import math

import torch
from torch import Tensor

from vmas_ros.scenarios.common import for_index as shaped_for
from vmas_ros.scenarios.common import continuous_heuristic_kwargs, read_kwargs, selected_rows
from vmas_ros.simulator import geometry as geo
from vmas_ros.simulator.core import Agent, Landmark, Line, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.joints import Joint
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import LINE_MIN_DIST, Color

#: name -> default of every kwarg (the heuristic takes them too)
DEFAULTS = {"random_start_angle": True, "pos_shaping_factor": 1.0, "collision_reward": -10.0, "max_speed_1": None}
N_AGENTS = 2
AGENT_RADIUS = 0.03
BALL_RADIUS = AGENT_RADIUS
SPACING = 0.5  # agent to agent along the rods
WALL_LENGTH = 2.0
MAX_START_ANGLE = math.pi / 6
GOAL_DISTANCE = 0.01


def validate(config: dict) -> None:
    """Raise ValueError for a kwarg value the task cannot be built with."""
    if not isinstance(config["random_start_angle"], bool):
        raise ValueError(f"buzz_wire: random_start_angle must be a bool, got {config['random_start_angle']!r}")
    for name in ("pos_shaping_factor", "collision_reward"):
        value = config[name]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"buzz_wire: {name} must be a finite number, got {value!r}")
    speed = config["max_speed_1"]
    if speed is not None and (isinstance(speed, bool) or not isinstance(speed, (int, float)) or not speed > 0):
        raise ValueError(f"buzz_wire: max_speed_1 must be None or a number > 0, got {speed!r}")


def channel_layout() -> list:
    """(name, length, x, y, rot) of every line of the channel, in world order: walls, then floors."""
    walls = [(f"wall {i}", WALL_LENGTH, side * SPACING / 4, 0.0, math.pi / 2) for i, side in enumerate((-1, 1))]
    floors = [(f"floor {i}", SPACING / 2, 0.0, side * WALL_LENGTH / 2, 0.0) for i, side in enumerate((-1, 1))]
    return walls + floors


class Scenario(BaseScenario):
    supports_batched_reset = True
    fresh_observations = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = read_kwargs(kwargs, DEFAULTS)
        validate(config)
        self.random_start_angle = config["random_start_angle"]
        self.pos_shaping_factor = float(config["pos_shaping_factor"])
        self.collision_reward = float(config["collision_reward"])
        self.max_speed_1 = config["max_speed_1"]

        world = World(batch_dim, device, substeps=15, joint_force=900.0, collision_force=1500.0)
        for i in range(N_AGENTS):
            world.add_agent(Agent(
                name=f"agent_{i}", shape=Sphere(AGENT_RADIUS), u_multiplier=1.0, mass=1.0,
                max_speed=self.max_speed_1 if i == 1 else None,
            ))
        self.goal = Landmark(name="goal", shape=Sphere(radius=BALL_RADIUS), collide=False, color=Color.GREEN)
        world.add_landmark(self.goal)
        self.ball = Landmark(name="ball", shape=Sphere(radius=BALL_RADIUS), collide=True, movable=True)
        world.add_landmark(self.ball)
        self.joints = []
        for agent in world.agents:
            joint = Joint(agent, self.ball, dist=SPACING / 2, rotate_a=True, rotate_b=True, collidable=False, width=0)
            self.joints.append(joint)
            world.add_joint(joint)
        layout = channel_layout()
        self.lines = [Landmark(name=n, collide=True, shape=Line(length=l), color=Color.BLACK) for n, l, *_ in layout]
        for line in self.lines:
            world.add_landmark(line)
        self._line_pos = torch.tensor([[x, y] for _, _, x, y, _ in layout], device=world.device)  # [4, 2]
        self._line_rot = torch.tensor([[rot] for *_, rot in layout], device=world.device)  # [4, 1]
        self._line_length = torch.tensor([length for _, length, *_ in layout], device=world.device)

        #: per env [B]: the ball's distance to the goal x pos_shaping_factor, as of the last reward
        self.pos_shaping = torch.zeros(batch_dim, device=world.device)
        #: per env [B]: something touched the channel in the last step (ends the episode)
        self.collided = torch.zeros(batch_dim, dtype=torch.bool, device=world.device)
        self.pos_rew = torch.zeros(batch_dim, device=world.device)
        self.collision_rew = torch.zeros(batch_dim, device=world.device)
        return world

    # ------------------------------------------------------------------- reset
    def reset_world_at(self, env_index=None) -> None:
        world, device = self.world, self.world.device
        rows = selected_rows(world.batch_dim, env_index)
        limit = MAX_START_ANGLE if self.random_start_angle else 0.0
        angle = torch.empty(rows, 1, device=device).uniform_(-limit, limit)
        half_rod = (SPACING / 2) * torch.cat([torch.cos(angle), torch.sin(angle)], dim=1)  # ball -> agent 1

        def uniform(low: float, high: float) -> Tensor:
            return low + (high - low) * torch.rand(rows, 1, device=device)

        ball = torch.cat([uniform(-AGENT_RADIUS, AGENT_RADIUS), uniform(-WALL_LENGTH / 2 + 2 * AGENT_RADIUS, -AGENT_RADIUS)], 1)
        goal = torch.cat([uniform(-AGENT_RADIUS, AGENT_RADIUS), uniform(-AGENT_RADIUS, WALL_LENGTH / 2 - 2 * AGENT_RADIUS)], 1)
        self.goal.set_pos(shaped_for(goal, env_index), batch_index=env_index)
        self.ball.set_pos(shaped_for(ball, env_index), batch_index=env_index)
        for i, (agent, joint) in enumerate(zip(world.agents, self.joints)):
            sign = -1.0 if i == 0 else 1.0
            agent.set_pos(shaped_for(ball + sign * half_rod, env_index), batch_index=env_index)
            # each rod points from its agent to the ball (VMAS 1.5's angles, not wrapped)
            joint.landmark.set_pos(shaped_for(ball + sign * half_rod / 2, env_index), batch_index=env_index)
            joint.landmark.set_rot(shaped_for(angle + (math.pi if i == 1 else 0.0), env_index), batch_index=env_index)
        for k, line in enumerate(self.lines):
            line.set_pos(self._line_pos[k], batch_index=env_index)
            line.set_rot(self._line_rot[k], batch_index=env_index)

        shaping = torch.linalg.vector_norm(ball - goal, dim=-1) * self.pos_shaping_factor
        if env_index is None:
            self.pos_shaping = shaping
            self.collided = torch.zeros_like(self.collided)
        else:
            self.pos_shaping[env_index] = shaped_for(shaping, env_index)
            self.collided[env_index] = False

    # ------------------------------------------------------------------ reward
    def touching(self) -> Tensor:
        """Which of agent 0, agent 1, the ball touch which channel line: [B, 3, 4] bool.

        As ``World.is_overlapping`` for a disc and a line: the centre within
        radius + ``LINE_MIN_DIST`` of the segment (all three discs have radius 0.03).
        """
        discs = torch.stack([e.state.pos for e in (*self.world.agents, self.ball)], dim=1).unsqueeze(2)  # [B, 3, 1, 2]
        centre = torch.stack([line.state.pos for line in self.lines], dim=1).unsqueeze(1)  # [B, 1, 4, 2]
        rot = torch.stack([line.state.rot[:, 0] for line in self.lines], dim=1).unsqueeze(1)  # [B, 1, 4]
        gap = geo.point_segment_distance(centre, rot, self._line_length, discs)
        return gap - LINE_MIN_DIST - AGENT_RADIUS < 0

    def reward(self, agent: Agent) -> Tensor:
        if agent is self.world.agents[0]:  # shared: compute once per step
            shaping = torch.linalg.vector_norm(self.ball.state.pos - self.goal.state.pos, dim=-1) * self.pos_shaping_factor
            self.pos_rew = self.pos_shaping - shaping
            self.pos_shaping = shaping
            touching = self.touching()
            self.collision_rew = touching.sum(dim=(1, 2)).float() * self.collision_reward
            self.collided = touching.any(dim=2).any(dim=1)
        return self.pos_rew + self.collision_rew

    # ------------------------------------------------------------- observation
    def observation(self, agent: Agent) -> Tensor:
        pos = agent.state.pos
        return torch.cat([pos, agent.state.vel, pos - self.goal.state.pos], dim=-1)

    def done(self) -> Tensor:
        arrived = torch.linalg.vector_norm(self.ball.state.pos - self.goal.state.pos, dim=-1) <= GOAL_DISTANCE
        return arrived | self.collided

    def info(self, agent: Agent) -> dict:
        return {"pos_rew": self.pos_rew, "collision_rew": self.collision_rew}


class HeuristicPolicy(BaseHeuristicPolicy):
    """Both agents rise side by side, level with each other, so the ball climbs the channel's axis.

    An agent knows the goal (relative to itself) and which side of the
    channel it is on (the sign of its x offset from the goal, which lies on
    the channel's axis within 0.03). It aims for the point ``SPACING / 2``
    beside the goal on its own side, at the goal's height: both agents then
    meet level with the goal, the rods horizontal and the ball between them,
    on the goal. The approach is a velocity command (sideways to the rod
    spacing first: the distance gain is ``side_gain``, upwards at most
    ``climb_speed``) tracked by a feed-forward against the drag plus a
    proportional term. Agents slower than ``max_speed_1`` keep both in step:
    the pace is capped by it. Continuous actions only.
    """

    side_gain = 3.0
    climb_gain = 1.5
    climb_speed = 0.25
    feedforward = 2.5  # force per unit of held speed: drag 0.25 per 0.1 s step, mass 1
    feedback = 4.0

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        config = continuous_heuristic_kwargs("buzz_wire", DEFAULTS, scenario_kwargs, continuous_action)
        validate(config)
        speed = config["max_speed_1"]
        self.pace = self.climb_speed if speed is None else min(self.climb_speed, 0.8 * speed)

    def compute_action(self, observation: Tensor, u_range: float) -> Tensor:
        if observation.shape[1] != 6:
            raise ValueError(f"buzz_wire heuristic: expected observation width 6, got {observation.shape[1]}")
        vel, from_goal = observation[:, 2:4], observation[:, 4:6]
        side = torch.where(from_goal[:, 0] < 0, -1.0, 1.0)
        target = torch.stack([side * SPACING / 2, torch.zeros_like(side)], dim=-1)  # relative to the goal
        error = target - from_goal
        wanted = torch.stack([
            (self.side_gain * error[:, 0]).clamp(-self.pace, self.pace),
            (self.climb_gain * error[:, 1]).clamp(-self.pace, self.pace),
        ], dim=-1)
        force = self.feedforward * wanted + self.feedback * (wanted - vel)
        return force.clamp(-u_range, u_range)
