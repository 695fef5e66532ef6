"""``vmas-ros soak node``: sim_node as a real process, recording, watched by Foxglove, driven by commands.

What a deployment looks like for hours, in one command: sim_node runs as its
own process with a bag being recorded and the Foxglove server on; this process
connects a Foxglove WebSocket client (which subscribes to channels and
teleoperates ``agent_1``) and a ROS publisher that sends ``agent_0`` Twists at
a fixed rate, and follows ``/clock``. It samples the node's RSS and the bag's
size, and at the end stops the node with SIGINT and reads the bag back.

Why each figure:
- *missed steps*: the node is paced (real time, or ``rate_hz``); steps taken
  over the measured window, from the sim time on ``/clock``, against wall time
  times the rate. A node that falls behind loses steps for good.
- *dropped commands*: every command the node receives is recorded in the bag,
  so sent minus recorded is what was lost on the way (DDS best effort, a full
  queue, the Foxglove thread).
- *memory growth*: RSS of the node process after warm-up (the bag's first
  chunks, DDS discovery and the Foxglove client's buffers grow early on).
"""
from __future__ import annotations

import argparse
import asyncio
import json
import signal
import socket
import statistics
import struct
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional

from vmas_ros.bench.soak_memory import MB, MemorySample, growth_mb, rss_bytes, slope_per_hour, write_outputs

__all__ = ["NodeSoakResult", "add_node_arguments", "read_bag_counts", "run_node_command", "run_node_soak"]

FOXGLOVE_SUBPROTOCOL = "foxglove.sdk.v1"
STARTUP_TIMEOUT_S = 60.0


@dataclass
class NodeSoakResult:
    """What a node soak measured, and its verdict (``ok``)."""

    scenario: str
    duration_s: float
    rate_hz: float
    window_s: float
    steps_taken: int
    steps_expected: int
    missed_steps: int
    max_clock_gap_s: float
    real_time_factor: float
    commands_sent: int
    commands_recorded: int
    dropped_commands: int
    foxglove_commands_sent: int
    foxglove_commands_recorded: int
    foxglove_messages_received: int
    rss_after_warmup_mb: float
    rss_end_mb: float
    rss_growth_mb: float
    rss_slope_mb_per_h: float
    max_growth_mb: float
    bag_path: str
    bag_mb: float
    bag_readable: bool
    bag_messages: int
    bag_clock_messages: int
    node_exit_code: Optional[int]
    ok: bool
    failures: List[str] = field(default_factory=list)
    samples: List[MemorySample] = field(default_factory=list)


# ------------------------------------------------------------------ Foxglove client
class FoxgloveProbe:
    """A foxglove.sdk.v1 WebSocket client on its own thread: subscribes to channels, counts
    message data, and publishes ``agent_1`` Twists at ``rate_hz`` (JSON, client-publish)."""

    def __init__(self, port: int, topics: List[str], twist_topic: str, rate_hz: float) -> None:
        self.url = f"ws://127.0.0.1:{port}"
        self.topics, self.twist_topic, self.rate_hz = topics, twist_topic, rate_hz
        self.received = 0
        self.sent = 0
        self.connected = threading.Event()
        self.error: Optional[str] = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=lambda: asyncio.run(self._main()), daemon=True, name="foxglove-probe")

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=10)

    async def _main(self) -> None:
        import websockets

        try:
            async with websockets.connect(self.url, subprotocols=[FOXGLOVE_SUBPROTOCOL], max_size=None) as ws:
                channels: Dict[str, int] = {}
                reader = asyncio.create_task(self._read(ws, channels))
                deadline = time.monotonic() + 20
                while not all(t in channels for t in self.topics) and time.monotonic() < deadline:
                    await asyncio.sleep(0.05)
                subs = [{"id": i + 1, "channelId": channels[t]} for i, t in enumerate(self.topics) if t in channels]
                await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                await ws.send(json.dumps({"op": "advertise", "channels": [
                    {"id": 1, "topic": self.twist_topic, "encoding": "json", "schemaName": "geometry_msgs/msg/Twist"}]}))
                self.connected.set()
                period = 1.0 / self.rate_hz if self.rate_hz > 0 else None
                while not self._stop.is_set():
                    if period is not None:
                        payload = json.dumps({"linear": {"x": 0.0, "y": 0.2, "z": 0.0},
                                              "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}).encode()
                        await ws.send(b"\x01" + struct.pack("<I", 1) + payload)
                        self.sent += 1
                    await asyncio.sleep(period or 0.2)
                reader.cancel()
        except Exception as error:  # noqa: BLE001 - reported in the result, the soak then fails
            self.error = f"{type(error).__name__}: {error}"
            self.connected.set()

    async def _read(self, ws, channels: Dict[str, int]) -> None:
        async for message in ws:
            if isinstance(message, str):
                msg = json.loads(message)
                if msg.get("op") == "advertise":
                    for channel in msg["channels"]:
                        channels[channel["topic"]] = channel["id"]
            elif message and message[0] == 1:  # MessageData
                self.received += 1


# --------------------------------------------------------------------------- bag
def read_bag_counts(path: Path) -> Dict[str, int]:
    """Messages per topic, read back with ``rosbags`` (an independent reader); raises if unreadable."""
    from rosbags.highlevel import AnyReader

    counts: Dict[str, int] = {}
    with AnyReader([path]) as reader:
        for connection, _, _ in reader.messages():
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
    return counts


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# --------------------------------------------------------------------------- run
def run_node_soak(
    duration_s: float = 3600.0, scenario: str = "simple_spread", num_envs: int = 1, rate_hz: float = 0.0,
    real_time_factor: float = 1.0, cmd_rate_hz: float = 20.0, foxglove_rate_hz: float = 5.0,
    sample_every_s: float = 10.0, warmup_s: Optional[float] = None, max_growth_mb: float = 32.0,
    max_missed_fraction: float = 0.01, max_dropped_fraction: float = 0.01, out_dir: str = "soak_results",
    progress: bool = True, extra_params: Optional[List[str]] = None,
) -> NodeSoakResult:
    """Run sim_node for ``duration_s`` with recording, a Foxglove client and commands, and judge it.

    The node's rate is ``rate_hz`` or, when 0, ``real_time_factor / dt``; the
    measured window starts after the warm-up (default 10% of the duration, at
    least one sample interval) so start-up (imports, DDS discovery) is not
    counted as missed steps.
    """
    import rclpy
    from geometry_msgs.msg import Twist
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock

    warmup = max(sample_every_s, duration_s * 0.1) if warmup_s is None else warmup_s
    if duration_s <= warmup:
        raise ValueError(f"--duration ({duration_s} s) must be longer than the warm-up ({warmup} s)")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    bag = out / "soak_node.mcap"
    if bag.exists():
        bag.unlink()
    port = _free_port()
    params = {"scenario": scenario, "num_envs": num_envs, "rate_hz": rate_hz, "real_time_factor": real_time_factor,
              "record_path": str(bag), "foxglove_port": port, "control": "zero"}
    cmd = [sys.executable, "-m", "vmas_ros.ros.sim_node", "--ros-args"]
    for name, value in params.items():
        cmd += ["-p", f"{name}:={value}"]
    for item in extra_params or []:
        cmd += ["-p", item]
    log = (out / "soak_node.log").open("w")
    node_proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
    context = rclpy.Context()
    rclpy.init(context=context)
    driver = rclpy.create_node("soak_driver", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(driver)
    clocks: List[tuple] = []  # (wall monotonic, sim ns)
    driver.create_subscription(Clock, "/clock", lambda m: clocks.append(
        (time.monotonic(), m.clock.sec * 1_000_000_000 + m.clock.nanosec)), QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    publisher = driver.create_publisher(Twist, "/agent_0/cmd_vel", QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    probe = FoxgloveProbe(port, ["/agent_0/pose", "/scene"], "/agent_1/cmd_vel", foxglove_rate_hz)
    samples: List[MemorySample] = []
    sent = 0
    failures: List[str] = []
    exit_code: Optional[int] = None
    try:
        deadline = time.monotonic() + STARTUP_TIMEOUT_S
        while (not clocks or publisher.get_subscription_count() == 0) and time.monotonic() < deadline:
            if node_proc.poll() is not None:
                raise RuntimeError(f"sim_node exited with code {node_proc.returncode} at start; see {out / 'soak_node.log'}")
            executor.spin_once(timeout_sec=0.1)
        if not clocks:
            raise RuntimeError(f"no /clock from sim_node within {STARTUP_TIMEOUT_S} s; see {out / 'soak_node.log'}")
        probe.start()
        probe.connected.wait(30)
        start = time.monotonic()
        next_cmd, next_sample, window_start = start, start, None
        bar = _bar(duration_s, progress)
        twist = Twist()
        twist.linear.x = 0.3
        while (now := time.monotonic()) < start + duration_s:
            if node_proc.poll() is not None:
                failures.append(f"sim_node died during the soak (exit code {node_proc.returncode})")
                break
            if cmd_rate_hz > 0 and now >= next_cmd:
                twist.angular.z = 0.5 if (sent // 50) % 2 else -0.5  # changing commands, not one repeated value
                publisher.publish(twist)
                sent += 1
                next_cmd += 1.0 / cmd_rate_hz
            if now >= next_sample:
                sim_steps = len(clocks)
                samples.append(MemorySample(sim_steps, now - start, rss_bytes(node_proc.pid) / MB,
                                            (bag.stat().st_size if bag.exists() else 0) / MB, True,
                                            _recent_rate(clocks)))
                next_sample += sample_every_s
                if window_start is None and now - start >= warmup:
                    window_start = len(clocks)
                if bar is not None:
                    bar.n = min(duration_s, now - start)
                    bar.refresh()
            wait = min(next_cmd if cmd_rate_hz > 0 else next_sample, next_sample) - time.monotonic()
            executor.spin_once(timeout_sec=max(0.0, min(wait, 0.05)))
        if bar is not None:
            bar.close()
        window_end = len(clocks)
        probe.stop()
        settle = time.monotonic() + 1.0  # commands in flight reach the node before it stops
        while time.monotonic() < settle:
            executor.spin_once(timeout_sec=0.05)
    finally:
        if node_proc.poll() is None:
            node_proc.send_signal(signal.SIGINT)
            try:
                exit_code = node_proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                node_proc.kill()
                exit_code = node_proc.wait()
                failures.append("sim_node did not stop within 30 s of SIGINT")
        else:
            exit_code = node_proc.returncode
        log.close()
        executor.shutdown()
        driver.destroy_node()
        rclpy.shutdown(context=context)
    return _node_verdict(
        scenario, duration_s, rate_hz, real_time_factor, clocks, window_start or 0, window_end, sent, probe, samples,
        warmup, bag, exit_code, failures, max_growth_mb, max_missed_fraction, max_dropped_fraction)


def _recent_rate(clocks: List[tuple], n: int = 50) -> float:
    """Steps per wall second over the last ``n`` clock messages."""
    if len(clocks) < 2:
        return 0.0
    (t0, _), (t1, _) = clocks[max(0, len(clocks) - n)], clocks[-1]
    return (min(n, len(clocks)) - 1) / (t1 - t0) if t1 > t0 else 0.0


def _node_verdict(scenario, duration_s, rate_hz, rtf, clocks, i0, i1, sent, probe, samples, warmup, bag,
                  exit_code, failures, max_growth_mb, max_missed_fraction, max_dropped_fraction) -> NodeSoakResult:
    """Turn the clock trace, counters, samples and the bag into figures and a verdict."""
    window = clocks[i0:i1]
    steps_sim = [b[1] - a[1] for a, b in zip(clocks, clocks[1:]) if b[1] > a[1]]
    dt_ns = statistics.median(steps_sim) if steps_sim else 0
    rate = rate_hz if rate_hz > 0 else (rtf * 1e9 / dt_ns if dt_ns else 0.0)
    wall = window[-1][0] - window[0][0] if len(window) > 1 else 0.0
    sim = (window[-1][1] - window[0][1]) / 1e9 if len(window) > 1 else 0.0
    taken = round(sim * 1e9 / dt_ns) if dt_ns else 0
    expected = round(wall * rate)
    gaps = [b[0] - a[0] for a, b in zip(window, window[1:])]
    counts: Dict[str, int] = {}
    readable = False
    try:
        counts = read_bag_counts(bag)
        readable = True
    except Exception as error:  # noqa: BLE001 - an unreadable bag is a finding, not a crash
        failures.append(f"bag {bag} does not read back: {type(error).__name__}: {error}")
    recorded = counts.get("/agent_0/cmd_vel", 0)
    fox_recorded = counts.get("/agent_1/cmd_vel", 0)
    warm_index = next((i for i, s in enumerate(samples) if s.wall_s >= warmup), max(0, len(samples) - 1))
    post = samples[warm_index:]
    rss_growth = growth_mb([s.rss_mb for s in samples], warm_index)
    if exit_code != 0:
        failures.append(f"sim_node exit code {exit_code} (expected 0 on SIGINT)")
    if taken <= 0:
        failures.append("no steps measured in the window")
    missed = expected - taken
    if expected and missed > max(1, max_missed_fraction * expected):
        failures.append(f"missed {missed} of {expected} steps (limit {max_missed_fraction:.1%})")
    dropped = sent - recorded
    if readable and sent and dropped > max(1, max_dropped_fraction * sent):
        failures.append(f"{dropped} of {sent} commands never reached the node (limit {max_dropped_fraction:.1%})")
    if probe.error or probe.received == 0:
        failures.append(f"Foxglove client received nothing ({probe.error or 'no message data'})")
    if len(post) < 4:
        failures.append(f"only {len(post)} memory samples after warm-up: too few to judge (lower --sample-every)")
    if rss_growth > max_growth_mb:
        failures.append(f"node RSS grew {rss_growth:.1f} MB after warm-up (limit {max_growth_mb} MB)")
    return NodeSoakResult(
        scenario=scenario, duration_s=duration_s, rate_hz=rate, window_s=wall, steps_taken=taken,
        steps_expected=expected, missed_steps=missed, max_clock_gap_s=max(gaps, default=0.0),
        real_time_factor=sim / wall if wall else 0.0, commands_sent=sent, commands_recorded=recorded,
        dropped_commands=dropped, foxglove_commands_sent=probe.sent, foxglove_commands_recorded=fox_recorded,
        foxglove_messages_received=probe.received,
        rss_after_warmup_mb=samples[warm_index].rss_mb if samples else 0.0, rss_end_mb=samples[-1].rss_mb if samples else 0.0,
        rss_growth_mb=rss_growth, rss_slope_mb_per_h=slope_per_hour([s.wall_s for s in post], [s.rss_mb for s in post]),
        max_growth_mb=max_growth_mb, bag_path=str(bag), bag_mb=bag.stat().st_size / MB if bag.exists() else 0.0,
        bag_readable=readable, bag_messages=sum(counts.values()), bag_clock_messages=counts.get("/clock", 0),
        node_exit_code=exit_code, ok=not failures, failures=failures, samples=samples,
    )


def _bar(total_s: float, enabled: bool):
    if not enabled:
        return None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm(total=total_s, desc="soak node", unit="s", file=sys.stderr, bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f} s")


# --------------------------------------------------------------------------- CLI
def add_node_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``vmas-ros soak node``."""
    parser.add_argument("--duration", type=float, default=3600.0, help="seconds to run (default 3600)")
    parser.add_argument("--scenario", default="simple_spread", help="scenario (default simple_spread)")
    parser.add_argument("--num-envs", dest="soak_num_envs", type=int, default=1, help="sim_node num_envs (default 1)")
    parser.add_argument("--rate-hz", type=float, default=0.0, help="sim_node rate_hz; 0: real time (default 0)")
    parser.add_argument("--real-time-factor", type=float, default=1.0, help="sim_node real_time_factor (default 1)")
    parser.add_argument("--cmd-rate", type=float, default=20.0, help="agent_0 Twists per second over ROS (default 20)")
    parser.add_argument("--foxglove-cmd-rate", type=float, default=5.0,
                        help="agent_1 Twists per second from the Foxglove client (default 5)")
    parser.add_argument("--sample-every", type=float, default=10.0, help="seconds between memory samples (default 10)")
    parser.add_argument("--warmup", type=float, default=None, help="seconds before growth and steps are judged "
                                                                   "(default 10%% of --duration)")
    parser.add_argument("--max-growth-mb", type=float, default=32.0, help="node RSS growth that fails the run (default 32)")
    parser.add_argument("--max-missed", type=float, default=0.01, help="fraction of missed steps that fails (default 0.01)")
    parser.add_argument("--max-dropped", type=float, default=0.01, help="fraction of dropped commands that fails (default 0.01)")
    parser.add_argument("-p", "--param", action="append", default=[], metavar="NAME:=VALUE",
                        help="extra sim_node parameter (repeatable)")


def run_node_command(args: argparse.Namespace) -> int:
    """``vmas-ros soak node``: 0 when every check passed, 1 when one failed, 2 on bad arguments."""
    try:
        result = run_node_soak(
            duration_s=args.duration, scenario=args.scenario, num_envs=args.soak_num_envs, rate_hz=args.rate_hz,
            real_time_factor=args.real_time_factor, cmd_rate_hz=args.cmd_rate, foxglove_rate_hz=args.foxglove_cmd_rate,
            sample_every_s=args.sample_every, warmup_s=args.warmup, max_growth_mb=args.max_growth_mb,
            max_missed_fraction=args.max_missed, max_dropped_fraction=args.max_dropped, out_dir=args.out,
            progress=not args.no_progress, extra_params=args.param,
        )
    except (ValueError, RuntimeError) as error:
        print(f"vmas-ros soak node: {error}", file=sys.stderr)
        return 2 if isinstance(error, ValueError) else 1
    paths = write_outputs(result, args.out, "soak_node", x_label="time", plot=not args.no_plot)
    print(format_node(result))
    for path in paths.values():
        print(f"wrote {path}")
    return 0 if result.ok else 1


def format_node(r: NodeSoakResult) -> str:
    """A short human summary of a node soak."""
    return "\n".join([
        f"soak node: {r.scenario} for {r.duration_s:.0f} s at {r.rate_hz:.1f} steps/s: {r.steps_taken} steps in the "
        f"{r.window_s:.0f} s window, expected {r.steps_expected} (missed {r.missed_steps}), real-time factor "
        f"{r.real_time_factor:.4f}, longest /clock gap {r.max_clock_gap_s * 1e3:.0f} ms",
        f"  commands: ROS {r.commands_recorded}/{r.commands_sent} recorded (dropped {r.dropped_commands}), Foxglove "
        f"{r.foxglove_commands_recorded}/{r.foxglove_commands_sent}; Foxglove client got {r.foxglove_messages_received} messages",
        f"  node RSS {r.rss_after_warmup_mb:.0f} MB after warm-up, {r.rss_end_mb:.0f} MB at end: growth "
        f"{r.rss_growth_mb:+.1f} MB, slope {r.rss_slope_mb_per_h:+.1f} MB/h",
        f"  bag {r.bag_path}: {r.bag_mb:.1f} MB, {'reads back' if r.bag_readable else 'UNREADABLE'} "
        f"({r.bag_messages} messages, {r.bag_clock_messages} on /clock); node exit code {r.node_exit_code}",
        "  verdict: " + ("ok" if r.ok else "FAILED: " + "; ".join(r.failures)),
    ])
