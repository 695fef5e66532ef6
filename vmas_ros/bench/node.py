"""``vmas-ros bench node``: how many steps per second sim_node sustains while it publishes.

The node runs in this process, unpaced (``real_time_factor: 0``), spun by an
ordinary rclpy executor exactly as ``sim_node`` spins itself, so the figure
includes the executor's own overhead per timer callback. A separate subscriber
process (``python -m vmas_ros.bench.node --subscriber``) subscribes to the
published topics and counts what arrives, so DDS really delivers every message
across processes (with no subscriber a publisher does much less work).

A run builds the node once, waits until the subscriber is matched on every
topic, spins it for ``--warmup`` untimed windows and then ``--repeats`` timed
windows of ``--duration`` seconds each; steps/s is the median over the windows.
Each window is followed by a profiled one of the same length, in which the
node's ``StepPhases`` splits each step into actions, engine (``env.step``),
lidar, conversion (snapshot + message fill) and publish, the rest of the wall
time being the executor: its timers slow the node down, so steps/s comes
from the plain windows (the node as users run it) and the parts from the
profiled ones (``profiled_steps_per_s`` says what the timed node managed).
When the compiled step gathers the published env itself (small batches with
``compile_physics``), the lidar casts run inside the engine part and the
lidar part only takes their result: compare engine + lidar across modes.
Results go to ``node_benchmark.{csv,json,md}``.
Benchmarks measure; tests never assert on these numbers.
"""
from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Dict, List, Optional

NODE_COLUMNS = [
    "run_id", "scenario", "scenario_kwargs", "lidar_rays", "num_envs", "compiled", "compile_physics", "compile_s",
    "unpaced_batch_ms", "window",
    "duration_s", "steps",
    "steps_per_s", "wall_us", "actions_us", "engine_us", "lidar_us", "convert_us", "publish_us", "executor_us",
    "profiled_steps_per_s", "cpu_us", "threads", "loadavg_1m",
]
#: seconds the subscriber waits for messages in flight before it counts from zero (see _subscriber_main)
MARK_SETTLE_S = 0.3
#: topic kinds the subscriber can take: the target's four, and everything else sim_node publishes by default
CORE_KINDS = ("pose", "odom", "scan", "clock")
ALL_KINDS = CORE_KINDS + ("arrays", "markers", "observation", "reward", "points")
#: what a swarm's viewer takes (per-agent topics off): every pose in one array, every lidar hit in one cloud
SWARM_KINDS = ("arrays", "points")


def add_node_bench_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Options of ``vmas-ros bench node`` (``--repeats``, ``--warmup``, ``--threads``, ``--out``,
    ``--no-progress`` are the shared bench options)."""
    node = parser.add_argument_group("node options (vmas-ros bench node)")
    node.add_argument("--scenario", default="simple_spread", help="node: scenario (default simple_spread)")
    node.add_argument("--scenario-kwargs", default='{"n_agents": 4}',
                      help='node: scenario_kwargs as JSON (default \'{"n_agents": 4}\')')
    node.add_argument("--lidar-rays", type=int, default=12, help="node: rays of each agent's lidar (default 12; 0: no lidar)")
    node.add_argument("--node-num-envs", type=int, default=1, help="node: num_envs of the node (default 1)")
    node.add_argument("--duration", type=float, default=3.0, help="node: seconds per timed window (default 3)")
    node.add_argument("--subscribe", choices=("core", "all", "swarm", "none"), default="core",
                      help="node: topics the subscriber process takes: core = pose, odom, scan, /clock (default); "
                           "all = also pose arrays, markers, observations, rewards, the lidar point cloud; "
                           "swarm = agents/poses and lidar/points only; none = no subscriber")
    node.add_argument("--unpaced-batch-ms", type=float, default=None,
                      help="node: the node's unpaced_batch_ms, wall ms of steps per executor round (default: the "
                           "node's, 4)")
    node.add_argument("--node-compile", choices=("auto", "true", "false"), default=None,
                      help="node: the node's compile_physics (default: the node's, auto: compiled in the background, "
                           "timed once it is in use); --compile-physics means true")
    node.add_argument("--raw-subscriber", action="store_true",
                      help="node: the subscriber takes the serialised bytes without deserialising them")
    return parser


# ------------------------------------------------------------------ subscriber
def _subscriber_main(argv: List[str]) -> int:
    """The subscriber process: ``topic=pkg/msg/Name`` arguments; prints ``ready``, restarts its counts
    at each ``mark`` line on stdin (answering ``marked``), counts until another line, then prints the
    counts as one JSON line."""
    import importlib

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    rclpy.init()
    node = rclpy.create_node(f"bench_node_subscriber_{os.getpid()}")
    counts: Dict[str, int] = {}
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    raw = bool(argv) and argv[0] == "--raw"
    for spec in argv[1:] if raw else argv:
        topic, kind = spec.split("=")
        package, _, name = kind.split("/")
        msg_type = getattr(importlib.import_module(f"{package}.msg"), name)
        counts[topic] = 0

        def on_message(_msg, topic=topic):
            counts[topic] += 1

        # by default the messages are deserialised, as a real consumer does; --raw only takes the bytes
        node.create_subscription(msg_type, topic, on_message, qos, raw=raw)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    stop = threading.Event()

    def commands() -> None:
        # "mark": the publisher stopped stepping; once what it sent has arrived, count from zero
        while sys.stdin.readline().strip() == "mark":
            time.sleep(MARK_SETTLE_S)
            for topic in counts:
                counts[topic] = 0
            print("marked", flush=True)
        stop.set()

    threading.Thread(target=commands, daemon=True).start()
    print("ready", flush=True)
    while not stop.is_set():
        executor.spin_once(timeout_sec=0.05)
    print(json.dumps(counts), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def _topics(node, kinds) -> Dict[str, str]:
    """topic -> type name of the node's publishers in the chosen kinds."""
    wanted = {}
    messages = node.state_messages
    resolved = node.state_pub.topic_names
    for topic, kind in zip(resolved, messages.types):
        leaf = topic.rsplit("/", 1)[-1]
        group = ("clock" if topic == "/clock" else "scan" if leaf.startswith("scan") else
                 "arrays" if leaf == "poses" else "markers" if leaf == "markers" else
                 "points" if topic.endswith("lidar/points") else leaf)
        if group in kinds:
            wanted[topic] = kind
    if "observation" in kinds or "reward" in kinds:
        for pub in node.agent_topics.obs_pubs if "observation" in kinds else []:
            wanted[pub.topic_name] = "std_msgs/msg/Float32MultiArray"
        for pub in node.agent_topics.reward_pubs if "reward" in kinds else []:
            wanted[pub.topic_name] = "std_msgs/msg/Float32"
    return wanted


# ------------------------------------------------------------------- the run
def run_node_benchmark(scenario: str = "simple_spread", scenario_kwargs: str = '{"n_agents": 4}', lidar_rays: int = 12, num_envs: int = 1,
                       duration: float = 3.0, repeats: int = 3, warmup: int = 1, subscribe: str = "core",
                       raw_subscriber: bool = False, progress: bool = True, compile_physics: str = "auto",
                       unpaced_batch_ms: Optional[float] = None, compile_timeout: float = 600.0) -> dict:
    """Measure the node; returns ``{"rows": [...per window...], "summary": {...}}``.

    ``compile_physics``: the node's ``compile_physics`` parameter. ``true``: the first step compiles,
    inside the warm-up window (so ``warmup`` must be at least 1); ``auto`` (the node's default): the
    node compiles in the background, and the warm-up lasts until the compiled step is in use (at most
    ``compile_timeout`` seconds), so that the timed windows measure what a node runs from then on.
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from tqdm import tqdm

    from vmas_ros.ros.publish import StepPhases
    from vmas_ros.ros.sim_node import SimNode

    if duration <= 0 or repeats < 1 or warmup < 0 or lidar_rays < 0 or num_envs < 1:
        raise ValueError("duration must be > 0, repeats >= 1, warmup >= 0, lidar_rays >= 0, num_envs >= 1")
    if compile_physics not in ("auto", "true", "false"):
        raise ValueError(f"compile_physics must be auto, true or false, got {compile_physics!r}")
    if compile_physics == "true" and warmup < 1:
        raise ValueError(f"--compile-physics needs --warmup >= 1 (the first step compiles), got {warmup}")
    run_id = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    subscriber: Optional[subprocess.Popen] = None
    node = None
    rows: List[dict] = []
    try:
        extra = {} if unpaced_batch_ms is None else {"unpaced_batch_ms": float(unpaced_batch_ms)}
        node = SimNode(scenario=scenario, scenario_kwargs=scenario_kwargs, num_envs=num_envs, real_time_factor=0.0,
                       add_lidar=lidar_rays > 0, lidar_rays=max(1, lidar_rays), compile_physics=compile_physics, **extra)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        kinds = {"core": CORE_KINDS, "all": ALL_KINDS, "swarm": SWARM_KINDS, "none": ()}[subscribe]
        topics = _topics(node, kinds)
        if topics:
            subscriber = subprocess.Popen(
                [sys.executable, "-m", "vmas_ros.bench.node", "--subscriber", *(["--raw"] if raw_subscriber else []),
                 *[f"{t}={k}" for t, k in topics.items()]],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=dict(os.environ))
            if subscriber.stdout.readline().strip() != "ready":
                raise RuntimeError("the subscriber process did not start")
            _wait_matched(node, executor, topics)
            # messages the node sent while the subscriber matched topic by topic are not counted:
            # the node does not spin until the subscriber has received them and starts from zero
            subscriber.stdin.write("mark\n")
            subscriber.stdin.flush()
            if subscriber.stdout.readline().strip() != "marked":
                raise RuntimeError("the subscriber process did not start counting")
        published_before = node.steps
        total = warmup + repeats
        with tqdm(total=total, disable=not progress, desc="bench node", unit="window", file=sys.stderr,
                  dynamic_ncols=True) as bar:
            for window in range(total):
                if window == warmup:
                    _wait_compiled(node, executor, compile_timeout)
                # steps/s as users run the node (no timers in the step), then the same time with StepPhases
                steps, wall, cpu = _spin_window(node, executor, duration)
                node.phases = phases = StepPhases()
                profiled = _spin_window(node, executor, duration)
                node.phases = None
                row = _row(run_id, scenario, scenario_kwargs, lidar_rays, num_envs, window - warmup, duration, steps, wall,
                           cpu, phases, profiled)
                row["compiled"] = node.env.world.physics_compiled
                row["compile_physics"] = compile_physics
                compiler = node.env.world.background_compiler
                row["compile_s"] = None if compiler is None else compiler.first_ready_s
                row["unpaced_batch_ms"] = node.params.unpaced_batch_ms
                bar.set_postfix_str(f"{row['steps_per_s']:.0f} steps/s" + (" (warm-up)" if window < warmup else ""))
                bar.update(1)
                if window >= warmup:
                    rows.append(row)
        published = {t: node.steps - published_before for t in topics}
        received = _stop_subscriber(subscriber) if subscriber is not None else {}
        subscriber = None
    finally:
        if subscriber is not None:
            subscriber.kill()
            subscriber.wait(10)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return {"rows": rows, "summary": _summary(rows, topics, published, received, subscribe)}


def _spin_window(node, executor, duration: float) -> tuple:
    """Spin the node for ``duration`` s: (steps, wall s, CPU s of this thread)."""
    steps0, start, cpu0 = node.steps, time.perf_counter(), time.thread_time()
    end = start + duration
    while time.perf_counter() < end:
        executor.spin_once(timeout_sec=0.1)
    return node.steps - steps0, time.perf_counter() - start, time.thread_time() - cpu0


def _wait_compiled(node, executor, timeout: float) -> None:
    """Spin the node (untimed) until its background compile, if any, is done: the timed windows
    measure the compiled step in use, not the eager steps before it."""
    compiler = node.env.world.background_compiler
    end = time.perf_counter() + timeout
    while compiler is not None and not (compiler.started and compiler.idle):
        if time.perf_counter() > end:
            raise RuntimeError(f"the node's background compile took more than {timeout:.0f} s")
        executor.spin_once(timeout_sec=0.05)


def _wait_matched(node, executor, topics: Dict[str, str], timeout: float = 20.0) -> None:
    """Spin (unpaced steps count as warm-up) until the subscriber is matched on every topic."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if all(node.count_subscribers(t) > 0 for t in topics):
            return
        executor.spin_once(timeout_sec=0.05)
    raise RuntimeError(f"the subscriber process was not matched on {sorted(topics)} within {timeout} s")


def _stop_subscriber(subscriber: subprocess.Popen) -> Dict[str, int]:
    time.sleep(0.5)  # the last messages in flight
    out, _ = subscriber.communicate("stop\n", timeout=30)
    lines = [line for line in out.splitlines() if line.startswith("{")]
    return json.loads(lines[-1]) if lines else {}


def _row(run_id, scenario, scenario_kwargs, lidar_rays, num_envs, window, duration, steps, wall, cpu, phases,
         profiled: tuple) -> dict:
    """One window: steps/s, wall and CPU per step of the plain run; the parts of a step from the profiled
    run that followed it (``profiled``: its steps, wall and CPU seconds; ``phases`` its StepPhases)."""
    import torch

    profiled_steps, profiled_wall, _ = profiled
    per = phases.per_step_us(profiled_steps)
    profiled_wall_us = 1e6 * profiled_wall / max(1, profiled_steps)
    return {
        "run_id": run_id, "scenario": scenario, "scenario_kwargs": scenario_kwargs, "lidar_rays": lidar_rays, "num_envs": num_envs,
        "window": window, "duration_s": wall, "steps": steps, "steps_per_s": steps / wall, "wall_us": 1e6 * wall / max(1, steps),
        **{f"{name}_us": per[name] for name in phases.NAMES},
        "executor_us": profiled_wall_us - sum(per.values()), "profiled_steps_per_s": profiled_steps / profiled_wall,
        "cpu_us": 1e6 * cpu / max(1, steps), "threads": torch.get_num_threads(),
        "loadavg_1m": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
    }


def _summary(rows, topics, published, received, subscribe) -> dict:
    median = {key: statistics.median(r[key] for r in rows) for key in
              ("steps_per_s", "wall_us", "actions_us", "engine_us", "lidar_us", "convert_us", "publish_us", "executor_us",
               "profiled_steps_per_s", "cpu_us")}
    return {
        "median": median, "subscribe": subscribe, "topics": topics,
        "messages_published": sum(published.values()), "messages_received": sum(received.values()),
        "received_by_topic": received, "published_by_topic": published,
    }


def format_node_table(result: dict) -> str:
    m, s = result["summary"]["median"], result["summary"]
    lines = ["| steps/s | wall us/step | CPU us/step | profiled steps/s | engine | lidar | convert | publish | actions "
             "| executor |",
             "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
             f"| {m['steps_per_s']:.0f} | {m['wall_us']:.0f} | {m['cpu_us']:.0f} | {m['profiled_steps_per_s']:.0f} | "
             f"{m['engine_us']:.0f} | {m['lidar_us']:.0f} | {m['convert_us']:.0f} | {m['publish_us']:.0f} | "
             f"{m['actions_us']:.0f} | {m['executor_us']:.0f} |",
             "(us per step of each part: from the profiled windows)",
             "", f"subscriber ({s['subscribe']}): received {s['messages_received']} of {s['messages_published']} "
                 f"messages published on {len(s['topics'])} topics during the run"]
    return "\n".join(lines)


def write_node_results(result: dict, out_dir) -> Dict[str, Path]:
    from vmas_ros.bench.report import machine_info, write_csv

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"csv": out / "node_benchmark.csv", "json": out / "node_benchmark.json", "md": out / "node_benchmark.md"}
    write_csv(paths["csv"], result["rows"], NODE_COLUMNS)
    info = machine_info([dict(r, device="cpu") for r in result["rows"]])
    paths["json"].write_text(json.dumps({"machine": info, **result}, indent=2, default=str), encoding="utf-8")
    paths["md"].write_text(format_node_table(result) + "\n", encoding="utf-8")
    return paths


def _compile_option(args: argparse.Namespace) -> str:
    """The node's compile_physics from ``--node-compile`` and the shared ``--compile-physics`` (= true)."""
    chosen = getattr(args, "node_compile", None)
    if getattr(args, "compile_physics", False):
        if chosen not in (None, "true"):
            raise ValueError(f"--compile-physics means --node-compile true, but --node-compile {chosen} was given too")
        return "true"
    return chosen or "auto"


def run_node_bench_command(args: argparse.Namespace) -> int:
    """``vmas-ros bench node``: 0 on success, 2 on bad options."""
    try:
        compile_physics = _compile_option(args)
    except ValueError as error:
        print(f"vmas-ros bench node: {error}", file=sys.stderr)
        return 2
    options = dict(scenario=getattr(args, "scenario", "simple_spread"), scenario_kwargs=getattr(args, "scenario_kwargs", '{"n_agents": 4}'),
                   lidar_rays=getattr(args, "lidar_rays", 12), num_envs=getattr(args, "node_num_envs", 1),
                   duration=getattr(args, "duration", 3.0), repeats=getattr(args, "repeats", 3),
                   warmup=getattr(args, "warmup", 1), subscribe=getattr(args, "subscribe", "core"),
                   raw_subscriber=bool(getattr(args, "raw_subscriber", False)),
                   compile_physics=compile_physics,
                   unpaced_batch_ms=getattr(args, "unpaced_batch_ms", None))
    from vmas_ros.bench.timing import pinned_threads

    try:
        with pinned_threads(getattr(args, "threads", None)):
            result = run_node_benchmark(progress=not getattr(args, "no_progress", False), **options)
    except ValueError as error:
        print(f"vmas-ros bench node: {error}", file=sys.stderr)
        return 2
    paths = write_node_results(result, getattr(args, "out", "bench_results"))
    print(format_node_table(result))
    print()
    for path in paths.values():
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["--subscriber"]:
        sys.exit(_subscriber_main(sys.argv[2:]))
    parser = add_node_bench_arguments(argparse.ArgumentParser(prog="python -m vmas_ros.bench.node"))
    for flag, default in (("--repeats", 3), ("--warmup", 1)):
        parser.add_argument(flag, type=int, default=default)
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--out", default="bench_results")
    parser.add_argument("--no-progress", action="store_true")
    sys.exit(run_node_bench_command(parser.parse_args()))
