"""What the library wrappers (gym, gymnasium, gymnasium_vec, pettingzoo, rllib) share.

Every wrapper does the same three conversions: the Environment's per-agent
tensors (a list, or a dict by name with ``dict_spaces=True``) become numpy
arrays keyed by agent; numpy actions become ``[num_envs, size]`` tensors on
``env.device``; and the per-agent spaces are read off the Environment's own
spaces. Keeping them here means one place decides dtypes and shape checks, so
the wrappers cannot drift apart.

:class:`BaseGymWrapper` is the base of the three gym-style wrappers, under
VMAS's name: it holds the Environment (``env`` and ``unwrapped`` both return
it, as VMAS code expects) and packs per-agent values the way VMAS's wrappers
return them (a list in agent order, or a dict by name with ``dict_spaces``).
"""
from __future__ import annotations

from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import torch
from gymnasium import spaces
from torch import Tensor

from vmas_ros.envs.environment import Environment

__all__ = [
    "BaseGymWrapper",
    "agent_names",
    "agent_spaces",
    "actions_to_tensors",
    "by_agent",
    "pack",
    "require_single_env",
    "merge_where",
    "require_terminated_truncated",
    "select_env",
    "to_numpy",
    "to_gymnasium_space",
    "vector_info",
]


def require_single_env(env: Environment, wrapper: str, hint: str = "") -> None:
    """Refuse batched Environments for wrappers whose library sees one episode at a time."""
    if env.num_envs != 1:
        raise ValueError(
            f"wrapper {wrapper!r} needs num_envs=1, got num_envs={env.num_envs}{hint}"
        )


def require_terminated_truncated(env: Environment, wrapper: str) -> None:
    """The libraries separate termination from truncation; the Environment must report both.

    ``make_env(wrapper=...)`` turns ``terminated_truncated`` on by itself; this
    only fires when a wrapper class is built around an Environment made without it.
    """
    if not env.terminated_truncated:
        raise ValueError(
            f"wrapper {wrapper!r} needs an Environment made with terminated_truncated=True "
            f"(make_env(..., wrapper={wrapper!r}) sets it for you)"
        )


def agent_names(env: Environment) -> List[str]:
    """The names of the agents that take actions, in the Environment's order."""
    return [agent.name for agent in env.agents]


def by_agent(env: Environment, values: Union[Sequence, Mapping]) -> Dict[str, Any]:
    """Per-agent values keyed by name, whether the Environment returned a list or a dict."""
    if isinstance(values, Mapping):
        return dict(values)
    return {agent.name: value for agent, value in zip(env.agents, values)}


def pack(values: Dict[str, Any], as_dict: bool) -> Union[List, Dict[str, Any]]:
    """A dict by agent name, or a list in agent order: what VMAS's wrappers return.

    Lists, not tuples, because VMAS code checks ``isinstance(obs, list)``; the
    ``Tuple`` spaces of gymnasium and gym accept lists in ``contains``.
    """
    return dict(values) if as_dict else list(values.values())


_SPACE_TYPES = ("Box", "Discrete", "MultiDiscrete", "MultiBinary", "Tuple", "Dict")


def to_gymnasium_space(space: Any) -> spaces.Space:
    """The gymnasium twin of a space: itself if it is one, else a converted legacy ``gym`` space.

    The Environment builds legacy ``gym`` spaces while ``install_as_vmas()`` is in
    effect (TorchRL needs them); the gymnasium-facing wrappers still owe
    gymnasium spaces. Read by class name and attributes, so ``gym`` is never imported here.
    """
    if isinstance(space, spaces.Space):
        return space
    kind = type(space).__name__
    if kind not in _SPACE_TYPES or not type(space).__module__.startswith("gym."):
        raise TypeError(f"expected a gymnasium or gym space, got {type(space).__module__}.{kind}: {space!r}")
    if kind == "Box":
        return spaces.Box(low=space.low, high=space.high, shape=space.shape, dtype=space.dtype)
    if kind == "Discrete":
        return spaces.Discrete(int(space.n), start=int(getattr(space, "start", 0)))
    if kind == "MultiDiscrete":
        return spaces.MultiDiscrete(space.nvec, dtype=space.dtype)
    if kind == "MultiBinary":
        return spaces.MultiBinary(space.n)
    if kind == "Tuple":
        return spaces.Tuple([to_gymnasium_space(s) for s in space.spaces])
    return spaces.Dict({key: to_gymnasium_space(s) for key, s in space.spaces.items()})


def agent_spaces(env: Environment) -> Tuple[Dict[str, spaces.Space], Dict[str, spaces.Space]]:
    """Per-agent (observation, action) gymnasium spaces by name (the Environment's own when gymnasium)."""
    names = agent_names(env)
    obs_space, act_space = to_gymnasium_space(env.observation_space), to_gymnasium_space(env.action_space)
    if isinstance(obs_space, spaces.Dict):
        return {n: obs_space[n] for n in names}, {n: act_space[n] for n in names}
    return dict(zip(names, obs_space.spaces)), dict(zip(names, act_space.spaces))


def to_numpy(value: Any, index: Optional[int] = None) -> Any:
    """Tensors (also nested in dicts, lists, tuples) to numpy; ``index`` picks one env's row.

    Floating point values become float32 because every Box space the Environment
    builds is float32, and gymnasium's ``Box.contains`` refuses float64.
    """
    if isinstance(value, Tensor):
        tensor = value.detach()
        if index is not None:
            tensor = tensor[index]
        array = tensor.cpu().numpy()
        if np.issubdtype(array.dtype, np.floating) and array.dtype != np.float32:
            array = array.astype(np.float32)
        return array
    if isinstance(value, Mapping):
        return {key: to_numpy(item, index) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(to_numpy(item, index) for item in value)
    return value


def select_env(value: Any, index: int) -> Any:
    """One env's row of every tensor in a nested structure, kept as tensors (``return_numpy=False``)."""
    if isinstance(value, Tensor):
        return value[index]
    if isinstance(value, Mapping):
        return {key: select_env(item, index) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(select_env(item, index) for item in value)
    return value


def _expected_shapes(space: spaces.Space, batch: Optional[int], batch_of_one: bool) -> List[Tuple[int, ...]]:
    """Action shapes accepted for one agent, the space's own first.

    The space's shape (with a leading ``num_envs`` when batched), plus a
    trailing 1 for Discrete; with ``batch_of_one`` a single env also takes a
    leading 1, which is what ``env.unwrapped.get_random_action(agent)`` gives
    (``[num_envs=1, size]``) and what VMAS code feeds VMAS's single-env wrappers.
    """
    leads = [()] if batch is None else [(batch,)]
    if batch is None and batch_of_one:
        leads.append((1,))
    shapes = []
    for lead in leads:
        shapes.append(lead + tuple(space.shape))
        if isinstance(space, spaces.Discrete):
            shapes.append(lead + (1,))
    return shapes


def actions_to_tensors(
    env: Environment,
    actions: Union[Sequence, Mapping],
    batched: bool,
    names: Optional[Sequence[str]] = None,
    batch_of_one: bool = False,
) -> List[Tensor]:
    """Numpy (or list, or tensor) actions per agent -> ``[num_envs, size]`` tensors on ``env.device``.

    ``batched=False`` means one env's action per agent (the space's own shape),
    ``batched=True`` adds the leading ``num_envs`` dimension. A wrong shape raises
    a ValueError naming the agent and the expected shape here, because after the
    reshape to ``[num_envs, size]`` the Environment could no longer tell which
    shape the caller meant. Range, NaN and dtype checks stay the Environment's.
    ``batch_of_one=True`` (the gym-style wrappers, as VMAS's) also takes a
    single env's action with a leading dimension of 1.
    """
    names = list(names) if names is not None else agent_names(env)
    if isinstance(actions, Mapping):
        missing = [n for n in names if n not in actions]
        unknown = [k for k in actions if k not in names]
        if missing or unknown:
            raise ValueError(f"actions must have exactly the agents {names}; missing {missing}, unknown {unknown}")
        ordered = [actions[n] for n in names]
    elif isinstance(actions, (list, tuple)):
        if len(actions) != len(names):
            raise ValueError(f"expected actions for {len(names)} agents {names}, got {len(actions)}")
        ordered = list(actions)
    else:
        raise ValueError(
            f"actions must be a tuple/list (one per agent) or a dict by agent name, got {type(actions).__name__}"
        )
    _, act_spaces = agent_spaces(env)
    batch = env.num_envs if batched else None
    tensors = []
    for agent, name, action in zip(env.agents, names, ordered):
        space = act_spaces[name]
        if isinstance(action, Tensor):
            tensor = action  # the Environment refuses a wrong device with a message saying so
        else:
            try:
                tensor = torch.as_tensor(np.asarray(action), device=env.device)
            except (TypeError, ValueError, RuntimeError) as error:
                raise ValueError(f"action for agent {name!r} is not numeric: {error}") from None
        accepted = _expected_shapes(space, batch, batch_of_one)
        if tuple(tensor.shape) not in accepted:
            raise ValueError(
                f"action for agent {name!r} has shape {tuple(tensor.shape)}, expected {accepted[0]} "
                f"(action space {space})"
            )
        if env.continuous_actions and tensor.dtype.is_floating_point and tensor.dtype != torch.float32:
            tensor = tensor.float()
        tensors.append(tensor.reshape(env.num_envs, env.get_agent_action_size(agent)))
    return tensors


def vector_info(tree: Mapping, mask: np.ndarray) -> Dict[str, Any]:
    """Batched infos in gymnasium's vector layout: each key ``k`` gets a boolean ``_k`` mask."""
    out: Dict[str, Any] = {}
    for key, value in tree.items():
        out[key] = vector_info(value, mask) if isinstance(value, Mapping) else value
        out[f"_{key}"] = mask.copy()
    return out


def merge_where(mask: Tensor, new: Any, old: Any) -> Any:
    """``new`` where ``mask`` (per env) is set, else ``old``; recurses into dicts, lists and tuples."""
    if isinstance(new, Tensor):
        shaped = mask.reshape(-1, *([1] * (new.dim() - 1)))
        return torch.where(shaped, new, old)
    if isinstance(new, Mapping):
        return {key: merge_where(mask, new[key], old[key]) for key in new}
    if isinstance(new, (list, tuple)):
        return type(new)(merge_where(mask, n, o) for n, o in zip(new, old))
    return new


class SingleEnvWrapper:
    """``render``, ``close`` and the reset of the wrappers around one env (gymnasium, pettingzoo, rllib).

    Listed first among a wrapper's bases, so these override the library's defaults.
    Subclasses set ``self.env`` (an Environment with ``num_envs=1``) and ``self.render_mode``.
    """

    env: Any
    render_mode: Optional[str]

    def _reset_env(self, seed: Optional[int]) -> Tuple[Dict[str, Any], Dict[str, Any]]:
        """Re-seed (when ``seed`` is given) and reset; every agent's observation and info, by name, as numpy."""
        if seed is not None:
            self.env.seed(seed)
        obs, infos = self.env.reset(return_info=True)
        return to_numpy(by_agent(self.env, obs), index=0), to_numpy(by_agent(self.env, infos), index=0)

    def render(self) -> Optional[np.ndarray]:
        """The frame as an HxWx3 uint8 array (None when made with ``render_mode=None``)."""
        if self.render_mode is None:
            return None
        return self.env.render(mode="rgb_array", env_index=0)

    def close(self) -> None:
        self.env.close()


class BaseGymWrapper:
    """What the gym, gymnasium and gymnasium_vec wrappers share, under VMAS's class name.

    Listed first among a wrapper's bases, so ``unwrapped`` is the Environment
    (gym's and gymnasium's own ``unwrapped`` would return the wrapper): VMAS
    code reads ``env.unwrapped.n_agents``, ``.agents`` and ``.get_random_action(agent)``.

    Args:
        env: the Environment.
        return_numpy: numpy arrays out (True) or torch tensors on ``env.device``.
        vectorized: False for the single-env wrappers, which drop the batch
            dimension (row 0) and give rewards and flags as Python scalars.
    """

    def __init__(self, env: Environment, return_numpy: bool, vectorized: bool) -> None:
        self._env = env
        self.return_numpy = return_numpy
        self.dict_spaces = env.dict_spaces
        self.vectorized = vectorized

    @property
    def env(self) -> Environment:
        """The wrapped Environment."""
        return self._env

    @property
    def unwrapped(self) -> Environment:
        """The wrapped Environment, as in VMAS (not the wrapper itself)."""
        return self._env

    @property
    def spec(self) -> Any:
        """gymnasium's ``EnvSpec`` of this env, kept on the Environment: ``gymnasium.make`` and ``make_vec``
        write it to ``env.unwrapped`` (the Environment here) and then read ``env.spec`` back."""
        return getattr(self._env, "spec", None)

    @spec.setter
    def spec(self, value: Any) -> None:
        self._env.spec = value

    def _convert(self, value: Any) -> Any:
        """Tensors (nested) to the output type: row 0 of the batch unless vectorized."""
        index = None if self.vectorized else 0
        if self.return_numpy:
            return to_numpy(value, index=index)
        return value if index is None else select_env(value, index)

    def _per_agent(self, values: Union[Sequence, Mapping]) -> Union[List, Dict[str, Any]]:
        """Observations (or batched rewards): a list in agent order, or a dict with ``dict_spaces``."""
        return pack(self._convert(by_agent(self._env, values)), self.dict_spaces)

    def _scalar_rewards(self, rews: Union[Sequence, Mapping]) -> Union[List[float], Dict[str, float]]:
        """One env's reward per agent as Python floats, whatever ``return_numpy`` says (as VMAS)."""
        return pack({name: float(r[0]) for name, r in by_agent(self._env, rews).items()}, self.dict_spaces)

    def _infos(self, infos: Union[Sequence, Mapping]) -> Dict[str, Any]:
        """Infos always by agent name, also without ``dict_spaces`` (as VMAS)."""
        return self._convert(by_agent(self._env, infos))

    def _render_env(self, mode: str, env_index: Optional[int], agent_index_focus: Optional[int],
                    visualize_when_rgb: bool, **kwargs: Any) -> Any:
        """Forward VMAS's render keywords to ``Environment.render``, only those the caller set."""
        if agent_index_focus is not None:
            kwargs["agent_index_focus"] = agent_index_focus
        if visualize_when_rgb:
            kwargs["visualize_when_rgb"] = visualize_when_rgb
        if env_index is not None:
            kwargs["env_index"] = env_index
        return self._env.render(mode=mode, **kwargs)
