"""``vmas-ros deploy-eval``: one exported policy, the same start states, in the engine and on ``robot_fleet``.

The engine side runs the policy batched over the episodes
(:mod:`~vmas_ros.deploy.engine_side`); the fleet side replays each start on
``robot_fleet`` (numpy robots with latency, lag and noise, not the engine)
through ``policy_node`` with an adapter and body-frame cmd_vel, as on robots
(:mod:`~vmas_ros.deploy.fleet_side`). The output folder gets ``engine.json``,
``fleet_summary.json``, ``report.json``, ``report.md``, ``comparison.png``
and both nodes' logs. See docs/deploy.md.
"""
from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
from pathlib import Path
from typing import Any, Dict, List, Optional

import numpy as np
import yaml

from vmas_ros.adapters.pieces import lead_problem, margin_problem
from vmas_ros.ros.params import ACT_ON

#: scenario -> the shipped adapter that rebuilds its observation (vmas_ros.adapters.ADAPTER_NAMES)
ADAPTER_OF = {"simple_spread": "simple_spread", "navigation": "navigation", "diff_drive": "diff_drive",
              "goal": "goal"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--policy", required=True, help="exported policy (.json beside its .onnx)")
    parser.add_argument("--seeds", default="0..4", help="env seeds: '0..4' or '0,3,7' (default 0..4)")
    parser.add_argument("--episodes-per-seed", type=int, default=1, help="episodes (envs) per seed (default 1)")
    parser.add_argument("--seconds", type=float, default=15.0, help="length of every episode, s (default 15)")
    parser.add_argument("--drive", choices=("holonomic", "diff_drive"), default="holonomic",
                        help="the fleet's robots, and policy_node's base (default holonomic)")
    parser.add_argument("--twist", action="store_true",
                        help="commands as geometry_msgs/Twist (default: TwistStamped, as Jazzy's diff_drive_controller)")
    parser.add_argument("--cmd-vel-scale", default="auto",
                        help="policy_node's cmd_vel_scale; auto: the speed a held action settles at in the engine "
                             "(dt / (mass x drag) for force-driven agents, 1 for velocity commands)")
    parser.add_argument("--latency", type=float, default=0.05, help="fleet command latency, s (default 0.05)")
    parser.add_argument("--latency-sweep", default="", metavar="S,S,...",
                        help="run the fleet once per command latency (s, e.g. 0,0.05,0.1,0.15,0.2) instead of at "
                             "--latency, each in its own subfolder, and write sweep.md/.json/.png: where the fleet's "
                             "success falls below 90%% of the engine's")
    parser.add_argument("--lag", type=float, default=0.1, help="fleet velocity lag time constant, s (default 0.1)")
    parser.add_argument("--odom-noise", default="0.01,0.01,0.02",
                        help="fleet odometry noise sigmas: position m, yaw rad, velocity m/s (default 0.01,0.01,0.02)")
    parser.add_argument("--end-at-done", action="store_true",
                        help="end an episode with one goal per robot once every robot stands on its goal, in both "
                             "(robot_fleet's end_on_goals): coverage is taken there and later contacts do not count")
    parser.add_argument("--headings", choices=("auto", "engine", "random"), default="auto",
                        help="fleet start headings: engine's, or random; auto: engine's where the agents turn, "
                             "random where they never do (default auto)")
    parser.add_argument("--fleet-param", action="append", default=[], metavar="NAME:=VALUE",
                        help="another robot_fleet parameter (repeatable)")
    parser.add_argument("--act-on", choices=ACT_ON, default=None,
                        help="when policy_node acts: timer, at 1 / the engine's dt; scan, as soon as every robot's "
                             "new scan is in (policy_node's act_on; default timer)")
    parser.add_argument("--scan-margin", type=float, default=None, metavar="M",
                        help="the navigation adapter's scan_margin, m: every scan return read that much closer, so "
                             "the policy keeps that much more room (default 0; the reports state it)")
    parser.add_argument("--scan-lead", type=float, default=None, metavar="S",
                        help="the navigation adapter's scan_lead, s: each ray's return also read closer by what the "
                             "robot's odometry speed towards it covers in S seconds (default 0; the reports state it)")
    parser.add_argument("--policy-param", action="append", default=[], metavar="NAME:=VALUE",
                        help="another policy_node parameter (repeatable), e.g. lookahead:=0.2")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def parse_seeds(text: str) -> List[int]:
    """``'0..4'`` -> [0, 1, 2, 3, 4]; ``'0,3,7'`` -> [0, 3, 7]."""
    try:
        if ".." in text:
            first, last = (int(part) for part in text.split(".."))
            seeds = list(range(first, last + 1))
        else:
            seeds = [int(part) for part in text.split(",")]
    except ValueError:
        raise ValueError(f"--seeds must look like '0..4' or '0,3,7', got {text!r}") from None
    if not seeds or min(seeds) < 0:
        raise ValueError(f"--seeds must name at least one seed >= 0, got {text!r}")
    return seeds


def parse_params(items: List[str], option: str) -> Dict[str, Any]:
    """``['name:=value', ...]`` with YAML values."""
    found = {}
    for item in items:
        name, sep, value = item.partition(":=")
        if not sep or not name:
            raise ValueError(f"{option} must be NAME:=VALUE, got {item!r}")
        found[name] = yaml.safe_load(value)
    return found


def held_action_speed(scenario: str, kwargs: Dict[str, Any]) -> float:
    """m/s per action unit the scenario's first agent settles at when an action is held (see --cmd-vel-scale)."""
    from vmas_ros.envs.make_env import make_env
    from vmas_ros.simulator.dynamics.diff_drive import DiffDrive

    env = make_env(scenario, num_envs=1, **kwargs)
    agent, world = env.world.agents[0], env.world
    if isinstance(agent.dynamics, DiffDrive) or hasattr(agent, "controller"):
        return 1.0
    drag = world.drag if agent.drag is None else agent.drag
    multiplier = float(np.asarray(agent.action.u_multiplier_tensor.cpu()).ravel()[0])
    return multiplier * world.dt / (agent.mass * drag) if drag > 0 else 1.0


def fleet_starts(starts: List[dict], mode: str, rng: np.random.Generator) -> List[dict]:
    """The engine's starts with the fleet's headings (``--headings``)."""
    turning = any(abs(row[2]) > 1e-9 for start in starts for row in start["robots"])
    random = mode == "random" or (mode == "auto" and not turning)
    out = []
    for start in starts:
        robots = [list(row) for row in start["robots"]]
        if random:
            for row in robots:
                row[2] = float(rng.uniform(-math.pi, math.pi))
        out.append({"robots": robots, "goals": start["goals"]})
    return out


def act_on_of(option: Optional[str], extra: Dict[str, Any]) -> str:
    """policy_node's ``act_on`` from ``--act-on`` or ``--policy-param act_on:=...`` (default timer).

    Two different values are refused, so the report never names another mode than the one that ran.
    """
    given = extra.get("act_on")
    if given is not None and option is not None and given != option:
        raise ValueError(f"--act-on {option} and --policy-param act_on:={given} disagree; give one of them")
    return option or given or "timer"


def adapter_kwargs_of(extra: Dict[str, Any]) -> Dict[str, Any]:
    """``--policy-param adapter_kwargs:=...`` as a mapping (given as one, or as its YAML-flow text); {} without."""
    given = extra.get("adapter_kwargs")
    if isinstance(given, str):
        try:
            given = yaml.safe_load(given or "{}")
        except yaml.YAMLError as error:
            raise ValueError(f"--policy-param adapter_kwargs must be a YAML-flow mapping, got {given!r}: {error}") \
                from None
    if given is None:
        return {}
    if not isinstance(given, dict):
        raise ValueError(f"--policy-param adapter_kwargs must be a mapping like {{scan_yaw: 0.5}}, got {given!r}")
    return dict(given)


#: the navigation adapter's scan kwargs this command sets, with their options and how each is checked
SCAN_OPTIONS = {"scan_margin": ("--scan-margin", lambda value, name: margin_problem(value, name=name)),
                "scan_lead": ("--scan-lead", lead_problem)}


def scan_kwargs_of(args: argparse.Namespace) -> Dict[str, float]:
    """``--scan-margin`` and ``--scan-lead`` as the adapter kwargs they set, the options not given left out."""
    found = {"scan_margin": args.scan_margin, "scan_lead": args.scan_lead}
    return {name: value for name, value in found.items() if value is not None}


def adapter_kwargs_with_scan(scan: Dict[str, float], extra: Dict[str, Any]) -> Dict[str, Any]:
    """The adapter kwargs of the fleet run: ``--policy-param adapter_kwargs`` with ``scan`` in them.

    ``scan``: ``scan_margin`` and/or ``scan_lead`` from their options. A value
    that is negative or not finite is refused naming its option; so is one
    that disagrees with the same kwarg in ``adapter_kwargs``, so the report
    never names another one than ran.
    """
    kwargs = adapter_kwargs_of(extra)
    for name, value in scan.items():
        option, problem_of = SCAN_OPTIONS[name]
        problem = problem_of(value, option)
        if problem:
            raise ValueError(problem)
        given = kwargs.get(name)
        if given is not None and given != value:
            raise ValueError(f"{option} {value:g} and --policy-param adapter_kwargs' {name} {given!r} "
                             f"disagree; give one of them")
        kwargs[name] = value
    return kwargs


def policy_node_params(policy_path: str, adapter: str, twist: bool, drive: str, scale: float, dt: float,
                       act_on: str, extra: Dict[str, Any], scan: Optional[Dict[str, float]] = None) -> Dict[str, Any]:
    """policy_node's parameters for the fleet run: body-frame cmd_vel through ``adapter`` at the engine's
    rate (1 / ``dt``), acting on ``act_on``, then ``extra`` (``--policy-param``); ``scan``
    (``--scan-margin``, ``--scan-lead``) goes into ``adapter_kwargs``."""
    params = {"policy_path": str(Path(policy_path).resolve()), "adapter": adapter, "output": "cmd_vel",
              "use_stamped_cmd_vel": not twist, "base": drive, "cmd_vel_scale": scale, "rate_hz": 1.0 / dt,
              **extra, "act_on": act_on}
    kwargs = adapter_kwargs_with_scan(scan or {}, extra)
    if kwargs or "adapter_kwargs" in extra:
        params["adapter_kwargs"] = kwargs
    return params


def fleet_adapter(spec: str, kwargs: Dict[str, Any], policy) -> Any:
    """The adapter policy_node will build for ``policy``, built here first: its refusals (a margin beyond the
    lidar's range, a kwarg it does not take) come before anything runs, and it says which margin and lead run."""
    from vmas_ros.adapters import load_adapter
    from vmas_ros.simulator.env_snapshot import unique_names

    return load_adapter(spec, unique_names(policy.agents), policy.observation_size, kwargs,
                        policy.metadata.get("scenario_kwargs") or {})


def _own_arguments() -> List[str]:
    """This command's arguments as typed (after ``deploy-eval``), for the report's heading."""
    argv = sys.argv[1:]
    return argv[argv.index("deploy-eval") + 1:] if "deploy-eval" in argv else argv


def run(args: argparse.Namespace) -> int:
    try:
        return _run(args)
    except (ValueError, RuntimeError) as error:
        print(f"vmas-ros deploy-eval: {error}", file=sys.stderr)
        return 2 if isinstance(error, ValueError) else 1


def _run(args: argparse.Namespace) -> int:
    from vmas_ros.deploy import engine_side, fleet_side, report, sweep
    from vmas_ros.policy.onnx_policy import OnnxPolicy

    seeds = parse_seeds(args.seeds)
    fleet_extra, policy_extra = parse_params(args.fleet_param, "--fleet-param"), parse_params(args.policy_param,
                                                                                               "--policy-param")
    act_on = act_on_of(args.act_on, policy_extra)
    noise = [float(v) for v in args.odom_noise.split(",")]
    if len(noise) != 3 or min(noise) < 0:
        raise ValueError(f"--odom-noise must be three sigmas >= 0 (position, yaw, velocity), got {args.odom_noise!r}")
    latencies = sweep.parse_latencies(args.latency_sweep) if args.latency_sweep else []
    if args.episodes_per_seed < 1 or args.seconds <= 0:
        raise ValueError(f"--episodes-per-seed must be >= 1 and --seconds > 0, got {args.episodes_per_seed} and "
                         f"{args.seconds}")
    try:
        policy = OnnxPolicy.load(args.policy)
    except Exception as error:  # the loader's errors (JSON, checksum, ONNX) all mean "unusable"
        raise ValueError(f"--policy {args.policy!r} cannot be loaded: {error}") from None
    scenario, kwargs = policy.metadata["scenario"], dict(policy.metadata["scenario_kwargs"])
    adapter = ADAPTER_OF.get(scenario)
    if adapter is None and "adapter" not in policy_extra:
        raise ValueError(f"no shipped adapter for scenario {scenario!r} (shipped: {', '.join(ADAPTER_OF)}); "
                         f"give one with --policy-param adapter:=package.module:Class")
    scan = scan_kwargs_of(args)
    if scan and ADAPTER_OF.get(scenario) != "navigation" and "adapter" not in policy_extra:
        name = next(iter(scan))
        raise ValueError(f"{SCAN_OPTIONS[name][0]} is the navigation adapter's {name}; scenario {scenario!r} runs "
                         f"adapter {adapter!r}, which reads no scans")
    scale = held_action_speed(scenario, kwargs) if args.cmd_vel_scale == "auto" else float(args.cmd_vel_scale)
    adapter_spec = policy_extra.get("adapter", adapter or "")
    built = fleet_adapter(adapter_spec, adapter_kwargs_with_scan(scan, policy_extra), policy)
    # what runs (None: an adapter without them), for the reports
    scan_run = {name: getattr(built, name, None) for name in SCAN_OPTIONS}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    engine = {"episodes": [], "starts": []}
    labels = []
    for seed in seeds:
        part = engine_side.engine_episodes(policy, scenario, kwargs, args.episodes_per_seed, seed, args.seconds,
                                           end_at_done=args.end_at_done)
        engine.update({k: v for k, v in part.items() if k not in ("episodes", "starts")})
        engine["episodes"] += part["episodes"]
        engine["starts"] += part["starts"]
        labels += [f"seed {seed} env {e['env_index']}" for e in part["episodes"]]
    (out / "engine.json").write_text(json.dumps(engine, indent=1))

    fleet_params = {"n_robots": len(policy.agents), "robot_names": ",".join(policy.agents),
                    "robot_radius": engine["radius"], "goal_radius": engine["goal_radius"], "drive": args.drive,
                    "use_stamped_cmd_vel": not args.twist, "command_latency": args.latency,
                    "velocity_lag": args.lag, "odom_noise_position": noise[0], "odom_noise_yaw": noise[1],
                    "odom_noise_velocity": noise[2], "end_on_goals": args.end_at_done, "seed": seeds[0],
                    **fleet_extra}
    policy_params = policy_node_params(args.policy, adapter or "", args.twist, args.drive, scale, engine["dt"],
                                       act_on, policy_extra, scan)
    starts = fleet_starts(engine["starts"], args.headings, np.random.default_rng(seeds[0]))
    command = "vmas-ros deploy-eval " + " ".join(shlex.quote(a) for a in _own_arguments())
    margin_note = report.scan_note(scan_run)

    def fleet_report(folder: Path, latency: float) -> Dict[str, Any]:
        """The fleet's run at ``latency`` into ``folder``, its report written there; returns the totals."""
        summary = fleet_side.fleet_episodes(folder, starts, args.seconds, {**fleet_params, "command_latency": latency},
                                            policy_params, progress=not args.quiet)
        rows = report.pair_episodes(engine, summary, labels)
        found = report.totals(rows, engine["per_robot_goals"])
        heading = {"policy": args.policy, "scenario": scenario, "scenario_kwargs": json.dumps(kwargs),
                   "command": command, "fleet": summary["parameters"], "act_on": act_on, **scan_run,
                   "policy_node": ", ".join(f"{k} {v}" for k, v in policy_params.items()
                                          if k not in ("policy_path", "act_on"))}
        (folder / "report.json").write_text(json.dumps({"heading": heading, "rows": rows, "totals": found}, indent=1))
        text = report.markdown(rows, found, engine["per_robot_goals"], heading)
        (folder / "report.md").write_text(text)
        report.plot(rows, engine["per_robot_goals"], folder / "comparison.png",
                    f"{scenario}: engine vs robot_fleet ({args.drive}, latency {latency} s, lag {args.lag} s, "
                    f"policy_node on {act_on}{margin_note})")
        print(text)
        return found

    if not latencies:
        fleet_report(out, args.latency)
        return 0
    text = sweep.run_sweep(out, latencies, fleet_report, policy=args.policy, command=command,
                           per_robot_goals=engine["per_robot_goals"], act_on=act_on, scan=scan_run)
    print(text)
    return 0
