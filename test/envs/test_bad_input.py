"""Bad input is rejected loudly, with a message that says what was wrong and where.

Actions (shape, dtype, device, NaN/inf, range, dict keys, count), make_env
arguments, reset_at selectors and engine constructors. A rejected step leaves
the env exactly as it was.
"""
from __future__ import annotations

import math
import re
import warnings

import pytest
import torch

import vmas_ros
from vmas_ros.simulator.core import Agent, Box, Landmark, Line, Sphere, World
from vmas_ros.simulator.joints import Joint

N = 4


def make(name="simple_spread", **kwargs):
    kwargs.setdefault("num_envs", N)
    kwargs.setdefault("seed", 0)
    return vmas_ros.make_env(name, device="cpu", **kwargs)


def good_actions(env):
    return [torch.zeros(N, env.get_agent_action_size(a)) for a in env.agents]


def with_action(env, agent_index, action):
    actions = good_actions(env)
    actions[agent_index] = action
    return actions


def snapshot(env):
    return {
        (e.name, f): getattr(e.state, f).clone() for e in env.world.entities for f in ("pos", "vel", "rot", "ang_vel")
    }


def assert_unchanged(env, before):
    for (name, field), value in before.items():
        entity = next(e for e in env.world.entities if e.name == name)
        assert torch.equal(getattr(entity.state, field), value), f"{name}.{field} changed by a rejected step"


# ------------------------------------------------------------------ action shape


@pytest.mark.parametrize(
    "shape",
    [(N, 3), (N, 1), (N - 1, 2), (N + 1, 2), (N * 2,), (N,), (N, 2, 1), (2,)],
    ids=lambda s: "x".join(map(str, s)),
)
def test_wrong_action_shape_names_agent_and_expected_shape(shape):
    env = make()
    with pytest.raises(ValueError) as info:
        env.step(with_action(env, 1, torch.zeros(shape)))
    message = str(info.value)
    assert "agent_1" in message
    assert f"({N}, 2)" in message, message
    assert str(tuple(shape)) in message, "the message should also show what was given"


def test_wrong_discrete_action_shape():
    env = make(continuous_actions=False)
    with pytest.raises(ValueError, match=re.escape(f"expected ({N}, 1)")) as info:
        env.step(with_action(env, 2, torch.zeros(N, 2, dtype=torch.long)))
    assert "agent_2" in str(info.value)


def test_wrong_multidiscrete_action_shape():
    env = make(continuous_actions=False, multidiscrete_actions=True)
    with pytest.raises(ValueError, match=re.escape(f"expected ({N}, 2)")):
        env.step(with_action(env, 0, torch.zeros(N, 1, dtype=torch.long)))


def test_non_numeric_action():
    env = make()
    with pytest.raises(ValueError, match="agent_0"):
        env.step(with_action(env, 0, "left"))


# ------------------------------------------------------------ dtype and device


@pytest.mark.parametrize("dtype", [torch.bool, torch.complex64])
def test_wrong_action_dtype(dtype):
    env = make()
    with pytest.raises(ValueError) as info:
        env.step(with_action(env, 2, torch.zeros(N, 2, dtype=dtype)))
    message = str(info.value)
    assert "agent_2" in message and str(dtype) in message, message


@pytest.mark.parametrize("dtype", [torch.bool, torch.complex64])
def test_wrong_discrete_action_dtype(dtype):
    env = make(continuous_actions=False)
    with pytest.raises(ValueError, match="agent_0"):
        env.step(with_action(env, 0, torch.zeros(N, 1, dtype=dtype)))


def test_wrong_action_device():
    other = "cuda" if torch.cuda.is_available() else "meta"
    env = make()
    with pytest.raises(ValueError) as info:
        env.step(with_action(env, 1, torch.zeros(N, 2, device=other)))
    message = str(info.value)
    assert "agent_1" in message and other in message and "cpu" in message, message


def test_other_real_dtypes_are_accepted():
    env = make()
    env.step(with_action(env, 0, torch.ones(N, 2, dtype=torch.float64) * 0.5))
    env.step(with_action(env, 1, torch.ones(N, 2, dtype=torch.int64)))
    assert env.agents[1].action.u.dtype == torch.float32
    torch.testing.assert_close(env.agents[1].action.u, torch.ones(N, 2))


# --------------------------------------------------------------- NaN, inf, range


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf], ids=["nan", "inf", "-inf"])
def test_non_finite_actions_are_rejected(bad):
    env = make(clamp_actions=False)
    action = torch.zeros(N, 2)
    action[2, 1] = bad
    with pytest.raises(ValueError, match=r"NaN or inf") as info:
        env.step(with_action(env, 1, action))
    assert "agent_1" in str(info.value) and "env 2" in str(info.value)


def test_non_finite_actions_are_rejected_even_when_clamping():
    env = make(clamp_actions=True)
    action = torch.zeros(N, 2)
    action[0, 0] = math.nan
    with pytest.raises(ValueError, match=r"NaN"):
        env.step(with_action(env, 0, action))


@pytest.mark.parametrize("bad", [math.inf, -math.inf], ids=["inf", "-inf"])
def test_infinite_actions_are_rejected_even_when_clamping(bad):
    env = make(clamp_actions=True)
    action = torch.zeros(N, 2)
    action[1, 1] = bad
    with pytest.raises(ValueError, match=r"NaN or inf"):
        env.step(with_action(env, 0, action))


def test_out_of_range_continuous_action_raises():
    env = make()
    action = torch.zeros(N, 2)
    action[3, 0] = 1.5
    with pytest.raises(ValueError, match="out of range") as info:
        env.step(with_action(env, 2, action))
    message = str(info.value)
    assert "agent_2" in message and "env 3" in message and "clamp_actions" in message
    # the bounds themselves are allowed
    env.step(with_action(env, 2, torch.tensor([[1.0, -1.0]] * N)))


def test_out_of_range_continuous_action_is_clamped_when_asked():
    env = make(clamp_actions=True)
    action = torch.tensor([[1.5, -3.0], [0.2, -0.4], [-7.0, 1.0], [100.0, 0.0]])
    env.step(with_action(env, 0, action))
    expected = torch.tensor([[1.0, -1.0], [0.2, -0.4], [-1.0, 1.0], [1.0, 0.0]])
    torch.testing.assert_close(env.agents[0].action.u, expected)
    torch.testing.assert_close(env.agents[0].state.force, expected)


def test_clamping_respects_u_multiplier():
    env = make("waterfall", clamp_actions=True)  # u_range 1, u_multiplier 0.7
    env.step(with_action(env, 0, torch.full((N, 2), 2.0)))
    torch.testing.assert_close(env.agents[0].action.u, torch.full((N, 2), 0.7))


@pytest.mark.parametrize("bad", [9, -1, 100])
def test_discrete_index_out_of_range(bad):
    env = make(continuous_actions=False)
    action = torch.zeros(N, 1, dtype=torch.long)
    action[1, 0] = bad
    with pytest.raises(ValueError, match="out of range") as info:
        env.step(with_action(env, 0, action))
    assert "agent_0" in str(info.value)
    env.step(with_action(env, 0, torch.full((N, 1), 8, dtype=torch.long)))  # the last index is fine


@pytest.mark.parametrize("bad", [[3, 0], [0, -1]])
def test_multidiscrete_index_out_of_range(bad):
    env = make(continuous_actions=False, multidiscrete_actions=True)
    action = torch.zeros(N, 2, dtype=torch.long)
    action[0] = torch.tensor(bad)
    with pytest.raises(ValueError, match="out of range"):
        env.step(with_action(env, 1, action))


def test_discrete_non_integer_value():
    env = make(continuous_actions=False)
    with pytest.raises(ValueError, match="non-integer"):
        env.step(with_action(env, 0, torch.full((N, 1), 1.5)))
    env.step(with_action(env, 0, torch.full((N, 1), 2.0)))  # integral floats are fine
    assert env.agents[0].action.u.tolist() == [[0.0, 1.0]] * N


# ---------------------------------------------------------- dicts and counts


def test_dict_missing_an_agent():
    env = make()
    actions = {a.name: torch.zeros(N, 2) for a in env.agents}
    del actions["agent_1"]
    with pytest.raises(ValueError, match=r"missing \['agent_1'\]"):
        env.step(actions)


def test_dict_with_unknown_name():
    env = make()
    actions = {a.name: torch.zeros(N, 2) for a in env.agents}
    actions["agent_7"] = torch.zeros(N, 2)
    with pytest.raises(ValueError, match=r"unknown \['agent_7'\]") as info:
        env.step(actions)
    assert "agent_0" in str(info.value), "the message lists the valid names"


@pytest.mark.parametrize("count", [0, 2, 4])
def test_wrong_number_of_actions(count):
    env = make()
    with pytest.raises(ValueError, match=rf"3 agents, got {count}"):
        env.step([torch.zeros(N, 2)] * count)


def test_actions_must_be_a_list_a_dict_or_one_stacked_tensor():
    env = make()
    with pytest.raises(ValueError, match=r"a list \(one per agent\), a dict by agent name or one stacked "
                                         r"\[n_agents, num_envs, size\] tensor, got int"):
        env.step(3)


# ------------------------------------------------------------ rejected steps


@pytest.mark.parametrize(
    "bad_actions",
    [
        lambda env: with_action(env, 2, torch.full((N, 2), math.nan)),
        lambda env: with_action(env, 2, torch.full((N, 2), 5.0)),
        lambda env: with_action(env, 2, torch.zeros(N, 3)),
        lambda env: {"agent_0": torch.ones(N, 2), "agent_1": torch.ones(N, 2)},
    ],
    ids=["nan", "out-of-range", "shape", "missing-agent"],
)
def test_rejected_step_leaves_the_env_unchanged(bad_actions):
    env, twin = make(), make()
    push = [torch.full((N, 2), 0.5) for _ in env.agents]
    env.step(push)
    twin.step(push)
    before = snapshot(env)
    u_before = [a.action.u.clone() for a in env.agents]
    actions = bad_actions(env)
    if isinstance(actions, list):  # valid actions for the first agents: they must not be applied either
        actions[0] = torch.ones(N, 2)
    with pytest.raises(ValueError):
        env.step(actions)
    assert_unchanged(env, before)
    assert all(torch.equal(a.action.u, u) for a, u in zip(env.agents, u_before)), "no action may be half-applied"
    assert torch.equal(env.steps, torch.ones(N))
    # and the env carries on exactly like one that never saw the bad step
    out, twin_out = env.step(push), twin.step(push)
    for o, t in zip(out[0], twin_out[0]):
        assert torch.equal(o, t)


# ------------------------------------------------------------------- make_env


def test_unknown_scenario_lists_valid_names():
    with pytest.raises(ValueError) as info:
        vmas_ros.make_env("no_such_scenario", num_envs=1)
    message = str(info.value)
    assert "no_such_scenario" in message
    for name in vmas_ros.list_scenarios():
        assert name in message
    assert "simple_spread" in message and "waterfall" in message


def test_misspelt_scenario_gets_a_suggestion():
    with pytest.raises(ValueError, match="did you mean 'simple_spread'"):
        vmas_ros.make_env("simple_sprad", num_envs=1)


def test_scenario_name_with_py_suffix_is_accepted_like_vmas():
    env = vmas_ros.make_env("simple_spread.py", num_envs=1)
    assert env.n_agents == 3


def test_non_scenario_object_is_rejected():
    with pytest.raises(TypeError, match="BaseScenario"):
        vmas_ros.make_env(42, num_envs=1)


def test_unused_scenario_kwargs_warn():
    with pytest.warns(UserWarning, match="n_agentz"):
        env = make(n_agentz=5)
    assert env.n_agents == 3
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert make(n_agents=2).n_agents == 2  # consumed kwargs do not warn


def test_unused_kwargs_warn_for_waterfall_too():
    with pytest.warns(UserWarning, match="gravity"):
        make("waterfall", gravity=1.0)


def test_bad_scenario_kwarg_values():
    with pytest.raises(ValueError, match="n_agents"):
        make(n_agents=0)


@pytest.mark.parametrize("num_envs", [0, -3, 2.0, "4", None, True])
def test_bad_num_envs(num_envs):
    with pytest.raises(ValueError, match="num_envs"):
        vmas_ros.make_env("simple_spread", num_envs=num_envs)


@pytest.mark.parametrize("max_steps", [0, -1, 2.5])
def test_bad_max_steps(max_steps):
    with pytest.raises(ValueError, match="max_steps"):
        make(max_steps=max_steps)


def test_unknown_wrapper():
    with pytest.raises(ValueError, match="wrapper"):
        make(wrapper="gym")


# --------------------------------------------------------------------- reset_at


@pytest.mark.parametrize(
    "index",
    [N, -N - 1, [0, N], torch.tensor([N + 2]), torch.tensor([-N - 1])],
    ids=["int", "negative-int", "list", "tensor", "negative-tensor"],
)
def test_reset_at_out_of_range(index):
    env = make()
    with pytest.raises(ValueError, match="out of range"):
        env.reset_at(index)


@pytest.mark.parametrize("length", [N - 1, N + 1, 1])
def test_reset_at_wrong_mask_length(length):
    env = make()
    with pytest.raises(ValueError, match=rf"\({N},\)"):
        env.reset_at(torch.ones(length, dtype=torch.bool))


@pytest.mark.parametrize(
    "index", [1.0, torch.tensor([0.0, 1.0]), torch.zeros(2, 2, dtype=torch.long), True], ids=["float", "float-tensor", "2d", "bool"]
)
def test_reset_at_bad_index_type(index):
    env = make()
    with pytest.raises(ValueError):
        env.reset_at(index)


def test_rejected_reset_at_changes_nothing():
    env = make()
    env.step([torch.full((N, 2), 0.5) for _ in env.agents])
    before = snapshot(env)
    with pytest.raises(ValueError):
        env.reset_at([0, N])  # index 0 is valid, but the call as a whole is not
    assert_unchanged(env, before)
    assert torch.equal(env.steps, torch.ones(N))


# ------------------------------------------------------------------ constructors


@pytest.mark.parametrize("mass", [0.0, -1.0, math.nan])
@pytest.mark.parametrize("cls", [Landmark, Agent])
def test_non_positive_mass(cls, mass):
    with pytest.raises(ValueError, match="mass"):
        cls("thing", mass=mass)


@pytest.mark.parametrize("radius", [0.0, -0.1, math.nan])
def test_bad_sphere_radius(radius):
    with pytest.raises(ValueError, match="radius"):
        Sphere(radius=radius)


@pytest.mark.parametrize("length,width", [(0.0, 0.1), (0.1, 0.0), (-0.2, 0.1), (0.1, -1.0)])
def test_bad_box_sides(length, width):
    with pytest.raises(ValueError, match="length" if length <= 0 else "width"):
        Box(length=length, width=width)


@pytest.mark.parametrize("length", [0.0, -1.0])
def test_bad_line_length(length):
    with pytest.raises(ValueError, match="length"):
        Line(length=length)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(batch_dim=0), "batch_dim"),
        (dict(batch_dim=-2), "batch_dim"),
        (dict(batch_dim=1.5), "batch_dim"),
        (dict(batch_dim=1, dt=0.0), "dt"),
        (dict(batch_dim=1, substeps=0), "substeps"),
        (dict(batch_dim=1, contact_margin=0.0), "contact_margin"),
    ],
)
def test_bad_world_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        World(device="cpu", **kwargs)


def test_joints_need_more_than_one_substep():
    world = World(batch_dim=1, device="cpu", substeps=1)
    a, b = Agent("a"), Agent("b")
    world.add_agent(a)
    world.add_agent(b)
    with pytest.raises(ValueError, match="substeps"):
        world.add_joint(Joint(a, b, dist=0.0))
    world_ok = World(batch_dim=1, device="cpu", substeps=2)
    c, d = Agent("c"), Agent("d")
    world_ok.add_agent(c)
    world_ok.add_agent(d)
    world_ok.add_joint(Joint(c, d, dist=0.2))
    assert len(world_ok.joints) == 2


def test_bad_joint_arguments():
    a, b = Agent("a"), Agent("b")
    with pytest.raises(ValueError, match="itself"):
        Joint(a, a)
    with pytest.raises(ValueError, match="dist"):
        Joint(a, b, dist=-0.1)
    with pytest.raises(ValueError, match="anchor"):
        Joint(a, b, anchor_a=(2.0, 0.0))


def test_duplicate_entity_names():
    world = World(batch_dim=1, device="cpu")
    world.add_agent(Agent("twin"))
    with pytest.raises(ValueError, match="twin"):
        world.add_landmark(Landmark("twin"))


def test_empty_entity_name():
    with pytest.raises(ValueError, match="name"):
        Landmark("")
