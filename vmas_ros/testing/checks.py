"""The checks of ``check_scenario``, one function each, in the order it runs them.

Each takes the ``Subject`` (the scenario, and how to build fresh envs of it),
raises AssertionError saying what it found against what it expected, raises
``CheckSkipped`` when it does not apply, and may return a note (what it could
not look at). vmas_ros/testing/check_scenario.py lists them and runs them.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional

import torch

from vmas_ros.testing import parity
from vmas_ros.testing.report import CheckSkipped
from vmas_ros.testing.rollout import (
    SPACE_MODES, by_agent, describe_envs, named_tensors, non_finite, space_actions, space_mismatch,
)
from vmas_ros.testing.state import capture_kept, changed_rows, copy_kept_tensors, entity_state, per_env
from vmas_ros.testing.vmas_differences import RESYNC, design_difference
from vmas_ros.testing.vmas_states import SCENARIO_STATES

__all__ = [
    "Subject", "check_spaces", "check_reset_observations", "check_step_outputs", "check_device", "check_finite",
    "check_determinism", "check_reset_at", "check_batching", "check_vmas_parity",
]

#: steps taken before ``reset_at`` so that every env has moved away from its start
_WARM_UP_STEPS = 3
#: the env that ``reset_at`` resets, and the env whose actions ``batching`` changes
_RESET_ENV, _CHANGED_ENV = 1, 0
#: the per-agent action space of each layout (the dict layout has continuous actions)
_ACTION_SPACES = {"continuous": "Box", "discrete": "Discrete", "multidiscrete": "MultiDiscrete"}


@dataclass
class Subject:
    """The scenario under check, and how to build fresh envs of it."""

    label: str
    new_scenario: Callable[[], object]
    registered: Optional[str]
    num_envs: int
    steps: int
    seed: int
    device: torch.device
    vmas_name: Optional[str]
    atol: float
    scenario_state: Optional[Callable[[object, object], None]]
    scenario_kwargs: Dict[str, object] = field(default_factory=dict)

    def make(self, **layout):
        """A new env of a fresh copy of the scenario, in the layout ``layout`` (``SPACE_MODES``' keywords)."""
        from vmas_ros.envs.make_env import make_env

        # eager: the checks are of the scenario, and VMAS parity is bit for bit on the eager path only
        return make_env(self.new_scenario(), num_envs=self.num_envs, device=self.device, seed=self.seed,
                        compile_physics=False, **self.scenario_kwargs, **layout)


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise AssertionError(message)


def _layout(options: dict) -> str:
    return ", ".join(f"{k}={v!r}" for k, v in options.items()) or "the defaults"


def _named(env, when: str, obs, rews=None, dones=None, infos=None) -> Dict[str, torch.Tensor]:
    """Values an env returned (``obs`` alone for a reset) and the entities' states, by name.

    Each tensor is [B, ...]; names read ``"reward of agent_0 after step 2"``
    (``when`` ends every name, so that values of several calls can be pooled).
    """
    parts = []
    for kind, values in (("observation", obs), ("reward", rews), ("info", infos)):
        if values is not None:
            for agent, value in by_agent(env, values):
                parts += named_tensors(f"{kind} of {agent}", value)
    if dones is not None:
        parts += named_tensors("dones", dones)
    parts += list(entity_state(env).items())
    suffix = f" {when}" if when else ""
    return {f"{where}{suffix}": value for where, value in parts}


def _first_difference(before: Dict[str, torch.Tensor], after: Dict[str, torch.Tensor],
                      rows: Optional[torch.Tensor] = None) -> Optional[str]:
    """The first key whose value differs between the two (bitwise), or None.

    With ``rows`` (a [B] mask) only those rows of batch-first tensors are
    compared, and the answer names the envs: ``"<key> in envs [...]"``.
    Without, whole tensors are compared, whatever their shape.
    """
    if rows is None:
        changed = [key for key, value in before.items()
                   if key not in after or after[key].shape != value.shape or not torch.equal(after[key], value)]
    else:
        changed = changed_rows(before, after, rows)
    if not changed:
        return None
    key = changed[0]
    old, new = before[key], after.get(key)
    more = f", and {len(changed) - 1} more value(s)" if len(changed) > 1 else ""
    if new is None:
        return f"{key} (it no longer holds one row per env: was {list(old.shape)}){more}"
    if new.shape != old.shape:
        return f"{key} (its shape went from {list(old.shape)} to {list(new.shape)}){more}"
    if rows is None:
        return f"{key}{more}"
    differs = (new != old).reshape(old.shape[0], -1).any(dim=1) & rows.to(old.device)
    return f"{key} in {describe_envs(differs.cpu())}{more}"


# ---------------------------------------------------------------------- checks
def check_spaces(subject: Subject) -> None:
    """Builds in every layout; observation and action spaces are per-agent gymnasium spaces of its kind."""
    from vmas_ros.compat.spaces import space_types

    kinds = space_types()
    for mode, options in SPACE_MODES.items():
        try:
            env = subject.make(**options)
        except Exception as error:
            raise AssertionError(
                f"make_env with {_layout(options)} raised {type(error).__name__}: {error}") from error
        names = [agent.name for agent in env.agents]
        _require(len(set(names)) == len(names), f"agent names must be unique, got {names}")
        expected_action = _ACTION_SPACES.get(mode, "Box")
        for what, space in (("observation space", env.observation_space), ("action space", env.action_space)):
            _require(isinstance(space, kinds.Space),
                     f"the {what} is a {type(space).__name__}, expected a {kinds.__name__} space")
            if mode == "dict":
                _require(type(space).__name__ == "Dict" and sorted(space.spaces) == sorted(names),
                         f"with dict_spaces=True the {what} must be a Dict keyed by the agents {names}, got {space}")
                per_agent = [space.spaces[name] for name in names]
            else:
                _require(type(space).__name__ == "Tuple" and len(space.spaces) == len(names),
                         f"the {what} must be a Tuple of one space per agent ({len(names)}), got {space}")
                per_agent = list(space.spaces)
            for agent, agent_space in zip(env.agents, per_agent):
                where = f"{what} of {agent.name} ({mode} layout)"
                if what == "observation space":
                    _check_observation_space(agent_space, where)
                else:
                    _require(type(agent_space).__name__ == expected_action,
                             f"{where} is {agent_space}, expected a {expected_action}")
                    _check_action_space(env, agent, agent_space, where)


def _check_observation_space(space, where: str) -> None:
    if type(space).__name__ == "Dict":
        for key, sub in space.spaces.items():
            _check_observation_space(sub, f"{where}[{key!r}]")
        return
    _require(type(space).__name__ == "Box", f"{where} is {space}, expected a Box or a Dict of them")
    _require(len(space.shape) >= 1, f"{where} has shape {space.shape}: observation() must return [B, n], not [B]")


def _check_action_space(env, agent, space, where: str) -> None:
    kind = type(space).__name__
    if kind == "Box":
        size = env.get_agent_action_size(agent)
        _require(space.shape == (size,), f"{where} has shape {space.shape}, the agent's action size is {size}")
        _require(bool((space.low <= space.high).all()) and bool(abs(space.low).max(initial=0) < float("inf"))
                 and bool(abs(space.high).max(initial=0) < float("inf")),
                 f"{where} has bounds low={space.low} high={space.high}: they must be finite with low <= high")
    elif kind == "Discrete":
        _require(int(space.n) >= 1, f"{where} has n={space.n}, expected at least 1 choice")
    else:
        _require(bool((space.nvec >= 1).all()),
                 f"{where} has nvec={space.nvec}, expected at least 1 choice per component")


def check_reset_observations(subject: Subject) -> None:
    """``reset()``'s observations fit the space, [B, ...], as a list in agent order and as a dict by name."""
    for mode in ("continuous", "dict"):
        env = subject.make(**SPACE_MODES[mode])
        obs = env.reset()
        when = "after reset" + (" (dict layout)" if mode == "dict" else "")
        _check_observations(env, obs, when, SPACE_MODES[mode])


def _check_observations(env, obs, when: str, options: dict) -> None:
    names = [agent.name for agent in env.agents]
    if options.get("dict_spaces"):
        _require(isinstance(obs, dict) and list(obs) == names,
                 f"with dict_spaces=True the observations {when} must be a dict keyed by {names}, got "
                 f"{list(obs) if isinstance(obs, dict) else type(obs).__name__}")
        spaces = [env.observation_space.spaces[name] for name in names]
    else:
        _require(isinstance(obs, list) and len(obs) == len(names),
                 f"the observations {when} must be a list of one per agent ({len(names)}), got {type(obs).__name__}"
                 + (f" of {len(obs)}" if isinstance(obs, (list, tuple)) else ""))
        spaces = list(env.observation_space.spaces)
    for (name, value), space in zip(by_agent(env, obs), spaces):
        problem = space_mismatch(value, space, env.num_envs, f"observation of {name} {when}")
        _require(problem is None, problem)


def check_step_outputs(subject: Subject) -> None:
    """In every layout, a random step returns observations, rewards, dones and infos of VMAS's shapes, dtypes."""
    batch = subject.num_envs
    for mode, options in SPACE_MODES.items():
        env = subject.make(**options)
        gen = torch.Generator().manual_seed(subject.seed)
        for step in (1, 2):
            result = env.step(space_actions(env, gen))
            _require(isinstance(result, (list, tuple)) and len(result) == 4,
                     f"step must return (obs, rews, dones, infos), got {type(result).__name__}")
            obs, rews, dones, infos = result
            when = f"after step {step} ({mode} layout)"
            _check_observations(env, obs, when, options)
            for name, reward in by_agent(env, rews):
                where = f"reward of {name} {when}"
                _require(isinstance(reward, torch.Tensor),
                         f"{where} is a {type(reward).__name__}, expected a tensor [{batch}]")
                _require(tuple(reward.shape) == (batch,), f"{where} has shape {list(reward.shape)}, expected [{batch}]")
                _require(torch.is_floating_point(reward),
                         f"{where} has dtype {reward.dtype}, expected a floating-point one")
            found = f"{dones.dtype} {list(dones.shape)}" if isinstance(dones, torch.Tensor) else type(dones).__name__
            _require(isinstance(dones, torch.Tensor) and tuple(dones.shape) == (batch,) and dones.dtype == torch.bool,
                     f"dones {when} must be a bool tensor [{batch}], got {found}")
            for name, info in by_agent(env, infos):
                where = f"info of {name} {when}"
                _require(isinstance(info, dict), f"{where} is a {type(info).__name__}, expected a dict of tensors")
                _check_info(info, where, batch)


def _check_info(info: dict, where: str, batch: int) -> None:
    for key, value in info.items():
        if isinstance(value, dict):
            _check_info(value, f"{where}[{key!r}]", batch)
            continue
        _require(isinstance(value, torch.Tensor),
                 f"{where}[{key!r}] is a {type(value).__name__}, expected a tensor [{batch}, ...]")
        _require(value.dim() >= 1 and value.shape[0] == batch,
                 f"{where}[{key!r}] has shape {list(value.shape)}, expected the batch ({batch}) first")


def check_device(subject: Subject) -> None:
    """Every tensor reset, step and reset_at return, and every entity's state, is on ``device``."""
    wanted = subject.device
    env = subject.make()
    gen = torch.Generator().manual_seed(subject.seed)
    found = _named(env, "after reset", env.reset())
    found.update(_named(env, "after a step", *env.step(space_actions(env, gen))))
    found.update(_named(env, "after reset_at(0)", env.reset_at(0)))
    for where, value in found.items():
        on_device = value.device.type == wanted.type and (wanted.index is None or value.device.index == wanted.index)
        _require(on_device, f"{where} is on {value.device}, expected {wanted} (the device the env was made on)")


def check_finite(subject: Subject) -> None:
    """Observations, rewards, infos and entity states stay finite over ``steps`` random steps."""
    env = subject.make()
    gen = torch.Generator().manual_seed(subject.seed)
    values = _named(env, "after reset", env.reset())
    for step in range(subject.steps + 1):
        if step:
            values = _named(env, f"after step {step}", *env.step(space_actions(env, gen)))
        for where, value in values.items():
            problem = non_finite(value, where)
            _require(problem is None, problem)


def check_determinism(subject: Subject) -> None:
    """Two envs built with the same seed, given the same actions, return the same values bit for bit."""
    first, second = subject.make(), subject.make()
    gen = torch.Generator().manual_seed(subject.seed)
    every_env = torch.ones(subject.num_envs, dtype=torch.bool, device=subject.device)
    hint = ("; a scenario must draw its randomness from torch's, numpy's or Python's global generators, "
            "which the env seeds and keeps apart")
    for step in range(subject.steps + 1):
        when = f"after step {step}" if step else "after reset"
        if step:
            actions = space_actions(first, gen)
            mine = _named(first, when, *first.step([a.clone() for a in actions]))
            theirs = _named(second, when, *second.step([a.clone() for a in actions]))
        else:
            mine, theirs = _named(first, when, first.reset()), _named(second, when, second.reset())
        difference = (_first_difference(mine, theirs, every_env)
                      or _first_difference(capture_kept(first), capture_kept(second)))
        _require(difference is None, f"two envs made with seed={subject.seed} and given the same actions differ "
                 f"{when}: {difference}{hint}")


def check_reset_at(subject: Subject) -> Optional[str]:
    """``reset_at(1)`` changes env 1 and leaves every other env bit-identical."""
    if subject.num_envs < 2:
        raise CheckSkipped("needs num_envs >= 2 to see that the other envs are left alone")
    env = subject.make()
    gen = torch.Generator().manual_seed(subject.seed)
    for _ in range(_WARM_UP_STEPS):
        obs = env.step(space_actions(env, gen))[0]
    again = env.get_from_scenario(True, False, False, False)[0]
    every_env = torch.ones(env.num_envs, dtype=torch.bool, device=env.device)
    noisy = _first_difference(_named(env, "", obs), _named(env, "", again), every_env)
    before = _named(env, "", obs if noisy is None else [])
    before.update(per_env(capture_kept(env), env.num_envs))
    obs = env.reset_at(_RESET_ENV)
    after = _named(env, "", obs)
    after.update(per_env(capture_kept(env), env.num_envs))
    chosen = torch.zeros(env.num_envs, dtype=torch.bool, device=env.device)
    chosen[_RESET_ENV] = True
    leaked = _first_difference(before, after, ~chosen)
    _require(leaked is None, f"reset_at({_RESET_ENV}) must change env {_RESET_ENV} only, but it changed {leaked}")
    _require(bool(changed_rows(before, after, chosen)),
             f"reset_at({_RESET_ENV}) left env {_RESET_ENV} exactly as {_WARM_UP_STEPS} random steps had left it")
    if noisy is not None:
        return f"observations are noisy (two readings differ: {noisy}), so only states were compared"
    return None


def check_batching(subject: Subject) -> Optional[str]:
    """Giving env 0 other actions leaves envs 1.. exactly as they were with the original actions."""
    if subject.num_envs < 2:
        raise CheckSkipped("needs num_envs >= 2 to compare one env's effect on the others")
    original, changed = subject.make(), subject.make()
    gen, other_gen = torch.Generator().manual_seed(subject.seed), torch.Generator().manual_seed(subject.seed + 1)
    others = torch.ones(subject.num_envs, dtype=torch.bool, device=subject.device)
    others[_CHANGED_ENV] = False
    env_0_diverged = False
    for step in range(1, subject.steps + 1):
        actions, alternative = space_actions(original, gen), space_actions(original, other_gen)
        edited = [a.clone() for a in actions]
        for action, other in zip(edited, alternative):
            action[_CHANGED_ENV] = other[_CHANGED_ENV]
        when = f"at step {step}"
        mine = _named(original, when, *original.step(actions))
        theirs = _named(changed, when, *changed.step(edited))
        mine.update(per_env(capture_kept(original), subject.num_envs))
        theirs.update(per_env(capture_kept(changed), subject.num_envs))
        leaked = _first_difference(mine, theirs, others)
        _require(leaked is None, f"only env {_CHANGED_ENV}'s actions were changed, yet {leaked} changed with them")
        env_0_diverged = env_0_diverged or bool(changed_rows(mine, theirs, ~others))
    if not env_0_diverged:
        return f"env {_CHANGED_ENV}'s other actions changed nothing in env {_CHANGED_ENV} itself"
    return None


def check_vmas_parity(subject: Subject) -> Optional[str]:
    """VMAS's start copied into ours, then both stepped alike, agree within ``atol``.

    A shipped scenario compared with its own VMAS counterpart gets what the
    project knows about that pair: its ``vmas_states`` hook (unless the
    caller passes one), its ``vmas_differences`` (skipped under a deliberate
    difference, compared step by step from VMAS's state when chaotic).
    """
    from vmas_ros.compat.install import is_installed

    if is_installed():
        raise CheckSkipped("install_as_vmas() is in effect: 'vmas' names vmas_ros itself, so there is no oracle")
    try:
        import vmas
    except ImportError:
        raise CheckSkipped("vmas is not installed (pip install vmas==1.5.2)") from None
    name = subject.vmas_name or subject.registered
    if name is None:
        raise CheckSkipped(f"{subject.label} is not a registered scenario: pass vmas_name= to compare it with VMAS's")
    available = set(vmas.scenarios) | set(vmas.debug_scenarios) | set(vmas.mpe_scenarios)
    version = getattr(vmas, "__version__", "?")
    if name not in available:
        _require(subject.vmas_name is None, f"vmas_name={name!r}: VMAS {version} has no such scenario")
        raise CheckSkipped(f"VMAS {version} has no scenario named {name!r}")
    shipped = subject.registered == name  # one of ours, against its own counterpart
    difference = design_difference(name, subject.scenario_kwargs) if shipped else None
    if difference:
        raise CheckSkipped(f"{name} differs from VMAS {version} by design: {difference}")
    up = parity.make_vmas_env(name, subject.num_envs, subject.device, subject.seed, **subject.scenario_kwargs)
    ours = subject.make()
    parity.assert_same_space(ours.observation_space, up.observation_space, "observation space")
    parity.assert_same_space(ours.action_space, up.action_space, "action space")
    not_copied: List[str] = []
    hook = subject.scenario_state or (SCENARIO_STATES.get(name) if shipped else None)
    shipped_hook = hook is not None and subject.scenario_state is None
    parity.copy_start(up, ours, hook or (lambda theirs, mine: not_copied.extend(copy_kept_tensors(theirs, mine))))
    parity.copy_random_stream(up, ours)
    resync = RESYNC.get(name) if shipped else None
    squeezed = _squeeze_column_rewards(up)
    try:
        parity.run_lockstep(up, ours, subject.seed, steps=subject.steps, atol=subject.atol, resync=resync is not None,
                            actions=lambda gen: space_actions(ours, gen))
    except AssertionError as failure:
        hint = ""
        if not_copied:
            hint = (f"\n(VMAS's scenario keeps tensors that ours has none of the same name and shape for, so they were "
                    f"not copied: {', '.join(not_copied[:6])}{' ...' if len(not_copied) > 6 else ''}; if ours keeps "
                    f"that state under other names, pass scenario_state=<function (vmas_env, our_env)> to copy it)")
        elif shipped_hook:
            hint = f"\n(VMAS's per-env draw was copied by vmas_ros.testing.vmas_states.SCENARIO_STATES[{name!r}])"
        raise AssertionError(f"against VMAS's {name!r}: {failure}{hint}") from failure
    notes = ["VMAS's scenario gives [B, 1] rewards; they were compared as [B]" if squeezed else None,
             f"compared one step at a time from VMAS's state: {resync}" if resync else None,
             None if version == "1.5.2" else f"compared with VMAS {version}; vmas_ros follows 1.5.2"]
    return "; ".join(note for note in notes if note) or None


def _squeeze_column_rewards(up) -> List[bool]:
    """Make VMAS's scenario give a [B, 1] reward (wheel's) as [B], the shape of the API.

    The reward function is wrapped, not probed (a call may update shaping
    state). Returns a list that gets a True each time a reward was squeezed.
    """
    squeezed: List[bool] = []
    reward = up.scenario.reward

    def reward_as_row(agent):
        value = reward(agent)
        if value.dim() == 2 and value.shape[1] == 1:
            squeezed.append(True)
            return value.squeeze(-1)
        return value

    up.scenario.reward = reward_as_row
    return squeezed
