"""The step's three ways of keeping held entities still give bit-identical states.

``physics.step`` integrates free entities and leaves held ones (not
movable / not rotatable) untouched in one of three ways, picked by batch size
and layout: ``torch.where`` with bool masks (small batches), copying the held
(coordinate, entity) rows back with ``index_copy`` (large batches), or,
when the held entities form one block at an end of the entity list (landmarks
before agents), integrating only the free block and concatenating the held
rows back. These tests run the same large-batch worlds
through each path and require equal bits, and check the block detection.
"""
from __future__ import annotations

import pytest
import torch

from vmas_ros.simulator import physics
from vmas_ros.simulator.physics import integrator
from vmas_ros.simulator.physics.constants import _free_span
from vmas_ros.simulator.physics.integrator import Hold
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World

BATCH = 4096  # 3 x N x 4096 is above thresholds.SMALL_BATCH_ELEMENTS: the float-mask / block paths
STEPS = 5


def _world(layout: str, device: str) -> World:
    """Landmarks (held) and agents (free) in several arrangements, with limits, drag and walls."""
    kwargs = {"x_semidim": 1.0, "y_semidim": 1.0} if layout == "walls" else {}
    world = World(batch_dim=BATCH, device=device, substeps=3 if layout == "substeps" else 1, drag=0.25, **kwargs)
    # the world lists landmarks before agents; held agents make the other arrangements
    if layout != "held_last":
        world.add_landmark(Landmark(name="post", shape=Sphere(0.2), collide=True))
    for i in range(3):
        held = layout == "mixed" and i == 1  # a held entity between free ones: no single block
        world.add_agent(Agent(name=f"a{i}", shape=Sphere(0.15), max_speed=0.8 if i == 0 else None,
                              v_range=0.5 if i == 2 else None, movable=not held, rotatable=not held))
    if layout == "held_last":
        world.add_agent(Agent(name="statue", shape=Sphere(0.15), movable=False, rotatable=False))
    if layout == "no_rotation":  # free in x and y but not in the angle: not a whole-entity block
        world.add_agent(Agent(name="stiff", shape=Sphere(0.15), rotatable=False))
    world.reset(None)
    gen = torch.Generator().manual_seed(5)
    for e in world.entities:
        e.set_pos(((torch.rand(BATCH, 2, generator=gen) - 0.5) * 0.8).to(device), batch_index=None)
        # held entities with a velocity must keep it (VMAS skips their integration altogether)
        e.set_vel(((torch.rand(BATCH, 2, generator=gen) - 0.5) * 2).to(device), batch_index=None)
        e.set_ang_vel(((torch.rand(BATCH, 1, generator=gen) - 0.5) * 2).to(device), batch_index=None)
    return world


def _run(world: World, gen_seed: int):
    """Step from the world's state with fixed random actions; return the start and the state after each step."""
    tables = world.tables
    params = world._step_params()
    state = physics.PlanarState.from_vectors(physics.BodyState(
        *(torch.stack([getattr(e.state, f) for e in world.entities]) for f in ("pos", "vel", "rot", "ang_vel"))))
    gen = torch.Generator().manual_seed(gen_seed)
    out = [state]
    for _ in range(STEPS):
        actions = (torch.rand(3, tables.n_entities, BATCH, generator=gen) - 0.5).to(state.q.device)
        state = physics.step(state, tables, params, actions, None)
        out.append(state)
    return out


def _paths(world: World, monkeypatch):
    """The same run with the integrator's own choice, and forced through each way of holding entities
    still that applies: the free block (if the layout has one), copying held rows back, torch.where."""
    c = physics.step_constants(world.tables, world._step_params())
    runs = {"default": _run(world, 1)}
    for hold in (Hold.BLOCK, Hold.ROWS, Hold.WHERE):
        if hold is Hold.BLOCK and c.free_span is None:
            continue
        with monkeypatch.context() as m:
            m.setattr(integrator, "hold_method", lambda constants, elements, hold=hold: hold)
            runs[hold.name.lower()] = _run(world, 1)
    return c, runs


@pytest.mark.parametrize("layout", ["landmarks_first", "held_last", "walls", "substeps", "mixed", "no_rotation"])
def test_every_path_gives_the_same_bits(layout, device, monkeypatch):
    world = _world(layout, device)
    c, runs = _paths(world, monkeypatch)
    has_block = layout in ("landmarks_first", "held_last", "walls", "substeps")
    assert (c.free_span is not None) == has_block
    assert ("block" in runs) == has_block
    assert integrator.hold_method(c, 3 * c.free.shape[1] * BATCH) is (Hold.BLOCK if has_block else Hold.ROWS)
    assert len(c.held_rows) == int((~c.free).sum())  # held (coordinate, entity) rows, any layout
    for name, run in runs.items():
        for step, (ours, ref) in enumerate(zip(run, runs["where"])):
            assert torch.equal(ours.q, ref.q) and torch.equal(ours.v, ref.v), f"{layout}: {name} differs at step {step}"
    first, last = runs["default"][0], runs["default"][-1]
    held = ~c.free[..., 0]  # [3, N]
    assert held.any()
    # held rows keep their velocity and position; free rows moved
    assert torch.equal(first.v[held], last.v[held])
    assert torch.equal(first.q[held], last.q[held])
    assert not torch.equal(first.q[~held], last.q[~held])


def test_free_span_detection(device):
    def span(rows):  # rows: per entity, (movable, rotatable)
        free = torch.tensor([[m for m, _ in rows], [m for m, _ in rows], [r for _, r in rows]], device=device)
        return _free_span(free.unsqueeze(-1))

    assert span([(False, False), (True, True), (True, True)]) == (1, 3)
    assert span([(True, True), (True, True), (False, False)]) == (0, 2)
    assert span([(True, True), (True, True)]) is None  # all free: nothing to keep still
    assert span([(False, False), (False, False)]) is None  # nothing free
    assert span([(True, True), (False, False), (True, True)]) is None  # held in the middle
    assert span([(False, False), (True, True), (False, False), (True, True)]) is None  # two blocks
    assert span([(False, False), (True, False)]) is None  # partly free entity
