"""The project's benchmark suite: vmas_ros against upstream VMAS 1.5.2 on CPU.

``vmas-ros bench suite`` runs the workloads of :data:`WORKLOADS` and reports each
speed-up next to the project's target (see :mod:`vmas_ros.bench.suite_report`).

How each side is measured, and why:

* Both libraries are built in this process with the same scenario name, kwargs
  and num_envs, and stepped with the *same* random actions (one seeded
  ``torch.Generator``, drawn uniformly in vmas_ros's action space and shared by
  both sides), so neither side gets easier inputs.
* Timing reuses :func:`vmas_ros.bench.timing.time_alternating`: the sides
  alternate inside every repeat (A B, A B, ...) so noise from other work on a
  shared machine hits both alike, and medians of ``repeats`` are reported.
  What is timed is ``steps`` calls of ``env.step`` (or ``World.step``); building,
  the reset before each repeat and action generation are not.
* ``spheres_100`` and ``scaling_agents`` build a world of overlapping spheres
  with each library's own ``World``/``Agent``/``Sphere`` API and time
  ``World.step`` alone: the engine, without any scenario code.
  ``swarm_N`` and ``scaling_agents_sparse`` do the same with the spheres spread
  out as a swarm (a square of side ``SWARM_SPACING * sqrt(N)``), after one
  untimed step, up to 100,000 agents.
* ``navigation_swarm_N`` steps navigation with N agents in that swarm layout,
  vmas_ros through the stacked action form (one ``[n_agents, num_envs, size]``
  tensor, as a swarm's controller would send it), the peer through its list
  of the same actions.
* ``memory_30k`` runs each side in a fresh ``python -c`` subprocess that imports
  only torch and its own library, so one side's allocations never inflate the
  other's peak RSS.
* ``mpe_1k`` reuses the MPE case of :mod:`vmas_ros.bench.mpe` (MPE steps one env
  at a time, as in the VMAS paper; ``mpe_max_envs`` caps and extrapolates).
* ``modes`` (``--modes eager compiled``) says how vmas_ros is stepped: eager,
  or with its physics through torch.compile (``make_env(..., compile_physics=True)``,
  ``World.compile_physics()``). With both, every timed point gets a second
  vmas_ros side, ``vmas_ros_compiled``, built by the same code
  (:mod:`vmas_ros.bench.suite_cases`) and timed in the same alternation as the
  others, so eager, compiled and the peer meet the same machine noise. With
  ``compiled`` alone (the old ``--compile-physics``) the one vmas_ros side is the
  compiled one: ``side="vmas_ros"``, ``compiled=True``, as earlier results
  files have it. Compiling happens in the warm-up runs (never timed);
  ``memory_30k`` is always eager.
* A workload whose scenario is not registered in ``vmas_ros.scenarios`` yet is
  reported as skipped rather than failing the run; upstream points above
  ``max_peer_agents`` are omitted (never extrapolated) and the report says so.
"""
from __future__ import annotations

import datetime as _dt
import difflib
import gc
import math
import statistics
import sys
import traceback
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Tuple

from vmas_ros.bench import mpe as _mpe
from vmas_ros.bench.common import COMPILED_SIDE, DEFAULT_NUM_ENVS
from vmas_ros.bench.report import plot_available
from vmas_ros.bench.suite_cases import SPHERE_SPACING, SWARM_SPACING
from vmas_ros.bench.suite_cases import record_timed_mode
from vmas_ros.simulator.compile_default import resolve_compile
from vmas_ros.bench.suite_cases import env_cases as _env_cases
from vmas_ros.bench.suite_cases import memory_run as _memory_run
from vmas_ros.bench.suite_cases import spheres_case as _spheres_case
from vmas_ros.bench.suite_report import (
    format_suite_table,
    summarize,
    write_suite_results,
)
from vmas_ros.bench.timing import Case, Timing, pinned_threads, time_alternating

__all__ = ["MODES", "WORKLOADS", "Workload", "navigation_swarm", "plan_suite", "resolve_modes", "run_suite",
           "run_suite_command", "validate_suite_options"]

SIDE, PEER_VMAS, PEER_MPE = "vmas_ros", "vmas", "mpe"
#: how vmas_ros can be stepped (``--modes``): as make_env does without flags (the default mode: compiled
#: where it can be, see vmas_ros.simulator.compile_default), eager, or its physics through torch.compile
MODES = ("default", "eager", "compiled")
CURVE_AGENTS = (10, 30, 100, 300, 1000)
#: the swarm curve goes where only a broad phase can: a step whose cost grows like the agents, not their pairs
CURVE_AGENTS_SPARSE = (100, 300, 1_000, 3_000, 10_000, 30_000, 100_000)
CURVE_ENVS = (1, 10, 100, 1000, 10000, 30000)
#: upstream VMAS buckets pairs in a Python loop with a host sync per pair: above this it takes minutes per step
DEFAULT_MAX_PEER_AGENTS = 100


@dataclass(frozen=True)
class Workload:
    """One row (or one curve) of the suite; ``num_envs`` is before ``--scale``."""

    name: str
    kind: str  # env, spheres, agents_curve, envs_curve, memory or mpe
    scenario: Optional[str]
    num_envs: int
    kwargs: Mapping[str, object] = field(default_factory=dict)
    n_agents: Optional[int] = None  # spheres only
    peer: str = PEER_VMAS
    spacing: float = SPHERE_SPACING  # spheres: they start in a square of side spacing * sqrt(n_agents)
    settle: bool = False  # spheres: one untimed step after the start is set (time the steady state)
    points: Tuple[int, ...] = ()  # curves: the default x values (agents or num_envs), before any option
    stacked_actions: bool = False  # env: vmas_ros gets [n_agents, num_envs, size], the peer still a list


def navigation_swarm(n_agents: int) -> Workload:
    """navigation with ``n_agents`` agents of radius 0.05 spawned like a swarm (a square of side
    ``SWARM_SPACING * sqrt(n_agents)``), LIDARs seeing each other, stepped with stacked actions.
    A function so that tests can build the same workload with a handful of agents."""
    half = SWARM_SPACING * math.sqrt(n_agents) / 2
    kwargs = {"n_agents": n_agents, "agent_radius": 0.05, "world_spawning_x": half, "world_spawning_y": half}
    return Workload(f"navigation_swarm_{n_agents}", "env", "navigation", 1, kwargs=kwargs, stacked_actions=True)


WORKLOADS: Dict[str, Workload] = {w.name: w for w in (
    Workload("spread_1", "env", "simple_spread", 1),
    Workload("spread_1k", "env", "simple_spread", 1_000),
    Workload("spread_30k", "env", "simple_spread", 30_000),
    Workload("transport_10k", "env", "transport", 10_000),
    Workload("flocking_10k", "env", "flocking", 10_000),
    Workload("discovery_1k", "env", "discovery", 1_000),
    Workload("spheres_100", "spheres", None, 32, n_agents=100),
    Workload("spread_60", "env", "simple_spread", 32, kwargs={"n_agents": 60}),  # VMAS: as many landmarks
    Workload("scaling_agents", "agents_curve", None, 1, points=CURVE_AGENTS),
    # a swarm: spheres of radius 0.05 spread over a square of side 0.5 * sqrt(N), about 3% of it covered
    *(Workload(f"swarm_{n}", "spheres", None, 1, n_agents=n, spacing=SWARM_SPACING, settle=True)
      for n in (1_000, 10_000, 100_000)),
    Workload("scaling_agents_sparse", "agents_curve", None, 1, spacing=SWARM_SPACING, settle=True,
             points=CURVE_AGENTS_SPARSE),
    *(navigation_swarm(n) for n in (1_000, 10_000)),
    Workload("scaling_envs", "envs_curve", "simple_spread", 1, points=CURVE_ENVS),
    Workload("memory_30k", "memory", "simple_spread", 30_000),
    Workload("mpe_1k", "mpe", "simple_spread", 1_000, peer=PEER_MPE),
)}


@dataclass
class Unit:
    """One measured point: a workload at one num_envs (and agent count), every side."""

    workload: Workload
    num_envs: int
    n_agents: Optional[int]
    sides: List[str]  # sides to measure: vmas_ros, then vmas_ros_compiled, then the peer
    skipped: Dict[str, str]  # side -> why it is not measured
    compiled_sides: Tuple[str, ...] = ()  # the sides built with compile_physics=True (default: timed compiled)
    default_mode: bool = False  # vmas_ros is built as make_env builds it without flags (compiled_sides says how)


# ----------------------------------------------------------------- options
def _scaled(n: int, scale: float) -> int:
    return max(1, int(round(n * scale)))


def _positive_ints(name: str, values, allow_none: bool = True) -> None:
    if values is None and allow_none:
        return
    if isinstance(values, (int, str)) or not isinstance(values, Sequence) or not values:
        raise ValueError(f"{name} must be a non-empty list of positive integers, got {values!r}")
    bad = [v for v in values if isinstance(v, bool) or not isinstance(v, int) or v < 1]
    if bad:
        raise ValueError(f"{name} must be positive integers; bad value(s): {bad}")


def resolve_modes(modes: Optional[Sequence[str]] = None, compile_physics: bool = False) -> Tuple[str, ...]:
    """The modes to measure, eager first, duplicates dropped; ValueError naming a bad one.

    None is the default mode alone: vmas_ros as a user gets it without flags. ``default`` is
    measured alone (it is eager or compiled per point already). ``compile_physics=True`` is
    the old spelling of ``modes=("compiled",)`` and is kept so existing commands and scripts
    still run; given with modes that say otherwise it is an error rather than a silent choice
    of one of them.
    """
    if modes is None:
        return ("compiled",) if compile_physics else ("default",)
    if isinstance(modes, str) or not isinstance(modes, Sequence) or not modes:
        raise ValueError(f"modes must be a non-empty list of {', '.join(MODES)}, got {modes!r}")
    bad = [m for m in modes if m not in MODES]
    if bad:
        raise ValueError(f"unknown mode(s) {bad}; valid modes: {', '.join(MODES)}")
    resolved = tuple(m for m in MODES if m in modes)
    if "default" in resolved and len(resolved) > 1:
        raise ValueError(f"--modes default measures vmas_ros as make_env builds it without flags and is given alone; "
                         f"got --modes {' '.join(modes)} (to time both ways side by side: --modes eager compiled)")
    if compile_physics and resolved != ("compiled",):
        raise ValueError(f"--compile-physics means --modes compiled, but --modes {' '.join(modes)} was given too; "
                         f"pass only one of them")
    return resolved


def validate_suite_options(workloads, steps, repeats, warmup, scale, threads, peers, curve_envs, curve_agents,
                           max_peer_agents, mpe_max_envs, modes: Optional[Sequence[str]] = None,
                           compile_physics: bool = False, curve_agents_sparse=None) -> Tuple[str, ...]:
    """Raise ValueError naming the bad value (and the valid ones) for any bad option;
    return the modes to measure (see :func:`resolve_modes`)."""
    resolved = resolve_modes(modes, compile_physics)
    if workloads is not None:
        if isinstance(workloads, str) or not workloads:
            raise ValueError(f"workloads must be a non-empty list of names, got {workloads!r}")
        for name in workloads:
            if name not in WORKLOADS:
                close = difflib.get_close_matches(str(name), WORKLOADS, n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise ValueError(f"unknown workload {name!r}{hint}; valid workloads: {', '.join(WORKLOADS)}")
    for name, value in (("steps", steps), ("repeats", repeats)):
        _mpe._positive_int(name, value)
    for name, value in (("threads", threads), ("max_peer_agents", max_peer_agents), ("mpe_max_envs", mpe_max_envs)):
        _mpe._positive_int(name, value, allow_none=True)
    if isinstance(warmup, bool) or not isinstance(warmup, int) or warmup < 0:
        raise ValueError(f"warmup must be a non-negative integer, got {warmup!r}")
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not math.isfinite(scale) or scale <= 0:
        raise ValueError(f"scale must be a finite number > 0 (e.g. 0.01), got {scale!r}")
    _positive_ints("curve_envs", curve_envs)
    _positive_ints("curve_agents", curve_agents)
    _positive_ints("curve_agents_sparse", curve_agents_sparse)
    if peers is not None:
        unknown = [p for p in ([peers] if isinstance(peers, str) else peers) if p not in _mpe.PEERS]
        if isinstance(peers, str) or unknown:
            raise ValueError(f"unknown peer(s) {unknown or [peers]}; valid peers: {list(_mpe.PEERS)}")
    compiles = "compiled" in resolved or (resolved == ("default",) and resolve_compile(None, 1) is not False)
    if compiles and warmup < 1:  # the first compiled run compiles for seconds: never time it
        raise ValueError(f"the {resolved[-1]} mode needs --warmup >= 1 (its first runs compile), got {warmup}; "
                         f"--modes eager times without one")
    return resolved


def _scenario_available(name: str) -> bool:
    """Registered in vmas_ros.scenarios (scenarios still being written are not, yet)."""
    from vmas_ros.scenarios import REGISTRY

    return name in REGISTRY


def _our_sides(kind: str, modes: Sequence[str], num_envs: int) -> Tuple[List[str], Tuple[str, ...]]:
    """vmas_ros's sides for a workload kind and which of them are compiled.

    Both modes: "vmas_ros" (eager) and "vmas_ros_compiled". Compiled alone: the one
    "vmas_ros" side, compiled (as ``--compile-physics`` always wrote it). memory is eager only,
    except in the default mode, where its subprocess builds the env without flags. Default: the one
    "vmas_ros" side as make_env builds it, its warm-up stepping on through the default mode's switch
    (``timing.through_the_switch``); its compiled column says how the timed runs went (the sphere
    worlds are built with ``World``, which compiles only when asked).
    """
    if modes == ("default",):  # env cases find out in their warm-up (suite_cases.env_cases)
        return [SIDE], ()
    if kind == "memory" or "compiled" not in modes:
        return [SIDE], ()
    if "eager" not in modes:
        return [SIDE], (SIDE,)
    return [SIDE, COMPILED_SIDE], (COMPILED_SIDE,)


def plan_suite(workloads: Optional[Sequence[str]] = None, scale: float = 1.0, peers: Optional[Sequence[str]] = None,
               curve_envs: Optional[Sequence[int]] = None, curve_agents: Optional[Sequence[int]] = None,
               max_peer_agents: Optional[int] = DEFAULT_MAX_PEER_AGENTS,
               modes: Sequence[str] = ("eager",), curve_agents_sparse: Optional[Sequence[int]] = None) -> List[Unit]:
    """The points to measure, in workload order, with the reason for every side left out.

    A curve's points are its option's (``curve_envs``, ``curve_agents``, ``curve_agents_sparse``)
    or else its own defaults. The peer is left out of every point with more agents than
    ``max_peer_agents`` (its pair loop makes it take minutes per step; never extrapolated)."""
    names = list(WORKLOADS) if workloads is None else list(dict.fromkeys(workloads))
    requested = set(_mpe.PEERS if peers is None else peers)
    chosen = {"scaling_envs": curve_envs, "scaling_agents": curve_agents, "scaling_agents_sparse": curve_agents_sparse}
    units: List[Unit] = []
    for name in names:
        w = WORKLOADS[name]
        curve = chosen.get(name) or w.points
        peer_reason = None
        if w.peer not in requested:
            peer_reason = f"peer {w.peer} not requested (--peers)"
        elif not _mpe._peer_installed(w.peer):
            peer_reason = f"{_mpe._PEER_MODULE[w.peer]} not installed ({_mpe._PEER_INSTALL[w.peer]})"
        if w.kind == "agents_curve":
            points = [(1, n) for n in sorted(set(curve))]
        elif w.kind == "envs_curve":
            points = [(n, None) for n in sorted({_scaled(n, scale) for n in curve})]
        else:
            points = [(_scaled(w.num_envs, scale), w.n_agents or w.kwargs.get("n_agents"))]
        for num_envs, n_agents in points:
            ours, compiled = _our_sides(w.kind, modes, num_envs)
            skipped: Dict[str, str] = {}
            if w.scenario is not None and not _scenario_available(w.scenario):
                skipped = {side: "scenario not available" for side in ours + [w.peer]}
            elif peer_reason:
                skipped[w.peer] = peer_reason
            elif max_peer_agents is not None and n_agents is not None and n_agents > max_peer_agents:
                skipped[w.peer] = (f"omitted: above --max-peer-agents {max_peer_agents} "
                                   f"(upstream is O(pairs) with host syncs; not extrapolated)")
            sides = [s for s in ours + [w.peer] if s not in skipped]
            units.append(Unit(w, num_envs, n_agents, sides, skipped, compiled, default_mode=modes == ("default",)))
    return units


# -------------------------------------------------------------------- rows
def _time_row(run_id: str, unit: Unit, side: str, steps: int, timing: Timing, measured_envs: int, loadavg) -> dict:
    """mpe.py's row (medians, extrapolation to num_envs), plus the suite's columns."""
    row = _mpe._row(run_id, side, "cpu", unit.num_envs, steps, timing, measured_envs, unit.num_envs, loadavg)
    row.update(scenario=unit.workload.scenario or "spheres", metric="time", value=row["per_step_ms"],
               unit="ms/step", rss_mb=None, baseline_rss_mb=None, compiled=side in unit.compiled_sides,
               default_mode=unit.default_mode and side == SIDE, first_run_s=timing.first_run_s)
    return row


def _other_row(run_id: str, unit: Unit, side: str, steps: int, threads: int, status: str, note: str) -> dict:
    """A row without a measurement (``status`` skipped or error, ``note`` says why)."""
    return {"run_id": run_id, "scenario": unit.workload.scenario or "spheres", "side": side, "device": "cpu",
            "num_envs": unit.num_envs, "steps": steps, "repeats": 0, "threads": threads, "times_s": [],
            "status": status, "note": note, "metric": "memory" if unit.workload.kind == "memory" else "time",
            "compiled": side in unit.compiled_sides, "default_mode": unit.default_mode and side == SIDE}


# ------------------------------------------------------------------ memory
def _memory_rows(run_id, unit, steps, repeats, threads, seed, loadavg, on_run) -> List[dict]:
    results: Dict[str, List[dict]] = {side: [] for side in unit.sides}
    for index in range(repeats):  # alternate the sides, as time_alternating does
        for side in unit.sides:
            results[side].append(_memory_run(side, unit, steps, threads, seed, default_mode=unit.default_mode))
            on_run(side, index, results[side][-1]["seconds"])
    rows = []
    for side, runs in results.items():
        unit.n_agents = runs[0]["n_agents"]
        times = [r["seconds"] for r in runs]
        timing = Timing(times_s=times, median_s=statistics.median(times), min_s=min(times), max_s=max(times),
                        repeats=repeats, warmup=0, threads=threads)
        row = _time_row(run_id, unit, side, steps, timing, unit.num_envs, loadavg)
        rss = [r["peak_rss_mb"] for r in runs]
        row.update(metric="memory", value=statistics.median(rss), unit="MB", rss_mb=rss, peak_rss_mb=max(rss),
                   baseline_rss_mb=statistics.median(r["baseline_rss_mb"] for r in runs))
        rows.append(row)
    return rows


# ------------------------------------------------------------------ runner
def _guarded(cases: Mapping[str, Case], failures: Dict[str, str]) -> Dict[str, Case]:
    """``cases`` with every call wrapped: a side whose call raises (say torch.compile failing
    in the warm-up) is recorded in ``failures`` and its later calls do nothing, so the
    other sides are still timed, alternating as before, and only that side gets an error row."""
    def wrap(side: str, fn: Optional[Callable[[], object]]) -> Optional[Callable[[], object]]:
        if fn is None:
            return None

        def call():
            if side in failures:
                return None
            try:
                return fn()
            except Exception as error:  # noqa: BLE001 - reported in the side's row, the run goes on
                traceback.print_exc(file=sys.stderr)
                failures[side] = f"{type(error).__name__}: {error}"
                return None

        return call

    return {side: Case(run=wrap(side, case.run), setup=wrap(side, case.setup),
                       warmup_run=wrap(side, case.warmup_run), device=case.device) for side, case in cases.items()}


def _measure(unit: Unit, run_id: str, steps: int, repeats: int, warmup: int, threads: int, mpe_max_envs,
             seed: int, on_run: Callable) -> List[dict]:
    """Rows of every side of ``unit``: time_alternating over all of them (memory: fresh processes)."""
    w, loadavg = unit.workload, _mpe._loadavg()
    if w.kind == "memory":  # no warm-up: each run is a fresh process, as a user's first run would be
        return _memory_rows(run_id, unit, steps, repeats, threads, seed, loadavg, on_run)
    measured = {side: unit.num_envs for side in unit.sides}
    if w.kind == "mpe":
        default = None if unit.default_mode else False  # None: make_env's default, timed through its switch
        cases = {side: _mpe._vmas_case(SIDE, unit.num_envs, "cpu", steps, side in unit.compiled_sides or default,
                                       on_switch=lambda compiled: record_timed_mode(unit, compiled))
                 for side in unit.sides if side != PEER_MPE}
        if PEER_MPE in unit.sides:
            measured[PEER_MPE] = min(unit.num_envs, mpe_max_envs or unit.num_envs)
            cases[PEER_MPE] = _mpe._mpe_case(measured[PEER_MPE], steps, seed)
        unit.n_agents = _mpe.N_AGENTS
    elif w.kind in ("spheres", "agents_curve"):
        cases = {side: _spheres_case(side, unit.n_agents, unit.num_envs, steps, seed, side in unit.compiled_sides,
                                     spacing=w.spacing, settle=w.settle)
                 for side in unit.sides}
    else:
        cases = _env_cases(unit, steps, seed)
    failures: Dict[str, str] = {}
    timings = time_alternating(_guarded(cases, failures), repeats=repeats, warmup=warmup, on_run=on_run)
    rows = [_other_row(run_id, unit, side, steps, threads, "error", failures[side]) if side in failures
            else _time_row(run_id, unit, side, steps, timings[side], measured[side], loadavg) for side in unit.sides]
    del cases, timings
    return rows


def run_suite(workloads: Optional[Sequence[str]] = None, steps: int = 100, repeats: int = 3, warmup: int = 1,
              scale: float = 1.0, threads: Optional[int] = None, peers: Optional[Sequence[str]] = None,
              curve_envs: Optional[Sequence[int]] = None, curve_agents: Optional[Sequence[int]] = None,
              max_peer_agents: Optional[int] = DEFAULT_MAX_PEER_AGENTS, mpe_max_envs: Optional[int] = None,
              seed: int = 0, progress: bool = True, compile_physics: bool = False,
              modes: Optional[Sequence[str]] = None, curve_agents_sparse: Optional[Sequence[int]] = None) -> List[dict]:
    """Measure the chosen workloads (default all); one row per (workload, point, side).

    Every row has ``status``: ``ok``, ``skipped`` (``note`` says why: scenario not
    available, peer missing, above ``max_peer_agents``) or ``error`` (the exception,
    also printed on stderr; the other workloads still run). Raises ValueError for
    bad options. ``threads`` pins torch threads here and in the memory subprocesses.
    ``modes`` (default ``("eager",)``) are how vmas_ros is stepped: with ``"compiled"``
    its physics runs through torch.compile (compiled in the warm-up runs, not timed;
    memory_30k stays eager); with both, compiled rows have ``side="vmas_ros_compiled"``.
    ``compile_physics=True`` is the older spelling of ``modes=("compiled",)``.
    """
    modes = validate_suite_options(workloads, steps, repeats, warmup, scale, threads, peers, curve_envs,
                                   curve_agents, max_peer_agents, mpe_max_envs, modes, compile_physics,
                                   curve_agents_sparse)
    units = plan_suite(workloads, scale, peers, curve_envs, curve_agents, max_peer_agents, modes, curve_agents_sparse)
    run_id = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
    from tqdm import tqdm

    rows: List[dict] = []
    total = sum(repeats * len(u.sides) for u in units)
    with pinned_threads(threads) as in_effect, tqdm(total=total, disable=not progress, desc="bench suite",
                                                    unit="run", file=sys.stderr, dynamic_ncols=True) as bar:
        for unit in units:
            label = f"{unit.workload.name} {unit.num_envs} envs" + (
                f" {unit.n_agents} agents" if unit.workload.kind == "agents_curve" else "")
            bar.set_postfix_str(f"{label}: building", refresh=True)

            done = [0]

            def on_run(side, index, seconds, label=label, done=done):
                bar.set_postfix_str(f"{label}: {side} #{index + 1} {seconds:.3g}s", refresh=False)
                bar.update(1)
                done[0] += 1

            measured: List[dict] = []
            if unit.sides:
                try:
                    measured = _measure(unit, run_id, steps, repeats, warmup, in_effect, mpe_max_envs, seed, on_run)
                except Exception as error:  # one broken workload must not lose an hour of others
                    traceback.print_exc(file=sys.stderr)
                    message = f"{type(error).__name__}: {error}"
                    measured = [_other_row(run_id, unit, s, steps, in_effect, "error", message) for s in unit.sides]
                    bar.update(repeats * len(unit.sides) - done[0])  # the runs it will not do
            for row in measured:
                row.setdefault("status", "ok")
                row.setdefault("note", "")
            skipped = [_other_row(run_id, unit, s, steps, in_effect, "skipped", why) for s, why in unit.skipped.items()]
            for row in sorted(measured + skipped, key=lambda r: {SIDE: 0, COMPILED_SIDE: 1}.get(r["side"], 2)):
                row.update(workload=unit.workload.name, n_agents=unit.n_agents)
                rows.append(row)
            gc.collect()
    return rows


# --------------------------------------------------------------------- CLI
def run_suite_command(args) -> int:
    """``vmas-ros bench suite``: 0 when every measured workload ran, 1 if one errored, 2 on bad options."""
    options = dict(
        workloads=getattr(args, "workloads", None), steps=args.steps, repeats=getattr(args, "repeats", 3),
        warmup=getattr(args, "warmup", 1), scale=getattr(args, "scale", 1.0), threads=getattr(args, "threads", None),
        peers=getattr(args, "peers", None), curve_envs=getattr(args, "curve_envs", None),
        curve_agents=getattr(args, "curve_agents", None), mpe_max_envs=getattr(args, "mpe_max_envs", None),
        curve_agents_sparse=getattr(args, "curve_agents_sparse", None),
        max_peer_agents=getattr(args, "max_peer_agents", None), modes=getattr(args, "modes", None),
        compile_physics=bool(getattr(args, "compile_physics", False)),
    )
    if options["max_peer_agents"] is None:
        options["max_peer_agents"] = DEFAULT_MAX_PEER_AGENTS
    try:
        validate_suite_options(**options)
        devices = getattr(args, "devices", None) or ["cpu"]
        if [d for d in devices if d != "cpu"]:
            raise ValueError(f"the suite runs on cpu only (its targets are CPU targets); got devices {devices}; "
                             "valid: cpu")
        num_envs = getattr(args, "bench_num_envs", None)
        if num_envs is not None and list(num_envs) != list(DEFAULT_NUM_ENVS):
            raise ValueError(f"--num-envs {' '.join(map(str, num_envs))} is for 'bench mpe'; the suite takes "
                             f"--scale and --curve-envs")
    except ValueError as error:
        print(f"vmas-ros bench suite: {error}", file=sys.stderr)
        return 2
    plot = plot_available(not getattr(args, "no_plot", False))
    rows = run_suite(progress=not getattr(args, "no_progress", False), **options)
    paths = write_suite_results(rows, getattr(args, "out", "bench_results"), plot=plot)
    print(format_suite_table(summarize(rows)))
    print()
    for path in paths.values():
        print(f"wrote {path}")
    return 1 if any(r["status"] == "error" for r in rows) else 0

