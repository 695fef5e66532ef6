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
from typing import Dict, Iterator, List, Optional, Sequence, Tuple

import numpy as np
import torch

FIELDS = ("pos", "vel", "rot", "ang_vel")
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
def _holders(env) -> Iterator[Tuple[str, object]]:
    yield "scenario", env.scenario
    for entity in env.world.entities:
        yield f"entity[{entity.name}]", entity


def _kept_tensors(owner, prefix: str, depth: int = 2) -> Iterator[Tuple[str, torch.Tensor]]:
    """Tensors the scenario keeps in public attributes, one or two levels down (lists, dicts, plain objects).

    Entities, worlds and scenarios met on the way are not entered: they are
    holders of their own, or the engine.
    """
    for key, value in list(vars(owner).items()):
        if key.startswith("_"):
            continue
        path = f"{prefix}.{key}"
        if isinstance(value, torch.Tensor):
            yield path, value
        elif isinstance(value, (list, tuple)) and value and all(isinstance(v, torch.Tensor) for v in value):
            for i, v in enumerate(value):
                yield f"{path}[{i}]", v
        elif isinstance(value, dict) and value and all(isinstance(v, torch.Tensor) for v in value.values()):
            for i, (k, v) in enumerate(value.items()):  # keys that are objects (e.g. agents) by position
                yield f"{path}{{{k if isinstance(k, (str, int)) else f'#{i}'}}}", v
        elif depth > 1 and hasattr(value, "__dict__") and not _is_engine_object(value):
            yield from _kept_tensors(value, path, depth - 1)


def _is_engine_object(value) -> bool:
    names = {cls.__name__ for cls in type(value).__mro__}
    return bool(names & {"Entity", "World", "BaseScenario", "Environment", "Shape"}) or isinstance(value, types.ModuleType)


def capture_start(env) -> Dict[str, torch.Tensor]:
    """Entity states and kept tensors after a reset, keyed by path."""
    start = {}
    for entity in env.world.entities:
        for field in FIELDS:
            start[f"{STATE}[{entity.name}].{field}"] = getattr(entity.state, field).clone()
    for prefix, holder in _holders(env):
        for path, value in _kept_tensors(holder, f"{KEPT}:{prefix}"):
            start[path] = value.clone()
    return start


def _assign(owner, path: str, value: torch.Tensor) -> bool:
    """Write ``value`` in place of the tensor at ``path`` below ``owner``; False where ours has no such place."""
    parts = re.findall(r"\.(\w+)|\[(\d+)\]|\{([^}]*)\}", path)
    target = owner
    for attr, index, key in parts[:-1]:
        target = getattr(target, attr, None) if attr else (target[int(index)] if index else target.get(key))
        if target is None:
            return False
    attr, index, key = parts[-1]
    if attr:
        if not isinstance(getattr(target, attr, None), torch.Tensor):
            return False
        setattr(target, attr, value.clone())
    elif index:
        target[int(index)] = value.clone()
    elif key.startswith("#"):
        target[list(target)[int(key[1:])]] = value.clone()
    else:
        target[key] = value.clone()
    return True


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
    holders = dict(_holders(env))
    missing = []
    for path, value in start.items():
        if path.startswith(KEPT):
            rest = path[len(KEPT) + 1:]  # "scenario.x..." or "entity[name].x..."
            holder_name = rest[: rest.index("]") + 1] if rest.startswith("entity[") else "scenario"
            if not _assign(holders[holder_name], rest[len(holder_name):], value):
                missing.append(path)
    return missing


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
