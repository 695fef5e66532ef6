"""Straight-line code that takes one fixed structure of arguments apart, and puts one together.

A direct graph (:mod:`vmas_ros.simulator.direct_graph`) is called with the
same structure of arguments on every step: a state dataclass, a tuple of
action tensors, a None. Walking that structure generically costs a Python
call per node and per step, which at one env is a visible share of the step.
So once the structure is known, it is written out as a function of its own,
the way :mod:`dataclasses` writes ``__init__``: ``picker`` returns the
tensors in order (or None when the arguments no longer have that structure,
and the caller then walks them generically), and ``builder`` turns the
compiled code's flat outputs back into the structure it returns.

Structures are those of ``direct_graph._flatten``: ``TENSOR`` (a slot),
``("C", value)`` (a value kept as is), ``(tuple | list, [items])`` and
``(dataclass type, {field: item})``.
"""
from __future__ import annotations

from typing import Callable, List, Optional, Sequence

import torch

__all__ = ["TENSOR", "picker", "builder"]

TENSOR = "T"  # a slot for the next tensor in a flattened structure
_PRIMITIVE = (int, float, bool, str, type(None))


class _Writer:
    """Lines of one generated function, and the objects its code refers to by name."""

    def __init__(self) -> None:
        self.lines: List[str] = []
        self.names: dict = {"Tensor": torch.Tensor}
        self._count = 0

    def fresh(self, prefix: str) -> str:
        self._count += 1
        return f"{prefix}{self._count}"

    def refer(self, value) -> str:
        name = self.fresh("k")
        self.names[name] = value
        return name

    def function(self, name: str, argument: str, result: str) -> Callable:
        body = "\n".join(f"    {line}" for line in self.lines + [f"return {result}"])
        code = f"def {name}({argument}):\n{body}\n"
        exec(compile(code, f"<{name}>", "exec"), self.names)  # noqa: S102 - our own generated source
        return self.names[name]


def picker(structure, count: int, positions: Optional[Sequence[int]] = None) -> Callable[[tuple], Optional[list]]:
    """``pick(args)``: the ``count`` tensors of ``args`` in the order ``_flatten`` gives them, or None when
    ``args`` does not have ``structure`` (another container type or length, another constant).

    ``positions``: ``structure`` is that of the tuple of ``args[position]`` for each position (the
    arguments that vary from call to call); the others are not looked at."""
    writer = _Writer()
    slots: List[str] = []

    def visit(node, expression: str) -> None:
        if node == TENSOR:
            slot = writer.fresh("t")
            writer.lines += [f"{slot} = {expression}", f"if not isinstance({slot}, Tensor): return None"]
            slots.append(slot)
            return
        kind, content = node
        if kind == "C":  # a constant: primitives by value, other objects by type, as the signature keys them
            if type(content) in _PRIMITIVE:
                writer.lines.append(f"if type({expression}) is not {writer.refer(type(content))} or "
                                    f"{expression} != {writer.refer(content)}: return None")
            else:
                writer.lines.append(f"if type({expression}) is not {writer.refer(type(content))}: return None")
            return
        name = writer.fresh("v")
        writer.lines += [f"{name} = {expression}", f"if type({name}) is not {writer.refer(kind)}: return None"]
        if kind in (tuple, list):
            writer.lines.append(f"if len({name}) != {len(content)}: return None")
            for index, item in enumerate(content):
                visit(item, f"{name}[{index}]")
        else:
            for field, item in content.items():
                visit(item, f"{name}.{field}")

    if positions is None:
        visit(structure, "args")
    else:
        kind, items = structure
        if kind is not tuple or len(items) != len(positions):
            raise AssertionError(f"expected the structure of {len(positions)} arguments, got {structure!r}")
        writer.lines.append(f"if len(args) <= {max(positions, default=-1)}: return None")
        for position, item in zip(positions, items):
            visit(item, f"args[{position}]")
    if len(slots) != count:
        raise AssertionError(f"structure holds {len(slots)} tensors, expected {count}")
    return writer.function("pick", "args", "[" + ", ".join(slots) + "]")


def builder(structure) -> Callable[[Sequence], object]:
    """``build(outputs)``: ``structure`` with its tensor slots filled from ``outputs`` in order."""
    writer = _Writer()
    position = [0]

    def expression(node) -> str:
        if node == TENSOR:
            position[0] += 1
            return f"outputs[{position[0] - 1}]"
        kind, content = node
        if kind == "C":
            return writer.refer(content)
        if kind is tuple:
            items = [expression(item) for item in content]
            return "(" + "".join(f"{item}, " for item in items) + ")"
        if kind is list:
            return "[" + ", ".join(expression(item) for item in content) + "]"
        fields = ", ".join(f"{field}={expression(item)}" for field, item in content.items())
        return f"{writer.refer(kind)}({fields})"

    result = expression(structure)
    return writer.function("build", "outputs", result)
