"""The world state: entities read their state lazily after a step, and every change is seen.

``World.state`` replaced eager per-entity write-back (see simulator/world_state.py);
these tests pin the VMAS semantics it must keep: an entity's tensors alias its
state until the next step, setters and in-place writes are seen by the next
step and by ``stacked_state``, and adding entities or moving devices loses nothing.
"""
from __future__ import annotations

import re

import pytest
import torch

import vmas_ros
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.tracing import tracing
from vmas_ros.simulator.world_state import WorldState

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def _world(device, n_agents=3, batch=4):
    world = World(batch_dim=batch, device=device)
    for i in range(n_agents):
        world.add_agent(Agent(name=f"a{i}", shape=Sphere(0.1)))
    for i, agent in enumerate(world.agents):
        agent.set_pos(torch.tensor([0.5 * i, 0.0], device=device), batch_index=None)
        agent.set_vel(torch.tensor([0.1, 0.2 * i], device=device), batch_index=None)
    return world


def _state(world):
    return {f: torch.stack([getattr(e.state, f) for e in world.entities]).clone() for f in ("pos", "vel", "rot", "ang_vel")}


def _twin_runs(device, edit, steps=3):
    """Two identical worlds; ``edit(world)`` after the first step of one of them."""
    worlds = [_world(device), _world(device)]
    for step in range(steps):
        for i, world in enumerate(worlds):
            world.step()
            if step == 0 and i == 1:
                edit(world)
    return [_state(w) for w in worlds]


@pytest.mark.parametrize("device", DEVICES)
def test_a_step_leaves_every_field_readable_and_stacked_state_agrees(device):
    world = _world(device)
    world.step()
    for field in ("pos", "vel", "rot", "ang_vel"):
        stacked = world.stacked_state(field)
        assert stacked is world.stacked_state(field), "one stack per state: caches key on its identity"
        for i, entity in enumerate(world.entities):
            value = getattr(entity.state, field)
            assert value.shape == (4, 2 if field in ("pos", "vel") else 1) and value.device.type == torch.device(device).type
            assert torch.equal(value, stacked[i])
    x, y = world.stacked_xy("pos")
    assert torch.equal(torch.stack([x, y], -1), world.stacked_state("pos"))
    before = world.stacked_state("pos")
    world.step()
    assert world.stacked_state("pos") is not before


@pytest.mark.parametrize("device", DEVICES)
def test_tensors_read_before_a_step_keep_their_values(device):
    world = _world(device)
    world.step()
    old = world.agents[1].state.pos
    kept = old.clone()
    world.step()
    assert torch.equal(old, kept), "the step must not write into tensors handed out before it"
    assert not torch.equal(world.agents[1].state.pos, kept)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("edit", ["pos_in_place", "rot_in_place", "vel_setter", "set_pos_index", "ang_vel_in_place"])
def test_changes_between_steps_reach_the_next_step(device, edit):
    def change(world):
        a = world.agents[0].state
        if edit == "pos_in_place":
            a.pos[:, 0] += 0.3
        elif edit == "rot_in_place":
            a.rot[:] = 1.0
        elif edit == "ang_vel_in_place":
            a.ang_vel.add_(2.0)
        elif edit == "vel_setter":
            a.vel = torch.zeros(4, 2, device=device)
        elif edit == "set_pos_index":
            world.agents[0].set_pos(torch.tensor([0.9, 0.9], device=device), batch_index=2)

    untouched, edited = _twin_runs(device, change)
    changed = {f for f in untouched if not torch.equal(untouched[f][0], edited[f][0])}
    assert changed, f"{edit}: the edit after step 1 did not change agent a0's later state"
    # the other agents are far from a0 (no contact): they must not notice anything
    for f in untouched:
        assert torch.equal(untouched[f][1:], edited[f][1:])


@pytest.mark.parametrize("device", DEVICES)
def test_an_in_place_write_is_seen_at_once_by_stacked_state_and_by_other_entities(device):
    world = _world(device)
    world.step()
    expected = world.stacked_state("pos").clone()
    world.agents[0].state.pos[1] = torch.tensor([7.0, 8.0], device=device)
    expected[0, 1] = torch.tensor([7.0, 8.0], device=device)
    assert torch.equal(world.stacked_state("pos"), expected)
    x, _ = world.stacked_xy("pos")
    assert x[0, 1] == 7.0
    assert torch.equal(world.agents[2].state.pos, expected[2]), "an untouched entity still reads its own state"


@pytest.mark.parametrize("device", DEVICES)
def test_adding_entities_after_steps_keeps_every_state(device):
    world = _world(device)
    world.step()
    world.step()
    before = _state(world)
    world.add_landmark(Landmark(name="late_landmark", collide=False))  # landmarks come first: every row moves
    world.add_agent(Agent(name="late_agent", shape=Sphere(0.1)))
    after = _state(world)
    for f in before:
        assert torch.equal(after[f][1:1 + 3], before[f]), f"{f} of the first agents changed when entities were added"
        assert torch.equal(after[f][0], torch.zeros_like(after[f][0]))
    world.step()  # and the bigger world steps
    assert world.stacked_state("pos").shape[0] == 5


def test_moving_the_world_keeps_its_state():
    world = _world("cpu")
    world.step()
    before = _state(world)
    world.to("cpu")
    assert all(torch.equal(before[f], _state(world)[f]) for f in before)
    world.step()  # steps from the entities' own tensors
    assert torch.isfinite(world.stacked_state("pos")).all()


def test_an_entity_outside_a_world_refuses_state_but_reads_none():
    agent = Agent(name="loose")
    assert agent.state.pos is None
    with pytest.raises(RuntimeError, match="add loose to a world"):
        agent.state.pos = torch.zeros(1, 2)


@pytest.mark.parametrize("field, width", [("pos", 2), ("vel", 2), ("rot", 1), ("force", 2), ("torque", 1)])
def test_a_state_field_of_the_wrong_shape_is_refused_naming_it(field, width):
    agent = _world("cpu").agents[0]
    before = getattr(agent.state, field).clone()
    for bad in (torch.zeros(4, width + 1), torch.zeros(4)):
        message = f"a0.{field} must have shape [4, {width}], got {tuple(bad.shape)}"
        with pytest.raises(ValueError, match=re.escape(message)):
            setattr(agent.state, field, bad)
    torch.testing.assert_close(getattr(agent.state, field), before)


def test_env_steps_equal_with_and_without_reading_entity_state_between_steps():
    """Reading (and so fetching) entity fields must not change what the steps compute."""
    runs = []
    for read in (False, True):
        env = vmas_ros.make_env("simple_spread", num_envs=8, seed=11)
        env.reset()
        gen = torch.Generator().manual_seed(0)
        for _ in range(5):
            env.step([torch.rand(8, 2, generator=gen) * 2 - 1 for _ in env.agents])
            if read:
                [(a.state.pos, a.state.vel, a.state.rot) for a in env.world.entities]
        runs.append(torch.stack([a.state.pos for a in env.world.entities]))
    assert torch.equal(runs[0], runs[1])


@pytest.mark.parametrize("device", DEVICES)
def test_planar_state_is_the_step_output_and_follows_changes(device):
    world = _world(device)
    world.step()
    q, v = world.planar_state()
    assert q is world.planar_state()[0], "unchanged state: the same tensors (scenarios cache on them)"
    assert torch.equal(q[:2].permute(1, 2, 0), world.stacked_state("pos"))
    assert torch.equal(v[2], world.stacked_state("ang_vel")[..., 0])
    world.agents[1].set_pos(torch.tensor([3.0, -2.0], device=device), batch_index=None)
    moved, _ = world.planar_state()
    assert moved is not q and moved[0, 1].eq(3.0).all() and moved[1, 1].eq(-2.0).all()
    assert moved is world.planar_state()[0], "rebuilt once per change, not per call"


@pytest.mark.parametrize("device", DEVICES)
def test_set_positions_equals_setting_each_entity_and_keeps_the_state_clean(device):
    worlds = [_world(device, n_agents=4), _world(device, n_agents=4)]
    for world in worlds:
        world.step()
    x = torch.tensor([[0.1] * 4, [0.2] * 4], device=device)
    y = torch.tensor([[-0.3] * 4, [0.4] * 4], device=device)
    batched, single = worlds
    seen = []
    batched.agents[1].subscribe(type("Watcher", (), {"notify": lambda self, *a, **k: seen.append(k)})())
    batched.set_positions(batched.agents[1:3], x, y)
    assert batched.state.clean(), "consecutive rows written after a step go straight into the state"
    assert seen == [{"batch_index": None}], "observers hear about the move as with set_pos"
    for agent, px, py in zip(single.agents[1:3], x, y):
        agent.set_pos(torch.stack([px, py], -1), batch_index=None)
    for a, b in zip(batched.entities, single.entities):
        assert torch.equal(a.state.pos, b.state.pos)
    assert torch.equal(batched.stacked_state("pos"), single.stacked_state("pos"))
    batched.step()
    single.step()
    assert torch.equal(batched.stacked_state("pos"), single.stacked_state("pos"))
    # not consecutive, or the state already changed: entity by entity, same result
    batched.agents[0].set_vel(torch.zeros(4, 2, device=device), batch_index=None)
    single.agents[0].set_vel(torch.zeros(4, 2, device=device), batch_index=None)
    batched.set_positions([batched.agents[3], batched.agents[0]], x, y)
    for agent, px, py in zip([single.agents[3], single.agents[0]], x, y):
        agent.set_pos(torch.stack([px, py], -1), batch_index=None)
    assert torch.equal(batched.stacked_state("pos"), single.stacked_state("pos"))
    with pytest.raises(ValueError, match="2 entities but x"):
        batched.set_positions(batched.agents[:2], x[:1], y[:1])


@pytest.mark.parametrize("device", DEVICES)
def test_state_kernels_run_with_the_step_once_per_state(device):
    world = _world(device)
    calls, traces = [], []

    def centre(q, v):
        # compiling traces it (and calls it once on copies, as the trace will); a compiled step calls neither
        (traces if tracing() else calls).append(1)
        return q[:2].mean(dim=1), v[2].abs().sum(dim=0)

    handle = world.add_state_kernel(centre)
    assert world.take_state_kernel_output(handle) is None, "no step yet"
    world.step()
    assert not calls and world.take_state_kernel_output(handle) is None, "eager steps leave kernels to their users"
    world.compile_physics()
    world.step()
    assert traces and not calls, "the compiled step computed the kernel in its graph"
    got = world.take_state_kernel_output(handle)
    q, v = world.planar_state()
    torch.testing.assert_close(got[0], q[:2].mean(dim=1))
    torch.testing.assert_close(got[1], v[2].abs().sum(dim=0))
    assert world.take_state_kernel_output(handle) is None, "handed out once: a second reader computes its own"
    traced = len(traces)
    world.step()
    assert len(traces) == traced and not calls, "the compiled step runs the kernel without tracing it again"
    got = world.take_state_kernel_output(handle)
    q, v = world.planar_state()
    torch.testing.assert_close(got[0], q[:2].mean(dim=1))
    world.step()
    world.agents[0].set_pos(torch.zeros(4, 2, device=device), batch_index=None)
    assert world.take_state_kernel_output(handle) is None, "the state changed after the step"


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("setting", ["none", "some", "all"])
def test_a_reset_is_zero_until_set_and_the_next_step_sees_exactly_what_was_set(device, setting):
    """``World.reset(None)`` zeroes the state without allocating it; what the scenario sets afterwards
    (some entities' positions, or every field of every entity) is what the next step starts from."""
    worlds = [_world(device), _world(device)]
    for world in worlds:
        world.step()
        world.reset(None)
    zeroed = worlds[0]
    assert zeroed.state.zeroed, "a reset of all envs allocates no state"
    gen = torch.Generator().manual_seed(1)
    chosen = {"none": [], "some": [0, 2], "all": [0, 1, 2]}[setting]
    for index in chosen:
        values = {f: torch.rand(4, w, generator=gen).to(device) for f, w in (("pos", 2), ("vel", 2), ("rot", 1), ("ang_vel", 1))}
        for world in worlds:
            entity = world.entities[index]
            for f, value in values.items():
                getattr(entity, "set_" + f)(value.clone(), batch_index=None)
    # the reference world reads every field first (allocating the zero state), the other one never does
    expected = _state(worlds[1])
    for f in ("pos", "vel", "rot", "ang_vel"):
        for i, entity in enumerate(worlds[1].entities):
            want = expected[f][i] if i in chosen else torch.zeros_like(expected[f][i])
            assert torch.equal(getattr(entity.state, f), want)
    q, v = zeroed.planar_state()
    # with something set, the step's state is built over the zeros without allocating a zero state first
    assert zeroed.state.zeroed == bool(chosen)
    assert torch.equal(torch.stack([q[0], q[1]], -1), expected["pos"]) and torch.equal(q[2], expected["rot"][..., 0])
    assert torch.equal(torch.stack([v[0], v[1]], -1), expected["vel"]) and torch.equal(v[2], expected["ang_vel"][..., 0])
    for world in worlds:
        world.step()
    after = [_state(w) for w in worlds]
    for f in after[0]:
        assert torch.equal(after[0][f], after[1][f])


@pytest.mark.parametrize("device", DEVICES)
def test_a_step_lets_go_of_the_tensors_it_consumed(device):
    """Tensors an entity was given before a step are dropped by the step (they are stale; holding them kept
    2 MB alive at 30,000 envs); tensors read back from it afterwards are the step's output."""
    world = _world(device)
    given = torch.full((4, 2), 0.25, device=device)
    world.agents[0].set_pos(given, batch_index=None)
    assert world.agents[0].state.pos is given
    world.step()
    assert all(e.state.__dict__["_" + f] is None for e in world.entities for f in ("pos", "vel", "rot", "ang_vel"))
    assert torch.equal(world.agents[0].state.pos, world.stacked_state("pos")[0])


@pytest.mark.parametrize("device", DEVICES)
def test_the_world_state_is_what_the_world_and_its_entities_read(device):
    """``World.state`` owns the state: the world's batched reads are its reads, every entity reads its own row
    of it, and an entity added later gets the row ``World.entities`` gives it."""
    world = _world(device)
    assert isinstance(world.state, WorldState)
    world.step()
    state = world.state
    assert world.planar_state()[0] is state.planar_state()[0]
    assert world.stacked_state("vel") is state.stacked_state("vel")
    assert torch.equal(world.stacked_xy("pos")[1], state.stacked_xy("pos")[1])
    for slot, entity in enumerate(world.entities):
        assert entity.state._world_state is state and entity.state._slot == slot
        assert torch.equal(entity.state.pos, state.view("pos", slot))
    world.add_landmark(Landmark(name="late", collide=False))
    assert [e.state._slot for e in world.entities] == list(range(4)) and world.entities[0].name == "late"
    assert not state.clean(), "rows moved: the next read rebuilds from the entities"
    assert torch.equal(state.stacked_state("pos")[1:], torch.stack([a.state.pos for a in world.agents]))


def test_state_kernels_are_registered_by_handle_and_replaced_in_place():
    world = _world("cpu")

    def first(q, v):
        return q.sum()

    def second(q, v):
        return v.sum()

    handles = [world.add_state_kernel(first), world.add_state_kernel(second)]
    assert handles == [0, 1] and world.state.kernels == (first, second)
    world.replace_state_kernel(0, None)
    assert world.state.kernels == (None, second)
    with pytest.raises(ValueError, match="no state kernel 2: handles are 0..1"):
        world.replace_state_kernel(2, first)
