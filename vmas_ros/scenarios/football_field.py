"""The football pitch: kwargs defaults, geometry, fixed fixtures, the ball's wall script, drawing.

Everything here is static once the scenario's kwargs are known, so it lives
apart from the task logic in ``football.py`` and the scripted team in
``football_ai.py`` (which both import it).

Coordinates: the pitch is centred at the origin, ``length`` along x and
``width`` along y. Blue defends the left goal (x < 0) and attacks the right
one; red the opposite. Goals are ``goal_size`` wide and ``goal_depth`` deep,
behind the goal lines at x = +-length / 2.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from vmas_ros.simulator.core import Box, Landmark, Line
from vmas_ros.simulator.utils import Color

#: every scenario kwarg and its default (VMAS 1.5.2's football defaults); the
#: heuristic accepts the same names so the registry can hand it the scenario's kwargs
DEFAULTS: dict = {
    "viewer_size": (1200, 800),
    "n_blue_agents": 3,
    "n_red_agents": 3,
    "ai_red_agents": True,
    "ai_blue_agents": False,
    "physically_different": False,
    "spawn_in_formation": False,
    "only_blue_formation": True,
    "formation_agents_per_column": 2,
    "randomise_formation_indices": False,
    "formation_noise": 0.2,
    "n_traj_points": 0,
    "ai_strength": 1.0,
    "ai_decision_strength": 1.0,
    "ai_precision_strength": 1.0,
    "disable_ai_red": False,
    "agent_size": 0.025,
    "goal_size": 0.35,
    "goal_depth": 0.1,
    "pitch_length": 3.0,
    "pitch_width": 1.5,
    "ball_mass": 0.25,
    "ball_size": 0.02,
    "u_multiplier": 0.1,
    "enable_shooting": False,
    "u_rot_multiplier": 0.0003,
    "u_shoot_multiplier": 0.6,
    "shooting_radius": 0.08,
    "shooting_angle": math.pi / 2,
    "max_speed": 0.15,
    "ball_max_speed": 0.3,
    "dense_reward": True,
    "pos_shaping_factor_ball_goal": 10.0,
    "pos_shaping_factor_agent_ball": 0.1,
    "distance_to_ball_trigger": 0.4,
    "scoring_reward": 100.0,
    "observe_teammates": True,
    "observe_adversaries": True,
    "dict_obs": False,
}

BLUE_COLOR = (0.22, 0.49, 0.72)
RED_COLOR = (0.89, 0.10, 0.11)
NET_COLOR, NET_ALPHA = (0.5, 0.5, 0.5), 0.5
#: the ball's anti-stick script: it acts within this many agent sizes of a side line,
BALL_WALL_ZONE = 2.0
#: only while slower than this (m/s; upstream reads the y speed for both axes),
BALL_SLOW_SPEED = 0.3
#: with at most this force (N)
BALL_WALL_FORCE = 0.05
#: width of the painted centre circle's ring
CIRCLE_RING = 0.02


@dataclass(frozen=True)
class Pitch:
    """Sizes of the pitch and its players (all in metres)."""

    length: float
    width: float
    goal_size: float
    goal_depth: float
    agent_size: float
    ball_size: float

    @property
    def goal_line(self) -> float:
        """x beyond which the whole ball is past the goal line (the scoring test and shaping target)."""
        return self.length / 2 + self.ball_size / 2

    @property
    def x_semidim(self) -> float:
        """The world's x limit: the back of the nets."""
        return self.length / 2 + self.goal_depth - self.agent_size

    @property
    def y_semidim(self) -> float:
        """The world's y limit: the side lines (there are no side walls, the world clamps instead)."""
        return self.width / 2 - self.agent_size

    @property
    def wall_length(self) -> float:
        """Each of the four goal-line walls runs from a goal post to a corner."""
        return self.width / 2 - self.agent_size - self.goal_size / 2

    def fixtures(self) -> list[tuple[str, str, float, float, float]]:
        """The fixed landmarks in world order: ``(name, kind, x, y, rotation)``.

        ``kind`` is ``"wall"`` (a goal-line wall), ``"back"`` (the back of a
        net), ``"side"`` (a net's side) or ``"net"`` (the painted net, not
        collidable). The order and names are VMAS's.
        """
        l2, w4, g4 = self.length / 2, self.width / 4, self.goal_size / 4
        half_pi = math.pi / 2
        back_x = self.length / 2 + self.goal_depth - self.agent_size
        side_x = self.length / 2 + self.goal_depth / 2 - self.agent_size
        net_x = self.length / 2 + self.goal_depth / 2 - self.agent_size / 2
        post_y = self.goal_size / 2
        return [
            ("Right Top Wall", "wall", l2, w4 + g4, half_pi),
            ("Left Top Wall", "wall", -l2, w4 + g4, half_pi),
            ("Right Bottom Wall", "wall", l2, -w4 - g4, half_pi),
            ("Left Bottom Wall", "wall", -l2, -w4 - g4, half_pi),
            ("Right Goal Back", "back", back_x, 0.0, half_pi),
            ("Left Goal Back", "back", -back_x, 0.0, half_pi),
            ("Right Goal Top", "side", side_x, post_y, 0.0),
            ("Left Goal Top", "side", -side_x, post_y, 0.0),
            ("Right Goal Bottom", "side", side_x, -post_y, 0.0),
            ("Left Goal Bottom", "side", -side_x, -post_y, 0.0),
            ("Blue Net", "net", -net_x, 0.0, 0.0),
            ("Red Net", "net", net_x, 0.0, 0.0),
        ]

    def make_fixture(self, name: str, kind: str) -> Landmark:
        """The landmark of one fixture (see ``fixtures``)."""
        if kind == "net":
            net = Landmark(
                name=name, collide=False, movable=False,
                shape=Box(length=self.goal_depth, width=self.goal_size), color=NET_COLOR,
            )
            net.alpha = NET_ALPHA  # half-transparent, so the ball stays visible inside
            return net
        length = {"wall": self.wall_length, "back": self.goal_size, "side": self.goal_depth}[kind]
        return Landmark(name=name, collide=True, movable=False, shape=Line(length=length), color=Color.WHITE)

    def fixture_poses(self, device) -> tuple[Tensor, Tensor]:
        """Positions [F, 2] and rotations [F, 1] of ``fixtures()``, as tensors on ``device``."""
        table = self.fixtures()
        pos = torch.tensor([[x, y] for _, _, x, y, _ in table], dtype=torch.float32, device=device)
        rot = torch.tensor([[r] for *_, r in table], dtype=torch.float32, device=device)
        return pos, rot


def ball_wall_push(pos: Tensor, vel: Tensor, pitch: Pitch) -> Tensor:
    """The ball's own force [B, 2] that keeps it from sticking to the pitch's edges.

    Within ``BALL_WALL_ZONE`` agent sizes of a side or goal line, a slow ball
    is nudged back towards the middle: the nudge grows linearly as the gap
    closes and fades out as the ball speeds up (upstream measures the speed
    on the y axis for both components, which we keep for parity). Inside the
    goal mouth the x nudge is off, so the ball can roll into the net.
    """
    zone = pitch.agent_size * BALL_WALL_ZONE
    half = torch.tensor([pitch.length / 2, pitch.width / 2], device=pos.device)
    zone_t = torch.tensor(zone, device=pos.device)
    nearness_hi = 1 - torch.minimum(half - pos, zone_t) / zone  # towards the right / top lines
    nearness_lo = 1 - torch.minimum(half + pos, zone_t) / zone  # towards the left / bottom lines
    slow_t = torch.tensor(BALL_SLOW_SPEED, device=pos.device)
    slowness = 1 - torch.minimum(vel[:, 1:2].abs(), slow_t) / BALL_SLOW_SPEED
    push = (nearness_lo - nearness_hi) * slowness * BALL_WALL_FORCE
    in_mouth = (pos[:, 1] < pitch.goal_size / 2) & (pos[:, 1] > -pitch.goal_size / 2)
    return torch.stack([torch.where(in_mouth, 0.0, push[:, 0]), push[:, 1]], dim=-1)


# -------------------------------------------------------------------- drawing
def pitch_geoms(pitch: Pitch, with_grass: bool = True) -> list:
    """The painted pitch: grass and centre circle (if ``with_grass``), then the white lines."""
    from vmas_ros.simulator import rendering

    geoms = []
    l2, w2, inset = pitch.length / 2, pitch.width / 2, pitch.agent_size
    if with_grass:
        grass = rendering.make_polygon([(-l2, -w2), (-l2, w2), (l2, w2), (l2, -w2)])
        grass.set_color(*Color.GREEN.value)
        ring = rendering.make_circle(pitch.goal_size / 2)
        ring.set_color(*Color.WHITE.value)
        inner = rendering.make_circle(pitch.goal_size / 2 - CIRCLE_RING)
        inner.set_color(*Color.GREEN.value)
        geoms += [grass, ring, inner]
    lines = [
        ((0.0, -w2 + inset), (0.0, w2 - inset)),  # half-way line
        ((l2 - inset, -w2 + inset), (l2 - inset, w2 - inset)),  # goal lines
        ((-l2 + inset, -w2 + inset), (-l2 + inset, w2 - inset)),
        ((-l2 + inset, w2 - inset), (l2 - inset, w2 - inset)),  # side lines
        ((-l2 + inset, -w2 + inset), (l2 - inset, -w2 + inset)),
    ]
    for start, end in lines:
        line = rendering.Line(start, end, width=2)
        line.set_color(*Color.WHITE.value)
        geoms.append(line)
    return geoms


def shooting_geoms(pos, rot: float, color, radius: float, angle: float, intensity: float, agent_size: float) -> list:
    """An agent's kicking sector (where the ball must be to shoot) and a bar showing its last kick."""
    from vmas_ros.simulator import rendering

    pose = rendering.Transform()
    pose.set_rotation(rot)
    pose.set_translation(*pos)
    sector = rendering.make_circle(radius=radius, angle=angle, filled=True)
    sector.add_attr(pose)
    sector.set_color(*color, alpha=0.5)
    reach = radius * intensity
    bar = rendering.make_polygon([(0, -agent_size / 2), (0, agent_size / 2), (reach, agent_size / 2), (reach, -agent_size / 2)])
    bar.add_attr(pose)
    bar.set_color(*color, alpha=1.0)
    return [sector, bar]
