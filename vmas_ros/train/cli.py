"""``vmas-ros train`` and ``vmas-ros export``: argument parsing and entry points.

Flags are generated from :class:`TrainConfig`'s fields (``lmbda`` is ``--lambda``,
underscores become dashes), so the CLI, config files and the dataclass never
drift apart. Precedence: dataclass defaults < ``--config FILE`` < checkpoint
(``--resume``) < explicit flags.
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import MISSING, fields
from pathlib import Path
from typing import Any, Dict, Mapping, Optional, Sequence

from vmas_ros.train.config import ALGORITHM_NAMES, TrainConfig, load_config_file

__all__ = ["add_train_arguments", "run_train_command", "add_export_arguments", "run_export_command"]


def _flag(name: str) -> str:
    return "--lambda" if name == "lmbda" else "--" + name.replace("_", "-")


def _json_object(text: str) -> Dict[str, Any]:
    try:
        value = json.loads(text)
    except json.JSONDecodeError as error:
        raise argparse.ArgumentTypeError(f"expected a JSON object, e.g. '{{\"n_agents\": 4}}': {error}")
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"expected a JSON object, got {type(value).__name__}")
    return value


def add_train_arguments(parser: argparse.ArgumentParser) -> None:
    """One flag per TrainConfig field (default None = "not given"), plus --config and --resume."""
    parser.add_argument("--config", default=None, metavar="FILE",
                        help="YAML or JSON file of config fields (flags override it)")
    parser.add_argument("--resume", default=None, metavar="DIR",
                        help="continue the run in DIR (its checkpoint.pt) up to --iterations; "
                             "output goes to DIR unless --out is given")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    add_config_flags(parser)


def add_config_flags(parser: argparse.ArgumentParser, skip: Sequence[str] = (),
                     defaults: Optional[Mapping[str, Any]] = None) -> None:
    """One flag per TrainConfig field not in ``skip`` (argparse default None = "not given").

    ``defaults`` overrides the default shown in the help (what the caller fills in
    for flags that were not given), e.g. the suite's.
    """
    for f in fields(TrainConfig):
        if f.name in skip:
            continue
        default = f.default if f.default is not MISSING else f.default_factory()  # type: ignore[misc]
        default = (defaults or {}).get(f.name, default)
        kwargs: Dict[str, Any] = {"dest": f.name, "default": None,
                                  "help": f"{f.metadata.get('help', '')} (default {json.dumps(default)})"}
        if isinstance(default, bool):
            kwargs["action"] = argparse.BooleanOptionalAction
        elif isinstance(default, dict):
            kwargs.update(type=_json_object, metavar="JSON")
        else:
            kwargs["type"] = type(default)
        if f.name == "algorithm":
            kwargs["choices"] = ALGORITHM_NAMES
        parser.add_argument(_flag(f.name), **kwargs)


def config_from_args(args: argparse.Namespace) -> tuple:
    """(TrainConfig, resume checkpoint state or None) from parsed flags."""
    values: Dict[str, Any] = {}
    source = "flags"
    if args.config:
        values.update(load_config_file(args.config))
        source = args.config
    state = None
    if args.resume:
        from vmas_ros.train.checkpoint import load_checkpoint

        state = load_checkpoint(args.resume)
        values.update(state["config"])
        values["out"] = str(Path(args.resume))
        source = f"{args.resume} (checkpoint)"
    flags = {f.name: getattr(args, f.name) for f in fields(TrainConfig) if getattr(args, f.name) is not None}
    values.update(flags)
    return TrainConfig.from_dict(values, source=source), state


def run_train_command(args: argparse.Namespace) -> int:
    """Train, print a summary; exit status 2 on bad configuration."""
    try:
        config, state = config_from_args(args)
    except ValueError as error:
        print(f"vmas-ros train: {error}", file=sys.stderr)
        return 2
    from vmas_ros.train.trainer import Trainer

    try:
        trainer = Trainer(config, resume_state=state, progress=not args.quiet)
    except ValueError as error:
        print(f"vmas-ros train: {error}", file=sys.stderr)
        return 2
    except ConnectionError as error:
        print(f"vmas-ros train: cannot reach Ray at {config.ray_address!r}: {error}", file=sys.stderr)
        return 2
    if state is not None:
        print(f"resuming {config.out} at iteration {trainer.iteration} ({trainer.frames} frames)")
    from vmas_ros.train.ray_collection import CollectorLost

    try:
        summary = trainer.run()
    except (KeyboardInterrupt, CollectorLost) as error:
        return _stopped_early(trainer, error)
    finally:
        trainer.close()  # idempotent: whatever else goes wrong, the collectors stop and Ray is left
    last = trainer.history[-1] if trainer.history else {}
    print(f"trained {config.algorithm} on {config.scenario}: {summary['iterations']} iterations, "
          f"{summary['frames']} frames; last mean episode reward {last.get('episode_reward_mean', float('nan')):.4f}")
    if "eval" in summary:
        print(f"evaluation ({summary['eval']['episodes']} episodes, deterministic): "
              f"mean episode reward {summary['eval']['episode_reward_mean']:.4f}")
    print(f"outputs in {config.out}: log.csv, learning_curve.png, checkpoint.pt, policy.onnx + policy.json"
          + (", eval.gif" if "gif" in summary.get("eval", {}) else ""))
    return 0


def _stopped_early(trainer, error: BaseException) -> int:
    """Save what the completed iterations learnt and say how to continue; exit 130 on Ctrl-C, else 1."""
    try:
        trainer.save()
    finally:
        trainer.close()
    config = trainer.config
    how = "interrupted" if isinstance(error, KeyboardInterrupt) else str(error)
    ray = f" --ray-address {config.ray_address}" if config.ray_address != "none" else ""
    print(f"vmas-ros train: {how}; saved the checkpoint of iteration {trainer.iteration} in {config.out}; "
          f"continue with: vmas-ros train --resume {config.out}{ray}", file=sys.stderr)
    return 130 if isinstance(error, KeyboardInterrupt) else 1


def add_export_arguments(parser: argparse.ArgumentParser) -> None:
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--checkpoint", metavar="PATH", help="checkpoint.pt, or a run directory containing one")
    source.add_argument("--from-benchmarl", metavar="RUN_DIR",
                        help="a BenchMARL MAPPO/IPPO run folder (or checkpoint .pt), converted in BenchMARL's venv")
    parser.add_argument("--out", required=True, metavar="STEM",
                        help="writes STEM.onnx and STEM.json (the policy format OnnxPolicy and the ROS node load)")
    parser.add_argument("--benchmarl-python", metavar="PATH",
                        help="BenchMARL venv's python for --from-benchmarl (default: $VMAS_ROS_BENCHMARL_VENV/bin/python "
                             "or <repo>/.venv-benchmarl/bin/python, made by scripts/setup_benchmarl.sh)")


def run_export_command(args: argparse.Namespace) -> int:
    """Export a checkpoint's (or a BenchMARL run's) deterministic policy to ONNX + JSON metadata."""
    if getattr(args, "from_benchmarl", None):
        # BenchMARL unpickles the run in its own venv; this side only reads the ONNX + JSON it writes
        import os
        import subprocess

        from vmas_ros.policy.onnx_policy import OnnxPolicy

        repo = Path(__file__).resolve().parents[2]
        python = args.benchmarl_python or str(
            Path(os.environ.get("VMAS_ROS_BENCHMARL_VENV") or repo / ".venv-benchmarl") / "bin" / "python")
        if not Path(python).is_file():
            print(f"vmas-ros export: no BenchMARL python at {python}; create BenchMARL's venv with "
                  f"`bash scripts/setup_benchmarl.sh` (in {repo}) or pass --benchmarl-python", file=sys.stderr)
            return 2
        out = Path(args.out).resolve()
        out = out.with_suffix("") if out.suffix in (".onnx", ".json") else out
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(repo), os.environ.get("PYTHONPATH")])))
        run = subprocess.run([python, "-m", "vmas_ros.train.benchmarl_export", str(Path(args.from_benchmarl).resolve()),
                              str(out)], cwd=repo, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        if run.returncode != 0:
            errors = [line for line in run.stderr.splitlines() if line.startswith("vmas-ros export")]
            print("\n".join(errors) or run.stderr[-4000:] or f"vmas-ros export: conversion failed ({python})",
                  file=sys.stderr)
            return 2
        json_path = out.parent / (out.name + ".json")
        try:
            OnnxPolicy.load(json_path)
        except ValueError as error:
            print(f"vmas-ros export: the converted policy does not load: {error}", file=sys.stderr)
            return 2
        print(f"wrote {out.parent / (out.name + '.onnx')} and {json_path}")
        return 0
    from vmas_ros.train.export import export_checkpoint

    try:
        onnx_path, json_path = export_checkpoint(args.checkpoint, args.out)
    except ValueError as error:
        print(f"vmas-ros export: {error}", file=sys.stderr)
        return 2
    print(f"wrote {onnx_path} and {json_path}")
    return 0
