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
from vmas_ros.simulator.compiling import WorldKernel
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color

#: name -> default of every kwarg
DEFAULTS = {"n_agents": 3, "obs_agents": True}

AGENT_RADIUS = 0.15
#: below this many envs, the reward and observations take the formulation with fewer calls (each
#: call's fixed cost dominates); from it on, the one with fewer passes over memory
FEW_ENVS = 64


class Scenario(BaseScenario):
    supports_batched_reset = True
    fresh_observations = True  # computed afresh per collection (few envs: views of one result), never written to

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
        self._reward_cache = None
        n_landmarks = self._n_landmarks = n_agents
        #: per observing agent, the rows of world.stacked_state() it sees relative to itself:
        #: every landmark, then (with obs_agents) every other agent; entities are landmarks then agents
        self._seen_rows = [
            list(range(n_landmarks)) + ([n_landmarks + j for j in range(n_agents) if j != i] if self.obs_agents else [])
            for i in range(n_agents)
        ]
        #: the same rows in the flattened [A * N] (agent, entity) offsets of _relative_few_envs
        self._seen_flat_rows = [i * (n_landmarks + n_agents) + row for i, rows in enumerate(self._seen_rows) for row in rows]
        self._seen_rows_on: dict = {}  # (which rows, device) -> [A, R] index tensor
        self._agent_index = {agent.name: i for i, agent in enumerate(world.agents)}
        self._few_cache = None  # (pos stack, vel stack, (rewards, observations)) of the last state, few envs only
        self._pairs_cache = None  # (q, v, positions, velocities) as complex pairs, many envs (see _state_pairs)
        self._overlap = None  # see _overlap_thresholds
        self._few_kernel = WorldKernel(world, self._few_envs_kernel)  # compiled with the world's physics
        # at a few envs every step computes them with its physics (one compiled call for both when compiled)
        self._few_handle = world.add_state_kernel(self._few_envs_kernel) if batch_dim < FEW_ENVS else None
        # fill the index and threshold caches now: filled inside a compiled trace they would split its graph
        self._overlap_thresholds(world.device, world.agents)
        self._seen_rows_on[("relative", world.device)] = torch.tensor(self._seen_flat_rows, device=world.device)
        return world

    def _few_envs_kernel(self, q: torch.Tensor, v: torch.Tensor) -> tuple:
        """:func:`_few_envs_outputs` with this world's constants (a state kernel: a pure function of q, v)."""
        seen = self._seen_rows_on.get(("relative", q.device))
        if seen is None:
            seen = self._seen_rows_on[("relative", q.device)] = torch.tensor(self._seen_flat_rows, device=q.device)
        return _few_envs_outputs(q, v, self._n_landmarks, self._overlap_thresholds(q.device)[0], seen)

    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = world.batch_dim if env_index is None else (1 if isinstance(env_index, int) else len(env_index))
        for entity in world.agents + world.landmarks:
            pos = torch.empty(rows, world.dim_p, device=world.device).uniform_(-1.0, 1.0)
            entity.set_pos(pos if env_index is None else pos.squeeze(0) if isinstance(env_index, int) else pos, batch_index=env_index)

    def reward(self, agent: Agent) -> torch.Tensor:
        if agent is self.world.agents[0]:
            self._reward_cache = self._reward_few_envs() if self.world.batch_dim < FEW_ENVS else self._reward_many_envs()
        return self._reward_cache

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

    def _reward_many_envs(self) -> torch.Tensor:
        # planar components: squared distances over contiguous [rows, B] blocks vectorise
        x, y = self.world.stacked_xy("pos")
        n_landmarks = len(self.world.landmarks)
        n_agents = x.shape[0] - n_landmarks
        ax, ay, lx, ly = x[n_landmarks:], y[n_landmarks:], x[:n_landmarks], y[:n_landmarks]
        # each landmark's distance to its nearest agent, summed over landmarks: [A, L, B] -> [B]
        # (sqrt is monotonic, so the nearest agent is found on squared distances; the floor keeps
        # the root's gradient finite when an agent sits exactly on a landmark)
        coverage = _squared_gaps(ax, ay, lx, ly).amin(dim=0).clamp_min(1e-30).sqrt().sum(dim=0)
        overlaps = (_squared_gaps(ax, ay, ax, ay) < self._overlap_thresholds(x.device)[1]).sum(dim=(0, 1))
        return -n_agents * coverage - overlaps.float()

    def _few_envs(self) -> tuple:
        """``(rewards [B], observations [A, B, obs])`` in one pass over the state, once per state (few envs).

        At a few envs each tensor call's fixed cost is the cost: both are read
        from one ``[A, N, B, 2]`` table of offsets, and the whole computation is
        one :class:`~vmas_ros.simulator.compiling.WorldKernel` (one compiled
        call when the world compiles its physics). Keyed on the identity of the
        world's stacked positions and velocities, like :meth:`_observations`.
        """
        world = self.world
        q, v = world.planar_state()
        cached = self._few_cache
        if cached is not None and cached[0] is q and cached[1] is v:
            return cached[2]
        outputs = None if self._few_handle is None else world.take_state_kernel_output(self._few_handle)
        if outputs is None:  # the state changed since the step (a reset, a setter), or many envs
            outputs = self._few_kernel(q, v)
        self._few_cache = (q, v, outputs)
        return outputs

    def _reward_few_envs(self) -> torch.Tensor:
        return self._few_envs()[0]

    def observation(self, agent: Agent) -> torch.Tensor:
        index = self._agent_index[agent.name]
        last = index == len(self._agent_index) - 1
        if self.world.batch_dim >= FEW_ENVS:
            observation = self._agent_observation(index)
            if last:
                self._pairs_cache = None
            return observation
        observation = self._observations()[index]
        if last:
            # the environment asks in agent order: the next collection computes afresh, so
            # observations handed out (without a copy, see fresh_observations) never alias later ones
            self._few_cache = None
        return observation

    def _observations(self) -> torch.Tensor:
        """Every agent's observation ``[A, B, obs]`` at a few envs: computed with the rewards, once per
        state (see :meth:`_few_envs`)."""
        return self._few_envs()[1]

    def _agent_observation(self, index: int) -> torch.Tensor:
        """Agent ``index``'s observation ``[B, obs]`` at many envs, from the planar state.

        One tensor per agent, as the env hands them out: at 30,000 envs one
        ``[A, B, obs]`` block made the heap's high-water mark jump by its size
        from run to run, and one block per agent did not. Laid out ``[B, (own
        pos, own vel, landmarks, other agents)]`` as complex numbers, i.e. (x, y) pairs: each
        slot is written, or a relative position subtracted into it, as whole
        8-byte pairs (a strided write of single floats takes twice the passes).
        The positions as pairs are built once per state for all agents
        (:meth:`_state_pairs`); the only other temporary is the other agents' gathered rows.
        """
        positions, velocities = self._state_pairs()
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

    def _state_pairs(self) -> tuple:
        """Every entity's position ``[N, B]`` and every agent's velocity ``[A, B]`` as complex (x, y) pairs,
        once per state (keyed on the planar state's identity; dropped after the last agent's observation)."""
        q, v = self.world.planar_state()
        cached = self._pairs_cache
        if cached is None or cached[0] is not q or cached[1] is not v:
            n_landmarks = self._n_landmarks
            cached = self._pairs_cache = (q, v, torch.complex(q[0], q[1]),
                                          torch.complex(v[0, n_landmarks:], v[1, n_landmarks:]))
        return cached[2], cached[3]

    def _other_agents_index(self, index: int, device):
        """The state rows of the agents agent ``index`` observes (None without ``obs_agents``), cached."""
        key = ("others", index, device)
        if key not in self._seen_rows_on:
            rows = self._seen_rows[index][self._n_landmarks:]
            self._seen_rows_on[key] = torch.tensor(rows, device=device) if rows else None
        return self._seen_rows_on[key]


def _few_envs_outputs(q: torch.Tensor, v: torch.Tensor, n_landmarks: int, overlap_below: torch.Tensor,
                      seen: torch.Tensor) -> tuple:
    """Rewards ``[B]`` and observations ``[A, B, obs]`` from the planar state ``[3, N, B]`` (landmarks first).

    ``overlap_below`` ``[A, A, 1]``: distance under which two agents overlap
    (negative for pairs that cannot); ``seen``: each agent's observed rows of
    the flattened ``[A * N]`` offsets. A pure function of tensors (see
    ``WorldKernel``): the same numbers as the many-envs formulation.
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
    return rewards, observations


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
