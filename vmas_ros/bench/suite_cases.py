"""How the benchmark suite (:mod:`vmas_ros.bench.suite`) builds what it measures:
one timed :class:`~vmas_ros.bench.timing.Case` per side of a workload point, and
the fresh-process run of ``memory_30k``.

Kept apart from the runner so the runner reads as "plan, time, report" and so
that every side, including the compiled vmas_ros side (``vmas_ros_compiled``),
is built by the same code: a compiled side differs from the eager one only by
``compile_physics=True`` (``World.compile_physics()`` for the sphere worlds),
never by its scenario, kwargs, seed or actions.
"""
from __future__ import annotations

import importlib
import json
import math
import os
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Dict, List, Mapping

import torch

from vmas_ros.bench.common import COMPILED_SIDE
from vmas_ros.bench.timing import Case, through_the_switch

if TYPE_CHECKING:  # only for the annotations: suite imports this module
    from vmas_ros.bench.suite import Unit

__all__ = ["SPHERE_RADIUS", "SPHERE_SPACING", "SWARM_SPACING", "library_of", "env_cases", "spheres_case",
           "memory_run"]

SPHERE_RADIUS = 0.05
#: spheres start uniform in a square of side SPHERE_SPACING * sqrt(n): constant density, ~80% covered, so many overlap
SPHERE_SPACING = 0.1
#: a swarm's spacing: a square of side 0.5 * sqrt(n), about 3% covered
SWARM_SPACING = 0.5


def library_of(side: str) -> str:
    """The package a side imports: both vmas_ros sides (eager and compiled) are ``vmas_ros``."""
    return "vmas" if side == "vmas" else "vmas_ros"


def _make_env(side: str, scenario: str, num_envs: int, kwargs: Mapping, seed: int, compiled: bool = False,
              default_mode: bool = False):
    make = importlib.import_module(library_of(side)).make_env
    extra = {"compile_physics": compiled} if library_of(side) == "vmas_ros" and not default_mode else {}
    return make(scenario, num_envs=num_envs, device="cpu", continuous_actions=True, seed=seed, **dict(kwargs), **extra)


def _action_bounds(env) -> List[tuple]:
    return [(torch.as_tensor(s.low), torch.as_tensor(s.high)) for s in env.action_space.spaces]


def _random_actions(bounds, num_envs: int, steps: int, seed: int) -> List[List[torch.Tensor]]:
    """``steps`` lists of one [num_envs, dim] tensor per agent, uniform in the bounds, from one seeded generator."""
    generator = torch.Generator().manual_seed(seed)
    return [[low + (high - low) * torch.rand(num_envs, low.numel(), generator=generator) for low, high in bounds]
            for _ in range(steps)]


def env_cases(unit: "Unit", steps: int, seed: int) -> Dict[str, Case]:
    """One env per side of ``unit`` (compiled where ``unit.compiled_sides`` says), the same
    actions for all (drawn in the first side's action space, which is vmas_ros's).

    With ``workload.stacked_actions`` the vmas_ros sides get each step's actions as one
    ``[n_agents, num_envs, size]`` tensor (stacked before timing), the form a swarm's
    controller sends; the peer has no such form and gets the same values as its list."""
    w = unit.workload
    ours_default = unit.default_mode and "vmas_ros" in unit.sides
    envs = {side: _make_env(side, w.scenario, unit.num_envs, w.kwargs, seed, side in unit.compiled_sides,
                            default_mode=ours_default and side == "vmas_ros") for side in unit.sides}
    first = envs[unit.sides[0]]
    unit.n_agents = first.n_agents
    dims = {side: [int(low.numel()) for low, _ in _action_bounds(env)] for side, env in envs.items()}
    if len({tuple(d) for d in dims.values()}) > 1:
        raise RuntimeError(f"{w.name}: the sides' action spaces differ: {dims}")
    actions = _random_actions(_action_bounds(first), unit.num_envs, steps, seed)
    stacked = [torch.stack(action) for action in actions] if w.stacked_actions else actions
    cases = {}
    for side, env in envs.items():
        env.reset()

        def run(env=env, side_actions=stacked if library_of(side) == "vmas_ros" else actions):
            for action in side_actions:
                env.step(action)

        warmup_run = None
        if ours_default and side == "vmas_ros":
            warmup_run = through_the_switch(env, run, stacked, on_done=lambda compiled: record_timed_mode(unit, compiled))
        cases[side] = Case(run=run, setup=env.reset, warmup_run=warmup_run, device="cpu")
    return cases


def record_timed_mode(unit: "Unit", compiled: bool) -> None:
    unit.compiled_sides = ("vmas_ros",) if compiled else ()


def spheres_case(side: str, n_agents: int, num_envs: int, steps: int, seed: int, compiled: bool = False,
                 spacing: float = SPHERE_SPACING, settle: bool = False) -> Case:
    """``n_agents`` spheres built with the side's own World/Agent/Sphere, uniform in a square of side
    ``spacing * sqrt(n_agents)`` (overlapping at the default spacing); times World.step.

    ``settle``: one untimed step after the start is set, on every side, so that the timed steps are the
    steady state; otherwise the first one also gathers what was set agent by agent (see docs/swarm.md)."""
    core = importlib.import_module(f"{library_of(side)}.simulator.core")
    world = core.World(batch_dim=num_envs, device="cpu")
    if compiled and library_of(side) == "vmas_ros":
        world.compile_physics()
    for i in range(n_agents):
        world.add_agent(core.Agent(name=f"sphere_{i}", shape=core.Sphere(radius=SPHERE_RADIUS)))
    world.reset(None)
    generator = torch.Generator().manual_seed(seed)
    pos = (torch.rand(n_agents, num_envs, 2, generator=generator) - 0.5) * (spacing * math.sqrt(n_agents))
    force = torch.rand(n_agents, num_envs, 2, generator=generator) * 2 - 1

    def setup():  # the same start and action forces before every run, on every side
        for agent, p, f in zip(world.agents, pos, force):
            agent.set_pos(p.clone(), batch_index=None)
            agent.set_vel(torch.zeros(num_envs, 2), batch_index=None)
            agent.state.force = f.clone()
        if settle:
            world.step()

    def run():
        for _ in range(steps):
            world.step()

    setup()
    return Case(run=run, setup=setup, device="cpu")


# ------------------------------------------------------------------ memory
# Peak RSS is the kernel's high-water mark (VmHWM). It is reset after the imports
# (Linux /proc/self/clear_refs "5") so that a transient peak while importing torch
# cannot hide the env's own use; elsewhere ru_maxrss since process start is used.
# Eager (VMAS_ROS_COMPILE=0), or in the default mode as make_env builds the env without flags.
_MEMORY_SCRIPT = r"""
import gc, json, resource, sys, time
import torch
cfg = json.loads(sys.argv[1])
torch.set_num_threads(cfg["threads"])
from importlib import import_module
make_env = import_module(cfg["module"]).make_env
def status_mb(key):
    try:
        with open("/proc/self/status") as handle:
            for line in handle:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 1024
gc.collect()
try:
    with open("/proc/self/clear_refs", "w") as handle:
        handle.write("5")
except OSError:
    pass
baseline = status_mb("VmRSS")
n = cfg["num_envs"]
env = make_env(cfg["scenario"], num_envs=n, device="cpu", continuous_actions=True, seed=cfg["seed"], **cfg["kwargs"])
env.reset()
g = torch.Generator().manual_seed(cfg["seed"])
bounds = [(torch.as_tensor(s.low), torch.as_tensor(s.high)) for s in env.action_space.spaces]
start = time.perf_counter()
for _ in range(cfg["steps"]):
    env.step([lo + (hi - lo) * torch.rand(n, lo.numel(), generator=g) for lo, hi in bounds])
seconds = time.perf_counter() - start
print(json.dumps({"peak_rss_mb": status_mb("VmHWM"), "baseline_rss_mb": baseline, "seconds": seconds,
                  "n_agents": env.n_agents}))
"""


def memory_run(side: str, unit: "Unit", steps: int, threads: int, seed: int, default_mode: bool = False) -> dict:
    """Peak RSS (MiB) of a fresh interpreter that imports only torch and ``side``'s library and steps it:
    eager, or with ``default_mode`` as make_env builds it without flags."""
    if side == COMPILED_SIDE:
        raise ValueError("memory_30k is measured eager only; there is no compiled memory run")
    config = {"module": library_of(side), "scenario": unit.workload.scenario, "num_envs": unit.num_envs,
              "kwargs": dict(unit.workload.kwargs), "steps": steps, "threads": threads, "seed": seed}
    environ = dict(os.environ)
    root = str(Path(importlib.import_module("vmas_ros").__file__).resolve().parent.parent)  # source checkouts too
    environ["PYTHONPATH"] = os.pathsep.join(p for p in (root, environ.get("PYTHONPATH")) if p)
    if not default_mode:  # the default mode keeps the caller's VMAS_ROS_COMPILE, as the timed points do
        environ["VMAS_ROS_COMPILE"] = "0"
    done = subprocess.run([sys.executable, "-c", _MEMORY_SCRIPT, json.dumps(config)], capture_output=True,
                          text=True, env=environ, check=False)
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode != 0 or not lines:
        raise RuntimeError(f"memory subprocess for {side} failed (exit {done.returncode}): {done.stderr[-800:]}")
    return json.loads(lines[-1])
