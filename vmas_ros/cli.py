"""``vmas-ros``: the project's command line.

Subcommands:
    list    the registered scenarios
    demo    a short headless run of a scenario's heuristic: prints what happened
            (reward against random actions, speed) and optionally saves a picture
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from typing import List, Optional

import torch


def _parse_kwargs(text: Optional[str]) -> dict:
    if not text:
        return {}
    try:
        value = json.loads(text)
    except json.JSONDecodeError as error:
        raise SystemExit(f"--scenario-kwargs must be a JSON object, e.g. '{{\"n_agents\": 4}}': {error}")
    if not isinstance(value, dict):
        raise SystemExit(f"--scenario-kwargs must be a JSON object, got {type(value).__name__}")
    return value


def _rollout(env, policy, steps: int, progress: bool) -> torch.Tensor:
    """Mean per-env return of the first agent's team reward over ``steps`` steps."""
    from tqdm import tqdm

    obs = env.reset()
    total = torch.zeros(env.num_envs, device=env.device)
    for _ in tqdm(range(steps), disable=not progress, desc="steps", leave=False):
        if policy is None:
            actions = env.get_random_actions()
        else:
            actions = [policy.compute_action(o, u_range=a.u_range) for o, a in zip(obs, env.agents)]
        obs, rews, _, _ = env.step(actions)
        total += torch.stack(rews, dim=0).mean(dim=0)
    return total


def cmd_list(args: argparse.Namespace) -> int:
    from vmas_ros.scenarios import list_scenarios

    for name in list_scenarios():
        print(name)
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    import vmas_ros
    from vmas_ros.scenarios import heuristic

    kwargs = _parse_kwargs(args.scenario_kwargs)
    try:
        env = vmas_ros.make_env(args.scenario, num_envs=args.num_envs, device=args.device, seed=args.seed, **kwargs)
    except ValueError as error:
        print(f"vmas-ros demo: {error}", file=sys.stderr)
        return 2
    policy = heuristic(args.scenario)(continuous_action=True)
    print(f"scenario {args.scenario}: {env.n_agents} agents, {len(env.world.landmarks)} landmarks, "
          f"{args.num_envs} envs on {env.device}, {args.steps} steps")
    start = time.perf_counter()
    heuristic_return = _rollout(env, policy, args.steps, progress=not args.quiet)
    elapsed = time.perf_counter() - start
    random_return = _rollout(env, None, args.steps, progress=not args.quiet)
    print(f"heuristic mean return per env: {heuristic_return.mean().item():10.3f}")
    print(f"random    mean return per env: {random_return.mean().item():10.3f}")
    rate = args.steps * args.num_envs / elapsed
    print(f"speed: {elapsed / args.steps * 1e3:.2f} ms per batched step, {rate:,.0f} env-steps/s")
    if args.image:
        from PIL import Image

        Image.fromarray(env.render(mode="rgb_array", env_index=0)).save(args.image)
        print(f"saved a picture of env 0 to {args.image}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="vmas-ros", description="Vectorized multi-robot simulation for ROS 2.")
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="list the scenarios").set_defaults(func=cmd_list)
    demo = sub.add_parser("demo", help="short headless run of a scenario's heuristic")
    demo.add_argument("--scenario", default="simple_spread", help="scenario name (see `vmas-ros list`)")
    demo.add_argument("--scenario-kwargs", default=None, help="JSON object of scenario kwargs")
    demo.add_argument("--num-envs", type=int, default=256, help="parallel envs (default 256)")
    demo.add_argument("--steps", type=int, default=100, help="steps per rollout (default 100)")
    demo.add_argument("--device", default="cpu", help="torch device (default cpu)")
    demo.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    demo.add_argument("--image", default=None, help="save a PNG of env 0 at the end")
    demo.add_argument("--quiet", action="store_true", help="no progress bar")
    demo.set_defaults(func=cmd_demo)
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    if getattr(args, "num_envs", 1) < 1 or getattr(args, "steps", 1) < 1:
        print("vmas-ros: --num-envs and --steps must be >= 1", file=sys.stderr)
        return 2
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
