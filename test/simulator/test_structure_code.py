"""The code written for one structure of arguments (vmas_ros/simulator/structure_code.py).

A direct graph takes its arguments apart with it on every call, so it must
give exactly the generic walk's tensors, in its order, and refuse (None)
every argument list that no longer has the structure it was written for:
otherwise compiled code would run on inputs it was not traced for.
"""
from __future__ import annotations

import pytest
import torch

from vmas_ros.simulator.direct_graph import _flatten, rebuild
from vmas_ros.simulator.physics.types import PlanarState
from vmas_ros.simulator.structure_code import builder, picker


def _arguments(device, actions=None, flag=True):
    state = PlanarState(torch.rand(3, 2, 4, device=device), torch.rand(3, 2, 4, device=device))
    if actions is None:
        actions = (torch.rand(2, 4, 2, device=device), torch.rand(2, 4, 1, device=device))
    return (object(), state, actions, None, flag)


def _walk(args, positions):
    tensors, signature = [], []
    structure = _flatten(tuple(args[i] for i in positions), tensors, signature)
    return structure, tensors


POSITIONS = (1, 2, 3, 4)  # what varies: the first argument is the caller's layout, never looked at


def test_the_picker_gives_the_walks_tensors_in_its_order(device):
    args = _arguments(device)
    structure, tensors = _walk(args, POSITIONS)
    pick = picker(structure, POSITIONS)
    fresh = _arguments(device)  # other tensors, same structure: the picker reads them, not the first ones
    picked = pick(fresh)
    assert [t is u for t, u in zip(picked, _walk(fresh, POSITIONS)[1])] == [True] * 4
    assert picked[0] is fresh[1].q and picked[3] is fresh[2][1]


@pytest.mark.parametrize("change", ["actions as one tensor", "three actions", "a list, not a tuple",
                                    "another flag", "a flag of another type", "a state field not a tensor"])
def test_the_picker_refuses_arguments_of_another_structure(device, change):
    args = _arguments(device)
    structure, tensors = _walk(args, POSITIONS)
    pick = picker(structure, POSITIONS)
    other = list(_arguments(device))
    if change == "actions as one tensor":
        other[2] = torch.rand(2, 4, 3, device=device)
    elif change == "three actions":
        other[2] = other[2] + (torch.rand(2, 4, 1, device=device),)
    elif change == "a list, not a tuple":
        other[2] = list(other[2])
    elif change == "another flag":
        other[4] = False
    elif change == "a flag of another type":
        other[4] = 1  # equal to True, but the signature keys Python values with their type
    else:
        other[1] = PlanarState(other[1].q, None)
    assert pick(tuple(other)) is None
    assert pick(tuple(other[:3])) is None, "too few arguments"


def test_the_builder_rebuilds_what_the_generic_rebuild_does(device):
    outputs = [torch.rand(3, 2, 4, device=device) for _ in range(4)]
    structure, tensors = _walk((PlanarState(*outputs[:2]), [outputs[2], (None, 7, outputs[3])]), (0, 1))
    built = builder(structure)(outputs)
    expected = rebuild(structure, iter(outputs))
    assert type(built) is tuple and type(built[0]) is PlanarState and type(built[1]) is list
    assert built[0].q is outputs[0] and built[0].v is outputs[1]
    assert built[1][0] is outputs[2] and built[1][1] == (None, 7, outputs[3])
    assert repr(built) == repr(expected)
