"""``vmas-ros train-suite``: the VMAS paper's Figure 3 (four PPO variants on four scenarios) in one command.

Trains every ``--algorithms`` x ``--scenarios`` x ``--seeds`` combination one
after another in this process (parallel runs on one machine would only fight
over its cores) or, with ``--ray-address``, as Ray tasks across a cluster
(:mod:`vmas_ros.train.suite_ray`), each with the existing
:class:`~vmas_ros.train.trainer.Trainer` in its own folder
``<out>/runs/<scenario>_<algorithm>_seed<seed>``, then measures
each scenario's heuristic with the same episode length and number of envs and
writes the report (see :mod:`vmas_ros.train.suite_report`).

Resumable, so an interrupted suite costs only the iterations since the last
checkpoint: a run whose folder holds ``suite_done.json`` and a checkpoint at
(or past) ``--iterations`` is skipped; a run with only a checkpoint continues
from it. A folder trained with different settings is refused rather than mixed
into one curve.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import fields
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

from vmas_ros.train.cli import add_config_flags
from vmas_ros.train.config import ALGORITHM_NAMES, TrainConfig, load_config_file
from vmas_ros.train.suite_run import (  # noqa: F401 - re-exported
    DONE_MARKER, SuiteRun, check_same_settings, run_name, train_one,
)

__all__ = ["add_train_suite_arguments", "run_train_suite_command", "SuiteRun", "plan_runs", "train_one",
           "check_same_settings",
           "heuristic_return", "run_name", "DEFAULT_SCENARIOS", "DONE_MARKER"]

#: the paper's Figure 3 scenarios
DEFAULT_SCENARIOS = ("transport", "wheel", "balance", "give_way")
#: TrainConfig fields the suite sets per run; they are not flags and not allowed in --config
_PER_RUN = ("scenario", "algorithm", "seed", "out", "scenario_kwargs")
#: suite defaults that differ from ``vmas-ros train``: no per-run evaluation or GIF (the curve is the result)
_SUITE_DEFAULTS = {"eval_episodes": 0, "gif": False}


# ---------------------------------------------------------------------- CLI
def add_train_suite_arguments(parser: argparse.ArgumentParser) -> None:
    """Suite options plus one flag per shared TrainConfig field (same names as ``vmas-ros train``)."""
    parser.add_argument("--algorithms", nargs="+", default=list(ALGORITHM_NAMES), metavar="ALGO",
                        help=f"algorithms to train (default: {' '.join(ALGORITHM_NAMES)})")
    parser.add_argument("--scenarios", nargs="+", default=list(DEFAULT_SCENARIOS), metavar="NAME",
                        help=f"scenarios (default: {' '.join(DEFAULT_SCENARIOS)}, the paper's Figure 3)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0], metavar="SEED",
                        help="seeds; each algorithm and scenario is trained once per seed (default: 0)")
    parser.add_argument("--out", default="runs/train_suite",
                        help="suite folder: runs go to OUT/runs/<scenario>_<algorithm>_seed<seed> "
                             "(default runs/train_suite)")
    parser.add_argument("--report-dir", default=None, metavar="DIR",
                        help="where the plots, CSVs and summary go (default: --out)")
    parser.add_argument("--config", default=None, metavar="FILE",
                        help="YAML or JSON file of shared TrainConfig fields (flags override it)")
    parser.add_argument("--threads", type=int, default=None,
                        help="torch CPU threads (default: torch's own choice)")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    add_config_flags(parser, skip=_PER_RUN, defaults=_SUITE_DEFAULTS)


def _base_values(args: argparse.Namespace) -> Dict[str, Any]:
    """Shared config values: suite defaults < --config < flags (the per-run fields are refused in the file)."""
    values: Dict[str, Any] = dict(_SUITE_DEFAULTS)
    if args.config:
        loaded = {key.replace("-", "_"): value for key, value in load_config_file(args.config).items()}
        fixed = sorted(set(loaded) & set(_PER_RUN))
        if fixed:
            raise ValueError(f"{args.config}: {fixed} are set per run by the suite; use --scenarios, "
                             f"--algorithms, --seeds and --out instead")
        values.update(loaded)
    values.update({f.name: getattr(args, f.name) for f in fields(TrainConfig)
                   if f.name not in _PER_RUN and getattr(args, f.name) is not None})
    return values


def _check_names(kind: str, names: Sequence[Any], valid: Optional[Sequence[Any]]) -> None:
    if not names:
        raise ValueError(f"--{kind} needs at least one value")
    duplicates = sorted({str(n) for n in names if list(names).count(n) > 1})
    if duplicates:
        raise ValueError(f"--{kind}: {', '.join(duplicates)} given more than once")
    if valid is not None:
        unknown = [n for n in names if n not in valid]
        if unknown:
            raise ValueError(f"--{kind}: unknown {', '.join(map(repr, unknown))}; valid: {', '.join(valid)}")


def plan_runs(args: argparse.Namespace) -> List[SuiteRun]:
    """Validate the options and list the runs (scenario-major, so each scenario's plot fills up in turn)."""
    from vmas_ros.scenarios import heuristic, list_scenarios

    _check_names("algorithms", args.algorithms, ALGORITHM_NAMES)
    _check_names("scenarios", args.scenarios, list_scenarios())
    _check_names("seeds", args.seeds, None)
    negative = [s for s in args.seeds if s < 0]
    if negative:
        raise ValueError(f"--seeds must be >= 0, got {negative[0]}")
    if args.threads is not None and args.threads < 1:
        raise ValueError(f"--threads must be >= 1, got {args.threads}")
    for name in args.scenarios:
        heuristic(name)  # ValueError naming the scenario if it has none: no reference line
    base = _base_values(args)
    runs = []
    for scenario in args.scenarios:
        for algorithm in args.algorithms:
            for seed in args.seeds:
                out = Path(args.out) / "runs" / run_name(scenario, algorithm, seed)
                config = TrainConfig.from_dict({**base, "scenario": scenario, "algorithm": algorithm,
                                                "seed": seed, "out": str(out)}, source="train-suite options")
                runs.append(SuiteRun(scenario, algorithm, seed, config))
    return runs


def _train_on_ray(runs: List[SuiteRun], bar, histories: Dict[str, Any], statuses: Dict[str, str]) -> int:
    """Train every run as a Ray task (see :mod:`vmas_ros.train.suite_ray`); non-zero exit status on failure."""
    from vmas_ros.train.ray_collection import connect
    from vmas_ros.train.suite_ray import train_runs_on_ray

    config = runs[0].config
    if config.collectors != 1:
        print(f"vmas-ros train-suite: --collectors {config.collectors}: on Ray each run is one task that steps "
              f"its own envs; give it more CPUs with --collector-cpus", file=sys.stderr)
        return 2

    def done(run: SuiteRun, result: Dict[str, Any]) -> None:
        histories[run.name], statuses[run.name] = result["history"], result["status"]
        bar.set_postfix_str(f"{run.name} {result['status']}")
        bar.update(1)

    try:
        joined = connect(config.ray_address)
    except ConnectionError as error:
        print(f"vmas-ros train-suite: cannot reach Ray at {config.ray_address!r}: {error}", file=sys.stderr)
        return 2
    try:
        failures = train_runs_on_ray(runs, config.collector_cpus, done)
    except ValueError as error:
        print(f"vmas-ros train-suite: {error}", file=sys.stderr)
        return 2
    finally:
        if joined:
            import ray

            ray.shutdown()
    if failures:
        bar.close()
        for run, reason in failures:
            print(f"vmas-ros train-suite: {run.name} failed: {reason}", file=sys.stderr)
        print(f"vmas-ros train-suite: {len(failures)} of {len(runs)} runs failed; the others are saved. Rerun the "
              f"same command to retry them (finished runs are skipped)", file=sys.stderr)
        return 1
    return 0


def heuristic_return(scenario: str, num_envs: int, max_steps: int, seed: int, device: str = "cpu") -> Dict[str, float]:
    """The scenario heuristic's mean episode return per agent, in the training curve's units.

    Same env construction as training (continuous actions, the scenario's default
    kwargs, ``num_envs`` envs, seed) and the same episode: at most ``max_steps``
    steps, rewards counted up to the first done, averaged over agents and envs,
    which is what ``episode_reward_mean`` in a run's ``log.csv`` averages. The env
    gets no ``max_steps`` of its own (the loop stops there; the returns are the
    same), so ``done_fraction`` counts only episodes the scenario itself ended
    (success), as in ``vmas-ros evaluate``, not the truncation every env reaches.
    """
    from vmas_ros.envs.make_env import make_env
    from vmas_ros.bench.heuristics import episode_returns
    from vmas_ros.scenarios import make_heuristic

    env = make_env(scenario, num_envs=num_envs, device=device, seed=seed, continuous_actions=True)
    returns, _length, finished = episode_returns(env, make_heuristic(scenario), max_steps)
    return {"mean_return": float(returns.mean()), "done_fraction": float(finished.float().mean())}


# ------------------------------------------------------------------ command
def run_train_suite_command(args: argparse.Namespace) -> int:
    """Plan, train every run, measure the heuristics, write the report. Exit 2 on bad options."""
    import torch
    from tqdm import tqdm

    from vmas_ros.train.suite_report import write_report

    try:
        runs = plan_runs(args)
    except ValueError as error:
        print(f"vmas-ros train-suite: {error}", file=sys.stderr)
        return 2
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    histories: Dict[str, List[Dict[str, float]]] = {}
    statuses: Dict[str, str] = {}
    start = time.perf_counter()
    bar = tqdm(total=len(runs), desc="train-suite", unit="run", disable=args.quiet, position=0)
    if runs[0].config.ray_address != "none":
        code = _train_on_ray(runs, bar, histories, statuses)
        if code:
            return code
    for run in (r for r in runs if r.name not in statuses):
        bar.set_postfix_str(run.name)

        def show(row: Dict[str, float], run: SuiteRun = run) -> None:
            bar.set_postfix_str(f"{run.name} it {row['iteration']} reward {row['episode_reward_mean']:.3f}")

        try:
            result = train_one(run, progress=not args.quiet, on_iteration=show)
        except ValueError as error:
            bar.close()
            print(f"vmas-ros train-suite: {run.name}: {error}", file=sys.stderr)
            return 2
        histories[run.name], statuses[run.name] = result["history"], result["status"]
        bar.update(1)
    bar.close()
    heuristics: Dict[str, Dict[str, float]] = {}
    config = runs[0].config
    for scenario in args.scenarios:
        values = [heuristic_return(scenario, config.num_envs, config.max_steps, seed, config.device)
                  for seed in args.seeds]
        heuristics[scenario] = {key: sum(v[key] for v in values) / len(values) for key in values[0]}
    report_dir = Path(args.report_dir or args.out)
    paths = write_report(report_dir, runs, histories, heuristics, args.scenarios, args.algorithms)
    counts = {s: sum(1 for v in statuses.values() if v == s) for s in ("trained", "resumed", "skipped")}
    print(f"{len(runs)} runs ({counts['trained']} trained, {counts['resumed']} resumed, "
          f"{counts['skipped']} skipped) in {time.perf_counter() - start:.0f} s; runs in {Path(args.out) / 'runs'}")
    print((report_dir / "summary.md").read_text())
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0
