"""What an env holds, as named tensors: the pieces the checks compare and copy.

Two kinds of state make up an env at a given moment:

* the entities' physical state, ``"<entity name>.<field>"`` for the fields
  ``FIELDS`` (``entity_state``), each [B, 2] or [B, 1];
* the tensors a scenario keeps on itself or on its entities in public
  attributes (goals, shaping terms, secrets), by path (``kept_tensors``):
  ``"scenario.goal_pos"``, ``"entity[agent_0].pos_shaping"``,
  ``"scenario.targets[2]"``, ``"scenario.shaping{agent_0}"``.

Both VMAS's envs and ours are read the same way (the names are looked up, not
the classes), so one env's kept tensors can be copied into the other's
(``copy_kept_tensors``, ``assign_kept``), and one env's rows can be compared
before and after an operation (``changed_rows``).
"""
from __future__ import annotations

import re
import types
from typing import Dict, Iterator, List, Optional, Sequence, Tuple

import torch

__all__ = [
    "FIELDS", "entity_state", "holders", "kept_tensors", "capture_kept", "per_env", "assign_kept",
    "copy_kept_tensors", "changed_rows",
]

#: the state fields of every entity, [B, 2] (pos, vel) or [B, 1] (rot, ang_vel)
FIELDS = ("pos", "vel", "rot", "ang_vel")


def entity_state(env, fields: Sequence[str] = FIELDS) -> Dict[str, torch.Tensor]:
    """A copy of every entity's ``fields``, keyed ``"<entity name>.<field>"``, each [B, ...]."""
    return {f"{e.name}.{f}": getattr(e.state, f).clone() for e in env.world.entities for f in fields}


def holders(env) -> Iterator[Tuple[str, object]]:
    """Where a scenario keeps its own tensors: the scenario itself, then each entity (``entity[<name>]``)."""
    yield "scenario", env.scenario
    for entity in env.world.entities:
        yield f"entity[{entity.name}]", entity


def is_engine_object(value) -> bool:
    """Entities, worlds, scenarios, envs and shapes (by class name, VMAS's or ours) and modules."""
    names = {cls.__name__ for cls in type(value).__mro__}
    engine = {"Entity", "World", "BaseScenario", "Environment", "Shape"}
    return bool(names & engine) or isinstance(value, types.ModuleType)


def kept_tensors(owner, prefix: str, depth: int = 2) -> Iterator[Tuple[str, torch.Tensor]]:
    """Tensors ``owner`` keeps in public attributes, one or two levels down (lists, dicts, plain objects).

    Yields ``(path, tensor)`` with the tensor itself (not a copy). Entities,
    worlds and scenarios met on the way are not entered: they are holders of
    their own, or the engine. Dict keys that are not strings or ints (agents,
    for instance) are named by position, ``{#i}``.
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
            for i, (k, v) in enumerate(value.items()):
                yield f"{path}{{{k if isinstance(k, (str, int)) else f'#{i}'}}}", v
        elif depth > 1 and hasattr(value, "__dict__") and not is_engine_object(value):
            yield from kept_tensors(value, path, depth - 1)


def capture_kept(env, clone: bool = True) -> Dict[str, torch.Tensor]:
    """Every tensor the env's scenario keeps (see ``kept_tensors``), keyed by ``<holder><path>``.

    With ``clone=False`` the values are the scenario's own tensors, so that
    writing into them (``copy_``) changes the scenario.
    """
    kept = {}
    for prefix, holder in holders(env):
        for path, value in kept_tensors(holder, prefix):
            kept[path] = value.clone() if clone else value
    return kept


def per_env(tensors: Dict[str, torch.Tensor], num_envs: int) -> Dict[str, torch.Tensor]:
    """The tensors of ``tensors`` that hold one row per env, with that dimension moved first: [B, ...].

    A tensor is taken when exactly one of its dimensions has size
    ``num_envs``. One with several (an [n_agents, B] tensor when n_agents = B)
    is left out: which of them is the batch cannot be told from the shape.
    """
    rows = {}
    for key, value in tensors.items():
        dims = [d for d, size in enumerate(value.shape) if size == num_envs]
        if len(dims) == 1:
            rows[key] = value.movedim(dims[0], 0)
    return rows


def assign_kept(env, path: str, value: torch.Tensor) -> bool:
    """Put a copy of ``value`` in place of the tensor at ``path`` (a ``capture_kept`` key) of ``env``'s scenario.

    The attribute, list item or dict entry is rebound to the copy (the old
    tensor is not written). Returns False, changing nothing, where ``env``
    has no tensor at that path.
    """
    holder_name = path[: path.index("]") + 1] if path.startswith("entity[") else "scenario"
    target = dict(holders(env)).get(holder_name)
    parts = re.findall(r"\.(\w+)|\[(\d+)\]|\{([^}]*)\}", path[len(holder_name):])
    if target is None or not parts:
        return False
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


def copy_kept_tensors(source, target) -> List[str]:
    """Write every tensor ``source``'s scenario keeps into ``target``'s tensor at the same path.

    In place (``copy_``) where it can, so tensors ``target`` shares with other
    objects stay shared; a tensor that cannot be written in place (an
    expanded view) is replaced (``assign_kept``). A path is copied only where
    ``target`` keeps a tensor of the same shape and dtype there; returns the
    paths that were not copied, sorted.
    """
    theirs = capture_kept(source)
    mine = capture_kept(target, clone=False)
    missing = []
    for path, value in theirs.items():
        place: Optional[torch.Tensor] = mine.get(path)
        if place is None or place.shape != value.shape or place.dtype != value.dtype:
            missing.append(path)
            continue
        try:
            place.copy_(value.to(place.device))
        except RuntimeError:  # several elements of ``place`` share one memory location
            assign_kept(target, path, value.to(place.device))
    return sorted(missing)


def changed_rows(before: Dict[str, torch.Tensor], after: Dict[str, torch.Tensor], rows: torch.Tensor) -> List[str]:
    """The keys whose tensor differs (bitwise, NaN differing from itself) in any of ``rows``.

    ``rows`` is a [B] bool mask of the first dimension; a key missing from
    ``after``, or whose shape changed, counts as changed.
    """
    changed = []
    for key, value in before.items():
        other, here = after.get(key), rows.to(value.device)
        if other is None or other.shape != value.shape or not torch.equal(other[here], value[here].to(other.device)):
            changed.append(key)
    return changed
