"""A standalone-compiled graph called at its generated code, without the layers around it.

``standalone_compile`` hands back an artifact whose every call passes through
a frame-evaluation guard, AOTAutograd's runtime wrapper (the bookkeeping for
inputs a graph writes into and outputs that alias something) and the compiled
graph's own bookkeeping (profiler labels, cache statistics) before it reaches
inductor's generated ``call``. At one env those layers take longer than the
kernel they lead to. For the engine's graphs, which see no gradients and no
random numbers, the bookkeeping has nothing to do: the generated code takes
the graph's lifted constants followed by the inputs, and gives the outputs.

That is checked, not assumed. :func:`bare_call` finds the layers through
their ``__wrapped__`` links (the lifted constants are the list the
AOTAutograd layer closes over), then runs the artifact and the bare call on
copies of the same inputs. It keeps the bare call only when both give the
same number of outputs with the same shapes, strides, dtypes and bits,
sharing memory with the same inputs and with each other alike, and leave the
inputs the same. Anything else (a torch whose layers look different, outputs
that would alias other memory, inputs a copy cannot reproduce) keeps the
artifact, which is always correct.
"""
from __future__ import annotations

from typing import Callable, List, Optional, Sequence, Tuple

import torch

__all__ = ["bare_call"]

#: how many ``__wrapped__`` links to follow before giving up on finding the generated code
_MAX_LAYERS = 16
#: the name under which AOTAutograd's outer layer keeps the graph's lifted constants
_CONSTANTS = "params_buffers_flat"


def _layers(artifact) -> Optional[Tuple[list, Callable]]:
    """``(lifted constants, generated call)`` of ``artifact``, or None when its layers are not as expected."""
    layer = getattr(artifact, "_compiled_fn", None)
    constants = None
    for _ in range(_MAX_LAYERS):  # to the innermost layer (wrappers copy its attributes, so only it counts)
        code = getattr(layer, "__code__", None)
        if constants is None and code is not None and _CONSTANTS in code.co_freevars:
            constants = layer.__closure__[code.co_freevars.index(_CONSTANTS)].cell_contents
        inner = getattr(layer, "__wrapped__", None)
        if inner is None:
            break
        layer = inner
    generated = getattr(layer, "current_callable", None)
    if not isinstance(constants, list) or not callable(generated):
        return None
    return list(constants), generated


def _copies(tensors: Sequence[torch.Tensor]) -> Optional[List[torch.Tensor]]:
    """Clones with the same strides, or None when a tensor's layout cannot be cloned as it is (overlapping
    or gapped memory: a compiled graph reads its inputs by their strides)."""
    copies = [tensor.detach().clone() for tensor in tensors]
    if any(copy.stride() != tensor.stride() for copy, tensor in zip(copies, tensors)):
        return None
    return copies


def _same_bits(a, b) -> bool:
    if not (isinstance(a, torch.Tensor) and isinstance(b, torch.Tensor)):
        return False
    if a.shape != b.shape or a.stride() != b.stride() or a.dtype != b.dtype or a.device != b.device:
        return False
    if a.dtype == torch.bool:
        return torch.equal(a, b)
    return torch.equal(_bytes(a), _bytes(b))


def _bytes(tensor: torch.Tensor) -> torch.Tensor:
    """``tensor``'s elements as bytes, in order (NaNs and signed zeros compared as the bits they are)."""
    dense = torch.empty_like(tensor, memory_format=torch.contiguous_format).copy_(tensor)
    return dense.view(-1).view(torch.uint8)


def _same_results(first: Sequence, second: Sequence) -> bool:
    return len(first) == len(second) and all(_same_bits(a, b) for a, b in zip(first, second))


def _sharing(outputs: Sequence[torch.Tensor], inputs: Sequence[torch.Tensor]) -> tuple:
    """Which memory each output lives in: the position of the input it shares memory with, else the
    first output it shares memory with (as ``-1 - position``), else None. Two calls that agree on this
    agree on what aliases what."""
    inputs_at = {}
    for position, tensor in enumerate(inputs):
        inputs_at.setdefault(tensor.untyped_storage().data_ptr(), position)
    outputs_at: dict = {}
    sharing = []
    for position, tensor in enumerate(outputs):
        memory = tensor.untyped_storage().data_ptr()
        if memory in inputs_at:
            sharing.append(inputs_at[memory])
        else:
            sharing.append(None if memory not in outputs_at else -1 - outputs_at[memory])
            outputs_at.setdefault(memory, position)
    return tuple(sharing)


def _boxed(artifact: Callable) -> Callable[[list], object]:
    """``artifact`` in the generated code's calling convention: one list of inputs."""
    def call(inputs: list):
        return artifact(*inputs)

    return call


def bare_call(artifact: Callable, tensors: Sequence[torch.Tensor]) -> Tuple[Callable[[list], object], list, bool]:
    """``(call, constants, bare)``: ``call([*constants, *inputs])`` gives the graph's outputs for its tensor
    ``inputs``; ``bare`` says whether ``call`` is the generated code itself (see the module docstring) or
    ``artifact`` behind a function of that convention. ``call`` may empty the list it is given: pass a new
    one each time.

    ``tensors`` are example inputs of the signature the artifact was compiled for; they are only read.
    The artifact's first call, which writes inductor's autotuning cache, happens here on their copies.
    """
    layers = _layers(artifact)
    artifact_inputs, bare_inputs = _copies(tensors), _copies(tensors)
    if layers is None or artifact_inputs is None:
        return _boxed(artifact), [], False
    constants, generated = layers
    try:
        expected = artifact(*artifact_inputs)
        got = generated([*constants, *bare_inputs])
    except Exception:  # the layers are not what they seemed: the artifact serves
        return _boxed(artifact), [], False
    if not (isinstance(got, (tuple, list)) and _same_results(expected, got)
            and _same_results(artifact_inputs, bare_inputs)
            and _sharing(expected, artifact_inputs) == _sharing(got, bare_inputs)):
        return _boxed(artifact), [], False
    return generated, constants, True
