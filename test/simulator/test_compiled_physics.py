"""The compiled physics path (World.compile_physics / make_env(compile_physics=True)) equals the eager one.

torch.compile may fuse and reorder float ops, so the two paths agree to float
rounding, not bit for bit; over a short horizon (before contacts could amplify a
last-bit difference) states must match closely. Each case compiles once (~10 s).
"""
from __future__ import annotations

import pytest
import torch

import vmas_ros
from vmas_ros.simulator.direct_graph import graphs_compiled
from vmas_ros.simulator.thresholds import GEMM_SCATTER_MAX_CELLS

STEPS = 8


def _rollout(env, actions):
    states = []
    for step_actions in actions:
        env.step(step_actions)
        states.append(torch.cat([env.world.stacked_state(f) for f in ("pos", "vel", "rot", "ang_vel")], dim=-1).clone())
    return torch.stack(states)


# transport: sphere-sphere and box-sphere contacts; balance: lines, boxes and gravity
@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["transport", "balance"])
def test_compiled_step_equals_eager(device, scenario):
    eager = vmas_ros.make_env(scenario, num_envs=16, device=device, seed=3)
    compiled = vmas_ros.make_env(scenario, num_envs=16, device=device, seed=3, compile_physics=True)
    assert compiled.world.physics_compiled and not eager.world.physics_compiled
    gen = torch.Generator(device="cpu").manual_seed(0)
    actions = [
        [(torch.rand(16, eager.get_agent_action_size(a), generator=gen) * 2 - 1).to(device) for a in eager.agents]
        for _ in range(STEPS)
    ]
    compiled_frames = graphs_compiled()
    expected, got = _rollout(eager, actions), _rollout(compiled, actions)
    # the compiled world really ran a compiled graph (a no-op flag would pass the comparison)
    assert graphs_compiled() > compiled_frames
    assert torch.isfinite(got).all()
    # the agents moved, so the comparison is not between two resting worlds
    assert (expected[-1] - expected[0]).abs().max() > 1e-3
    torch.testing.assert_close(got, expected, atol=1e-5, rtol=1e-4)


def test_compile_physics_can_be_turned_off(device):
    env = vmas_ros.make_env("simple_spread", num_envs=2, device=device)
    env.world.compile_physics()
    assert env.world.physics_compiled
    env.world.compile_physics(enabled=False)
    assert not env.world.physics_compiled


@pytest.mark.slow
def test_compiled_lidar_equals_eager(device):
    """flocking's LIDAR through the compiled ray kernels reads the same distances as the eager ones."""
    eager = vmas_ros.make_env("flocking", num_envs=16, device=device, seed=5)
    compiled = vmas_ros.make_env("flocking", num_envs=16, device=device, seed=5, compile_physics=True)
    for agent_e, agent_c in zip(eager.agents, compiled.agents):
        got, expected = agent_c.sensors[0].measure(), agent_e.sensors[0].measure()
        torch.testing.assert_close(got, expected, atol=1e-5, rtol=1e-5)
    # some rays hit an obstacle, so the comparison is not between two all-max readings
    assert (expected < agent_e.sensors[0].max_range).any()
    assert compiled.world._compiled.ray_kernels["sphere"] is not eager.world._compiled.ray_kernels["sphere"]


@pytest.mark.slow
@pytest.mark.parametrize("num_envs", [1, 64, 1000])  # 1000: above SMALL_BATCH_ELEMENTS, the held-block path
def test_the_compiled_step_is_one_graph_from_the_first_step(device, num_envs):
    """Compiling before any eager step must still give one graph, called directly: a cache filled inside the
    traced step (tables' helpers) would otherwise hold the trace's fake tensors or split the graph."""
    env = vmas_ros.make_env("simple_spread", num_envs=num_envs, device=device, seed=1, compile_physics=True)
    graphs = graphs_compiled()
    actions = [torch.zeros(num_envs, 2, device=device) for _ in env.agents]
    for _ in range(3):
        env.step(actions)
    # one graph: the physics, with (at a few envs) simple_spread's rewards and observations fused in as
    # a state kernel
    assert graphs_compiled() - graphs == 1
    copies = list(env.world._compiled.step._copies.values())
    assert copies and all(copy.direct for copy in copies)


@pytest.mark.slow
def test_many_compiled_worlds_in_one_process_all_stay_compiled(device):
    """Each world compiles its own copy of the step: dynamo gives up on a function after eight
    recompilations, which shared code would reach with the ninth world of a process."""
    graphs = graphs_compiled()
    for n_agents in range(1, 11):  # ten different worlds
        env = vmas_ros.make_env("simple_spread", num_envs=2, device=device, n_agents=n_agents, compile_physics=True)
        env.step([torch.zeros(2, 2, device=device) for _ in env.agents])
        assert all(copy.direct for copy in env.world._compiled.step._copies.values())
    # one graph per world: the physics step with simple_spread's few-envs kernel fused in
    assert graphs_compiled() - graphs == 10


@pytest.mark.slow
def test_world_kernel_follows_the_world_and_equals_eager(device):
    """A scenario's WorldKernel runs eagerly until its world compiles, then as one compiled graph."""
    from vmas_ros.simulator.compiling import WorldKernel

    env = vmas_ros.make_env("simple_spread", num_envs=4, device=device, seed=2)

    def spread(q, v):
        return (q[:2] - q[:2].mean(dim=1, keepdim=True)).square().sum(dim=(0, 1)) + v.abs().sum(dim=(0, 1))

    kernel = WorldKernel(env.world, spread)
    q, v = env.world.planar_state()
    graphs = graphs_compiled()
    eager = kernel(q, v)
    assert graphs_compiled() == graphs, "an eager world's kernel must not compile"
    env.world.compile_physics()
    compiled = kernel(q, v)
    assert graphs_compiled() == graphs + 1
    torch.testing.assert_close(compiled, eager, rtol=1e-5, atol=1e-6)


@pytest.mark.slow
def test_compiled_step_with_more_pairs_than_a_dense_scatter_equals_eager(device):
    """Above GEMM_SCATTER_MAX_CELLS the compiled step scatters through the opaque scatter_rows op."""
    import math

    from vmas_ros.simulator.core import Agent, Sphere, World

    n, batch = 40, 3
    assert n * (n * (n - 1) // 2) > GEMM_SCATTER_MAX_CELLS
    worlds = []
    for compiled in (False, True):
        world = World(batch_dim=batch, device=device)
        if compiled:
            world.compile_physics()
        for i in range(n):
            world.add_agent(Agent(name=f"s{i}", shape=Sphere(0.05)))
        gen = torch.Generator().manual_seed(0)
        for agent in world.agents:
            agent.set_pos(((torch.rand(batch, 2, generator=gen) - 0.5) * 0.1 * math.sqrt(n)).to(device), batch_index=None)
        worlds.append(world)
    for _ in range(3):
        for world in worlds:
            world.step()
    eager, compiled = (w.stacked_state("vel") for w in worlds)
    assert eager.abs().max() > 0.01, "the spheres overlap and push each other"
    torch.testing.assert_close(compiled, eager, rtol=1e-4, atol=1e-5)


@pytest.mark.slow
def test_compiled_step_checks_only_its_inputs_and_recompiles_for_a_new_layout(device):
    """The compiled step checks only the state and the actions (their shapes, strides, dtypes and devices);
    what it bakes in is its layout, so changing an entity's property (new tables) or a step parameter
    compiles a new copy that still equals eager."""
    from vmas_ros.simulator.tables import WorldTables

    eager = vmas_ros.make_env("simple_spread", num_envs=4, device=device, seed=1)
    compiled = vmas_ros.make_env("simple_spread", num_envs=4, device=device, seed=1, compile_physics=True)
    gen = torch.Generator(device="cpu").manual_seed(2)
    actions = [[(torch.rand(4, 2, generator=gen) * 2 - 1).to(device) for _ in eager.agents] for _ in range(4)]
    torch.testing.assert_close(_rollout(compiled, actions), _rollout(eager, actions), atol=1e-5, rtol=1e-4)
    steps = compiled.world._compiled.step
    (copy,) = steps._copies.values()
    assert copy.direct, "a one-graph step is called directly"
    (signature,) = copy._direct._graphs  # one input signature over the four steps
    assert not any(isinstance(item, WorldTables) for item in signature), "no check of what the layout key covers"
    state_q = compiled.world.planar_state()[0]
    assert (state_q.shape, state_q.stride(), state_q.dtype, state_q.device) in signature, "the state is checked"
    # a property change rebuilds the tables: a new compiled copy, still equal to eager
    for env in (eager, compiled):
        env.agents[0].mass = 3.0
        env.world.broad_phase = "env"
    torch.testing.assert_close(_rollout(compiled, actions), _rollout(eager, actions), atol=1e-5, rtol=1e-4)
    assert compiled.world._compiled.step._copies and copy not in compiled.world._compiled.step._copies.values()
    moved = [env.agents[0].state.pos.clone() for env in (eager, compiled)]
    torch.testing.assert_close(moved[1], moved[0], atol=1e-5, rtol=1e-4)


def _biased(q: torch.Tensor, bias: torch.Tensor, scale: float = 1.0) -> torch.Tensor:
    return q[0] * scale + bias


@pytest.mark.slow
def test_world_kernels_check_only_their_arguments(device):
    """A WorldKernel (here a lidar cast: a partial with a dozen bound tensors) is guarded on its arguments
    only; its bound constants are read afresh but not checked on each call."""
    import functools

    from vmas_ros.simulator.compiling import WorldKernel

    env = vmas_ros.make_env("simple_spread", num_envs=3, device=device, seed=0, compile_physics=True)
    bias = torch.ones(3, device=device)
    kernel = WorldKernel(env.world, functools.partial(_biased, bias=bias))
    q = env.world.planar_state()[0]
    torch.testing.assert_close(kernel(q), q[0] + 1)
    bias.fill_(2.0)  # read afresh: the constant's current value
    torch.testing.assert_close(kernel(q), q[0] + 2)
    assert kernel._compiled.direct and len(kernel._compiled._direct._graphs) == 1
    # each partial compiles into code of its own: another kernel of the same function with other constants
    # computes with its own, Python values included (torch.compile runs every partial through one shared
    # wrapper function: with guards cut to the arguments, this kernel ran the first one's code, scale 1)
    other = WorldKernel(env.world, functools.partial(_biased, bias=torch.full((3,), 5.0, device=device), scale=3.0))
    torch.testing.assert_close(other(q), q[0] * 3 + 5)
    torch.testing.assert_close(kernel(q), q[0] + 2)
    with pytest.raises(ValueError, match="no state kernel 5"):
        env.world.replace_state_kernel(5, None)


def _doubled_after_a_break(y):
    """Shared code with a graph break: a resumed frame whose guards name ``y``. The branch on a tensor's
    value makes the direct graph decline it too (a trace cannot know the value)."""
    torch._dynamo.graph_break()
    if bool(y.sum() > -1e30):
        return y * 2
    return y


def _outer(x):
    return _doubled_after_a_break(x + 1)


@pytest.mark.slow
def test_a_function_with_a_graph_break_keeps_all_its_guards(device):
    """A function the direct graph declines goes through torch.compile. Guards are cut only where a
    function compiles to one graph there: after a graph break the resumed frames
    are shared code whose guards name their own locals (``y`` here, not the checked ``x``), so a function
    that breaks is compiled with all of its guards and follows new shapes (cutting them ran the code
    compiled for 3 envs on 5: a size assertion inside the compiled code)."""
    from vmas_ros.simulator.compiling import LayoutCompiled, compile_for_world

    layout = LayoutCompiled(_outer, None, key=lambda x: "one layout", checked=("x",))
    kernel = compile_for_world(_outer, None, arguments_only=True)
    for n in (3, 5, 3):
        x = torch.arange(2.0 * n, device=device).view(2, n)
        torch.testing.assert_close(layout("owner", x), _outer(x))
        torch.testing.assert_close(kernel(x), _outer(x))
    assert kernel.one_graph is False and all(c.one_graph is False for c in layout._copies.values())
