"""The direct graph (vmas_ros/simulator/direct_graph.py): what it compiles, what it declines, and why.

The compiled step's own tests (test_compiled_physics.py) run it on worlds;
here small functions pin down its contract: results rebuilt in the
function's own structure, constants read afresh, one compile per input
signature, and a clear refusal for what only torch.compile may run.
"""
from __future__ import annotations

import pytest
import torch

from vmas_ros.simulator.direct_graph import DirectGraph, NotTraceable, graphs_compiled
from vmas_ros.simulator.physics.types import PlanarState
from vmas_ros.simulator.tracing import tracing


def _moved(state: PlanarState, push: torch.Tensor, scale: torch.Tensor):
    return PlanarState(state.q + push * scale, state.v * 2), (None, state.q.sum(), tracing())


def test_results_keep_their_structure_and_constants_are_read_afresh(device):
    scale = torch.ones(1, device=device)
    direct = DirectGraph(lambda state, push: _moved(state, push, scale))
    state = PlanarState(torch.rand(3, 2, 4, device=device), torch.rand(3, 2, 4, device=device))
    push = torch.rand(3, 2, 4, device=device)
    before = graphs_compiled()
    new, (nothing, total, traced) = direct(state, push)
    assert graphs_compiled() == before + 1
    assert isinstance(new, PlanarState) and nothing is None and traced is True  # (a Python value, as traced)
    torch.testing.assert_close(new.q, state.q + push)
    torch.testing.assert_close(total, state.q.sum())
    scale.fill_(3.0)  # a constant the graph reads: its current value counts
    torch.testing.assert_close(direct(state, push)[0].q, state.q + 3 * push)
    assert graphs_compiled() == before + 1, "the same signature runs the same compiled code"
    wider = PlanarState(torch.rand(3, 2, 5, device=device), torch.rand(3, 2, 5, device=device))
    torch.testing.assert_close(direct(wider, torch.zeros(3, 2, 5, device=device))[0].v, wider.v * 2)
    assert graphs_compiled() == before + 2 and len(direct._graphs) == 2


def _writes_its_constant(x, kept=torch.zeros(3)):
    kept.add_(x)
    return kept * 1


def _draws(x):
    return x + torch.rand_like(x)


def _branches(x):
    return x * 2 if bool(x.sum() > 0) else x


@pytest.mark.parametrize("fn, reason", [(_writes_its_constant, "writes into a tensor that is not one of its arguments"),
                                        (_draws, "draws random numbers"),
                                        (_branches, "tracing failed")])
def test_what_only_torch_compile_may_run_is_declined_naming_why(fn, reason):
    before = graphs_compiled()
    with pytest.raises(NotTraceable, match=reason):
        DirectGraph(fn)(torch.ones(3))
    assert graphs_compiled() == before, "declined before compiling anything"


def test_inputs_that_autograd_must_see_are_declined():
    x = torch.ones(3, requires_grad=True)
    with pytest.raises(NotTraceable, match="autograd"):
        DirectGraph(lambda t: t * 2)(x)
    direct = DirectGraph(lambda t: t * 2)
    with torch.no_grad():  # nothing for autograd to see: compiled, and the route remembers the signature
        torch.testing.assert_close(direct(x), torch.full((3,), 2.0))
        torch.testing.assert_close(direct(x), torch.full((3,), 2.0))
    with pytest.raises(NotTraceable, match="autograd"):  # the same signature, with grad mode on
        direct(x)


def test_other_strides_get_code_of_their_own(device):
    """The route checks every tensor's strides, not only its shape: a transposed input of the same shape
    is another signature."""
    direct = DirectGraph(lambda m: m + torch.arange(3, device=m.device))
    square = torch.rand(3, 3, device=device)
    before = graphs_compiled()
    torch.testing.assert_close(direct(square), square + torch.arange(3, device=device))
    torch.testing.assert_close(direct(square.t()), square.t() + torch.arange(3, device=device))
    torch.testing.assert_close(direct(square), square + torch.arange(3, device=device))
    assert graphs_compiled() == before + 2


def _add(x, pair):
    return x * 2 + (pair[0] - pair[1] if isinstance(pair, tuple) else pair)


def test_arguments_of_a_new_structure_get_code_of_their_own(device):
    """The arguments are taken apart by code written for their structure; another structure (a tensor
    where a tuple was) is walked, compiled for and becomes the route, and the first still runs its own."""
    direct = DirectGraph(_add)
    x, a, b = (torch.rand(4, device=device) for _ in range(3))
    before = graphs_compiled()
    torch.testing.assert_close(direct(x, (a, b)), x * 2 + a - b)
    torch.testing.assert_close(direct(x, a), x * 2 + a)
    torch.testing.assert_close(direct(x, (b, a)), x * 2 + b - a)
    torch.testing.assert_close(direct(x, b), x * 2 + b)
    assert graphs_compiled() == before + 2 and len(direct._graphs) == 2
