"""simple_crypto (MPE "covert communication").

Description
    Three immobile agents talk over a public channel of ``dim_c`` numbers:
    Alice (the speaker, green) knows a secret and a key, Bob (blue) knows the
    key, Eve (the adversary, red) knows neither. Each step every agent
    broadcasts a message (the communication part of its action); Bob's and
    Eve's messages are their guesses of the secret. Alice and Bob win when Bob
    reconstructs the secret and Eve does not, so Alice must encrypt it with the key.
    Agents' positions are random and play no part (they only place the drawing).
Observation (per agent, in this order)
    Alice: secret (dim_c), key (dim_c).
    Bob: key (dim_c), Alice's last message (dim_c).
    Eve: Alice's last message (dim_c).
Reward (individual, as in MPE and VMAS 1.5)
    A listener's score is minus the squared error of its last message to the
    secret, or 0 while its message is all zeros (silence is not scored).
    Eve gets her score; Alice and Bob both get Bob's score minus Eve's.
Starting state
    Secret and key: independent uniform random bit vectors of length
    ``dim_c`` per env (VMAS 1.5's choice; MPE uses one-hot vectors), redrawn
    when an env is reset; ``Scenario.secret`` and ``Scenario.key`` ([batch,
    dim_c] floats) hold them. Positions uniform in [-1, 1]^2.
Episode termination
    Never (set ``max_steps``).
Kwargs
    ``dim_c`` (4): length of the messages, the secret and the key.
"""
from __future__ import annotations

import torch

from vmas_ros.scenarios.common import read_kwargs
from vmas_ros.simulator.core import Agent, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color

#: name -> default of every kwarg
DEFAULTS = {"dim_c": 4}

#: (name, colour, adversary) in world order: Eve, Bob, Alice (as MPE and VMAS)
ROLES = (("eve_0", Color.RED, True), ("bob_0", Color.BLUE, False), ("alice_0", Color.GREEN, False))
EVE, BOB, ALICE = range(3)


def _reset_rows(world: World, env_index) -> torch.Tensor:
    """The env indices a reset touches, as a 1-D long tensor (None means every env)."""
    if env_index is None:
        return torch.arange(world.batch_dim, device=world.device)
    return torch.as_tensor(env_index, dtype=torch.long, device=world.device).reshape(-1)


def _bits(rows: int, width: int, device) -> torch.Tensor:
    return torch.randint(0, 2, (rows, width), device=device).float()


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        dim_c = read_kwargs(kwargs, DEFAULTS)["dim_c"]
        if isinstance(dim_c, bool) or not isinstance(dim_c, int) or dim_c < 1:
            raise ValueError(f"simple_crypto: dim_c must be a positive int, got {dim_c!r}")
        world = World(batch_dim=batch_dim, device=device, dim_c=dim_c)
        for name, color, adversary in ROLES:
            agent = Agent(name=name, collide=False, movable=False, color=color, adversary=adversary, silent=False)
            agent.speaker = name.startswith("alice")  # VMAS 1.5 exposes the role on the agent
            world.add_agent(agent)
        self.secret = torch.zeros(batch_dim, dim_c, device=device)
        self.key = torch.zeros(batch_dim, dim_c, device=device)
        return world

    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = _reset_rows(world, env_index)
        self.secret[rows] = _bits(len(rows), world.dim_c, world.device)
        self.key[rows] = _bits(len(rows), world.dim_c, world.device)
        pos = torch.empty(len(rows), len(world.agents), 2, device=world.device).uniform_(-1.0, 1.0)
        for agent, p in zip(world.agents, pos.unbind(1)):
            agent.set_pos(p, batch_index=None if env_index is None else rows)

    def _scores(self) -> torch.Tensor:
        """[B, 2]: Eve's and Bob's scores (minus squared error to the secret; 0 when silent)."""
        guesses = torch.stack([self.world.agents[EVE].state.c, self.world.agents[BOB].state.c], dim=1)
        error = (guesses - self.secret.unsqueeze(1)).square().sum(dim=-1)
        spoke = (guesses != 0).any(dim=-1)
        return torch.where(spoke, -error, 0.0)

    def reward(self, agent: Agent) -> torch.Tensor:
        eve, bob = self._scores().unbind(-1)
        return eve if agent.adversary else bob - eve

    def observation(self, agent: Agent) -> torch.Tensor:
        said = self.world.agents[ALICE].state.c
        role = self.world.agents.index(agent)
        if role == ALICE:
            return torch.cat([self.secret, self.key], dim=-1)
        if role == BOB:
            return torch.cat([self.key, said], dim=-1)
        return said.clone()


class HeuristicPolicy(BaseHeuristicPolicy):
    """A one-time pad: Alice says ``secret XOR key``, Bob answers ``message XOR key``, Eve says 0.5.

    For bits, XOR is ``|a - b|``, and both Alice's observation (secret, key) and
    Bob's (key, message) are two halves whose XOR is what they should say, so
    one rule serves both. Bob decodes the message Alice sent a step earlier
    (the first step he answers with the key alone). The message is uniformly
    random whatever the secret, so Eve can do no better than 0.5 per bit
    (expected score ``-dim_c / 4`` against ``-dim_c / 3`` for random guesses).
    Agents do not move, so the physical action is zero. Eve's observation is
    half as wide as the others': ``dim_c`` tells them apart (set the attribute
    if the scenario was built with another value). Note the reward's
    loophole, kept from MPE and VMAS: an all-zero message is not scored, so a
    silent Eve would get 0; this policy does not exploit it.
    """

    dim_c = 4

    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        batch, width = observation.shape
        if width == 2 * self.dim_c:
            message = (observation[:, : self.dim_c] - observation[:, self.dim_c:]).abs().clamp(0.0, 1.0)
        elif width == self.dim_c:
            message = torch.full_like(observation, 0.5)
        else:
            raise ValueError(
                f"simple_crypto heuristic: observation width {width} fits no role for dim_c={self.dim_c}"
            )
        return torch.cat([torch.zeros(batch, 2, device=observation.device), message], dim=-1)
