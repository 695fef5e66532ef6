"""Training configuration: one flat dataclass, loadable from YAML/JSON, overridable by flags.

Defaults follow the VMAS paper's set-up (PPO, 60,000 env interactions per
iteration, two-layer tanh MLPs) scaled to something a laptop finishes; every
field is documented where it is declared, and ``vmas-ros train --help`` shows
the same text.
"""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Dict, Union

from vmas_ros.envs.randomisation import Randomisation

__all__ = ["TrainConfig", "ALGORITHM_NAMES", "load_config_file"]

ALGORITHM_NAMES = ("cppo", "mappo", "ippo", "hetippo")


@dataclass
class TrainConfig:
    """Everything a training run depends on; saved as ``config.json`` in the output directory."""

    # --- what to train
    scenario: str = field(default="balance", metadata={"help": "scenario name (see `vmas-ros list`)"})
    scenario_kwargs: Dict[str, Any] = field(default_factory=dict,
                                            metadata={"help": "keyword arguments for the scenario (JSON object)"})
    randomisation: Dict[str, Any] = field(default_factory=dict, metadata={
        "help": "per-env command latency, actuator lag, sensor noise, lidar dropout, mass and drag scales drawn at "
                "resets: JSON object of setting -> number or [low, high] (docs/training.md#randomisation)"})
    algorithm: str = field(default="mappo", metadata={"help": "cppo, mappo, ippo or hetippo (the paper's Figure 3)"})
    # --- how much data
    iterations: int = field(default=100, metadata={"help": "training iterations (collect a batch, then update)"})
    frames_per_batch: int = field(default=6000, metadata={
        "help": "env interactions per iteration (num_envs x steps); the paper uses 60000"})
    num_envs: int = field(default=60, metadata={"help": "parallel envs; steps per iteration = frames_per_batch / num_envs"})
    max_steps: int = field(default=100, metadata={"help": "episode length: envs are truncated and reset after this"})
    # --- PPO
    minibatch_size: int = field(default=400, metadata={"help": "transitions (env steps, all agents) per gradient step"})
    epochs: int = field(default=10, metadata={"help": "passes over each batch (PPO epochs)"})
    lr: float = field(default=5e-4, metadata={"help": "Adam learning rate for actor and critic"})
    gamma: float = field(default=0.99, metadata={"help": "discount factor"})
    lmbda: float = field(default=0.9, metadata={"help": "GAE lambda (key 'lambda' is accepted in config files)"})
    clip_epsilon: float = field(default=0.2, metadata={"help": "PPO ratio clipping"})
    entropy_coef: float = field(default=1e-4, metadata={"help": "entropy bonus coefficient"})
    critic_coef: float = field(default=1.0, metadata={"help": "weight of the value loss"})
    normalize_advantage: bool = field(default=True, metadata={
        "help": "standardise advantages per minibatch (keeps the PPO step size independent of the reward scale)"})
    max_grad_norm: float = field(default=1.0, metadata={"help": "gradient norm clipping"})
    # --- networks
    num_cells: int = field(default=256, metadata={"help": "hidden units per layer of actor and critic"})
    depth: int = field(default=2, metadata={"help": "hidden layers of actor and critic (the paper: 2)"})
    # --- run
    seed: int = field(default=0, metadata={"help": "seed for env and networks"})
    device: str = field(default="cpu", metadata={"help": "torch device for env and training (cpu, cuda)"})
    eval_episodes: int = field(default=8, metadata={
        "help": "episodes (parallel envs) of the deterministic policy evaluated at the end; 0: skip"})
    gif: bool = field(default=True, metadata={"help": "render env 0 of the evaluation to eval.gif"})
    checkpoint_every: int = field(default=10, metadata={"help": "save checkpoint.pt every N iterations (and at the end)"})
    out: str = field(default="runs/train", metadata={"help": "output directory"})
    # --- where the envs run (none of these changes the algorithm)
    ray_address: str = field(default="none", metadata={
        "help": "collect on Ray: 'local' (a Ray instance on this machine), 'auto' (the cluster `ray start` "
                "made here), a head's host:port; 'none': step the envs in this process"})
    collectors: int = field(default=1, metadata={
        "help": "Ray actors stepping num_envs / collectors envs each, spread over the cluster's nodes"})
    collector_cpus: int = field(default=1, metadata={"help": "CPUs (torch threads) each Ray collector reserves"})
    collector_device: str = field(default="cpu", metadata={
        "help": "torch device of the Ray collectors' envs (cuda: each collector reserves a GPU)"})

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> "TrainConfig":
        """Raise ValueError for values no run could use, naming the field."""
        if self.algorithm not in ALGORITHM_NAMES:
            raise ValueError(f"algorithm must be one of {ALGORITHM_NAMES}, got {self.algorithm!r}")
        if not isinstance(self.scenario_kwargs, dict):
            raise ValueError(f"scenario_kwargs must be a mapping, got {type(self.scenario_kwargs).__name__}")
        Randomisation.from_dict(self.randomisation)  # names a bad setting
        for name in ("iterations", "frames_per_batch", "num_envs", "max_steps", "minibatch_size", "epochs",
                     "num_cells", "depth", "checkpoint_every", "collectors", "collector_cpus"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a positive int, got {value!r}")
        if not isinstance(self.ray_address, str) or not self.ray_address.strip():
            raise ValueError(f"ray_address must be 'none', 'local', 'auto' or a head's host:port, "
                             f"got {self.ray_address!r}")
        if self.ray_address == "none" and self.collectors != 1:
            raise ValueError(f"collectors={self.collectors} needs Ray: give ray_address ('local', 'auto' or a "
                             f"head's host:port); without Ray the envs run in this process")
        if self.num_envs % self.collectors:
            raise ValueError(f"num_envs ({self.num_envs}) must be a multiple of collectors ({self.collectors}): "
                             f"each collector steps the same number of envs")
        if self.eval_episodes < 0:
            raise ValueError(f"eval_episodes must be >= 0, got {self.eval_episodes!r}")
        if self.frames_per_batch % self.num_envs:
            raise ValueError(f"frames_per_batch ({self.frames_per_batch}) must be a multiple of num_envs "
                             f"({self.num_envs}): each iteration steps every env the same number of times")
        if self.minibatch_size > self.frames_per_batch:
            raise ValueError(f"minibatch_size ({self.minibatch_size}) must be <= frames_per_batch "
                             f"({self.frames_per_batch})")
        for name, low, high in (("gamma", 0.0, 1.0), ("lmbda", 0.0, 1.0), ("clip_epsilon", 0.0, 1.0)):
            value = getattr(self, name)
            if not low <= value <= high:
                raise ValueError(f"{name} must be in [{low}, {high}], got {value!r}")
        for name in ("lr", "max_grad_norm"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("entropy_coef", "critic_coef"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        return self

    @property
    def steps_per_batch(self) -> int:
        """Steps each env takes per iteration."""
        return self.frames_per_batch // self.num_envs

    def to_dict(self) -> Dict[str, Any]:
        """JSON-ready copy (what ``config.json`` and checkpoints hold)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, values: Dict[str, Any], source: str = "config") -> "TrainConfig":
        """Build from a mapping; unknown keys are an error (a typo should not be silently ignored)."""
        values = dict(values)
        if "lambda" in values:
            if "lmbda" in values:
                raise ValueError(f"{source}: give either 'lambda' or 'lmbda', not both")
            values["lmbda"] = values.pop("lambda")
        values = {key.replace("-", "_"): value for key, value in values.items()}
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"{source}: unknown key(s) {unknown}; valid keys: {sorted(known)}")
        for f in fields(cls):
            if f.name in values:
                values[f.name] = _coerce(f, values[f.name], source)
        return cls(**values)

    def replace(self, **changes: Any) -> "TrainConfig":
        """A copy with some fields changed (validated again)."""
        return self.from_dict({**self.to_dict(), **changes})


def _coerce(f: dataclasses.Field, value: Any, source: str) -> Any:
    """Check a value's type against the field's default (YAML gives ints where floats are meant)."""
    default = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore[misc]
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ValueError(f"{source}: {f.name} must be true or false, got {value!r}")
        return value
    if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if not isinstance(value, type(default)) or isinstance(value, bool):
        raise ValueError(f"{source}: {f.name} must be {type(default).__name__}, got {value!r}")
    return value


def load_config_file(path: Union[str, Path]) -> Dict[str, Any]:
    """Read a YAML (``.yaml``/``.yml``) or JSON config file into a dict (not yet validated)."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"config file {str(path)!r} does not exist")
    text = path.read_text()
    if path.suffix.lower() in (".yaml", ".yml"):
        import yaml

        data = yaml.safe_load(text)
    elif path.suffix.lower() == ".json":
        data = json.loads(text)
    else:
        raise ValueError(f"config file must end in .yaml, .yml or .json, got {path.name!r}")
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a mapping of config keys, got {type(data).__name__}")
    return data
