"""Every shipped adapter against the Environment: the messages a robot publishes rebuild the observation.

For each task: an Environment stepped a few times with random actions; for
each env, the Odometry (``convert.fill_odometry``), a 360-ray LaserScan cast
by the engine from the same state (``convert.fill_scan``) and the goal poses
a robot would have; the adapter's rows must equal the Environment's
observations. Then each adapter's refusals and ``problems``.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import vmas_ros
from test.adapters import robot_messages as rm
from vmas_ros.adapters import (
    DiffDriveAdapter, GoalAdapter, NavigationAdapter, SimpleSpreadAdapter, load_adapter,
)

ATOL = 1e-5


def stepped(scenario: str, num_envs: int = 3, steps: int = 6, seed: int = 2, crowd: float = 0.0, **kwargs):
    """The env after ``steps`` random steps, and the last observations; ``crowd``: agents first squeezed into a
    square of that side round the origin, so that their lidars see each other."""
    env = vmas_ros.make_env(scenario, num_envs=num_envs, seed=seed, **kwargs)
    env.reset()
    if crowd:
        gen = torch.Generator().manual_seed(seed)
        for agent in env.agents:
            agent.set_pos((torch.rand(num_envs, 2, generator=gen) - 0.5) * crowd, batch_index=None)
    for _ in range(steps):
        obs, _, _, _ = env.step(env.get_random_actions())
    return env, obs


# ------------------------------------------------------------------ navigation
@pytest.mark.parametrize("dynamics", ["holonomic", "diff_drive"])
def test_navigation_adapter_rebuilds_the_observation(dynamics):
    env, obs = stepped("navigation", crowd=0.5, dynamics=dynamics)
    size = obs[0].shape[1]
    adapter = NavigationAdapter(rm.names(env), size, dynamics=dynamics)
    assert adapter.n_lidar_rays == 12
    rays_hit = 0
    for index in range(env.num_envs):
        latest = rm.robot_messages(env, index)
        assert set(adapter.topics()) == set(latest)
        built, wanted = adapter.build(latest), rm.expected(obs, index)
        assert adapter.problems == {}
        np.testing.assert_allclose(built, wanted, atol=ATOL)
        rays_hit += int((wanted[:, -12:] > 0).sum())
    assert rays_hit >= 3, "the agents must see each other for the lidar comparison to mean anything"
    if dynamics == "diff_drive":
        rot = torch.cat([a.state.rot for a in env.agents])
        assert rot.abs().max() > 1.0  # the agents are turned: body-frame rays differ from world-frame ones


def test_holonomic_navigation_adapter_turns_the_scan_by_the_heading():
    """A holonomic policy's rays point along fixed world directions; a real robot facing elsewhere
    scans in its own frame, so the adapter reads the scan at the training angles minus its heading."""
    env, obs = stepped("navigation", crowd=0.5)
    adapter = NavigationAdapter(rm.names(env), obs[0].shape[1])
    yaws = [2 * math.pi * degrees / 360 for degrees in (130, -75, 12, 181)]  # whole degrees: rays line up
    for index in range(env.num_envs):
        latest = rm.robot_messages(env, index, yaws)
        np.testing.assert_allclose(adapter.build(latest), rm.expected(obs, index), atol=ATOL)
    # read as if the robots faced along x, the same scans put the neighbours on other rays
    turned = NavigationAdapter(rm.names(env), obs[0].shape[1], dynamics="holonomic", scan_yaw=0.5)
    assert not np.allclose(turned.build(latest)[:, -12:], rm.expected(obs, index)[:, -12:], atol=ATOL)


@pytest.mark.parametrize("kwargs", [
    {"collisions": False, "n_agents": 3},
    {"collisions": False, "observe_all_goals": True, "n_agents": 3, "dynamics": "diff_drive"},
    {"n_lidar_rays": 8, "lidar_range": 0.6, "n_agents": 3, "observe_all_goals": True},
])
def test_navigation_adapter_follows_the_layout_kwargs(kwargs):
    env, obs = stepped("navigation", crowd=0.6, **kwargs)
    adapter_kwargs = {k: kwargs[k] for k in ("dynamics", "observe_all_goals", "lidar_range") if k in kwargs}
    adapter = NavigationAdapter(rm.names(env), obs[0].shape[1], **adapter_kwargs)
    assert adapter.n_lidar_rays == (kwargs.get("n_lidar_rays", 12) if kwargs.get("collisions", True) else 0)
    for index in range(env.num_envs):
        np.testing.assert_allclose(adapter.build(rm.robot_messages(env, index)), rm.expected(obs, index), atol=ATOL)


def test_navigation_adapter_refuses_sizes_that_do_not_fit():
    agents = ["agent_0", "agent_1"]
    with pytest.raises(ValueError, match=r"observation_size 18 does not fit .*n_lidar_rays=10.* = 16"):
        NavigationAdapter(agents, 18, n_lidar_rays=10)
    with pytest.raises(ValueError, match="observation_size 5 is too small"):
        NavigationAdapter(agents, 5)
    with pytest.raises(ValueError, match="dynamics must be one of holonomic, diff_drive, got 'tank'"):
        NavigationAdapter(agents, 18, dynamics="tank")
    with pytest.raises(ValueError, match="lidar_range"):
        NavigationAdapter(agents, 18, lidar_range=0)
    with pytest.raises(ValueError, match="'{agent}'"):
        NavigationAdapter(agents, 18, scan_topic="scan")
    assert NavigationAdapter(agents, 20, dynamics="diff_drive").n_lidar_rays == 12
    assert "agent_0/scan" not in NavigationAdapter(agents, 6).topics()  # no lidar: no scan to wait for


def test_navigation_adapter_names_each_agents_problem():
    env, obs = stepped("navigation", num_envs=1, crowd=0.5)
    adapter = NavigationAdapter(rm.names(env), obs[0].shape[1])
    latest = rm.robot_messages(env, 0)
    odom = latest["agent_1/odom"]
    odom.pose.pose.position.x = math.nan
    del latest["agent_2/goal"]
    half = latest["agent_3/scan"]
    half.angle_min, half.ranges = -math.pi / 2, list(half.ranges)[90:271]
    half.angle_max = half.angle_min + 180 * half.angle_increment
    built = adapter.build(latest)
    assert adapter.problems == {
        "agent_1": "agent_1/odom: NaN pose",
        "agent_2": "agent_2/goal: no message",
        "agent_3": "agent_3/scan: scan covers [-1.57, 1.57] rad, the training lidar needs rays all round the circle",
    }
    assert np.isnan(built[1:]).all()
    np.testing.assert_allclose(built[0], rm.expected(obs, 0)[0], atol=ATOL)
    assert adapter.build({}).shape == (4, 18) and adapter.problems["agent_0"] == (
        "agent_0/odom: no message; agent_0/goal: no message; agent_0/scan: no message")
    shared = NavigationAdapter(rm.names(env), 4 + 8 + 12, observe_all_goals=True)
    shared.build(latest)
    assert shared.problems["agent_0"] == "no goal of agent_2, which it observes"


def test_navigation_adapter_treats_nan_readings_by_the_scan_rules():
    env, obs = stepped("navigation", num_envs=1, crowd=0.5)
    adapter = NavigationAdapter(rm.names(env), obs[0].shape[1])
    latest = rm.robot_messages(env, 0)
    ranges = np.asarray(latest["agent_0/scan"].ranges, dtype=np.float64)
    # scan ray 180 + 30 k is training ray k; one NaN there reads its neighbour instead
    ranges[180] = np.nan
    latest["agent_0/scan"].ranges = ranges.tolist()
    built = adapter.build(latest)
    assert adapter.problems == {}
    neighbour = ranges[179] if ranges[179] <= 0.35 else 0.35
    assert built[0, 6] == pytest.approx(0.35 - neighbour, abs=1e-6)
    ranges[150:211] = np.nan  # a blind sector wider than the training rays' spacing: ray 0 cannot be read
    latest["agent_0/scan"].ranges = ranges.tolist()
    built = adapter.build(latest)
    assert np.isnan(built[0]).all() and "NaN readings" in adapter.problems["agent_0"]
    assert "training rays [0]" in adapter.problems["agent_0"]


@pytest.mark.parametrize("dynamics", ["holonomic", "diff_drive"])
def test_navigation_adapter_scan_margin_brings_only_the_lidar_closer(dynamics):
    env, obs = stepped("navigation", crowd=0.5, dynamics=dynamics)
    size, margin = obs[0].shape[1], 0.05
    plain = NavigationAdapter(rm.names(env), size, dynamics=dynamics, scan_margin=0.0)
    inflated = NavigationAdapter(rm.names(env), size, dynamics=dynamics, scan_margin=margin)
    assert plain.scan_margin == 0.0 and inflated.resampler.margin == margin
    closer = 0
    for index in range(env.num_envs):
        latest, wanted = rm.robot_messages(env, index), rm.expected(obs, index)
        np.testing.assert_allclose(plain.build(latest), wanted, atol=ATOL)  # margin 0: the engine's observation
        built = inflated.build(latest)
        assert inflated.problems == {}
        np.testing.assert_array_equal(built[:, :-12], plain.build(latest)[:, :-12])  # the rest is untouched
        rays, seen = built[:, -12:], wanted[:, -12:]
        hits = seen > 0
        np.testing.assert_allclose(rays[hits], np.minimum(seen[hits] + margin, 0.35), atol=ATOL)
        # no return within the training range: free, or a neighbour less than the margin beyond it
        assert ((rays[~hits] >= 0) & (rays[~hits] < margin + ATOL)).all()
        closer += int(hits.sum())
    assert closer >= 3, "the agents must see each other for the margin to show"



@pytest.mark.parametrize("dynamics", ["holonomic", "diff_drive"])
def test_navigation_adapter_scan_lead_reads_closer_what_the_robot_drives_at(dynamics):
    env, obs = stepped("navigation", crowd=0.5, dynamics=dynamics)
    size, lead = obs[0].shape[1], 0.5
    plain = NavigationAdapter(rm.names(env), size, dynamics=dynamics)
    leading = NavigationAdapter(rm.names(env), size, dynamics=dynamics, scan_lead=lead)
    assert plain.scan_lead == 0.0 and leading.resampler.lead == lead
    grown = 0
    for index in range(env.num_envs):
        latest = rm.robot_messages(env, index)
        before, after = plain.build(latest), leading.build(latest)
        assert leading.problems == {}
        np.testing.assert_array_equal(after[:, :-12], before[:, :-12])  # the rest is untouched
        for i, agent in enumerate(env.agents):
            yaw = float(agent.state.rot[index]) if dynamics == "diff_drive" else 0.0
            velocity = agent.state.vel[index].numpy()
            angles = leading.resampler.world_angles(yaw)
            extra = lead * np.maximum(velocity[0] * np.cos(angles) + velocity[1] * np.sin(angles), 0.0)
            hits = before[i, -12:] > 0
            np.testing.assert_allclose(after[i, -12:][hits], np.minimum(before[i, -12:][hits] + extra[hits], 0.35),
                                       atol=ATOL)
            assert (after[i, -12:] >= before[i, -12:] - ATOL).all()
            grown += int((after[i, -12:] > before[i, -12:] + 1e-4).sum())
    assert grown >= 2, "some agent must drive towards a neighbour it sees for the lead to show"


def test_navigation_adapter_refuses_a_margin_that_is_no_distance():
    agents = ["agent_0", "agent_1"]
    for margin, problem in [(-0.05, "scan_margin must be >= 0 m and below the training lidar's range 0.35 m, got "
                                     "-0.05"),
                            (math.nan, "scan_margin must be a finite number of metres, got nan"),
                            (math.inf, "scan_margin must be a finite number of metres, got inf"),
                            (5, "scan_margin must be >= 0 m and below the training lidar's range 0.35 m, got 5")]:
        with pytest.raises(ValueError) as error:
            NavigationAdapter(agents, 18, scan_margin=margin)
        assert str(error.value) == problem
        with pytest.raises(ValueError) as error:
            load_adapter("navigation", agents, 18, {"scan_margin": margin})
        assert str(error.value) == f"adapter 'navigation' refused its arguments: {problem}"
    assert NavigationAdapter(agents, 18, lidar_range=0.6, scan_margin=0.4).resampler.margin == 0.4
    for lead, problem in [(-1, "scan_lead must be >= 0 s, got -1"),
                          (math.nan, "scan_lead must be a finite number of seconds, got nan")]:
        with pytest.raises(ValueError) as error:
            load_adapter("navigation", agents, 18, {"scan_lead": lead})
        assert str(error.value) == f"adapter 'navigation' refused its arguments: {problem}"


def test_scan_margin_reaches_the_adapter_from_policy_nodes_parameters():
    """policy_node builds its adapter from ``adapter_kwargs`` (a YAML-flow string) as here."""
    from vmas_ros.ros.params import PolicyNodeParams, validate_policy_node

    text = "{scan_margin: 0.08}"
    assert validate_policy_node("adapter_kwargs", text) is None
    params = PolicyNodeParams(adapter="navigation", adapter_kwargs=text)
    adapter = load_adapter(params.adapter, ["agent_0", "agent_1"], 18, params.kwargs(), {"n_agents": 2})
    assert adapter.scan_margin == 0.08 and adapter.resampler.margin == 0.08
    assert load_adapter("navigation", ["agent_0", "agent_1"], 18, PolicyNodeParams().kwargs()).resampler.margin == 0


# ---------------------------------------------------------------- simple_spread
@pytest.mark.parametrize("n_agents,obs_agents", [(3, True), (2, False)])
def test_simple_spread_adapter_rebuilds_the_observation(n_agents, obs_agents):
    env, obs = stepped("simple_spread", n_agents=n_agents, obs_agents=obs_agents)
    adapter = SimpleSpreadAdapter(rm.names(env), obs[0].shape[1], obs_agents=obs_agents)
    for index in range(env.num_envs):
        for yaws in (None, [0.7 * (k + 1) for k in range(n_agents)]):  # robots facing anywhere: same vector
            latest = {t: m for t, m in rm.robot_messages(env, index, yaws).items() if t.endswith("/odom")}
            latest["landmarks/poses"] = rm.pose_array(env.world.landmarks, index)
            assert set(adapter.topics()) == set(latest)
            np.testing.assert_allclose(adapter.build(latest), rm.expected(obs, index), atol=ATOL)
            assert adapter.problems == {}


def test_simple_spread_adapter_problems():
    env, obs = stepped("simple_spread", num_envs=1)
    adapter = SimpleSpreadAdapter(rm.names(env), obs[0].shape[1])
    latest = {f"{n}/odom": rm.odometry(a, 0) for n, a in zip(rm.names(env), env.agents)}
    assert np.isnan(adapter.build(latest)).all()
    assert adapter.problems["agent_2"] == "landmarks/poses: no message"
    latest["landmarks/poses"] = rm.pose_array(env.world.landmarks[:2], 0)
    adapter.build(latest)
    assert adapter.problems["agent_0"] == "landmarks/poses: 2 poses, expected 3"
    latest["landmarks/poses"] = rm.pose_array(env.world.landmarks, 0)
    latest["agent_1/odom"].twist.twist.linear.x = math.inf
    built = adapter.build(latest)
    assert adapter.problems == {"agent_0": "no odometry of agent_1, whom it observes",
                                "agent_1": "agent_1/odom: infinite twist",
                                "agent_2": "no odometry of agent_1, whom it observes"}
    assert np.isnan(built).all()


# ------------------------------------------------------------ debug diff_drive, goal
def test_diff_drive_adapter_rebuilds_the_observation():
    env, obs = stepped("diff_drive", n_agents=3)
    adapter = DiffDriveAdapter(rm.names(env), 4)
    assert rm.names(env) == ["diff_drive_0", "holo_rot_1", "holo_rot_2"]
    assert max(abs(float(a.state.rot[i])) for a in env.agents for i in range(3)) > 0.05  # turned: body twists
    for index in range(env.num_envs):
        latest = {f"{n}/odom": rm.odometry(a, index) for n, a in zip(rm.names(env), env.agents)}
        assert set(adapter.topics()) == set(latest)
        np.testing.assert_allclose(adapter.build(latest), rm.expected(obs, index), atol=ATOL)
    with pytest.raises(ValueError, match="observation_size 6 does not fit diff_drive"):
        DiffDriveAdapter(["a"], 6)


def test_goal_adapter_rebuilds_the_observation():
    env, obs = stepped("goal")
    name = rm.names(env)[0]
    assert name == "agent_0"
    adapter = GoalAdapter([name], 6)
    for index in range(env.num_envs):
        latest = {f"{name}/odom": rm.odometry(env.agents[0], index, yaw=0.3 * index),
                  f"{name}/goal": rm.goal_pose(env.scenario.goal, index)}
        assert set(adapter.topics()) == set(latest)
        np.testing.assert_allclose(adapter.build(latest), rm.expected(obs, index), atol=ATOL)
    latest[f"{name}/goal"].pose.position.y = math.nan
    assert np.isnan(adapter.build(latest)).all() and adapter.problems == {name: "agent_0/goal: NaN position"}
    assert np.isnan(adapter.build({f"{name}/goal": latest[f"{name}/goal"]})).all()
    assert adapter.problems[name] == "agent_0/odom: no message; agent_0/goal: NaN position"
    with pytest.raises(ValueError, match="observation_size 4 does not fit goal"):
        GoalAdapter([name], 4)


# --------------------------------------------------------------------- loading
@pytest.mark.parametrize("name, size, cls", [
    ("navigation", 18, NavigationAdapter), ("simple_spread", 14, SimpleSpreadAdapter),
    ("diff_drive", 4, DiffDriveAdapter), ("goal", 6, GoalAdapter),
    ("vmas_ros.ros.adapters:NavigationAdapter", 18, NavigationAdapter),
])
def test_load_adapter_takes_short_names(name, size, cls):
    agents = ["agent_0", "agent_1", "agent_2"][: 1 if cls is GoalAdapter else 3]
    assert type(load_adapter(name, agents, size, {})) is cls
    with pytest.raises(ValueError, match="refused its arguments"):
        load_adapter(name, agents, size, {"bogus": 1})


def test_the_policy_s_training_kwargs_decide_the_layout():
    """A diff-drive navigation policy (20 values: 4 + heading 2 + goal 2 + 12 rays) read without its kwargs
    would fit the holonomic layout with 14 rays; with the policy's kwargs it gets the heading and 12 rays."""
    agents = ["agent_0", "agent_1"]
    blind = load_adapter("navigation", agents, 20, {})
    assert blind.dynamics == "holonomic" and blind.n_lidar_rays == 14
    trained = load_adapter("navigation", agents, 20, {}, {"dynamics": "diff_drive", "n_agents": 2})
    assert trained.dynamics == "diff_drive" and trained.n_lidar_rays == 12 and trained.resampler.frame == "body"
    no_lidar = load_adapter("navigation", agents, 6, {}, {"collisions": False})
    assert no_lidar.n_lidar_rays == 0 and no_lidar.resampler is None
    spread = load_adapter("simple_spread", agents, 10, {}, {"obs_agents": False, "n_agents": 2})
    assert spread.obs_agents is False and spread.n_landmarks == 3
    # what the user gives wins over the training's
    with pytest.raises(ValueError, match="does not fit navigation"):
        load_adapter("navigation", agents, 20, {"n_lidar_rays": 12}, {"dynamics": "holonomic"})
    assert load_adapter("navigation", agents, 20, {"dynamics": "holonomic"}, {"dynamics": "diff_drive"}).dynamics \
        == "holonomic"


def test_goals_and_landmarks_stand_while_sensors_go_stale():
    agents = ["agent_0", "agent_1"]
    assert load_adapter("navigation", agents, 18, {}).standing_topics() == {"agent_0/goal", "agent_1/goal"}
    assert load_adapter("simple_spread", agents, 10, {"obs_agents": False}).standing_topics() == {"landmarks/poses"}
    assert load_adapter("goal", agents[:1], 6, {}).standing_topics() == {"agent_0/goal"}
    assert load_adapter("diff_drive", agents, 4, {}).standing_topics() == set()
    assert load_adapter("", agents, 4, {}).standing_topics() == set()
