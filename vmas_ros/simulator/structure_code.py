"""Functions made for one fixed structure of arguments: one takes it apart, one puts it together.

A direct graph (:mod:`vmas_ros.simulator.direct_graph`) is called with the
same structure of arguments on every step: a state dataclass, a tuple of
action tensors, a None. Walking that structure generically costs several
Python calls per node and per step, which at one env is a visible share of
the step. So once the structure is known, closures are made for it, each
node's work decided in advance (C-level ``itemgetter``/``attrgetter`` reads,
one type check per container): ``picker`` returns the tensors in order (or
None when the arguments no longer have that structure, and the caller then
walks them generically), and ``builder`` turns the compiled code's flat
outputs back into the structure it returns.

Structures are those of ``direct_graph._flatten``: ``TENSOR`` (a slot),
``("C", value)`` (a value kept as is), ``(tuple | list, [items])`` and
``(dataclass type, {field: item})``.
"""
from __future__ import annotations

from operator import attrgetter, itemgetter
from typing import Callable, List, Optional, Sequence

from torch import Tensor

__all__ = ["PRIMITIVES", "TENSOR", "picker", "builder"]

TENSOR = "T"  # a slot for the next tensor in a flattened structure
#: Python values a structure holds as they are (compared by value; other objects by type)
PRIMITIVES = (int, float, bool, str, type(None))

#: ``pick(value, out)``: append ``value``'s tensors to ``out``; False when ``value`` has another structure
Pick = Callable[[object, list], bool]


def _getter(make, keys: Sequence) -> Callable[[object], tuple]:
    """``value -> tuple of value's keys`` through one C-level getter (a 1-tuple for a single key)."""
    if len(keys) == 1:
        single = make(keys[0])
        return lambda value: (single(value),)
    return make(*keys)


def _tensors_only(kind: type, get: Callable[[object], tuple], count: int, sized: bool) -> Pick:
    def pick(value, out: list) -> bool:
        if type(value) is not kind or (sized and len(value) != count):
            return False
        values = get(value)
        for item in values:
            if not isinstance(item, Tensor):
                return False
        out.extend(values)
        return True
    return pick


def _nested(kind: type, get: Callable[[object], tuple], count: int, sized: bool, parts: List[Pick]) -> Pick:
    def pick(value, out: list) -> bool:
        if type(value) is not kind or (sized and len(value) != count):
            return False
        for part, item in zip(parts, get(value)):
            if not part(item, out):
                return False
        return True
    return pick


def _pick_node(node) -> Pick:
    if node == TENSOR:
        def pick(value, out: list) -> bool:
            if not isinstance(value, Tensor):
                return False
            out.append(value)
            return True
        return pick
    kind, content = node
    if kind == "C":  # a constant: primitives by value, other objects by type, as the signature keys them
        expected = type(content)
        if expected in PRIMITIVES:
            return lambda value, out: type(value) is expected and value == content
        return lambda value, out: type(value) is expected
    if kind in (tuple, list):
        keys, sized = range(len(content)), True
        get = _getter(itemgetter, list(keys)) if content else (lambda value: ())
        items = content
    else:
        keys, sized = list(content), False
        get = _getter(attrgetter, keys)
        items = list(content.values())
    if all(item == TENSOR for item in items) and items:
        return _tensors_only(kind, get, len(items), sized)
    return _nested(kind, get, len(items), sized, [_pick_node(item) for item in items])


def picker(structure, positions: Optional[Sequence[int]] = None) -> Callable[[tuple], Optional[list]]:
    """``pick(args)``: the tensors of ``args`` in the order ``_flatten`` gives them, or None when
    ``args`` does not have ``structure`` (another container type or length, another constant).

    ``positions``: ``structure`` is that of the tuple of ``args[position]`` for each position (the
    arguments that vary from call to call); the others are not looked at."""
    if positions is None:
        top, needed = _pick_node(structure), 0
        select = lambda args: args  # noqa: E731
    else:
        kind, items = structure
        if kind is not tuple or len(items) != len(positions):
            raise AssertionError(f"expected the structure of {len(positions)} arguments, got {structure!r}")
        top, needed = _pick_node(structure), max(positions, default=-1) + 1
        select = _getter(itemgetter, list(positions)) if positions else (lambda args: ())

    def pick(args) -> Optional[list]:
        if len(args) < needed:
            return None
        out: list = []
        return out if top(select(args), out) else None
    return pick


def _build_node(node, position: List[int]) -> Callable[[Sequence], object]:
    if node == TENSOR:
        index = position[0]
        position[0] += 1
        return itemgetter(index)
    kind, content = node
    if kind == "C":
        return lambda outputs: content
    if kind in (tuple, list):
        parts = [_build_node(item, position) for item in content]
        if kind is tuple:
            return lambda outputs: tuple([part(outputs) for part in parts])
        return lambda outputs: [part(outputs) for part in parts]
    names = list(content)
    parts = [_build_node(item, position) for item in content.values()]
    return lambda outputs: kind(**{name: part(outputs) for name, part in zip(names, parts)})


def builder(structure) -> Callable[[Sequence], object]:
    """``build(outputs)``: ``structure`` with its tensor slots filled from ``outputs`` in order."""
    return _build_node(structure, [0])
