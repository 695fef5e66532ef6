"""A compiled function called straight, without torch.compile's per-call machinery.

``torch.compile`` runs a compiled function through a frame evaluator, its
guards and its runtime wrappers on every call: a fixed cost that dwarfs a
one-env step's arithmetic. The engine's compiled functions do not need that
machinery: each is a pure function of its tensor arguments for a layout the
caller names (:class:`vmas_ros.simulator.compiling.LayoutCompiled`). So
:class:`DirectGraph` traces such a function once per input signature into an
FX graph of ATen ops (``make_fx``, on fake tensors), compiles that graph with
inductor (``standalone_compile``: the same compiler and disk caches
torch.compile uses), and calls the compiled code directly (its generated
code itself where that is checked to be the same, :mod:`~vmas_ros.simulator.bare_call`). Its only per-call work is
flattening the arguments and checking their shapes, strides, dtypes and
devices against the signature it compiled for.

What a trace bakes in, as torch.compile with cut guards did: Python values
read from the arguments' objects (the layout). Tensors reached through them
are graph constants that the compiled code reads afresh on every call.

It declines (:class:`NotTraceable`) what it cannot call safely, and the
caller then compiles with torch.compile as before: a function whose trace
needs a tensor's value (data-dependent Python), one that writes into a
tensor it did not get as an argument, one that draws random numbers, and
calls where autograd must see the inputs.
"""
from __future__ import annotations

import dataclasses
import sys
from typing import Callable, Dict, Hashable, List, Optional, Sequence, Tuple

import torch

try:
    from torch._C._dynamo.guards import TensorGuards as _TensorGuards
except ImportError:  # a torch without dynamo's C++ guards
    _TensorGuards = None

from vmas_ros.simulator.background_compile import copy_inputs
from vmas_ros.simulator.bare_call import bare_call
from vmas_ros.simulator.structure_code import PRIMITIVES
from vmas_ros.simulator.structure_code import TENSOR as _TENSOR
from vmas_ros.simulator.structure_code import builder, picker
from vmas_ros.simulator.tracing import traced

__all__ = ["DirectGraph", "NotTraceable", "graphs_compiled", "rebuild"]

_compiled_count = 0  # direct graphs compiled in this process (all threads)


def graphs_compiled() -> int:
    """How many graphs this process has compiled, directly or through torch.compile (tests read it to
    see that compiled code was made; a no-op flag would otherwise pass a comparison with eager)."""
    dynamo = sys.modules.get("torch._dynamo.utils")
    return _compiled_count + (dynamo.counters["stats"]["unique_graphs"] if dynamo is not None else 0)


class NotTraceable(Exception):
    """The function cannot be run as a direct graph; compile it the usual way."""


#: inductor's settings for a direct graph: no checks of the inputs' sizes and strides in the compiled code,
#: as the signature each graph is looked up by already pins them
_OPTIONS = {"config_patches": {"size_asserts": False}}
#: compiled signatures per function before it declines: more means its inputs' shapes keep changing
MAX_SIGNATURES = 8


def _same_metadata(tensors: List[torch.Tensor]) -> Callable[..., bool]:
    """A check that tensors have the shapes, strides, dtypes, devices and ``requires_grad`` of ``tensors``.

    Dynamo's own tensor check, in C++, where torch has it (comparing a tuple of
    each tensor's metadata costs several times more); else that tuple.
    """
    if _TensorGuards is not None:
        guards = _TensorGuards(*tensors, dynamic_dims_sizes=[list(t.shape) for t in tensors],
                               dynamic_dims_strides=[list(t.stride()) for t in tensors])
        return guards.check
    expected = _metadata(tensors)
    return lambda *given: _metadata(given) == expected


def _metadata(tensors) -> tuple:
    return tuple([(t.shape, t.stride(), t.dtype, t.device, t.requires_grad) for t in tensors])


def _flatten(value, tensors: List[torch.Tensor], signature: list) -> object:
    """The structure of ``value`` with its tensors moved to ``tensors`` (in order). ``signature`` gets what a
    compiled graph depends on: each tensor's shape, stride, dtype and device, and each Python value."""
    if isinstance(value, torch.Tensor):
        tensors.append(value)
        signature.append((value.shape, value.stride(), value.dtype, value.device))
        return _TENSOR
    if type(value) in (tuple, list):
        signature.append((type(value), len(value)))
        return type(value), [_flatten(item, tensors, signature) for item in value]
    names = _tensor_fields(value)
    if names:  # a state: rebuilt around the traced tensors
        signature.append(type(value))
        return type(value), {name: _flatten(getattr(value, name), tensors, signature) for name in names}
    # Python values are part of the signature; other objects (tables, parameters, functions) are the
    # caller's layout, which it keys on itself (LayoutCompiled): a trace reads them as the first call had them
    signature.append(value if type(value) in PRIMITIVES else type(value))
    return "C", value


_FIELDS: Dict[type, List[str]] = {}  # dataclass type -> its init fields' names (looked up on every call)


def _tensor_fields(value) -> Optional[List[str]]:
    """The field names of a dataclass instance whose fields are all tensors (such as a state), else None."""
    kind = type(value)
    names = _FIELDS.get(kind)
    if names is None:
        is_instance = dataclasses.is_dataclass(kind) and not isinstance(value, type)
        names = _FIELDS[kind] = [field.name for field in dataclasses.fields(kind) if field.init] if is_instance else []
    if names and all(isinstance(getattr(value, name), torch.Tensor) for name in names):
        return names
    return None


def rebuild(structure, tensors) -> object:
    """``structure`` (from :func:`_flatten`) with its tensor slots filled from the iterator ``tensors``."""
    if structure is _TENSOR:
        return next(tensors)
    kind, content = structure
    if kind == "C":
        return content
    if kind in (tuple, list):
        return kind(rebuild(item, tensors) for item in content)
    return kind(**{name: rebuild(item, tensors) for name, item in content.items()})


def _writes_a_constant(graph_module: torch.fx.GraphModule) -> bool:
    """Whether the traced graph writes into a tensor it reads as a constant (not an argument), directly or
    through a view (``out=`` included): the compiled code would not carry that write out."""
    roots: Dict[torch.fx.Node, torch.fx.Node] = {}
    for node in graph_module.graph.nodes:
        if node.op == "get_attr":
            roots[node] = node
        elif node.op == "call_function":
            schema = getattr(node.target, "_schema", None)
            if schema is None:
                continue
            for position, argument in enumerate(schema.arguments):
                given = node.args[position] if position < len(node.args) else node.kwargs.get(argument.name)
                alias = argument.alias_info
                if alias is None or not isinstance(given, torch.fx.Node) or given not in roots:
                    continue
                if alias.is_write:
                    return True
                roots[node] = roots[given]  # a view of a constant
    return False


#: ATen ops that draw random numbers: a compiled graph would draw them from its own generator, so a
#: function that draws stays with torch.compile, whose handling of the global generator is torch's own
_RANDOM = ("rand", "normal", "bernoulli", "uniform", "exponential", "multinomial", "poisson", "cauchy",
           "geometric", "log_normal", "random_", "dropout")


def _draws_random_numbers(graph_module: torch.fx.GraphModule) -> bool:
    return any(node.op == "call_function" and any(word in str(node.target) for word in _RANDOM)
               for node in graph_module.graph.nodes)


class DirectGraph:
    """``fn`` compiled per input signature and called directly (see the module's docstring).

    ``varying``: the positions of the arguments that change from call to call
    (the state and the actions of a step); the others are the caller's layout,
    which it keys on itself, so they are neither flattened nor checked, and a
    trace reads them as the first call passed them. None: every argument varies.
    Calling raises :class:`NotTraceable` for what must go through torch.compile.
    """

    def __init__(self, fn: Callable, varying: Optional[Sequence[int]] = None) -> None:
        self._fn = fn
        self._varying = None if varying is None else tuple(varying)
        #: signature -> (compiled code, the constants its inputs follow, output builder)
        self._graphs: Dict[Hashable, Tuple[Callable, list, Callable]] = {}
        #: the last structure of arguments seen: its picker, and per signature met with it (a check of the
        #: tensors' metadata, whether the check's tensors need gradients, the graph entry)
        self._route: Optional[Tuple[Callable, List[Tuple[Callable, bool, Tuple[Callable, list, Callable]]]]] = None
        #: how many of its graphs are called at their generated code (:mod:`~vmas_ros.simulator.bare_call`)
        self.bare_graphs = 0

    def prepare(self, *args) -> Tuple[Callable, List[torch.Tensor], Callable]:
        """``(compiled code, its inputs, output builder)`` for a call with ``args``, compiling on a new
        signature; the caller runs ``build(compiled(inputs))``, so that no frame of this module stands
        between it and the compiled code. ``inputs`` is a new list (the compiled code empties it): the
        graph's constants, then the tensors taken from ``args``.

        The arguments' structure is taken apart by closures made for it
        (:mod:`~vmas_ros.simulator.structure_code`) while it stays the same;
        a new structure goes through the generic walk, and becomes the route.
        """
        route = self._route
        if route is not None:
            tensors = route[0](args)
            if tensors is not None:
                for same_metadata, needs_grad, entry in route[1]:
                    if same_metadata(*tensors):
                        if needs_grad and torch.is_grad_enabled():
                            raise NotTraceable("autograd must see the inputs")
                        return entry[0], [*entry[1], *tensors], entry[2]
        return self._prepare_walking(args)

    def _prepare_walking(self, args: tuple) -> Tuple[Callable, List[torch.Tensor], Callable]:
        tensors: List[torch.Tensor] = []
        signature: list = []
        varying = self._varying
        structure = _flatten(args if varying is None else tuple(args[i] for i in varying), tensors, signature)
        if torch.is_grad_enabled() and any(tensor.requires_grad for tensor in tensors):
            raise NotTraceable("autograd must see the inputs")
        key = tuple(signature)
        entry = self._graphs.get(key)
        if entry is None:
            if len(self._graphs) >= MAX_SIGNATURES:
                raise NotTraceable(f"called with more than {MAX_SIGNATURES} input signatures")
            compiled, constants, output = self._compile(args, structure, tensors)
            entry = self._graphs[key] = (compiled, constants, builder(output))
        route = self._route
        if route is None or route[0](args) is None:  # a new structure: the route follows it
            route = self._route = (picker(structure, varying), [])
        route[1].append((_same_metadata(tensors), any(t.requires_grad for t in tensors), entry))
        return entry[0], [*entry[1], *tensors], entry[2]

    def _arguments(self, args: tuple, varying_args) -> tuple:
        """``args`` with the varying positions taken from ``varying_args`` (all of them when all vary)."""
        if self._varying is None:
            return tuple(varying_args)
        full = list(args)
        for position, value in zip(self._varying, varying_args):
            full[position] = value
        return tuple(full)

    def __call__(self, *args):
        compiled, inputs, build = self.prepare(*args)
        return build(compiled(inputs))

    def _compile(self, args: tuple, structure, tensors: List[torch.Tensor]) -> Tuple[Callable, list, object]:
        from torch._inductor import standalone_compile
        from torch.fx.experimental.proxy_tensor import make_fx

        # one eager call on copies first, taking the graph-friendly forms as the trace will: it fills what
        # they cache lazily (index tables, constants), which the trace must find filled, not fill with fakes
        with traced():
            self._fn(*copy_inputs(args))
        output: list = []

        def flat(*inputs):
            result = self._fn(*self._arguments(args, rebuild(structure, iter(inputs))))
            results: List[torch.Tensor] = []
            output.append(_flatten(result, results, []))
            return tuple(results)

        try:
            with traced():
                graph_module = make_fx(flat, tracing_mode="fake", _allow_non_fake_inputs=True)(*tensors)
        except Exception as error:  # data-dependent Python, an op fake tensors cannot run, ...
            raise NotTraceable(f"tracing failed: {type(error).__name__}: {error}") from error
        if _writes_a_constant(graph_module):
            raise NotTraceable("it writes into a tensor that is not one of its arguments")
        if _draws_random_numbers(graph_module):
            raise NotTraceable("it draws random numbers")
        if any(getattr(graph_module, node.target).requires_grad
               for node in graph_module.graph.nodes if node.op == "get_attr") and torch.is_grad_enabled():
            raise NotTraceable("autograd must see a constant it reads")
        try:
            # fixed shapes; standalone_compile gives inductor the shape environment its disk caches need. The
            # graph is handed over, not copied: a copy would hold copies of the constants, no longer read afresh
            compiled = standalone_compile(graph_module, list(tensors), dynamic_shapes="from_example_inputs",
                                          options=_OPTIONS, donate_graph_module=True)
        except Exception as error:  # no working compiler, say: torch.compile then meets it and says so
            raise NotTraceable(f"compiling failed: {type(error).__name__}: {error}") from error
        global _compiled_count
        _compiled_count += 1
        call, constants, bare = bare_call(compiled, tensors)  # its generated code straight, where that is the same
        self.bare_graphs += bare
        return call, constants, output[0]
