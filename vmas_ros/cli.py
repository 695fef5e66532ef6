"""``vmas-ros``: the project's command line.

Subcommands:
    list    the registered scenarios
    demo    a short headless run of a scenario's heuristic: prints what happened
            (reward against random actions, speed) and optionally saves a picture
    play    drive a scenario's agents with the keyboard (pygame window)
    bench   benchmarks against upstream VMAS and MPE (speed ratios, CSV/JSON/PNG)
    evaluate  each scenario's heuristic against random play (mean episode returns, CSV/Markdown)
    render  roll out a scenario and save it as a GIF, MP4 or PNG
    train   train a policy with CPPO, MAPPO, IPPO or HetIPPO (TorchRL PPO); exports it to ONNX
    export  export a training checkpoint's (or a BenchMARL run's) policy as <stem>.onnx + <stem>.json
    deploy-eval  an exported policy in the engine and on robot_fleet from the same starts, side by side
    train-suite  the paper's Figure 3: every algorithm on every scenario (and seed), one plot per
            scenario against its heuristic, a 2x2 figure, CSV and Markdown summary
    sim     start sim_node (the ROS 2 node) without ``ros2 launch``
    echo    print messages of a topic (``ros2 topic echo`` for wheel installs)
    drive   drive an agent: a Twist on its cmd_vel for a while, once the node listens
    topics  the topics (or services) of the ROS graph with their types
    call    call a std_srvs Trigger, SetBool or Empty service (sim_node's reset, pause, step)
    param   list, get, describe or set a node's parameters
    bag     ``bag info``: what a bag holds; ``bag play``: publish it again with its timing
    soak    long runs: memory growth, NaN/inf, missed steps (engine, or sim_node with bag + Foxglove)
    bag-recover  rebuild a finished MCAP bag from one whose recorder was killed
    dds-clean  remove Fast DDS shared memory that a killed process left half made
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
    """Per-env return ``[B]`` of the agents' mean reward over ``steps`` steps (``policy`` None: random actions)."""
    from tqdm import tqdm

    from vmas_ros.simulator.heuristic_policy import heuristic_actions

    obs = env.reset()
    total = torch.zeros(env.num_envs, device=env.device)
    for _ in tqdm(range(steps), disable=not progress, desc="steps", leave=False):
        obs, rews, _, _ = env.step(heuristic_actions(policy, env, obs))
        total += torch.stack(rews, dim=0).mean(dim=0)
    return total


def cmd_list(args: argparse.Namespace) -> int:
    from vmas_ros.scenarios import list_scenarios

    for name in list_scenarios():
        print(name)
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    import vmas_ros
    from vmas_ros.scenarios import make_heuristic

    kwargs = _parse_kwargs(args.scenario_kwargs)
    try:
        env = vmas_ros.make_env(args.scenario, num_envs=args.num_envs, device=args.device, seed=args.seed, **kwargs)
    except ValueError as error:
        print(f"vmas-ros demo: {error}", file=sys.stderr)
        return 2
    policy = make_heuristic(args.scenario, **kwargs)
    print(f"scenario {args.scenario}: {env.n_agents} agents, {len(env.world.landmarks)} landmarks, "
          f"{args.num_envs} envs on {env.device}, {args.steps} steps")
    if env.world.physics_compiled:  # compiled from the first step (VMAS_ROS_COMPILE=1): compile before timing
        print("compiling the physics step with torch.compile (once; VMAS_ROS_COMPILE=0 runs eagerly) ...",
              flush=True)
        start = time.perf_counter()
        env.step([env.get_random_action(agent) for agent in env.agents])
        env.reset()
        print(f"compiled in {time.perf_counter() - start:.1f} s")
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


def cmd_render(args: argparse.Namespace) -> int:
    """Roll out the heuristic (or random actions) in env 0 and save the frames."""
    from pathlib import Path

    import numpy as np
    from PIL import Image
    from tqdm import tqdm

    import vmas_ros
    from vmas_ros.scenarios import make_heuristic
    from vmas_ros.simulator.heuristic_policy import heuristic_actions
    from vmas_ros.simulator.video import VIDEO_SUFFIXES, save_frames

    out = Path(args.out)
    if out.suffix.lower() not in VIDEO_SUFFIXES:
        print(f"vmas-ros render: --out must end in {', '.join(VIDEO_SUFFIXES)}, got {out.name!r}", file=sys.stderr)
        return 2
    try:
        # eager: rendering one env costs far more than its steps, and compiling would delay the first frame
        env = vmas_ros.make_env(args.scenario, num_envs=1, device=args.device, seed=args.seed,
                                compile_physics=False, **_parse_kwargs(args.scenario_kwargs))
    except ValueError as error:
        print(f"vmas-ros render: {error}", file=sys.stderr)
        return 2
    policy = None if args.random else make_heuristic(args.scenario, **_parse_kwargs(args.scenario_kwargs))
    obs = env.reset()

    def frame():
        image = env.render(mode="rgb_array")
        if args.size and args.size != image.shape[1]:
            pil = Image.fromarray(image)
            image = np.asarray(pil.resize((args.size, round(args.size * pil.height / pil.width)), Image.LANCZOS))
        return image

    frames = [frame()]
    for _ in tqdm(range(args.steps), desc=f"render {args.scenario}", disable=args.quiet):
        obs, _, _, _ = env.step(heuristic_actions(policy, env, obs))
        frames.append(frame())
    out.parent.mkdir(parents=True, exist_ok=True)
    save_frames(frames, out, fps=args.fps)
    print(f"saved {len(frames)} frames of {args.scenario} to {out}")
    return 0


def cmd_sim(args: argparse.Namespace) -> int:
    from pathlib import Path

    from vmas_ros.ros.sim_node import main as sim_main

    ros_args = ["--ros-args"]
    if args.config:
        path = Path(args.config)
        if not path.is_file():
            print(f"vmas-ros sim: config file {path} does not exist", file=sys.stderr)
            return 2
        ros_args += ["--params-file", str(path)]
    if args.scenario:
        ros_args += ["-p", f"scenario:={args.scenario}"]
    if args.record:
        ros_args += ["-p", f"record_path:={args.record}"]
    for item in args.param or []:
        if ":=" not in item:
            print(f"vmas-ros sim: -p expects name:=value, got {item!r}", file=sys.stderr)
            return 2
        ros_args += ["-p", item]
    print("sim_node starting. In another terminal (same ROS_DOMAIN_ID):\n"
          "  vmas-ros echo /agent_0/scan        # or: ros2 topic echo /agent_0/scan\n"
          "  vmas-ros drive agent_0 --vx 0.3    # or: any geometry_msgs/Twist on /agent_0/cmd_vel\n"
          "Ctrl-C stops it.", flush=True)
    return sim_main(["sim_node"] + ros_args)


def _add_rollout_arguments(parser: argparse.ArgumentParser) -> None:
    """The options every rollout command takes: which scenario, how long, where and with which seed."""
    parser.add_argument("--scenario", default="simple_spread", help="scenario name (see `vmas-ros list`)")
    parser.add_argument("--scenario-kwargs", default=None, help="JSON object of scenario kwargs")
    parser.add_argument("--steps", type=int, default=100, help="steps to roll out (default 100)")
    parser.add_argument("--device", default="cpu", help="torch device (default cpu)")
    parser.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def _add_delegated(sub, name: str, help_text: str, add_arguments, run) -> None:
    """Subcommand ``name`` whose options (``add_arguments(parser)``) and handler (``run``) live in its own module."""
    parser = sub.add_parser(name, help=help_text)
    add_arguments(parser)
    parser.set_defaults(func=run)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="vmas-ros", description="Vectorized multi-robot simulation for ROS 2.")
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="list the scenarios").set_defaults(func=cmd_list)
    demo = sub.add_parser("demo", help="short headless run of a scenario's heuristic")
    _add_rollout_arguments(demo)
    demo.add_argument("--num-envs", type=int, default=256, help="parallel envs (default 256)")
    demo.add_argument("--image", default=None, help="save a PNG of env 0 at the end")
    demo.set_defaults(func=cmd_demo)
    from vmas_ros.interactive_rendering import add_play_arguments, run_play_command

    _add_delegated(sub, "play", "drive agents with the keyboard in a pygame window",
                   add_play_arguments, run_play_command)
    from vmas_ros.bench.cli import add_bench_arguments, run_bench_command

    _add_delegated(sub, "bench", "benchmarks (mpe: the VMAS paper's Figure 2, against VMAS and MPE)",
                   add_bench_arguments, run_bench_command)
    from vmas_ros.bench.heuristics import add_evaluate_arguments, run_evaluate_command

    _add_delegated(sub, "evaluate", "every scenario's heuristic against random play: episode returns",
                   add_evaluate_arguments, run_evaluate_command)
    from vmas_ros.train.cli import add_export_arguments, add_train_arguments, run_export_command, run_train_command

    _add_delegated(sub, "train", "train a policy (cppo, mappo, ippo, hetippo) and export it to ONNX",
                   add_train_arguments, run_train_command)
    from vmas_ros.train.suite import add_train_suite_arguments, run_train_suite_command

    _add_delegated(sub, "train-suite", "the paper's Figure 3: train cppo, mappo, ippo, hetippo on several scenarios "
                   "and plot them against the heuristics", add_train_suite_arguments, run_train_suite_command)
    _add_delegated(sub, "export", "export a training checkpoint or a BenchMARL run as <stem>.onnx + <stem>.json",
                   add_export_arguments, run_export_command)
    from vmas_ros.deploy import cli as deploy_cli

    _add_delegated(sub, "deploy-eval", "a policy in the engine and on robot_fleet (through policy_node) from the "
                   "same start states, side by side", deploy_cli.add_arguments, deploy_cli.run)
    render = sub.add_parser("render", help="save a rollout as .gif/.mp4/.png (headless)")
    _add_rollout_arguments(render)
    render.add_argument("--out", required=True, help="output file: .gif, .mp4 (needs imageio-ffmpeg) or .png (last frame)")
    render.add_argument("--random", action="store_true", help="random actions instead of the heuristic")
    render.add_argument("--size", type=int, default=0, help="output width in pixels (default: the scenario's)")
    render.add_argument("--fps", type=int, default=10, help="frames per second (default 10)")
    render.set_defaults(func=cmd_render)
    from vmas_ros.ros.params import SIM_PARAMS

    sim = sub.add_parser("sim", help="start sim_node (ROS 2) without ros2 launch",
                         formatter_class=argparse.RawDescriptionHelpFormatter,
                         description="Start sim_node in this process. Any node parameter below can be given\n"
                                     "with -p name:=value or in a --config file.",
                         epilog=SIM_PARAMS.help())
    sim.add_argument("--config", default=None, help="ROS parameter file (e.g. config/simple_spread.yaml)")
    sim.add_argument("--scenario", default=None, help="scenario name (overrides the config)")
    sim.add_argument("--record", default=None, help="record a bag: NAME.mcap (one MCAP file) or NAME (a rosbag2 bag folder)")
    sim.add_argument("-p", "--param", action="append", help="extra node parameter name:=value (repeatable)")
    sim.set_defaults(func=cmd_sim)
    from vmas_ros.viz import foxglove_layout

    _add_delegated(sub, "foxglove-layout", "write a Foxglove layout for a sim_node: its frame prefix and agents",
                   foxglove_layout.add_arguments, foxglove_layout.run)
    from vmas_ros.rostools.cli import add_rostool_parsers

    add_rostool_parsers(sub)  # vmas-ros echo, drive, topics, call, param, bag
    from vmas_ros.bench.soak import add_parser as add_soak_parser
    from vmas_ros.record.recover_cli import add_parser as add_bag_recover_parser

    add_bag_recover_parser(sub)
    add_soak_parser(sub)  # vmas-ros soak engine|node
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    num_envs, steps = getattr(args, "num_envs", 1), getattr(args, "steps", 1)
    if (isinstance(num_envs, int) and num_envs < 1) or (isinstance(steps, int) and steps < 1):
        print("vmas-ros: --num-envs and --steps must be >= 1", file=sys.stderr)
        return 2
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
