"""torch.compile for one world: private code copies, and scenario kernels that follow the world's choice.

``World.compile_physics()`` turns the compiled path on for a world (a World
built directly stays eager; ``make_env`` turns it on where a compiler works,
see :mod:`vmas_ros.simulator.compile_default`). Scenario
code whose hot part is a pure function of tensors wraps it in
:class:`WorldKernel`: while the world's physics is eager the function runs as
it is, and once the world compiles, the function is compiled too, so that one
flag covers the whole step (at a few envs each compiled call replaces dozens
of small tensor calls; on a GPU the same graphs are what CUDA graphs capture).
"""
from __future__ import annotations

import functools
import inspect
import logging
import re
import sys
import types
from typing import Callable, Dict, Hashable, Optional, Sequence

import torch

from vmas_ros.simulator.background_compile import BackgroundCompiler, copy_inputs
from vmas_ros.simulator.direct_graph import DirectGraph, NotTraceable

_log = logging.getLogger("vmas_ros")

__all__ = ["compile_failed", "own_copy", "compile_for_world", "LayoutCompiled", "StateFunction", "WorldKernel"]


def compile_failed(error: BaseException) -> bool:
    """Whether ``error`` is torch.compile failing to build code (no working compiler, say), not the
    function's own error. Looked up lazily: importing torch._dynamo costs seconds, and only a compiled
    call can raise it."""
    dynamo_errors = sys.modules.get("torch._dynamo.exc")
    return dynamo_errors is not None and isinstance(error, dynamo_errors.BackendCompilerFailed)


def own_copy(fn: Callable) -> Callable:
    """``fn`` with a code object of its own, for one world's ``torch.compile`` (also partials and bound methods).

    Dynamo keeps compiled graphs per code object and gives up (runs eagerly)
    after eight recompilations of one; every world's tables are guarded on, so
    without a private copy the ninth compiled world in a process (a test
    session, a sweep) would silently lose its compiled step.
    """
    if isinstance(fn, functools.partial):
        # torch.compile runs a partial (which has no frame) through one wrapper function shared by every
        # partial in the process: guards cut to the arguments would then let one partial's compiled code
        # run with another's constants. A function of our own gives each its own code object.
        return _calling(own_copy(fn.func), fn.args, fn.keywords)
    if isinstance(fn, types.MethodType):
        return types.MethodType(own_copy(fn.__func__), fn.__self__)
    copy = types.FunctionType(fn.__code__.replace(), fn.__globals__, fn.__name__, fn.__defaults__, fn.__closure__)
    copy.__kwdefaults__ = fn.__kwdefaults__
    return copy


def _calling(func: Callable, bound_args: tuple, bound_keywords: dict) -> Callable:
    """``func`` with ``bound_args``/``bound_keywords`` bound, as a plain function with a code object of its own.

    Its own parameters are named ``args``/``kwargs``: guards on the call's arguments keep those names
    (see :func:`_direct_arguments`), the bound constants are reached through the closure (names of
    their own, :data:`_BOUND`, whose guards the argument filter drops)."""
    _bound_func, _bound_args, _bound_keywords = func, bound_args, bound_keywords

    def call(*args, **kwargs):
        return _bound_func(*_bound_args, *args, **_bound_keywords, **kwargs)

    return own_copy(call)


def compile_for_world(fn: Callable, mode: Optional[str], arguments_only: bool = False,
                      background: Optional[BackgroundCompiler] = None) -> Callable:
    """A compiled private copy of ``fn`` (fixed shapes: a new batch size compiles again).

    ``arguments_only``: check only what is passed in on each call (see :func:`_direct_arguments`), for
    pure functions whose other inputs (a partial's constants, a bound method's attributes) never change.
    ``background``: compile there, running ``fn`` eagerly until it is done (arguments_only only).
    """
    if not arguments_only:
        return torch.compile(own_copy(fn), dynamic=False, mode=mode)
    return _OneGraph(fn, mode, _direct_arguments, background)


#: guards that cover process-wide state (grad mode, default device, ...): cheap, and never implied by a layout
_GLOBAL_GUARDS = frozenset({"GRAD_MODE", "GLOBAL_STATE", "DEFAULT_DEVICE", "TORCH_FUNCTION_STATE",
                            "DETERMINISTIC_ALGORITHMS", "AUTOGRAD_SAVED_TENSORS_HOOKS", "SHAPE_ENV"})
#: the guard source of an argument of the call itself: a parameter name, or a partial's ``args[i]``
_ARGUMENT = re.compile(r"(args\[\d+\]|[A-Za-z_]\w*)")
#: the locals of :func:`_calling`'s function that hold a partial's function and bound constants
_BOUND = frozenset({"_bound_func", "_bound_args", "_bound_keywords"})


def _direct_arguments(entries) -> list:
    """A ``guard_filter_fn`` keeping the guards on the call's own arguments and the global ones: not those
    on a partial's bound constants or a bound method's attributes (a lidar kernel has dozens)."""
    return [entry.guard_type in _GLOBAL_GUARDS or (bool(_ARGUMENT.fullmatch(entry.name)) and entry.name not in _BOUND)
            for entry in entries]


def _guards_on(arguments: Sequence[str]) -> Callable:
    """A ``guard_filter_fn`` that keeps the guards on ``arguments`` (and their items) and the global ones."""
    prefixes = tuple(arguments)

    def keep(entries) -> list:
        return [entry.guard_type in _GLOBAL_GUARDS or
                (entry.guard_type in ("TENSOR_MATCH", "DUPLICATE_INPUT") and entry.name.startswith(prefixes))
                for entry in entries]

    return keep


class _OneGraph:
    """``fn`` compiled as one graph with cut guards, or, if it cannot be one graph, compiled as usual.

    Guards are cut (``guard_filter``) only where the whole function is one
    frame (``fullgraph=True``): after a graph break the resumed frames are
    other, shared code objects whose guards name their own locals, and
    cutting those would let code compiled for one world run on another's
    shapes. A function that breaks falls back to ``torch.compile`` with all of
    its guards (correct, slower; the compiled-path tests require one graph).

    With a ``background`` compiler, the first call hands a copy of its inputs
    to it and every call runs ``fn`` eagerly until that compile is done and
    the world has switched, between two steps, to its compiled functions all
    at once (:mod:`vmas_ros.simulator.background_compile`).
    """

    def __init__(self, fn: Callable, mode: Optional[str], guard_filter: Callable,
                 background: Optional[BackgroundCompiler] = None, varying: Optional[Sequence[int]] = None) -> None:
        self._fn, self._mode, self._guard_filter = fn, mode, guard_filter
        #: the direct graph while it serves; None once it declined (torch.compile from then on)
        self._direct: Optional[DirectGraph] = DirectGraph(fn, varying) if mode is None else None
        self._compiled: Optional[Callable] = None  # torch.compile's copy, made only if needed
        self.one_graph: Optional[bool] = None  # known after the first call
        self._background = background
        self._eager_until_compiled = background is not None
        self._submitted = False
        self._ready = False  # (background) its compile is done; it runs compiled once the world has switched

    def __call__(self, *args, **kwargs):
        if self._eager_until_compiled:
            if self._ready and self._background.released:  # the world switched, between two steps
                self._eager_until_compiled = False
                return self._compiled_call(*args, **kwargs)
            if self._submitted:
                return self._fn(*args, **kwargs)
            # the inputs are copied before the eager call (which may write into them), and handed over after
            # it: an eager call fills what the function caches lazily, which a trace must find filled
            inputs = copy_inputs((args, kwargs))
            result = self._fn(*args, **kwargs)
            self._submitted = True
            self._background.submit(self._compiled_call, *inputs, self._background_done)
            return result
        return self._compiled_call(*args, **kwargs)

    def _background_done(self, ok: bool) -> None:
        # (on the compile thread) ready: compiled from the world's switch on; a failed compile stays eager
        self._ready = ok

    @property
    def direct(self) -> bool:
        """Whether calls go straight to the compiled code (:mod:`~vmas_ros.simulator.direct_graph`)."""
        return self._direct is not None and self.one_graph is True

    def _compiled_call(self, *args, **kwargs):
        if self._direct is not None:
            try:
                if kwargs:
                    raise NotTraceable("keyword arguments")
                compiled, inputs, build = self._direct.prepare(*args)
                self.one_graph = True
                return build(compiled(inputs))
            except NotTraceable as why:
                _log.debug("vmas_ros: %s compiles through torch.compile: %s", getattr(self._fn, "__name__", self._fn), why)
                self._direct, self.one_graph = None, None
        if self._compiled is None:
            self._compiled = torch.compile(own_copy(self._fn), dynamic=False, mode=self._mode, fullgraph=True,
                                           options={"guard_filter_fn": self._guard_filter})
        if self.one_graph is False:
            return self._compiled(*args, **kwargs)
        try:
            result = self._compiled(*args, **kwargs)
        except torch._dynamo.exc.Unsupported:
            if self.one_graph:  # it compiled as one graph before: this is not a graph break
                raise
            self.one_graph = False
            self._compiled = torch.compile(own_copy(self._fn), dynamic=False, mode=self._mode)
            return self._compiled(*args, **kwargs)
        self.one_graph = True
        return result


class LayoutCompiled:
    """``fn`` compiled once per layout, checking only its direct tensor arguments on each call.

    Dynamo guards everything a traced function reads: for the world's step,
    every table, constant and scenario attribute: hundreds of checks, a large
    share of a one-env ``env.step``. What those reads can be is known here: the
    world rebuilds its tables (a new object) whenever an
    entity or a property changes, and its step parameters are plain values.
    So ``key(*args)`` names the layout, each layout gets its own compiled
    copy, and what it checks is cut to the shapes, strides, dtypes and devices
    of the ``checked`` arguments (the state and the actions; named by
    parameter, a trailing dot for their attributes), plus, through
    torch.compile, the process-wide guards (grad mode, default device). Tensors reached through the other
    arguments are still read afresh on every call; Python values there are
    part of the layout. Only the copies of the current tables are kept.
    """

    def __init__(self, fn: Callable, mode: Optional[str], key: Callable[..., Hashable], checked: Sequence[str],
                 background: Optional[BackgroundCompiler] = None) -> None:
        self._fn, self._mode, self._key, self._background = fn, mode, key, background
        self._filter = _guards_on(checked)
        # the checked arguments' positions: a direct graph flattens and checks only those
        names = list(inspect.signature(fn).parameters)
        self._varying = tuple(names.index(name.rstrip(".")) for name in checked)
        self._owner: object = None  # what the cached copies were compiled for (the world's tables)
        self._copies: Dict[Hashable, Callable] = {}

    def __call__(self, owner: object, *args):
        if owner is not self._owner:  # new tables: the old copies are never called again
            self._owner, self._copies = owner, {}
        key = self._key(*args)
        compiled = self._copies.get(key)
        if compiled is None:
            compiled = self._copies[key] = _OneGraph(self._fn, self._mode, self._filter, self._background,
                                                     self._varying)
        return compiled(*args)


class WorldKernel:
    """A pure tensor function of a scenario, compiled when (and only when) its world compiles its physics.

    The function must not read mutable state other than its arguments: once
    compiled, only the arguments are checked on each call (a partial's bound
    tensors and a bound method's attributes are read afresh but not checked,
    and Python values there are baked in); pass what changes in as arguments.
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
            self._compiled = compile_for_world(self._fn, world.compile_mode, arguments_only=True,
                                               background=world.background_compiler)
            self._mode = world.compile_mode
        try:
            return self._compiled(*args, **kwargs)
        except Exception as error:
            if not compile_failed(error):
                raise
            world.fall_back_to_eager(error)
            return self._fn(*args, **kwargs)


class StateFunction:
    """A pure function of the planar state ``fn(q, v)``, evaluated at most once per state.

    What scenarios' ``batched_outputs`` hook runs on (see ``BaseScenario.outputs``).
    A compiled step evaluates it right after its physics, in the same graph;
    otherwise (eager steps, and after a reset or a setter changed the state)
    it runs when first asked for, as a :class:`WorldKernel`. The result is kept
    for the state it was computed from, matched by the identity of
    ``world.state.planar_state()``'s tensors, which every change of state replaces.
    """

    def __init__(self, world, fn: Callable) -> None:
        self._state = world.state  # its WorldState, asked directly: this runs several times per step
        self._handle = self._state.add_kernel(fn)
        self._kernel = WorldKernel(world, fn)
        self._last = None  # (q, v, output) of the last state asked for

    def __call__(self):
        last = self._last
        if last is not None and self._state.still_adopted(last[0], last[1]):
            return last[2]
        q, v = self._state.planar_state()
        if last is not None and last[0] is q and last[1] is v:
            return last[2]
        output = self._state.take_kernel_output(self._handle)
        if output is None:  # an eager step, or the state changed since the step
            output = self._kernel(q, v)
        self._last = (q, v, output)
        return output

    def forget(self) -> None:
        """Compute afresh when next asked, even for the same state (what was handed out stays theirs)."""
        self._last = None
