"""simple_spread (MPE "cooperative navigation").

Description
    ``n_agents`` agents and as many landmarks. Agents must cover every landmark
    while avoiding each other.
Observation (per agent, in this order)
    own position (2), own velocity (2), each landmark's position relative to
    the agent (2 x n_landmarks), and, with ``obs_agents=True``, each other
    agent's relative position (2 x (n_agents - 1)).
Reward (shared by all agents, as in VMAS 1.5)
    ``-n_agents * sum_l min_a |x_a - x_l|`` (how far each landmark is from its
    closest agent, counted once per agent) minus 1 for every ordered pair of
    agents that overlap.
Starting state
    Agents and landmarks uniform in [-1, 1]^2.
Episode termination
    Never (set ``max_steps``).
Kwargs
    ``n_agents`` (3), ``obs_agents`` (True).
"""
from __future__ import annotations

import torch

from vmas_ros.scenarios.common import greedy_first_match, read_kwargs
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.layout import as_pairs, complex_pairs
from vmas_ros.simulator.observation_layout import ObservationLayout
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.thresholds import FEW_ENVS
from vmas_ros.simulator.utils import Color

#: name -> default of every kwarg
DEFAULTS = {"n_agents": 3, "obs_agents": True}

AGENT_RADIUS = 0.15


class Scenario(BaseScenario):
    supports_batched_reset = True
    fresh_observations = True  # views of one result computed per collection, never written to

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = read_kwargs(kwargs, DEFAULTS)
        n_agents, self.obs_agents = config["n_agents"], config["obs_agents"]
        if not isinstance(n_agents, int) or n_agents < 1:
            raise ValueError(f"simple_spread: n_agents must be a positive int, got {n_agents!r}")
        world = World(batch_dim=batch_dim, device=device)
        for i in range(n_agents):
            world.add_agent(Agent(name=f"agent_{i}", collide=True, shape=Sphere(radius=AGENT_RADIUS), color=Color.BLUE))
        for i in range(n_agents):
            world.add_landmark(Landmark(name=f"landmark {i}", collide=False, color=Color.BLACK))
        n_landmarks = self._n_landmarks = n_agents
        #: per observing agent, the rows of world.stacked_state() it sees relative to itself:
        #: every landmark, then (with obs_agents) every other agent; entities are landmarks then agents
        self._seen_rows = [
            list(range(n_landmarks)) + ([n_landmarks + j for j in range(n_agents) if j != i] if self.obs_agents else [])
            for i in range(n_agents)
        ]
        #: the same rows in the flattened [A * N] (agent, entity) offsets of _few_envs_outputs
        self._seen_flat_rows = [i * (n_landmarks + n_agents) + row for i, rows in enumerate(self._seen_rows) for row in rows]
        self._seen_rows_on: dict = {}  # (which rows, device) -> [A, R] index tensor
        self._agent_index = {agent.name: i for i, agent in enumerate(world.agents)}
        self._overlap = None  # see _overlap_thresholds
        self._few_envs = batch_dim < FEW_ENVS
        self.fresh_rewards = self._few_envs  # a row of its own per agent (_few_envs_outputs)
        # fill the index and threshold caches now: filled while the step is traced they would split its graph
        self._overlap_thresholds(world.device, world.agents)
        self._seen_rows_on[("relative", world.device)] = torch.tensor(self._seen_flat_rows, device=world.device)
        return world

    def batched_outputs(self, q: torch.Tensor, v: torch.Tensor) -> tuple:
        """The shared reward, then what the observations are read from.

        A few envs: every agent's copy of the reward ``[B]`` and every agent's
        observation ``[B, obs]``, two tuples (one pass for all, see
        :func:`_few_envs_outputs`). Many envs: every entity's position
        ``[N, B, 2]`` and every agent's velocity ``[A, B, 2]``, from which each
        agent's observation is assembled on its own (:meth:`_agent_observation`);
        the reward ``[B]`` once.
        """
        if self._few_envs:
            seen = self._seen_rows_on.get(("relative", q.device))
            if seen is None:
                seen = self._seen_rows_on[("relative", q.device)] = torch.tensor(self._seen_flat_rows, device=q.device)
            return _few_envs_outputs(q, v, self._n_landmarks, self._overlap_thresholds(q.device)[0], seen)
        return _many_envs_outputs(q, v, self._n_landmarks, self._overlap_thresholds(q.device)[1])

    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = world.batch_dim if env_index is None else (1 if isinstance(env_index, int) else len(env_index))
        for entity in world.agents + world.landmarks:
            pos = torch.empty(rows, world.dim_p, device=world.device).uniform_(-1.0, 1.0)
            entity.set_pos(pos if env_index is None else pos.squeeze(0) if isinstance(env_index, int) else pos, batch_index=env_index)

    def reward(self, agent: Agent) -> torch.Tensor:
        if self._few_envs:
            return self.outputs()[0][self._agent_index[agent.name]]
        return self.outputs()[0]

    def _overlap_thresholds(self, device, agents=None) -> tuple:
        """``[A, A, 1]`` distances (and their squares) below which two agents overlap; -1 where a pair cannot count."""
        if self._overlap is None or self._overlap[0].device != device:
            agents = self.world.agents if agents is None else agents
            radii = torch.tensor([a.shape.radius for a in agents], device=device)
            reach = radii.view(-1, 1) + radii.view(1, -1)  # in float32, as the distances it is compared with
            # pairs that cannot count get a threshold no distance (or squared distance) is below: x * 1 + 0
            # or x * 0 - 1, exactly (the 0/1 mask from Python: no eye/bitwise kernels loaded just for this)
            counts = torch.tensor([[float(a.collide and a is not b) for b in agents] for a in agents], device=device)
            self._overlap = tuple((t * counts + (counts - 1)).unsqueeze(-1) for t in (reach, reach * reach))
        return self._overlap

    def observation(self, agent: Agent) -> torch.Tensor:
        index = self._agent_index[agent.name]
        if self._few_envs:
            return self.outputs()[1][index]
        return self._agent_observation(index)

    def observation_layout(self, agent: Agent) -> ObservationLayout:
        """Own position and velocity, then landmarks and other agents relative to the agent (minus its position)."""
        relative = range(4, 2 * (len(self._seen_rows[self._agent_index[agent.name]]) + 2), 2)
        return ObservationLayout(position=((0, 1),) + tuple((column, -1) for column in relative), velocity=((2, 1),))

    def _agent_observation(self, index: int) -> torch.Tensor:
        """Agent ``index``'s observation ``[B, obs]`` at many envs.

        One tensor per agent, as the env hands them out: one ``[A, B, obs]``
        block for all agents raised the heap's high-water mark by its size at
        many envs, and one block per agent did not. Laid out ``[B, (own pos,
        own vel, landmarks, other agents)]`` as complex numbers, i.e. (x, y)
        pairs: each slot is written, or a relative position subtracted into it,
        as whole 8-byte pairs (a strided write of single floats takes twice the
        passes). The pairs come from :meth:`batched_outputs`, once per state
        for all agents; the only other temporary is the other agents' gathered rows.
        """
        _, positions, velocities = self.outputs()
        positions, velocities = as_pairs(positions), as_pairs(velocities)
        n_landmarks = self._n_landmarks
        own = positions[n_landmarks + index]
        observation = torch.empty(own.shape[0], len(self._seen_rows[index]) + 2, dtype=positions.dtype,
                                  device=own.device)
        observation[:, 0] = own
        observation[:, 1] = velocities[index]
        own = own.unsqueeze(-1)  # [B, 1]
        _subtract_into(observation[:, 2:2 + n_landmarks], positions[:n_landmarks].t(), own)
        others = self._other_agents_index(index, own.device)
        if others is not None:
            _subtract_into(observation[:, 2 + n_landmarks:], positions.index_select(0, others).t(), own)
        return torch.view_as_real(observation).flatten(1)

    def _other_agents_index(self, index: int, device):
        """The state rows of the agents agent ``index`` observes (None without ``obs_agents``), cached."""
        key = ("others", index, device)
        if key not in self._seen_rows_on:
            rows = self._seen_rows[index][self._n_landmarks:]
            self._seen_rows_on[key] = torch.tensor(rows, device=device) if rows else None
        return self._seen_rows_on[key]


def _many_envs_outputs(q: torch.Tensor, v: torch.Tensor, n_landmarks: int, overlap_below_squared: torch.Tensor) -> tuple:
    """Rewards ``[B]``, positions ``[N, B]`` and agents' velocities ``[A, B]`` as (x, y) pairs
    (:func:`~vmas_ros.simulator.layout.complex_pairs`) from the planar state.

    On planar rows ``[N, B]``: squared distances over contiguous blocks
    vectorise. The nearest agent to each landmark is found on squared
    distances (sqrt is monotonic); the floor before the root keeps its
    gradient finite when an agent sits exactly on a landmark.
    """
    x, y = q[0], q[1]
    n_agents = x.shape[0] - n_landmarks
    ax, ay, lx, ly = x[n_landmarks:], y[n_landmarks:], x[:n_landmarks], y[:n_landmarks]
    coverage = _squared_gaps(ax, ay, lx, ly).amin(dim=0).clamp_min(1e-30).sqrt().sum(dim=0)  # [A, L, B] -> [B]
    overlaps = (_squared_gaps(ax, ay, ax, ay) < overlap_below_squared).sum(dim=(0, 1))
    rewards = -n_agents * coverage - overlaps.float()
    return rewards, complex_pairs(x, y), complex_pairs(v[0, n_landmarks:], v[1, n_landmarks:])


def _few_envs_outputs(q: torch.Tensor, v: torch.Tensor, n_landmarks: int, overlap_below: torch.Tensor,
                      seen: torch.Tensor) -> tuple:
    """Each agent's reward ``[B]`` and observation ``[B, obs]`` (two tuples, rows of one result each) from
    the planar state ``[3, N, B]`` (landmarks first).

    ``overlap_below`` ``[A, A, 1]``: distance under which two agents overlap
    (negative for pairs that cannot); ``seen``: each agent's observed rows of
    the flattened ``[A * N]`` offsets. A pure function of tensors (see
    ``Scenario.batched_outputs``): the same numbers as :func:`_many_envs_outputs`.
    """
    xy = q[:2].permute(1, 2, 0).contiguous()  # [N, B, 2]: contiguous pairs (strided ones slow every op below)
    agents = xy[n_landmarks:]
    relative = xy.unsqueeze(0) - agents.unsqueeze(1)  # [A, N, B, 2]: every entity relative to each agent
    distance = torch.linalg.vector_norm(relative, dim=-1)  # [A, N, B]
    coverage = distance[:, :n_landmarks].amin(dim=0).sum(dim=0)
    overlaps = (distance[:, n_landmarks:] < overlap_below).sum(dim=(0, 1))
    rewards = torch.sub(coverage * -agents.shape[0], overlaps)
    rows = torch.index_select(relative.flatten(0, 1), 0, seen).view(agents.shape[0], -1, *relative.shape[2:])
    own_vel = v[:2, n_landmarks:].permute(1, 2, 0)
    observations = torch.cat([agents, own_vel, rows.permute(0, 2, 1, 3).flatten(2)], dim=-1)
    return rewards.expand(agents.shape[0], -1).clone().unbind(0), observations.unbind(0)


def _subtract_into(destination: torch.Tensor, a: torch.Tensor, b: torch.Tensor) -> None:
    """``destination[...] = a - b`` in one pass (``out=``), or through a copy when autograd must see it."""
    if torch.is_grad_enabled() and (a.requires_grad or b.requires_grad):
        destination.copy_(a - b)  # out= refuses tensors that require grad
    else:
        torch.sub(a, b, out=destination)


def _squared_gaps(ax: torch.Tensor, ay: torch.Tensor, bx: torch.Tensor, by: torch.Tensor) -> torch.Tensor:
    """Squared distances ``[I, J, B]`` between points ``(ax, ay)`` ``[I, B]`` and ``(bx, by)`` ``[J, B]``."""
    dx, dy = ax.unsqueeze(1) - bx.unsqueeze(0), ay.unsqueeze(1) - by.unsqueeze(0)
    if dx.requires_grad or dy.requires_grad:
        return torch.addcmul(dx * dx, dy, dy)
    return dx.mul_(dx).addcmul_(dy, dy)  # in the differences' own memory: two [I, J, B] tensors, not four


class HeuristicPolicy(BaseHeuristicPolicy):
    """Go to a landmark no closer agent is going to (greedy matching from one's own observation).

    Each agent rebuilds the agent-landmark distance matrix from its observation,
    assigns pairs greedily (globally nearest pair first), and steers to its own
    landmark with a damped proportional controller.
    """

    gain = 3.0
    damping = 1.0

    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        batch = observation.shape[0]
        vel = observation[:, 2:4]
        rest = observation.shape[1] - 4
        n = (rest + 2) // 4  # 2n landmark coords + 2(n-1) agent coords
        landmarks = observation[:, 4:4 + 2 * n].view(batch, n, 2)
        others = observation[:, 4 + 2 * n:].view(batch, -1, 2)
        agents = torch.cat([torch.zeros(batch, 1, 2, device=observation.device), others], dim=1)  # self first
        mine = greedy_first_match(torch.cdist(agents, landmarks))  # from the distances [B, A, L]
        mine = torch.where(mine < 0, 0, mine)
        target = landmarks[torch.arange(batch, device=observation.device), mine]
        action = self.gain * target - self.damping * vel
        return action.clamp(-u_range, u_range)
