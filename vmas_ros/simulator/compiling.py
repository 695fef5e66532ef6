"""torch.compile for one world: private code copies, and scenario kernels that follow the world's choice.

``World.compile_physics()`` turns the compiled path on for a world (off by
default: compiling takes seconds and needs a C++ compiler on the CPU). Scenario
code whose hot part is a pure function of tensors wraps it in
:class:`WorldKernel`: while the world's physics is eager the function runs as
it is, and once the world compiles, the function is compiled too, so that one
flag covers the whole step (at a few envs each compiled call replaces dozens
of small tensor calls; on a GPU the same graphs are what CUDA graphs capture).
"""
from __future__ import annotations

import functools
import types
from typing import Callable, Optional

import torch

__all__ = ["own_copy", "compile_for_world", "WorldKernel"]


def own_copy(fn: Callable) -> Callable:
    """``fn`` with a code object of its own, for one world's ``torch.compile`` (also partials and bound methods).

    Dynamo keeps compiled graphs per code object and gives up (runs eagerly)
    after eight recompilations of one; every world's tables are guarded on, so
    without a private copy the ninth compiled world in a process (a test
    session, a sweep) would silently lose its compiled step.
    """
    if isinstance(fn, functools.partial):
        return functools.partial(own_copy(fn.func), *fn.args, **fn.keywords)
    if isinstance(fn, types.MethodType):
        return types.MethodType(own_copy(fn.__func__), fn.__self__)
    copy = types.FunctionType(fn.__code__.replace(), fn.__globals__, fn.__name__, fn.__defaults__, fn.__closure__)
    copy.__kwdefaults__ = fn.__kwdefaults__
    return copy


def compile_for_world(fn: Callable, mode: Optional[str]) -> Callable:
    """A compiled private copy of ``fn`` (fixed shapes: a new batch size compiles again)."""
    return torch.compile(own_copy(fn), dynamic=False, mode=mode)


class WorldKernel:
    """A pure tensor function of a scenario, compiled when (and only when) its world compiles its physics.

    The function must not read mutable Python state that changes between
    calls (guards would recompile on every change); pass tensors in instead.
    """

    def __init__(self, world, fn: Callable) -> None:
        self._world = world
        self._fn = fn
        self._compiled: Optional[Callable] = None
        self._mode: Optional[str] = None

    def __call__(self, *args, **kwargs):
        world = self._world
        if not world.physics_compiled:
            return self._fn(*args, **kwargs)
        if self._compiled is None or self._mode != world.compile_mode:
            self._compiled, self._mode = compile_for_world(self._fn, world.compile_mode), world.compile_mode
        return self._compiled(*args, **kwargs)
