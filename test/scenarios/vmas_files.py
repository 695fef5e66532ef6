"""VMAS's own scenario files, replayed on our engine: the trace recorder.

VMAS 1.5.2 ships its scenarios as Python files. A VMAS user's own scenario is
such a file too, so the strongest check of our engine's compatibility is to run
VMAS's files on it, with ``vmas`` imports re-pointed to ``vmas_ros``, and to
require VMAS's trajectories. The files are read from the installed ``vmas``
package when the test runs; none is kept in this repository.

Each side runs in a process of its own (``python -m test.scenarios.vmas_files``):
VMAS keeps its RNG in class attributes and, once ``vmas`` can resolve to
vmas_ros, two engines named ``vmas`` cannot share one interpreter. A side
writes one trace per scenario:

* ``vmas`` side: VMAS's env from the file, reset with the seed; the *start* is
  recorded (every entity's state, every tensor the scenario keeps on itself or
  on its entities, and the RNG streams), then ``steps`` steps with actions
  drawn from a generator seeded with the seed;
* ``vmas_ros`` side: our env from the re-pointed file, reset, then given the
  ``vmas`` side's start (so per-env draws such as goals coincide) and stepped
  with the same actions.

Every step records the entities' states, observations, rewards, dones and
infos; ``test_vmas_files.py`` compares the two traces.
"""
from __future__ import annotations

import argparse
import importlib.machinery
import random
import re
import sys
import types
import warnings
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np
import torch

from vmas_ros.testing.state import FIELDS, assign_kept, capture_kept

#: what a side records after the reset, under these path prefixes
STATE, KEPT = "state", "kept"
_IMPORT = re.compile(r"^(\s*)(from|import)\s+vmas\b", re.MULTILINE)


def vmas_scenario_files() -> Dict[str, Path]:
    """Every scenario file the installed ``vmas`` ships, by scenario name (found without importing vmas)."""
    spec = importlib.machinery.PathFinder.find_spec("vmas")  # the real one, even under install_as_vmas()
    if spec is None or not spec.submodule_search_locations:
        raise RuntimeError("the vmas package is not installed: pip install vmas==1.5.2")
    root = Path(list(spec.submodule_search_locations)[0]) / "scenarios"
    return {p.stem: p for p in sorted(root.rglob("*.py")) if p.name != "__init__.py"}


def repointed_source(path: Path) -> str:
    """The file's source with every ``vmas`` import re-pointed to ``vmas_ros``."""
    text = path.read_text()
    text = _IMPORT.sub(lambda m: f"{m.group(1)}{m.group(2)} vmas_ros", text)
    return text.replace("import vmas_ros\n", "import vmas_ros as vmas\n")


def load_repointed(name: str, path: Path) -> types.ModuleType:
    """Execute the re-pointed file as a module of its own (registered, for dataclasses and pickling)."""
    module = types.ModuleType(f"vmas_file_{name}")
    module.__file__ = str(path)  # files that read data beside themselves find VMAS's
    sys.modules[module.__name__] = module
    exec(compile(repointed_source(path), str(path), "exec"), module.__dict__)
    return module


# ------------------------------------------------------------ scenario state
def capture_start(env) -> Dict[str, torch.Tensor]:
    """Entity states and kept tensors after a reset, keyed by path.

    The kept tensors are those ``vmas_ros.testing.state.capture_kept`` finds
    (the same walk ``check_scenario`` copies VMAS's scenario state with), and
    ``apply_start`` writes them with its ``assign_kept``.
    """
    start = {}
    for entity in env.world.entities:
        for field in FIELDS:
            start[f"{STATE}[{entity.name}].{field}"] = getattr(entity.state, field).clone()
    for path, value in capture_kept(env).items():
        start[f"{KEPT}:{path}"] = value
    return start


def set_states(env, states: Dict[str, torch.Tensor], keep_joint_rotations: bool) -> None:
    """Give our entities the states ``{"name.field": [B, ...]}``.

    Moving a joint's end re-places its rod (atan2 of the ends, so an angle
    past pi comes back wrapped) and re-infers the rotation its rigid ends
    keep: the rods get their own states back in a second pass. Mid-run
    (``keep_joint_rotations``) the constraints keep the rotations they had,
    as VMAS's do, which no step moves; at the start they are inferred as a
    reset infers them.
    """
    entities = {e.name: e for e in env.world.entities}
    constraints = env.world.joints
    held = [c.fixed_rotation for c in constraints]
    for _ in range(2):
        for path, value in states.items():
            name, field = path.rsplit(".", 1)
            if not torch.equal(getattr(entities[name].state, field), value):
                getattr(entities[name], f"set_{field}")(value.clone(), batch_index=None)
    for constraint, rotation in zip(constraints, held if keep_joint_rotations else ()):
        constraint.fixed_rotation = rotation


def apply_start(env, start: Dict[str, torch.Tensor]) -> List[str]:
    """Give our env the recorded start; returns the kept-tensor paths ours has no place for."""
    set_states(env, {path[len(STATE) + 1:].replace("].", "."): value
                     for path, value in start.items() if path.startswith(STATE)}, keep_joint_rotations=False)
    return [path for path, value in start.items()
            if path.startswith(KEPT) and not assign_kept(env, path[len(KEPT) + 1:], value)]


def capture_rng(env) -> Dict[str, torch.Tensor]:
    """A VMAS env's RNG streams as tensors: VMAS swaps its own torch, numpy and Python
    states (a class attribute of its Environment) in around every call into the scenario."""
    torch_state, numpy_state, python_state = type(env).vmas_random_state
    kind, keys, pos, has_gauss, gauss = numpy_state
    version, internal, extra = python_state
    return {
        "torch": torch_state.clone(), "numpy_keys": torch.from_numpy(keys.astype(np.int64)),
        "numpy_rest": torch.tensor([pos, has_gauss, gauss], dtype=torch.float64),
        "python": torch.tensor([version, *internal, -1 if extra is None else extra], dtype=torch.int64),
    }


def give_rng(env, rng: Dict[str, torch.Tensor]) -> None:
    """Make ``rng`` our env's own RNG state (see ``Environment._own_rng``)."""
    pos, has_gauss, gauss = rng["numpy_rest"].tolist()
    python = rng["python"].tolist()
    env._rng_state.update(
        torch=rng["torch"],
        numpy=("MT19937", rng["numpy_keys"].numpy().astype(np.uint32), int(pos), int(has_gauss), gauss),
        python=(python[0], tuple(python[1:-1]), None if python[-1] == -1 else python[-1]),
    )


# -------------------------------------------------------------------- stepping
def actions_for(env, gen: torch.Generator) -> List[torch.Tensor]:
    """One step's actions, [B, action size] per agent: forces uniform in the agent's range, messages in [0, 1]."""
    actions = []
    for agent in env.agents:
        u_range = agent.action.u_range_tensor.cpu()
        draw = torch.rand(env.num_envs, env.get_agent_action_size(agent), generator=gen)
        force, message = draw[:, : len(u_range)], draw[:, len(u_range):]
        actions.append(torch.cat([(force * 2 - 1) * u_range, message], dim=1))
    return actions


def _as_list(values) -> list:
    return list(values.values()) if isinstance(values, dict) else list(values)


def record(env, seed: int, steps: int, reference: Optional[List[Dict[str, torch.Tensor]]] = None) -> Dict[str, list]:
    """``steps`` steps from the env's current state: per step states, obs, rewards, dones, infos.

    With ``reference`` (the other side's per-step states) every step after the
    first starts from the other side's state after the step before: each step
    is then compared from identical inputs (see ``parity.run_lockstep``'s resync).
    """
    gen = torch.Generator().manual_seed(seed)
    trace = {"states": [], "obs": [], "rews": [], "dones": [], "infos": []}
    for step in range(steps):
        if reference is not None and step:
            set_states(env, reference[step - 1], keep_joint_rotations=True)
        obs, rews, dones, infos = env.step(actions_for(env, gen))
        trace["states"].append({f"{e.name}.{f}": getattr(e.state, f).clone() for e in env.world.entities for f in FIELDS})
        trace["obs"].append([o.clone() for o in _as_list(obs)])
        trace["rews"].append([r.clone() for r in _as_list(rews)])
        trace["dones"].append(dones.clone())
        trace["infos"].append([{k: v.clone() for k, v in info.items() if isinstance(v, torch.Tensor)}
                               for info in _as_list(infos)])
    return trace


def run_side(side: str, names: List[str], num_envs: int, steps: int, seed: int, out: Path,
             resync: Sequence[str] = ()) -> None:
    """Record every scenario in ``names`` on ``side``; the vmas_ros side needs the vmas side's traces in ``out``.

    Scenarios named in ``resync`` are recorded on the vmas_ros side step by step from the vmas side's states.
    """
    files = vmas_scenario_files()
    torch.set_num_threads(1)
    warnings.simplefilter("ignore")
    for name in names:
        target = out / f"{name}.{side}.pt"
        try:
            if side == "vmas":
                import vmas

                env = vmas.make_env(name, num_envs=num_envs, device="cpu", seed=seed)
                start = capture_start(env)
                rng = capture_rng(env)
                missing: List[str] = []
            else:
                import vmas_ros

                module = load_repointed(name, files[name])
                env = vmas_ros.make_env(module.Scenario(), num_envs=num_envs, device="cpu", seed=seed)
                recorded = torch.load(out / f"{name}.vmas.pt", weights_only=True)
                missing = apply_start(env, recorded["start"])
                give_rng(env, recorded["rng"])  # the same noise from here on
                start, rng = capture_start(env), recorded["rng"]
            reference = recorded["trace"]["states"] if side == "vmas_ros" and name in resync else None
            trace = record(env, seed, steps, reference)
            torch.save({"start": start, "rng": rng, "missing": missing, "trace": trace, "error": None}, target)
        except Exception as error:  # recorded, so the test names the scenario and the error
            torch.save({"error": f"{type(error).__name__}: {error}"}, target)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--side", choices=("vmas", "vmas_ros"), required=True)
    parser.add_argument("--scenarios", nargs="+", required=True)
    parser.add_argument("--num-envs", type=int, default=4)
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--resync", nargs="*", default=(), help="scenarios stepped from the vmas side's states")
    args = parser.parse_args(argv)
    run_side(args.side, args.scenarios, args.num_envs, args.steps, args.seed, args.out, args.resync)
    return 0


if __name__ == "__main__":
    sys.exit(main())
