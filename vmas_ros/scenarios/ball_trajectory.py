"""ball_trajectory: two agents, each tied to a ball by a rod, spin it round a circle.

Description
    A ball (disc of radius 0.06, linear friction 0.04) sits between two agents
    (discs of radius 0.03, drag 0.25) on a plane without walls. With ``joints``
    (the default) each agent is tied to the ball by a rigid, non-colliding rod
    of length 0.2, free to turn at both ends; without them the agents must
    push the ball by contact. The team should drive the ball at speed 1 along
    the circle of radius 0.5 about the origin (drawn in black); with the
    default kwargs only the speed is rewarded.
Observation (per agent, in this order)
    own position (2), own velocity (2), own position minus the ball's (2), and
    own position again (2): 8 values (VMAS 1.5's layout, duplicate included).
Reward
    Shared by both agents, the sum of three shaping terms, each the decrease
    since the last step of:
    ``pos_shaping_factor`` x sqrt(ball's distance to the circle),
    ``speed_shaping_factor`` x |1 - ball speed|, and
    ``dist_shaping_factor`` x the summed distances of the agents to the ball.
    ``info`` reports the three terms (``pos_rew``, ``speed_rew``, ``dist_rew``).
    VMAS 1.5 recomputes (and re-baselines) the shaping on every agent's reward
    call, so its second agent always earns 0 and its ``info`` is always 0;
    here the reward is computed once per step and both agents earn it.
Starting state
    Ball uniform in [-0.5, 0.5]^2; the agents 0.2 to its left and right (which
    one goes left is drawn per env), everything at rest. VMAS 1.5 draws one
    left/right order per reset call (shared by the whole batch on a full
    reset), and its reset of a single env overwrites the position shaping of
    all envs with that env's value; here every env draws its own order and a
    partial reset touches only the selected envs.
Episode termination
    Never (set ``max_steps``).
Kwargs
    ``pos_shaping_factor`` (0), ``speed_shaping_factor`` (1),
    ``dist_shaping_factor`` (0), ``joints`` (True). With joints the world runs
    15 substeps, joint force 900 and collision force 1500; without, 5
    substeps, the default joint force and collision force 400.
"""
from __future__ import annotations

import math

import torch
from torch import Tensor

from vmas_ros.scenarios.common import for_index as shaped_for
from vmas_ros.scenarios.common import continuous_heuristic_kwargs, read_kwargs, selected_rows
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.joints import Joint
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import DRAG, JOINT_FORCE, Color

#: name -> default of every kwarg (the heuristic takes them too)
DEFAULTS = {"pos_shaping_factor": 0.0, "speed_shaping_factor": 1.0, "dist_shaping_factor": 0.0, "joints": True}
N_AGENTS = 2
AGENT_RADIUS = 0.03
BALL_RADIUS = 2 * AGENT_RADIUS
SPACING = 0.4  # agent to agent at the start; each rod is half of it
DESIRED_SPEED = 1.0
DESIRED_RADIUS = 0.5


def validate(config: dict) -> None:
    """Raise ValueError for a kwarg value the task cannot be built with."""
    for name in ("pos_shaping_factor", "speed_shaping_factor", "dist_shaping_factor"):
        value = config[name]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"ball_trajectory: {name} must be a finite number, got {value!r}")
    if not isinstance(config["joints"], bool):
        raise ValueError(f"ball_trajectory: joints must be a bool, got {config['joints']!r}")


def distance_to_circle(pos: Tensor) -> Tensor:
    """Distance of points [..., 2] to the circle of radius 0.5 about the origin: [...].

    Measured to the circle point on the ray through ``pos`` (the origin, which
    has no such ray, counts as 0 away, as in VMAS 1.5).
    """
    norm = torch.linalg.vector_norm(pos, dim=-1, keepdim=True)
    on_circle = torch.where(norm > 0, pos / norm * DESIRED_RADIUS, torch.zeros_like(pos))
    return torch.linalg.vector_norm(pos - on_circle, dim=-1)


class Scenario(BaseScenario):
    supports_batched_reset = True
    fresh_observations = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = read_kwargs(kwargs, DEFAULTS)
        validate(config)
        self.pos_shaping_factor = float(config["pos_shaping_factor"])
        self.speed_shaping_factor = float(config["speed_shaping_factor"])
        self.dist_shaping_factor = float(config["dist_shaping_factor"])
        self.use_joints = config["joints"]

        world = World(
            batch_dim, device, drag=0.0,
            substeps=15 if self.use_joints else 5,
            joint_force=900.0 if self.use_joints else JOINT_FORCE,
            collision_force=1500.0 if self.use_joints else 400.0,
        )
        for i in range(N_AGENTS):
            world.add_agent(Agent(name=f"agent_{i}", shape=Sphere(AGENT_RADIUS), drag=DRAG))
        self.ball = Landmark(
            name="ball", shape=Sphere(radius=BALL_RADIUS), collide=True, movable=True, linear_friction=0.04
        )
        world.add_landmark(self.ball)
        self.joints = []
        if self.use_joints:
            for agent in world.agents:
                # a rod of half the spacing, free to turn at both ends, that nothing bumps into
                joint = Joint(agent, self.ball, dist=SPACING / 2, rotate_a=True, rotate_b=True, collidable=False, width=0)
                self.joints.append(joint)
                world.add_joint(joint)

        #: per env [B]: each shaping quantity (x its factor) as of the last reward
        self.shaping = {name: torch.zeros(batch_dim, device=world.device) for name in ("pos", "speed", "dist")}
        self.rew = {name: torch.zeros(batch_dim, device=world.device) for name in ("pos", "speed", "dist")}
        self._reward = torch.zeros(batch_dim, device=world.device)
        return world

    # ------------------------------------------------------------------- reset
    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = selected_rows(world.batch_dim, env_index)
        ball = torch.empty(rows, world.dim_p, device=world.device).uniform_(-DESIRED_RADIUS, DESIRED_RADIUS)
        self.ball.set_pos(shaped_for(ball, env_index), batch_index=env_index)
        # which agent goes to the left: a random order of the two, per env
        left_first = torch.rand(rows, 1, device=world.device) < 0.5
        side = torch.where(left_first, -1.0, 1.0)  # agent 0's side; agent 1 takes the other
        for i, agent in enumerate(world.agents):
            offset = (side if i == 0 else -side) * (SPACING / 2)
            pos = ball + torch.cat([offset, torch.zeros_like(offset)], dim=1)
            agent.set_pos(shaped_for(pos, env_index), batch_index=env_index)
        shaping = self._shaping()
        for name, value in shaping.items():
            if env_index is None:
                self.shaping[name] = value
            else:
                self.shaping[name][env_index] = value[env_index]

    # ------------------------------------------------------------------ reward
    def _shaping(self) -> dict:
        """The three shaping quantities, each [B], times their factors."""
        ball = self.ball.state
        agents = torch.stack([a.state.pos for a in self.world.agents], dim=1)  # [B, 2, 2]
        return {
            "pos": distance_to_circle(ball.pos).sqrt() * self.pos_shaping_factor,
            "speed": (DESIRED_SPEED - torch.linalg.vector_norm(ball.vel, dim=-1)).abs() * self.speed_shaping_factor,
            "dist": torch.linalg.vector_norm(agents - ball.pos.unsqueeze(1), dim=-1).sum(dim=1)
            * self.dist_shaping_factor,
        }

    def reward(self, agent: Agent) -> Tensor:
        if agent is self.world.agents[0]:  # shared: compute (and re-baseline) once per step
            shaping = self._shaping()
            self.rew = {name: self.shaping[name] - value for name, value in shaping.items()}
            self.shaping = shaping
            self._reward = self.rew["pos"] + self.rew["speed"] + self.rew["dist"]
        return self._reward

    # ------------------------------------------------------------- observation
    def observation(self, agent: Agent) -> Tensor:
        pos = agent.state.pos
        return torch.cat([pos, agent.state.vel, pos - self.ball.state.pos, pos], dim=-1)

    def info(self, agent: Agent) -> dict:
        return {"pos_rew": self.rew["pos"], "speed_rew": self.rew["speed"], "dist_rew": self.rew["dist"]}

    def extra_render(self, env_index: int = 0) -> list:
        from vmas_ros.simulator import rendering

        circle = rendering.make_circle(DESIRED_RADIUS, filled=False)
        circle.set_color(*Color.BLACK.value)
        return [circle]


class HeuristicPolicy(BaseHeuristicPolicy):
    """Both agents carry the ball counter-clockwise round the circle, as fast as they can.

    Each agent works out the ball's position from its observation and asks
    for the velocity the ball should have there: ``speed`` along the
    counter-clockwise tangent of the circle through the ball, plus a radial
    pull (``radial_gain`` x the distance to the circle) that steers it onto
    the circle. Tied to the ball by rods, an agent moving at that velocity
    moves the ball at it, so the agent tracks it with a feed-forward plus a
    proportional term on its velocity error. The wanted speed 1 is out of
    reach (full force holds about 0.5 with the ball in tow), so in practice
    the agents push at full force along the tangent, which is what maximises
    the speed reward. Without joints agents cannot steer the ball well;
    continuous actions only.
    """

    speed = 1.05  # the wanted ball speed, a little above 1 so the pushes never ease off
    radial_gain = 2.0
    feedforward = 3.0  # force per unit of wanted speed
    feedback = 4.0

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        validate(continuous_heuristic_kwargs("ball_trajectory", DEFAULTS, scenario_kwargs, continuous_action))

    def compute_action(self, observation: Tensor, u_range: float) -> Tensor:
        if observation.shape[1] != 8:
            raise ValueError(f"ball_trajectory heuristic: expected observation width 8, got {observation.shape[1]}")
        pos, vel = observation[:, 0:2], observation[:, 2:4]
        ball = pos - observation[:, 4:6]
        radius = torch.linalg.vector_norm(ball, dim=-1, keepdim=True)
        radial = torch.where(radius > 1e-6, ball / radius.clamp_min(1e-6), torch.tensor([1.0, 0.0], device=ball.device))
        tangent = torch.stack([-radial[:, 1], radial[:, 0]], dim=-1)
        wanted = self.speed * tangent + self.radial_gain * (DESIRED_RADIUS - radius) * radial
        force = self.feedforward * wanted + self.feedback * (wanted - vel)
        return force.clamp(-u_range, u_range)
