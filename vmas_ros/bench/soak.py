"""``vmas-ros soak engine|node``: long runs that look for slow failures.

A benchmark measures speed over seconds; a soak watches for what only shows
after hours: memory that creeps up (a cache keyed by something that never
repeats, tensors kept alive by a list), a state that drifts into NaN or inf
after 50,000 steps, a node that slowly falls behind real time. Both modes
sample at fixed intervals, judge growth only after a warm-up (allocator pools,
lazily built tables and the first bag chunks legitimately grow early on), and
exit with code 1 when a check fails, so the short CI versions can fail.

``engine`` (this module) steps a scenario with random actions in-process and
samples the RSS and the memory held by live torch tensors; ``node``
(:mod:`vmas_ros.bench.soak_node`) runs sim_node as a separate process with
recording, a Foxglove client and a command publisher attached.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass, field
from typing import Callable, List, Optional

import torch

from vmas_ros.bench.soak_memory import (  # noqa: F401 - re-exported
    MB, MemorySample, growth_mb, live_tensor_bytes, rss_bytes, slope_per_hour, write_outputs,
)

__all__ = [
    "MemorySample", "EngineSoakResult", "add_parser", "growth_mb", "live_tensor_bytes", "rss_bytes", "run",
    "run_engine_soak", "write_outputs",
]


# --------------------------------------------------------------------- engine mode
@dataclass
class EngineSoakResult:
    """What an engine soak measured, and its verdict (``ok``)."""

    scenario: str
    num_envs: int
    steps_requested: int
    steps_done: int
    device: str
    wall_s: float
    steps_per_s: float
    env_steps_per_s: float
    warmup_steps: int
    rss_start_mb: float
    rss_after_warmup_mb: float
    rss_end_mb: float
    rss_growth_mb: float
    rss_slope_mb_per_h: float
    torch_growth_mb: float
    max_growth_mb: float
    max_torch_growth_mb: float
    nonfinite_at_step: Optional[int]
    finite_checks: int
    ok: bool
    failures: List[str] = field(default_factory=list)
    samples: List[MemorySample] = field(default_factory=list)


def _random_actions(env, generator: torch.Generator) -> List[torch.Tensor]:
    """Uniform actions in each agent's range, bounds included in the support (continuous actions)."""
    out = []
    for agent in env.agents:
        size = env.get_agent_action_size(agent)
        u = agent.action.u_range_tensor.to(env.device)
        raw = torch.rand(env.num_envs, size, device=env.device, generator=generator)
        out.append((raw * 2 - 1) * u[:size])
    return out


def _state_finite(env) -> torch.Tensor:
    """One 0-dim bool tensor: every entity's pos, vel, rot and ang_vel is finite in every env (no host read)."""
    world = env.world
    checks = [torch.isfinite(world.stacked_state(name)).all() for name in ("pos", "vel", "rot", "ang_vel")]
    return torch.stack(checks).all()


def run_engine_soak(
    scenario: str = "simple_spread",
    num_envs: int = 30_000,
    steps: int = 100_000,
    device: str = "cpu",
    seed: int = 0,
    sample_every: int = 1000,
    warmup_steps: Optional[int] = None,
    reset_every: int = 1000,
    max_growth_mb: float = 64.0,
    max_torch_growth_mb: float = 1.0,
    scenario_kwargs: Optional[dict] = None,
    progress: bool = True,
    max_minutes: float = 0.0,
    step_hook: Optional[Callable[[object, int], None]] = None,
) -> EngineSoakResult:
    """Step ``scenario`` with random actions and sample memory and finiteness every ``sample_every`` steps.

    The finiteness check costs one host read per interval (a single reduced bool),
    so the soak runs at the engine's own speed. Every ``reset_every`` steps all
    envs are reset (0: never), which exercises the reset path for leaks too.
    ``step_hook(env, step)`` runs after each step; the tests use it to inject a
    leak or a NaN and check the detector fires. A non-finite state stops the run,
    and so does ``max_minutes`` of wall time (0: no limit): the result then says
    exactly how many steps ran (``steps_done``).
    """
    from vmas_ros.envs.make_env import make_env

    if num_envs < 1 or steps < 1 or sample_every < 1:
        raise ValueError("num_envs, steps and sample_every must be >= 1")
    warmup = steps // 10 if warmup_steps is None else warmup_steps
    if not 0 <= warmup < steps:
        raise ValueError(f"warm-up ({warmup} steps) must be shorter than the run ({steps} steps)")
    dev = torch.device(device)
    env = make_env(scenario, num_envs=num_envs, device=dev, seed=seed, **(scenario_kwargs or {}))
    env.reset()
    generator = torch.Generator(device=dev)
    generator.manual_seed(seed)
    samples: List[MemorySample] = []
    start = time.perf_counter()
    samples.append(MemorySample(0, 0.0, rss_bytes() / MB, live_tensor_bytes(dev) / MB, True, 0.0))
    bar = _progress(steps, progress, f"soak engine {scenario} x{num_envs}")
    nonfinite_at, checks, done, last_t, last_step = None, 0, 0, start, 0
    try:
        for step in range(1, steps + 1):
            env.step(_random_actions(env, generator))
            done = step
            if step_hook is not None:
                step_hook(env, step)
            if step % sample_every == 0 or step == steps:
                finite = bool(_state_finite(env))  # the interval's one host read
                checks += 1
                now = time.perf_counter()
                rate = (step - last_step) / max(now - last_t, 1e-9)
                samples.append(MemorySample(step, now - start, rss_bytes() / MB, live_tensor_bytes(dev) / MB, finite, rate))
                last_t, last_step = now, step
                if not finite:
                    nonfinite_at = step
                    break
                if max_minutes and now - start > max_minutes * 60:
                    break
            if reset_every and step % reset_every == 0:
                env.reset()
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - start
    return _engine_verdict(scenario, num_envs, steps, done, dev, wall, warmup, samples, nonfinite_at, checks,
                           max_growth_mb, max_torch_growth_mb)


def _engine_verdict(scenario, num_envs, steps, done, dev, wall, warmup, samples, nonfinite_at, checks,
                    max_growth_mb, max_torch_growth_mb) -> EngineSoakResult:
    """Reduce the samples to growth figures and a pass/fail verdict with reasons."""
    warm_index = next((i for i, s in enumerate(samples) if s.step >= warmup and s.step > 0), len(samples) - 1)
    rss = [s.rss_mb for s in samples]
    tensors = [s.torch_mb for s in samples]
    post = samples[warm_index:]
    failures = []
    rss_growth, torch_growth = growth_mb(rss, warm_index), growth_mb(tensors, warm_index)
    if nonfinite_at is not None:
        failures.append(f"non-finite state found at the check after step {nonfinite_at}")
    if len(post) < 4:
        failures.append(f"only {len(post)} samples after warm-up: too few to judge memory (lower --sample-every)")
    if rss_growth > max_growth_mb:
        failures.append(f"RSS grew {rss_growth:.1f} MB after warm-up (limit {max_growth_mb} MB)")
    if torch_growth > max_torch_growth_mb:
        failures.append(f"live tensors grew {torch_growth:.2f} MB after warm-up (limit {max_torch_growth_mb} MB)")
    return EngineSoakResult(
        scenario=scenario, num_envs=num_envs, steps_requested=steps, steps_done=done, device=str(dev),
        wall_s=wall, steps_per_s=done / wall if wall > 0 else 0.0, env_steps_per_s=done * num_envs / wall if wall else 0.0,
        warmup_steps=warmup, rss_start_mb=rss[0], rss_after_warmup_mb=rss[warm_index], rss_end_mb=rss[-1],
        rss_growth_mb=rss_growth, rss_slope_mb_per_h=slope_per_hour([s.wall_s for s in post], [s.rss_mb for s in post]),
        torch_growth_mb=torch_growth, max_growth_mb=max_growth_mb, max_torch_growth_mb=max_torch_growth_mb,
        nonfinite_at_step=nonfinite_at, finite_checks=checks, ok=not failures, failures=failures, samples=samples,
    )


def _progress(total: int, enabled: bool, desc: str):
    if not enabled:
        return None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm(total=total, desc=desc, unit="step", mininterval=1.0, file=sys.stderr)


# ----------------------------------------------------------------------------- CLI
def add_parser(sub) -> argparse.ArgumentParser:
    """Add ``soak`` with its ``engine`` and ``node`` modes to an argparse subparsers object."""
    soak = sub.add_parser("soak", help="long runs: memory growth, NaN/inf, missed steps (engine or sim_node)")
    modes = soak.add_subparsers(dest="soak_mode", required=True, metavar="{engine,node}")
    engine = modes.add_parser("engine", help="step a scenario with random actions in-process")
    engine.add_argument("--scenario", default="simple_spread", help="scenario name (default simple_spread)")
    engine.add_argument("--scenario-kwargs", default=None, help="JSON mapping passed to the scenario")
    engine.add_argument("--num-envs", dest="soak_num_envs", type=int, default=30_000, help="parallel envs (default 30000)")
    engine.add_argument("--steps", type=int, default=100_000, help="steps to run (default 100000)")
    engine.add_argument("--device", default="cpu", help="torch device (default cpu)")
    engine.add_argument("--seed", type=int, default=0, help="env and action seed (default 0)")
    engine.add_argument("--sample-every", type=int, default=1000, help="steps between samples and NaN checks (default 1000)")
    engine.add_argument("--warmup-steps", type=int, default=None, help="steps before growth is judged (default 10%% of --steps)")
    engine.add_argument("--reset-every", type=int, default=1000, help="reset all envs every N steps; 0: never (default 1000)")
    engine.add_argument("--max-growth-mb", type=float, default=64.0, help="RSS growth after warm-up that fails the run (default 64)")
    engine.add_argument("--max-torch-growth-mb", type=float, default=1.0,
                        help="growth of live tensor memory after warm-up that fails the run (default 1)")
    engine.add_argument("--max-minutes", type=float, default=0.0,
                        help="stop after this much wall time, at the next sample; 0: run all --steps (default 0)")
    engine.add_argument("--threads", type=int, default=None, help="torch.set_num_threads (default: torch's)")
    from vmas_ros.bench.soak_node import add_node_arguments

    node = modes.add_parser("node", help="run sim_node as a process with recording, Foxglove and commands")
    add_node_arguments(node)
    for mode in (engine, node):
        mode.add_argument("--out", default="soak_results", help="output folder (default soak_results/)")
        mode.add_argument("--no-plot", action="store_true", help="do not write the PNG")
        mode.add_argument("--no-progress", action="store_true", help="no progress bar")
    soak.set_defaults(func=run)
    return soak


def run(args: argparse.Namespace) -> int:
    """Run ``vmas-ros soak``: 0 when every check passed, 1 when one failed, 2 on bad arguments."""
    if args.soak_mode == "node":
        from vmas_ros.bench.soak_node import run_node_command

        return run_node_command(args)
    try:
        kwargs = json.loads(args.scenario_kwargs) if args.scenario_kwargs else None
    except json.JSONDecodeError as error:
        print(f"vmas-ros soak: --scenario-kwargs is not JSON: {error}", file=sys.stderr)
        return 2
    if args.threads:
        torch.set_num_threads(args.threads)
    try:
        result = run_engine_soak(
            scenario=args.scenario, num_envs=args.soak_num_envs, steps=args.steps, device=args.device, seed=args.seed,
            sample_every=args.sample_every, warmup_steps=args.warmup_steps, reset_every=args.reset_every,
            max_growth_mb=args.max_growth_mb, max_torch_growth_mb=args.max_torch_growth_mb, scenario_kwargs=kwargs,
            progress=not args.no_progress, max_minutes=args.max_minutes,
        )
    except ValueError as error:
        print(f"vmas-ros soak: {error}", file=sys.stderr)
        return 2
    paths = write_outputs(result, args.out, "soak_engine", plot=not args.no_plot)
    print(format_engine(result))
    for path in paths.values():
        print(f"wrote {path}")
    return 0 if result.ok else 1


def format_engine(r: EngineSoakResult) -> str:
    """A short human summary of an engine soak."""
    lines = [
        f"soak engine: {r.scenario} x {r.num_envs} envs on {r.device}: {r.steps_done}/{r.steps_requested} steps "
        f"in {r.wall_s:.0f} s ({r.steps_per_s:.1f} steps/s, {r.env_steps_per_s:,.0f} env-steps/s)",
        f"  RSS {r.rss_start_mb:.0f} MB at start, {r.rss_after_warmup_mb:.0f} MB after warm-up ({r.warmup_steps} steps), "
        f"{r.rss_end_mb:.0f} MB at end: growth {r.rss_growth_mb:+.1f} MB, slope {r.rss_slope_mb_per_h:+.1f} MB/h",
        f"  live tensors growth {r.torch_growth_mb:+.3f} MB; {r.finite_checks} NaN/inf checks, "
        f"{'none failed' if r.nonfinite_at_step is None else f'non-finite at step {r.nonfinite_at_step}'}",
        "  verdict: " + ("ok" if r.ok else "FAILED: " + "; ".join(r.failures)),
    ]
    return "\n".join(lines)


def main(argv: Optional[List[str]] = None) -> int:
    """``python -m vmas_ros.bench.soak engine|node ...``: the same command without the ``vmas-ros`` CLI."""
    parser = argparse.ArgumentParser(prog="python -m vmas_ros.bench.soak")
    add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["soak"] + list(sys.argv[1:] if argv is None else argv))
    return run(args)


if __name__ == "__main__":
    sys.exit(main())
