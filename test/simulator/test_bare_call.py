"""Calling a compiled graph's generated code straight (vmas_ros/simulator/bare_call.py).

The bare call is kept only where it was seen to give what the compiled
artifact gives. Two small compiled functions show it kept and giving eager's
results (also for an output that is an input, and an input written in place);
artifacts built here in layers shaped like torch's show what the check
refuses: other bits, other aliasing, other writes, no layers, or inputs it
cannot copy.
"""
from __future__ import annotations

import pytest
import torch

from vmas_ros.simulator.bare_call import bare_call
from vmas_ros.simulator.direct_graph import DirectGraph


def _pure(x, y):
    return torch.sin(x) * y + 1, (x - y).norm(), x


def test_a_compiled_graph_is_called_at_its_generated_code_with_eager_results(device):
    x, y = torch.rand(5, 3, device=device), torch.rand(5, 3, device=device)
    direct = DirectGraph(_pure)
    first = direct(x, y)
    assert direct.bare_graphs == 1
    again = direct(x, y)
    for a, b in zip(first, again):
        assert torch.equal(a, b)
    torch.testing.assert_close(again[0], torch.sin(x) * y + 1)
    torch.testing.assert_close(again[1], (x - y).norm())
    assert again[2].data_ptr() == x.data_ptr(), "an output that is an input stays that input"


def _writes_its_input(x):
    x.add_(1)
    return x * 2


def test_an_input_written_in_place_is_written_as_eager_writes_it():
    direct = DirectGraph(_writes_its_input)
    z = torch.zeros(3)
    for expected in (1.0, 2.0):
        result = direct(z)
        torch.testing.assert_close(z, torch.full((3,), expected))
        torch.testing.assert_close(result, torch.full((3,), 2 * expected))


class _Generated:
    """The innermost layer: inductor's compiled graph, whose ``current_callable`` takes one list."""

    def __init__(self, call):
        self.current_callable = call


class _Artifact:
    """``fn`` behind layers shaped like standalone_compile's: an outer function closing over the lifted
    constants (here one, ``scale``), linked by ``__wrapped__`` to the generated code."""

    def __init__(self, fn, generated, scale):
        params_buffers_flat = [scale]

        def forward(*inputs):
            return generated.current_callable([*params_buffers_flat, *inputs])

        forward.__wrapped__ = generated
        self._compiled_fn = forward
        self._fn, self._scale = fn, scale

    def __call__(self, *inputs):
        return self._fn(self._scale, *inputs)


def _scaled(scale, x):
    return (x * scale,)


def _keeps(generated_fn):
    scale, x = torch.full((3,), 2.0), torch.rand(3)
    generated = _Generated(lambda args: generated_fn(*args))
    artifact = _Artifact(_scaled, generated, scale)
    call, constants, bare = bare_call(artifact, [x])
    assert (call is generated.current_callable) is bare and (constants == [scale]) is bare
    torch.testing.assert_close(call([*constants, x])[0], x * 2)  # either way, the artifact's result
    return bare


def test_the_generated_code_is_kept_only_where_it_gives_what_the_artifact_gives():
    assert _keeps(lambda scale, x: (x * scale,))
    assert not _keeps(lambda scale, x: (x * scale + 1e-7,)), "other bits"
    assert not _keeps(lambda scale, x: (x * scale, x)), "another number of outputs"
    assert not _keeps(lambda scale, x: (x.mul_(scale),)), "it writes into its input, and returns it"
    assert not _keeps(lambda scale, x: (x * scale, x.zero_())[:1]), "it writes into its input"
    assert not _keeps(lambda scale, x: (x * scale)[None]), "a tensor, not a tuple of outputs"
    assert not _keeps(_raises), "it raises: the artifact serves"


def _raises(scale, x):
    raise RuntimeError("not the generated code this looked like")


@pytest.mark.parametrize("inputs", [[torch.ones(2)], [torch.ones(1).expand(3)]], ids=["no layers", "overlapping input"])
def test_what_the_check_cannot_compare_keeps_the_artifact(inputs):
    def artifact(*tensors):
        return tuple(t * 2 for t in tensors)

    call, constants, bare = bare_call(artifact, inputs)
    assert not bare and constants == []
    assert torch.equal(call(list(inputs))[0], inputs[0] * 2), "the artifact, called with one list of inputs"
