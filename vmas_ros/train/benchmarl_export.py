"""Convert a BenchMARL MAPPO/IPPO run to our exported policy format (``STEM.onnx`` + ``STEM.json``).

Runs INSIDE BenchMARL's venv (``bash scripts/setup_benchmarl.sh``)::

    .venv-benchmarl/bin/python -m vmas_ros.train.benchmarl_export RUN_DIR STEM

``vmas-ros export --from-benchmarl RUN_DIR --out STEM`` runs this for you from
the main venv. ``RUN_DIR`` is a BenchMARL experiment folder (``config.pkl`` +
``checkpoints/checkpoint_<frames>.pt``; the newest checkpoint is taken), one
checkpoint file, or a folder holding exactly one experiment folder.

The run is reloaded with BenchMARL's own loader (``Experiment.reload_from_file``,
which unpickles the run's ``config.pkl``: only convert runs you trust). The
run folder is left untouched: BenchMARL rewrites ``config.pkl`` when it
reloads, so the reload happens on a temporary copy.

Supported: one agent group, continuous actions, MAPPO or IPPO with
BenchMARL's MLP actor and a TanhNormal action distribution (BenchMARL's
default ``use_tanh_normal: True``). The exported graph is the deterministic
action BenchMARL takes under ``ExplorationType.DETERMINISTIC`` (TanhNormal's
transformed mean), clipped to the bounds; before writing, the converter
checks it against BenchMARL's own policy on random observations (1e-5).
Anything else is refused with a ``ValueError`` naming what.
"""
from __future__ import annotations

import json
import re
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any, Dict, Tuple, Union

from vmas_ros.envs.make_env import make_env
from vmas_ros.compat.install import install_as_vmas

SUPPORTED_ALGORITHMS = ("mappo", "ippo")
# make_env's own arguments that BenchMARL passes along with the scenario kwargs
_ENV_LEVEL_KEYS = ("max_steps",)

__all__ = ["find_checkpoint", "export_benchmarl_run", "main"]


def find_checkpoint(run_dir: Union[str, Path]) -> Path:
    """The checkpoint to convert: the file itself, or the newest ``checkpoints/checkpoint_<frames>.pt``."""
    path = Path(run_dir).expanduser().resolve()
    if path.is_file():
        if path.suffix != ".pt":
            raise ValueError(f"{path}: expected a BenchMARL checkpoint (.pt) or run folder")
        return path
    if not path.is_dir():
        raise ValueError(f"{path}: no such BenchMARL run folder or checkpoint")
    if not (path / "config.pkl").is_file():
        runs = [child for child in sorted(path.iterdir()) if (child / "config.pkl").is_file()]
        if len(runs) != 1:
            raise ValueError(f"{path}: not a BenchMARL run folder (no config.pkl)"
                             + (f"; it holds {len(runs)} run folders, name one" if runs else ""))
        path = runs[0]
    checkpoints = list((path / "checkpoints").glob("*.pt"))
    if not checkpoints:
        raise ValueError(f"{path}: no checkpoints/*.pt (run BenchMARL with checkpoint_at_end or checkpoint_interval)")

    def frames(p: Path) -> Tuple[int, str]:
        match = re.search(r"(\d+)", p.stem)
        return (int(match.group(1)) if match else -1, p.name)

    return max(checkpoints, key=frames)


def _reload(checkpoint: Path, workdir: Path):
    """BenchMARL's own loader on a copy of the run (config.pkl + the checkpoint), on CPU, without loggers."""
    config_pkl = checkpoint.parent.parent / "config.pkl"
    if not config_pkl.is_file():
        raise ValueError(f"{checkpoint}: no config.pkl two levels up ({config_pkl}); not a BenchMARL run")
    copy_run = workdir / checkpoint.parent.parent.name
    (copy_run / "checkpoints").mkdir(parents=True)
    shutil.copy2(config_pkl, copy_run / "config.pkl")
    shutil.copy2(checkpoint, copy_run / "checkpoints" / checkpoint.name)
    from benchmarl.experiment import Experiment

    patch = {"save_folder": str(workdir), "loggers": [], "restore_map_location": "cpu",
             "sampling_device": "cpu", "train_device": "cpu", "buffer_device": "cpu"}
    return Experiment.reload_from_file(str(copy_run / "checkpoints" / checkpoint.name), experiment_patch=patch)


def _actor_parts(experiment) -> Dict[str, Any]:
    """Check the run is one we can export and pull out what the graph needs."""
    from benchmarl.models.mlp import Mlp
    from torchrl.modules import ProbabilisticActor, TanhNormal

    algorithm = experiment.algorithm_name
    if algorithm not in SUPPORTED_ALGORITHMS:
        raise ValueError(f"unsupported BenchMARL algorithm {algorithm!r}; only {list(SUPPORTED_ALGORITHMS)} "
                         "policies can be exported")
    if len(experiment.group_map) != 1:
        raise ValueError(f"heterogeneous agent groups are not supported: the run has groups "
                         f"{dict(experiment.group_map)}; the export format has one group of same-sized agents")
    if not experiment.continuous_actions:
        raise ValueError("discrete actions are not supported: the export format is continuous actions only")
    (group, agents), = experiment.group_map.items()
    actor = experiment.group_policies[group]
    if not isinstance(actor, ProbabilisticActor):
        raise ValueError(f"group {group!r}: expected a ProbabilisticActor policy, got {type(actor).__name__}")
    # ProbabilisticActor = [TensorDictSequential(model, NormalParamExtractor), distribution module]
    dist_module = actor.module[-1]
    dist_class = getattr(dist_module, "distribution_class", None)
    if dist_class is not TanhNormal:
        raise ValueError(f"action distribution {getattr(dist_class, '__name__', dist_class)} is not supported; "
                         "only TanhNormal (BenchMARL's use_tanh_normal: True) is")
    dist_kwargs = dict(getattr(dist_module, "distribution_kwargs", None) or {})
    if dist_kwargs.get("tanh_loc"):
        raise ValueError("TanhNormal with tanh_loc=True is not supported")
    params_module = actor.module[0]
    model = params_module.module[0] if hasattr(params_module, "module") and len(actor.module) == 2 else None
    if not isinstance(model, Mlp):
        raise ValueError(f"actor model {type(model).__name__} is not supported; only BenchMARL's Mlp is")
    if list(model.in_keys) != [(group, "observation")]:
        raise ValueError(f"actor reads {list(model.in_keys)}; only a single ({group!r}, 'observation') input "
                         "is supported")
    if not (model.input_has_agent_dim and model.output_has_agent_dim):
        raise ValueError("only actors with a per-agent input and output are supported")
    return {"algorithm": algorithm, "group": group, "agents": list(agents), "actor": actor, "network": model.mlp,
            "low": dist_kwargs.get("low"), "high": dist_kwargs.get("high")}


def _plain_network(network):
    """The BenchMARL MLP behind a plain ``nn.Module`` for the ONNX tracer.

    torchrl 0.11's ``MultiAgentMLP`` keeps its parameters in ``TensorDictParams``
    whose state dict holds a ``torch.Size``, which the TorchScript tracer cannot
    read; hidden from the module tree, the weights are traced as constants.
    """
    import torch

    class _Traceable(torch.nn.Module):
        def __init__(self, net) -> None:
            super().__init__()
            for parameter in net.parameters():  # traced as constants: no grad
                parameter.requires_grad_(False)
            object.__setattr__(self, "_net", net.eval())

        def forward(self, observation):
            return self._net(observation)

    return _Traceable(network)


def _task_scenario(experiment) -> Tuple[str, Dict[str, Any], Dict[str, Any]]:
    """VMAS scenario name, its kwargs, and the make_env-level kwargs (max_steps) from the task config."""
    task = experiment.task
    if task.env_name().lower() != "vmas":
        raise ValueError(f"only BenchMARL VMAS tasks are supported, got environment {task.env_name()!r}")
    config = dict(task.config or {})
    env_level = {key: config.pop(key) for key in _ENV_LEVEL_KEYS if key in config}
    return task.name.lower(), config, env_level


def _check_against_benchmarl(parts: Dict[str, Any], module, n_agents: int, obs_size: int) -> float:
    """Max |our deterministic action - BenchMARL's| on random observations; raise above 1e-5."""
    import torch
    from tensordict import TensorDict
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    group = parts["group"]
    obs = torch.randn(16, n_agents, obs_size, generator=torch.Generator().manual_seed(0)) * 2
    td = TensorDict({group: TensorDict({"observation": obs}, batch_size=[16, n_agents])}, batch_size=[16])
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        expected = parts["actor"](td)[group, "action"]
        ours = module(obs)
    diff = float((expected - ours).abs().max())
    if not diff <= 1e-5:
        raise RuntimeError(f"the exported graph disagrees with BenchMARL's deterministic action (max {diff})")
    return diff


def _require_onnx() -> None:
    """torch.onnx needs ``onnx`` (and the export check ``onnxruntime``) in this venv too."""
    import importlib.util

    missing = [name for name in ("onnx", "onnxscript", "onnxruntime") if importlib.util.find_spec(name) is None]
    if missing:
        raise ValueError(f"{sys.executable} lacks {', '.join(missing)}, needed to write ONNX; install with "
                         f"{sys.executable} -m pip install {' '.join(missing)} 'torch==<its torch version>'")


def export_benchmarl_run(run_dir: Union[str, Path], out_stem: Union[str, Path]) -> Tuple[Path, Path]:
    """Reload a BenchMARL run and write ``<out_stem>.onnx`` + ``<out_stem>.json``."""
    install_as_vmas()  # before benchmarl/torchrl import vmas
    import torch

    from vmas_ros.train.export import DeterministicPolicy, _shared_bounds, describe_env, export_policy

    checkpoint = find_checkpoint(run_dir)
    _require_onnx()
    with tempfile.TemporaryDirectory(prefix="vmas_ros_benchmarl_") as workdir:
        experiment = _reload(checkpoint, Path(workdir))
        parts = _actor_parts(experiment)
        scenario, scenario_kwargs, env_level = _task_scenario(experiment)
        env = make_env(scenario, num_envs=1, continuous_actions=True, compile_physics=False, **env_level,
                       **scenario_kwargs)  # only its spaces are read: nothing to compile for
        env_info = describe_env(env)
        if env_info["agents"] != parts["agents"]:
            raise ValueError(f"BenchMARL's group agents {parts['agents']} differ from the scenario's agents "
                             f"{env_info['agents']}")
        low, high = _shared_bounds(env_info)
        for name, ours, theirs in (("low", low, parts["low"]), ("high", high, parts["high"])):
            if theirs is not None and not torch.allclose(torch.as_tensor(theirs, dtype=torch.float32),
                                                         torch.tensor(ours).expand_as(torch.as_tensor(theirs))):
                raise ValueError(f"BenchMARL's action {name} {theirs} differs from the scenario's {ours}")
        n_agents, obs_size = len(env_info["agents"]), env_info["observation_size"]
        network = _plain_network(parts["network"])
        check = DeterministicPolicy(network, torch.tensor(low), torch.tensor(high)).eval()
        _check_against_benchmarl(parts, check, n_agents, obs_size)
        onnx_path, json_path = export_policy(network, env_info, scenario, scenario_kwargs, parts["algorithm"],
                                             out_stem)
    meta = json.loads(json_path.read_text())
    meta.update(env_level)  # e.g. max_steps: the episode length BenchMARL trained with
    meta["source"] = {"trainer": "benchmarl", "checkpoint": str(checkpoint), "group": parts["group"]}
    json_path.write_text(json.dumps(meta, indent=2) + "\n")
    return onnx_path, json_path


def main(argv=None) -> int:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("run_dir", help="BenchMARL run folder, checkpoint .pt, or folder holding one run folder")
    parser.add_argument("out", metavar="STEM", help="writes STEM.onnx and STEM.json")
    args = parser.parse_args(argv)
    try:
        onnx_path, json_path = export_benchmarl_run(args.run_dir, args.out)
    except ValueError as error:
        print(f"vmas-ros export --from-benchmarl: {error}", file=sys.stderr)
        return 2
    print(json.dumps({"onnx": str(onnx_path), "json": str(json_path)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
