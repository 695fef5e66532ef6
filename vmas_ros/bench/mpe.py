"""The MPE comparison of the VMAS paper (Fig. 2), with vmas_ros as a third side.

Task: ``simple_spread`` (3 agents, 3 landmarks), ``steps`` steps (100 in the
paper) against the number of parallel environments.

* ``vmas_ros`` and upstream ``vmas``: one batched env of ``num_envs`` copies
  (``make_env("simple_spread", num_envs=n, device=d, seed=0)``), stepped
  ``steps`` times.
* ``mpe`` (PettingZoo's ``mpe2.simple_spread_v3.parallel_env(N=3,
  continuous_actions=True, max_cycles=steps + 1)``): MPE is not vectorized, so,
  as in the paper, ``num_envs`` separate envs are stepped one after the other in
  a Python loop; the time for n envs is the sum over the n envs. Above
  ``mpe_max_envs`` only that many envs are really stepped and the time is
  extrapolated linearly (per-env time measured at the cap, times n); such rows
  have ``extrapolated: True``.

What is timed: the ``steps`` calls of ``step`` only. Env construction, the
reset before each repeat, and the random actions are not: the actions (uniform
in each action space) are generated once per env batch before timing, with the
side's own ``get_random_actions`` for VMAS/vmas_ros and one numpy sequence
shared by all MPE envs of a batch (MPE's step cost does not depend on the action
values). The sides are interleaved inside every repeat (A B C, A B C, ...) so
noise from other work on a shared machine hits them alike: quote the speed-up
ratios of one run.
"""
from __future__ import annotations

import datetime as _dt
import gc
import importlib
import os
import statistics
import sys
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
import torch

from vmas_ros.bench.common import (  # noqa: F401 - re-exported
    _LABEL,
    _PEER_INSTALL,
    _PEER_MODULE,
    BENCHMARKS,
    CSV_COLUMNS,
    N_AGENTS,
    PEERS,
    SCENARIO,
    SIDES,
)
from vmas_ros.bench.report import (  # noqa: F401 - re-exported
    _columns,
    _cpu_model,
    _csv_value,
    _extrapolation_note,
    _fmt_s,
    _plot,
    _title,
    _version,
    _vmas_ros_version,
    compute_ratios,
    format_table,
    machine_info,
    write_results,
)
from vmas_ros.bench.timing import Case, Timing, pinned_threads, through_the_switch, time_alternating

__all__ = [
    "SIDES",
    "PEERS",
    "available_peers",
    "compute_ratios",
    "default_devices",
    "format_table",
    "machine_info",
    "run_mpe_benchmark",
    "write_results",
]


# ----------------------------------------------------------------- validation
def default_devices() -> Tuple[str, ...]:
    """``("cpu",)``, plus ``"cuda"`` when torch sees a GPU."""
    return ("cpu", "cuda") if torch.cuda.is_available() else ("cpu",)


def _peer_installed(peer: str) -> bool:
    try:
        importlib.import_module(_PEER_MODULE[peer])
    except Exception:  # ImportError, or a broken install
        return False
    return True


def available_peers() -> Tuple[str, ...]:
    """The peers (``vmas``, ``mpe``) whose packages import here."""
    return tuple(peer for peer in PEERS if _peer_installed(peer))


def _positive_int(name: str, value, allow_none: bool = False) -> None:
    if value is None and allow_none:
        return
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{name} must be a positive integer{' or None' if allow_none else ''}, got {value!r}")


def _validate(num_envs, steps, repeats, devices, peers, mpe_max_envs, threads, warmup) -> None:
    """Raise ValueError with a clear message for any bad argument."""
    if isinstance(num_envs, (int, str)) or not isinstance(num_envs, Sequence) or len(num_envs) == 0:
        raise ValueError(f"num_envs must be a non-empty list of positive integers, got {num_envs!r}")
    for n in num_envs:
        _positive_int("every num_envs", n)
    _positive_int("steps", steps)
    _positive_int("repeats", repeats)
    _positive_int("mpe_max_envs", mpe_max_envs, allow_none=True)
    _positive_int("threads", threads, allow_none=True)
    if isinstance(warmup, bool) or not isinstance(warmup, int) or warmup < 0:
        raise ValueError(f"warmup must be a non-negative integer, got {warmup!r}")
    if devices is not None:
        if isinstance(devices, str) or len(devices) == 0:
            raise ValueError(f"devices must be a non-empty list such as ['cpu'], got {devices!r}")
        for device in devices:
            try:
                parsed = torch.device(device)
            except (RuntimeError, TypeError) as error:
                raise ValueError(f"unknown device {device!r}: {error}") from None
            if parsed.type not in ("cpu", "cuda"):
                raise ValueError(f"device must be cpu or cuda, got {device!r}")
            if parsed.type == "cuda" and not torch.cuda.is_available():
                raise ValueError(f"device {device!r} asked for, but torch sees no CUDA GPU here")
    if peers is not None:
        if isinstance(peers, str):
            raise ValueError(f"peers must be a list such as ['vmas', 'mpe'], got {peers!r}")
        unknown = [peer for peer in peers if peer not in PEERS]
        if unknown:
            raise ValueError(f"unknown peer(s) {unknown}; valid peers: {list(PEERS)}")


# -------------------------------------------------------------------- sides
def _vmas_case(side: str, num_envs: int, device: str, steps: int, compile_physics: Optional[bool] = False,
               on_switch: Optional[Callable[[bool], object]] = None) -> Case:
    """VMAS's or vmas_ros's simple_spread; for vmas_ros ``compile_physics`` None is the default mode, whose
    warm-up runs on through its switch to the compiled step (``on_switch(compiled)`` says how it ended)."""
    if side == "vmas_ros":
        from vmas_ros.envs.make_env import make_env

        make = make_env
        extra = {} if compile_physics is None else {"compile_physics": bool(compile_physics)}
    else:
        import vmas

        make, extra = vmas.make_env, {}
    env = make(SCENARIO, num_envs=num_envs, device=device, seed=0, **extra)
    env.reset()
    actions = [env.get_random_actions() for _ in range(steps)]  # generated once, not timed

    def run():
        for action in actions:
            env.step(action)

    if side == "vmas_ros" and compile_physics is None:
        return Case(run=run, setup=env.reset, device=device,
                    warmup_run=through_the_switch(env, run, actions, on_switch or (lambda compiled: None)))
    return Case(run=run, setup=env.reset, device=device)


def _mpe_case(real_envs: int, steps: int, seed: int = 0) -> Case:
    from mpe2 import simple_spread_v3

    envs = [simple_spread_v3.parallel_env(N=N_AGENTS, continuous_actions=True, max_cycles=steps + 1)
            for _ in range(real_envs)]

    def reset():
        for index, env in enumerate(envs):
            env.reset(seed=seed + index)

    reset()
    agents = list(envs[0].possible_agents)
    space = envs[0].action_space(agents[0])
    table = np.random.default_rng(seed).uniform(space.low, space.high, size=(steps, len(agents)) + space.shape)
    table = table.astype(space.dtype)
    actions = [{agent: table[t, k] for k, agent in enumerate(agents)} for t in range(steps)]

    def run():  # as the paper's script: every step, each env in turn
        for action in actions:
            for env in envs:
                env.step(action)

    warm = envs[: min(real_envs, 4)]

    def warmup_run():  # warms the code paths without paying for thousands of envs twice
        for action in actions:
            for env in warm:
                env.step(action)

    return Case(run=run, setup=reset, warmup_run=warmup_run, device="cpu")


def _loadavg() -> Optional[float]:
    try:
        return round(os.getloadavg()[0], 2)
    except (AttributeError, OSError):
        return None


def _row(run_id, side, device, num_envs, steps, timing: Timing, measured_envs, round_n, loadavg) -> dict:
    scale = num_envs / measured_envs
    times = [t * scale for t in timing.times_s]
    median = statistics.median(times)
    return {
        "run_id": run_id,
        "scenario": SCENARIO,
        "side": side,
        "device": device,
        "num_envs": num_envs,
        "steps": steps,
        "repeats": timing.repeats,
        "median_s": median,
        "min_s": min(times),
        "max_s": max(times),
        "per_step_ms": median / steps * 1e3,
        "env_steps_per_s": num_envs * steps / median,
        "extrapolated": measured_envs != num_envs,
        "measured_envs": measured_envs,
        "measured_in_round": round_n,
        "threads": timing.threads,
        "times_s": times,
        "peak_rss_mb": timing.peak_rss_mb,
        "torch_peak_mb": timing.torch_peak_mb,
        "loadavg_1m": loadavg,
    }


def run_mpe_benchmark(
    num_envs: Sequence[int],
    steps: int = 100,
    repeats: int = 3,
    devices: Optional[Sequence[str]] = None,
    peers: Optional[Sequence[str]] = None,
    mpe_max_envs: Optional[int] = None,
    threads: Optional[int] = None,
    progress: bool = True,
    warmup: int = 1,
) -> List[dict]:
    """Time ``steps`` steps of simple_spread for each ``num_envs`` and side; one row per
    (side, device, num_envs). See the module docstring for what is timed.

    ``devices`` defaults to cpu (+ cuda if available) for vmas_ros and VMAS (MPE is
    CPU only); ``peers`` defaults to those of ``("vmas", "mpe")`` that are
    installed, and a requested peer that is not installed is skipped with a note
    on stderr. ``threads`` pins ``torch.set_num_threads`` for the run (restored
    afterwards). Raises ValueError for bad arguments.
    """
    _validate(num_envs, steps, repeats, devices, peers, mpe_max_envs, threads, warmup)
    devices = [str(torch.device(d)) for d in (devices if devices is not None else default_devices())]
    devices = list(dict.fromkeys(devices))
    requested = list(PEERS) if peers is None else list(dict.fromkeys(peers))
    active = []
    for peer in requested:
        if _peer_installed(peer):
            active.append(peer)
        elif peers is not None:
            print(f"note: peer {peer!r} is not installed ({_PEER_INSTALL[peer]}); skipped", file=sys.stderr)
    rounds = sorted(set(int(n) for n in num_envs))
    run_id = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()

    # plan: which cases each round measures (MPE above the cap is measured once, at the cap)
    plan = []
    cap_measured = False
    for n in rounds:
        sides = [("vmas_ros", d) for d in devices] + ([("vmas", d) for d in devices] if "vmas" in active else [])
        mpe_envs = None
        if "mpe" in active:
            if mpe_max_envs is None or n <= mpe_max_envs:
                mpe_envs = n
                cap_measured = cap_measured or n == mpe_max_envs
            elif not cap_measured:
                mpe_envs = mpe_max_envs
                cap_measured = True
        plan.append((n, sides, mpe_envs))

    from tqdm import tqdm

    total = sum(repeats * (len(sides) + (mpe_envs is not None)) for _, sides, mpe_envs in plan)
    rows: List[dict] = []
    cap_result: Optional[Tuple[Timing, int]] = None  # (timing at the cap, round it was measured in)
    with pinned_threads(threads), tqdm(total=total, disable=not progress, desc="mpe bench", unit="run",
                                       file=sys.stderr, dynamic_ncols=True) as bar:
        for n, sides, mpe_envs in plan:
            loadavg = _loadavg()
            bar.set_postfix_str(f"{n} envs: building", refresh=True)
            cases: Dict[str, Case] = {}
            for side, device in sides:
                cases[f"{side}/{device}"] = _vmas_case(side, n, device, steps)
            if mpe_envs is not None:
                cases["mpe/cpu"] = _mpe_case(mpe_envs, steps)
            bar.set_postfix_str(f"{n} envs: warm-up", refresh=True)

            def on_run(name, index, seconds, n=n):
                bar.set_postfix_str(f"{n} envs: {name} #{index + 1} {seconds:.3g}s", refresh=False)
                bar.update(1)

            timings = time_alternating(cases, repeats=repeats, warmup=warmup, on_run=on_run)
            for side, device in sides:
                rows.append(_row(run_id, side, device, n, steps, timings[f"{side}/{device}"], n, n, loadavg))
            if "mpe" in active:
                if mpe_envs is not None:
                    timing = timings["mpe/cpu"]
                    if mpe_envs == mpe_max_envs:
                        cap_result = (timing, n)
                    rows.append(_row(run_id, "mpe", "cpu", n, steps, timing, mpe_envs, n, loadavg))
                else:  # above the cap, measured in an earlier round
                    timing, round_n = cap_result
                    rows.append(_row(run_id, "mpe", "cpu", n, steps, timing, mpe_max_envs, round_n, loadavg))
            del cases, timings
            gc.collect()
    return rows
