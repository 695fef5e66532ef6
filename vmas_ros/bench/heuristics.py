"""``vmas-ros evaluate``: every scenario's heuristic against random actions, as episode returns.

The heuristics table (docs/bench/heuristics.md) is produced by this module, so its numbers
can be re-measured by anyone with one command. For each scenario it runs one
batch of ``num_envs`` episodes with the heuristic and one with uniformly random
actions (same seed, so the same starts), each at most ``max_steps`` long, and
records per env:

* the **episode return** of every agent: the sum of its rewards up to and
  including the step on which the env first reports done (later steps are
  ignored; there is no auto-reset), averaged over agents and envs;
* per **team** (agent names up to their trailing ``_<index>``, e.g.
  ``adversary`` and ``agent``) the same mean, because competitive tasks only
  make sense per team;
* the fraction of envs that reported done within ``max_steps`` ("solved" for
  tasks whose episode ends on success);
* for the worlds whose reward is always zero (some debug scenarios), the
  **task score**: the sum over the episode of the per-step stand-in score the
  scenario module defines (``vmas_ros.scenarios.task_score``), averaged over
  envs. Such a scenario is built with the kwargs its score needs, which the
  table shows.

Results go to ``<out>.csv`` and ``<out>.md`` (the Markdown table) besides
being printed.
"""
from __future__ import annotations

import argparse
import csv
import os
import re
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import torch

from vmas_ros.simulator.heuristic_policy import heuristic_actions

__all__ = ["Evaluation", "add_evaluate_arguments", "episode_returns", "evaluate_scenario", "run_evaluate_command", "team_of"]

_TEAM_SUFFIX = re.compile(r"[ _]\d+$")


def team_of(agent_name: str) -> str:
    """The team an agent belongs to, read from its name: ``"adversary_2"`` -> ``"adversary"``."""
    return _TEAM_SUFFIX.sub("", agent_name) or agent_name


@dataclass
class Evaluation:
    """Episode statistics of one policy on one scenario."""

    scenario: str
    policy: str  # "heuristic" or "random"
    num_envs: int
    max_steps: int
    mean_return: float  # over agents and envs
    team_returns: Dict[str, float] = field(default_factory=dict)
    done_fraction: float = 0.0
    mean_episode_length: float = 0.0
    seconds: float = 0.0
    task_score: Optional[float] = None  # the stand-in score's episode sum, where the reward is always zero
    task_score_name: str = ""  # what that score measures
    scenario_kwargs: Dict[str, object] = field(default_factory=dict)


def episode_returns(env, policy, max_steps: int, progress=None, on_step=None) -> tuple:
    """One batched episode from ``env.reset()``: per-agent returns [A, B], per-env lengths [B]
    and which envs finished [B].

    Every agent plays ``policy.compute_action`` (uniform random actions when ``policy`` is
    None); an env's rewards count up to and including its first done step.
    ``on_step(observations, counted)``, if given, is called after every step with the new
    observations and the [B] mask of envs whose step still counts.
    """
    obs = env.reset()
    returns = torch.zeros(env.n_agents, env.num_envs, device=env.device)
    running = torch.ones(env.num_envs, dtype=torch.bool, device=env.device)
    length = torch.zeros(env.num_envs, device=env.device)
    for _ in range(max_steps):
        obs, rews, dones, _ = env.step(heuristic_actions(policy, env, obs))
        returns += torch.stack(rews) * running
        length += running
        if on_step is not None:
            on_step(obs, running)
        running = running & ~dones
        if progress is not None:
            progress.update(1)
    return returns, length, ~running


def evaluate_scenario(
    name: str, num_envs: int = 32, max_steps: int = 200, seed: int = 0, device: str = "cpu",
    scenario_kwargs: Optional[dict] = None, progress=None,
) -> List[Evaluation]:
    """The heuristic's and random play's :class:`Evaluation` on scenario ``name``."""
    from vmas_ros.envs.make_env import make_env
    from vmas_ros.scenarios import make_heuristic, task_score

    stand_in = task_score(name)
    score_name, score_fn, score_kwargs = stand_in if stand_in is not None else ("", None, {})
    kwargs = {**score_kwargs, **(scenario_kwargs or {})}
    results = []
    for label in ("heuristic", "random"):
        env = make_env(name, num_envs=num_envs, device=device, seed=seed, compile_physics=False,
                       **kwargs)  # eager: scores, not speed, and VMAS's heuristics score the same steps
        policy = make_heuristic(name, **kwargs) if label == "heuristic" else None
        score = torch.zeros(num_envs, device=env.device)

        def add_score(observations, counted, env=env, score=score):
            score.add_(score_fn(env, observations) * counted)

        start = time.perf_counter()
        returns, length, finished = episode_returns(
            env, policy, max_steps, progress, on_step=add_score if score_fn is not None else None)
        teams: Dict[str, List[int]] = {}
        for i, agent in enumerate(env.agents):
            teams.setdefault(team_of(agent.name), []).append(i)
        results.append(Evaluation(
            scenario=name, policy=label, num_envs=num_envs, max_steps=max_steps,
            mean_return=float(returns.mean()),
            team_returns={team: float(returns[rows].mean()) for team, rows in teams.items()},
            done_fraction=float(finished.float().mean()), mean_episode_length=float(length.mean()),
            seconds=time.perf_counter() - start,
            task_score=float(score.mean()) if score_fn is not None else None, task_score_name=score_name,
            scenario_kwargs=kwargs,
        ))
    return results


# ------------------------------------------------------------------- output
def _teams_text(evaluation: Evaluation) -> str:
    if len(evaluation.team_returns) < 2:
        return ""
    return ", ".join(f"{team} {value:.2f}" for team, value in evaluation.team_returns.items())


def format_markdown(results: Sequence[Evaluation]) -> str:
    """The heuristics table: one row per scenario, heuristic against random."""
    by_scenario: Dict[str, Dict[str, Evaluation]] = {}
    for result in results:
        by_scenario.setdefault(result.scenario, {})[result.policy] = result
    lines = [
        "| scenario | heuristic return | random return | heuristic per team | done within episode (heuristic / random) |",
        "| --- | ---: | ---: | --- | ---: |",
    ]
    scored = []
    for name, pair in by_scenario.items():
        h, r = pair["heuristic"], pair["random"]
        label = f"`{name}`" + (f" ({_kwargs_text(h.scenario_kwargs)})" if h.scenario_kwargs else "")
        lines.append(f"| {label} | {h.mean_return:.2f} | {r.mean_return:.2f} | {_teams_text(h)} | "
                     f"{h.done_fraction:.0%} / {r.done_fraction:.0%} |")
        if h.task_score is not None:
            scored.append((label, h, r))
    if scored:
        lines += [
            "", "Worlds whose reward is always zero, scored instead on their heuristic's stated goal "
            "(per-step score summed over the episode, mean over envs; higher is better):", "",
            "| scenario | task score | heuristic | random |", "| --- | --- | ---: | ---: |",
        ]
        lines += [f"| {label} | {h.task_score_name} | {h.task_score:.2f} | {r.task_score:.2f} |"
                  for label, h, r in scored]
    return "\n".join(lines) + "\n"


def _kwargs_text(kwargs: Dict[str, object]) -> str:
    return ", ".join(f"{key}={value!r}" for key, value in kwargs.items())


def provenance(command: str) -> str:
    """A line saying what produced a results file and where: the command, machine, torch, date."""
    import platform

    cpu = platform.processor() or platform.machine()
    return (f"Produced by `{command}` on {platform.system()} {cpu} ({os.cpu_count()} CPUs), "
            f"torch {torch.__version__}, {time.strftime('%Y-%m-%d')}.")


def write_results(results: Sequence[Evaluation], out: Path, header: str = "") -> List[Path]:
    """``<out>.csv`` (one row per scenario and policy) and ``<out>.md`` (``header``, then the table)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    csv_path, md_path = out.with_suffix(".csv"), out.with_suffix(".md")
    with csv_path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["scenario", "policy", "num_envs", "max_steps", "mean_return", "team_returns",
                         "done_fraction", "mean_episode_length", "seconds", "task_score", "task_score_name",
                         "scenario_kwargs"])
        for r in results:
            teams = ";".join(f"{team}={value:.6g}" for team, value in r.team_returns.items())
            writer.writerow([r.scenario, r.policy, r.num_envs, r.max_steps, f"{r.mean_return:.6g}", teams,
                             f"{r.done_fraction:.4g}", f"{r.mean_episode_length:.4g}", f"{r.seconds:.3g}",
                             "" if r.task_score is None else f"{r.task_score:.6g}", r.task_score_name,
                             _kwargs_text(r.scenario_kwargs)])
    md_path.write_text((header + "\n\n" if header else "") + format_markdown(results))
    return [csv_path, md_path]


# ---------------------------------------------------------------------- CLI
def add_evaluate_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The options of ``vmas-ros evaluate``."""
    parser.add_argument("--scenarios", nargs="+", default=None, metavar="NAME",
                        help="scenarios to evaluate (default: all registered)")
    parser.add_argument("--num-envs", dest="eval_num_envs", type=int, default=32,
                        help="episodes per policy and scenario, run as one batch (default 32)")
    parser.add_argument("--max-steps", type=int, default=200, help="episode length cap (default 200)")
    parser.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    parser.add_argument("--device", default="cpu", help="torch device (default cpu)")
    parser.add_argument("--out", default="bench_results/heuristics",
                        help="output path without suffix: writes .csv and .md (default bench_results/heuristics)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    return parser


def run_evaluate_command(args: argparse.Namespace) -> int:
    """Evaluate from parsed options: 0 on success, 2 on bad arguments."""
    from tqdm import tqdm

    from vmas_ros.scenarios import list_scenarios

    names = args.scenarios or list_scenarios()
    unknown = [n for n in names if n not in list_scenarios()]
    if unknown:
        print(f"vmas-ros evaluate: unknown scenario(s) {', '.join(map(repr, unknown))}; "
              f"valid: {', '.join(list_scenarios())}", file=sys.stderr)
        return 2
    if args.eval_num_envs < 1 or args.max_steps < 1:
        print(f"vmas-ros evaluate: --num-envs and --max-steps must be >= 1, got {args.eval_num_envs} "
              f"and {args.max_steps}", file=sys.stderr)
        return 2
    results: List[Evaluation] = []
    with tqdm(total=2 * args.max_steps * len(names), desc="evaluate", unit="step", disable=args.quiet) as bar:
        for name in names:
            bar.set_postfix_str(name)
            results += evaluate_scenario(name, args.eval_num_envs, args.max_steps, args.seed, args.device,
                                         progress=bar)
    print(format_markdown(results))
    command = "vmas-ros evaluate " + " ".join(sys.argv[2:]) if sys.argv[1:2] == ["evaluate"] else "vmas-ros evaluate"
    for path in write_results(results, Path(args.out), header=provenance(command)):
        print(f"wrote {path}")
    return 0
