"""Building and stepping envs the way the checks do: action layouts, random actions, output checks.

* ``SPACE_MODES``: the ``make_env`` keywords of each layout an env can be
  built with (continuous, discrete, multidiscrete actions; dict spaces);
* ``space_actions``: one step's actions drawn inside each agent's action
  space from a generator of the caller's (so two runs draw the same);
* ``by_agent``: a step's per-agent outputs (a list, or a dict by agent name)
  as ``[(agent name, value)]``;
* ``space_mismatch`` and ``non_finite``: what is wrong with one value, as a
  sentence, or None; ``named_tensors``: the tensors inside a nested value;
* ``random_steps``: a short random rollout whose every value must stay finite.

Everything raises AssertionError on its own (never a bare ``assert``), so
the checks hold under ``python -O`` too.
"""
from __future__ import annotations

from typing import Dict, List, Optional, Tuple

import torch

__all__ = [
    "ACTION_MODES", "SPACE_MODES", "space_actions", "by_agent", "describe_envs", "space_mismatch", "non_finite",
    "named_tensors", "random_steps",
]

#: the action layouts an env can be built with, as ``make_env`` kwargs (continuous, the default, spelt out)
ACTION_MODES: Dict[str, dict] = {
    "continuous": dict(continuous_actions=True),
    "discrete": dict(continuous_actions=False),
    "multidiscrete": dict(continuous_actions=False, multidiscrete_actions=True),
}
#: the action layouts (continuous left to the default) and the dict layout of observations and actions
SPACE_MODES: Dict[str, dict] = {
    "continuous": dict(),
    "discrete": ACTION_MODES["discrete"],
    "multidiscrete": ACTION_MODES["multidiscrete"],
    "dict": dict(dict_spaces=True),
}


def space_actions(env, gen: torch.Generator) -> List[torch.Tensor]:
    """Uniform actions inside each agent's action space, [B, action size] each, drawn from ``gen``.

    Box: uniform in [low, high] (so messages in [0, 1]); Discrete: [B, 1]
    indices; MultiDiscrete: [B, len(nvec)] indices. Drawn on the generator's
    device (the CPU for ``torch.Generator()``) so that they do not depend on
    the env's device, then moved to it.
    """
    actions = []
    for space in (env.get_agent_action_space(a) for a in env.agents):
        kind = type(space).__name__
        if kind == "Box":
            low, high = torch.tensor(space.low), torch.tensor(space.high)
            action = low + (high - low) * torch.rand(env.num_envs, len(low), generator=gen)
        elif kind == "Discrete":
            action = torch.randint(int(space.n), (env.num_envs, 1), generator=gen)
        else:
            nvec = torch.tensor(space.nvec)
            action = (torch.rand(env.num_envs, len(nvec), generator=gen) * nvec).long()
        actions.append(action.to(env.device))
    return actions


def by_agent(env, values) -> List[Tuple[str, object]]:
    """One step's per-agent outputs as ``[(agent name, value)]``, from a list (agent order) or a dict by name."""
    if isinstance(values, dict):
        return list(values.items())
    return [(agent.name, value) for agent, value in zip(env.agents, values)]


def describe_envs(mask: torch.Tensor) -> str:
    """``"envs [0, 3]"`` for a [B] bool mask (at most eight indices, then how many more)."""
    indices = mask.nonzero().flatten().tolist()
    shown = ", ".join(str(i) for i in indices[:8])
    more = f", ... ({len(indices)} in all)" if len(indices) > 8 else ""
    return f"env{'s' if len(indices) != 1 else ''} [{shown}{more}]"


def _shape(values) -> str:
    return "[" + ", ".join(str(int(n)) for n in values) + "]"


def space_mismatch(value, space, num_envs: int, where: str) -> Optional[str]:
    """Why ``value`` does not fit ``space`` with the batch dimension first, or None when it does.

    A Box wants a floating-point tensor of shape [num_envs, *space.shape] and
    dtype ``space.dtype``; a Dict space wants a dict with its keys, each value
    fitting its own space. ``where`` names the value in the sentence.
    """
    if type(space).__name__ == "Dict":
        if not isinstance(value, dict):
            return f"{where} is a {type(value).__name__}, its space is a Dict with keys {list(space.spaces)}"
        if list(value) != list(space.spaces):
            return f"{where} has keys {list(value)}, its space says {list(space.spaces)}"
        for key, sub in space.spaces.items():
            problem = space_mismatch(value[key], sub, num_envs, f"{where}[{key!r}]")
            if problem:
                return problem
        return None
    if not isinstance(value, torch.Tensor):
        return f"{where} is a {type(value).__name__}, expected a tensor"
    expected = (num_envs, *space.shape)
    if tuple(value.shape) != expected:
        return f"{where} has shape {_shape(value.shape)}, its space says {_shape(expected)} (the batch first)"
    wanted = getattr(torch, str(space.dtype), None)
    if wanted is not None and value.dtype != wanted:
        return f"{where} has dtype {value.dtype}, its space says {wanted}"
    return None


def non_finite(value: torch.Tensor, where: str) -> Optional[str]:
    """``"<where> is NaN or infinite in envs [...]"`` for a floating-point tensor [B, ...], else None."""
    if not torch.is_floating_point(value):
        return None
    bad = ~torch.isfinite(value)
    if not bool(bad.any()):
        return None
    rows = bad.reshape(bad.shape[0], -1).any(dim=1) if bad.dim() else bad.reshape(1)
    kinds = "NaN" if bool(torch.isnan(value).any()) else "infinite"
    return f"{where} is {kinds} in {describe_envs(rows)}"


def named_tensors(where: str, value) -> List[Tuple[str, torch.Tensor]]:
    """The tensors inside ``value`` (a tensor, or nested dicts of them), each named below ``where``.

    ``named_tensors("info of agent_0", {"a": t})`` is ``[("info of agent_0['a']", t)]``;
    values that are neither tensors nor dicts are left out.
    """
    if isinstance(value, dict):
        return [item for key, sub in value.items() for item in named_tensors(f"{where}[{key!r}]", sub)]
    return [(where, value)] if isinstance(value, torch.Tensor) else []


def random_steps(env, steps: int, gen: Optional[torch.Generator] = None, as_dict: bool = False):
    """Step ``env`` ``steps`` times at random; every observation and reward must stay finite.

    Actions are ``space_actions(env, gen)`` when ``gen`` is given, else
    ``env.get_random_actions()``; with ``as_dict`` they are passed as
    ``{agent name: action}``. Raises AssertionError naming the first value
    that is not finite, its agent, step and envs. Returns the last ``(obs, rews)``.
    """
    obs = rews = None
    for step in range(1, steps + 1):
        actions = env.get_random_actions() if gen is None else space_actions(env, gen)
        if as_dict:
            actions = {a.name: act for a, act in zip(env.agents, actions, strict=True)}
        obs, rews, _, _ = env.step(actions)
        for kind, outputs in (("observation", obs), ("reward", rews)):
            for name, value in by_agent(env, outputs):
                for where, tensor in named_tensors(f"{kind} of {name}", value):
                    problem = non_finite(tensor, f"{where} after step {step}")
                    if problem:
                        raise AssertionError(problem)
    return obs, rews
