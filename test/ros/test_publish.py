"""sim_node's bulk output (publish.py, env_snapshot.PublishedEnv) against the straightforward conversion.

The node publishes pre-serialised bytes filled in bulk, from the engine's
snapshot of the published env. Both must be invisible to consumers: for random
states, every message must have the length of, and decode to exactly the same
fields as, ``serialize_message`` of a message filled field by field with
``convert`` (the node's conversion before the bulk path; decoded because the
serialiser leaves CDR padding bytes uninitialised), and the node's snapshot
must equal the one gathered from the state, each lidar cast alone.
"""
from __future__ import annotations

import math
import random
from typing import Dict, List

import numpy as np
import pytest
import torch
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose, PoseArray, PoseStamped
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan
from visualization_msgs.msg import Marker, MarkerArray

import vmas_ros
from vmas_ros.ros import convert, sim_setup
from vmas_ros.simulator import env_snapshot
from vmas_ros.ros.params import SimParams
from test.simulator.lidar_setup import randomise, with_lidars
from vmas_ros.ros.publish import StateMessages
from vmas_ros.simulator import lidar_batch


def _markers(world, frame: str) -> MarkerArray:
    markers = MarkerArray()
    for k, entity in enumerate(world.entities):
        marker = Marker()
        convert.shape_marker(marker, entity, k, frame)
        markers.markers.append(marker)
    return markers


def _reference(world, names: List[str], geometry, snap, stamp_ns: int, frame: str, env_index: int,
               goals: Dict[int, int]) -> Dict[str, bytes]:
    """The per-message conversion, field by field (what sim_node published before the bulk path)."""
    stamp = Time(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
    out = {"/clock": serialize_message(Clock(clock=stamp))}
    n_landmarks = len(world.landmarks)
    for i, name in enumerate(names):
        k = n_landmarks + i
        x, y, yaw = snap.pos[k, 0], snap.pos[k, 1], snap.rot[k]
        pose, odom = PoseStamped(), Odometry()
        pose.header.frame_id = odom.header.frame_id = frame
        odom.child_frame_id = f"{name}/base_link"
        pose.header.stamp = odom.header.stamp = stamp
        convert.set_pose(pose.pose, x, y, yaw)
        convert.fill_odometry(odom, x, y, yaw, snap.vel[k, 0], snap.vel[k, 1], snap.ang_vel[k])
        out[f"/{name}/pose"], out[f"/{name}/odom"] = serialize_message(pose), serialize_message(odom)
        if i in goals:
            goal, g = PoseStamped(), goals[i]
            goal.header.frame_id, goal.header.stamp = frame, stamp
            convert.set_pose(goal.pose, snap.pos[g, 0], snap.pos[g, 1], snap.rot[g])
            out[f"/{name}/goal"] = serialize_message(goal)
        for j, ranges in enumerate(snap.scans.get(i, [])):
            scan = LaserScan()
            scan.header.frame_id, scan.header.stamp = f"{name}/base_link", stamp
            convert.fill_scan(scan, geometry[i][j], ranges)
            out[f"/{name}/scan" if j == 0 else f"/{name}/scan_{j}"] = serialize_message(scan)
    for topic, rows in (("/agents/poses", range(n_landmarks, len(snap.pos))), ("/landmarks/poses", range(n_landmarks))):
        array = PoseArray()
        array.header.frame_id, array.header.stamp = frame, stamp
        array.poses = [Pose() for _ in rows]
        for pose, k in zip(array.poses, rows):
            convert.set_pose(pose, snap.pos[k, 0], snap.pos[k, 1], snap.rot[k])
        out[topic] = serialize_message(array)
    markers = _markers(world, frame)
    for k, marker in enumerate(markers.markers):
        if isinstance(world.entities[k].color, torch.Tensor):
            marker.color.r, marker.color.g, marker.color.b = env_snapshot.rgb(world.entities[k].color, env_index)
        marker.header.stamp = stamp
        convert.set_pose(marker.pose, snap.pos[k, 0], snap.pos[k, 1], snap.rot[k])
    out["/world/markers"] = serialize_message(markers)
    return out


#: the node's own lidar as the robot profile makes it, at a smaller size: half a circle, a range_min
ROBOT_LIDAR = {"robot_lidar": True, "lidar_rays": 31, "lidar_angle_min": -math.pi / 2, "lidar_angle_max": math.pi / 2,
               "lidar_range": 2.0, "lidar_range_min": 0.5}


@pytest.mark.parametrize("scenario, kwargs, rays, robot", [
    ("simple_spread", {"n_agents": 4}, (12,), False),
    ("waterfall", {}, (7, 16), False),  # boxes and lines; two lidars per agent (scan and scan_1)
    ("transport", {}, (5,), False),  # a package colour drawn per env
    ("navigation", {"n_agents": 6}, (), True),  # goals; the node's lidar (-inf below range_min), then the scenario's
])
def test_bulk_messages_equal_the_per_message_conversion(scenario, kwargs, rays, robot):
    env = vmas_ros.make_env(scenario, num_envs=3, seed=1, **kwargs)
    with_lidars(env, rays)
    world = env.world
    names = env_snapshot.unique_names([a.name for a in world.agents])
    params = SimParams(**ROBOT_LIDAR) if robot else SimParams(add_lidar=False)
    own = sim_setup.add_node_lidars(world, params)
    lidars = sim_setup.published_lidars(world, own)
    geometry = sim_setup.scan_geometry(lidars, own, params.lidar_range_min)
    goals = sim_setup.goal_rows(world, env.scenario)
    assert bool(goals) == (scenario == "navigation")
    frame = "map"
    messages = StateMessages(names, len(world.landmarks), len(world.entities), geometry,
                             {i: [s.n_rays for s in ls] for i, ls in lidars.items()}, frame, _markers(world, frame),
                             goals=goals)
    per_env = [k for k, e in enumerate(world.entities) if isinstance(e.color, torch.Tensor)]
    if per_env:
        messages.set_colour_fields(per_env)
    n_scans = sum(len(ls) for ls in lidars.values())
    assert len(messages.topics) == len(set(messages.topics)) == 4 + 2 * len(names) + n_scans + len(goals)
    rng = torch.Generator().manual_seed(7)
    node_scans = []
    for trial in range(6):
        randomise(env, rng)
        env_index = trial % env.num_envs
        stamp_ns = random.Random(trial).randrange(0, 2**31 * 10**9)
        snap = env_snapshot.Snapshot.take(world, env_index, lidars)
        colours = [c for k in per_env for c in env_snapshot.rgb(world.entities[k].color, env_index)] if per_env else None
        messages.fill(snap, stamp_ns, colours)
        expected = _reference(world, names, geometry, snap, stamp_ns, frame, env_index, goals)
        assert sorted(expected) == sorted("/" + t.lstrip("/") for t in messages.topics)
        for topic, kind, payload in messages.payloads():
            reference = expected["/" + topic.lstrip("/")]
            # CDR padding bytes are not initialised by the serialiser: compare every field instead
            assert len(payload) == len(reference)
            mine, theirs = messages.decode(topic), deserialize_message(reference, type(messages.decode(topic)))
            assert mine == theirs, f"{topic} differs from the per-message conversion (trial {trial})"
        scans = [np.concatenate(s) for s in snap.scans.values()]
        assert any(np.isinf(np.where(s >= 2.0, np.inf, s)).any() for s in scans)  # some rays hit nothing
        node_scans += [np.array(messages.decode(f"{names[i]}/scan").ranges) for i in own]
    if robot:  # some rays of the node's lidars read -inf (something closer than range_min), some a distance
        published = np.concatenate(node_scans)
        assert (published == -np.inf).any() and np.isfinite(published).any()


def test_bulk_payloads_deserialise_to_the_state():
    env = vmas_ros.make_env("simple_spread", num_envs=1, seed=3, n_agents=2)
    with_lidars(env)
    world = env.world
    lidars = env_snapshot.agent_lidars(world)
    geometry = {i: [env_snapshot.ScanGeometry.of(s) for s in ls] for i, ls in lidars.items()}
    messages = StateMessages(["a", "b"], len(world.landmarks), len(world.entities), geometry,
                             {i: [12] for i in lidars}, "world", _markers(world, "world"))
    snap = env_snapshot.Snapshot.take(world, 0, lidars)
    messages.fill(snap, 12_500_000_000, None)
    odom = deserialize_message(messages.payload(messages.topics.index("b/odom")), Odometry)
    k = len(world.landmarks) + 1
    assert (odom.header.stamp.sec, odom.header.stamp.nanosec) == (12, 500_000_000)
    assert odom.pose.pose.position.x == float(snap.pos[k, 0]) and odom.child_frame_id == "b/base_link"
    assert odom.pose.pose.orientation.z == pytest.approx(math.sin(float(snap.rot[k]) / 2))
    clock = deserialize_message(messages.payload(0), Clock)
    assert (clock.clock.sec, clock.clock.nanosec) == (12, 500_000_000)


def test_the_published_env_is_the_gathered_snapshot_and_reuses_the_scenarios_readings(monkeypatch):
    """The node's snapshot (PublishedEnv, built as sim_node builds it) equals the state and every lidar
    cast alone; a lidar the scenario read in this step (flocking observes through its lidars) is not cast
    again, only the node's own ones (another layout) are."""
    env = vmas_ros.make_env("flocking", num_envs=3, seed=0)
    with_lidars(env, (6,))  # node lidars, which the scenario never reads
    world = env.world
    lidars = env_snapshot.agent_lidars(world)
    published = env_snapshot.PublishedEnv(world, lidars)
    assert not published.source.rides_along
    scenario_lidars = [s for ls in lidars.values() for s in ls if s.n_rays == 12]
    node_lidars = [s for ls in lidars.values() for s in ls if s.n_rays == 6]
    assert len(scenario_lidars) == 4 and len(node_lidars) == len(world.agents)
    casts = []
    original = lidar_batch.BatchedLidars.cast
    monkeypatch.setattr(lidar_batch.BatchedLidars, "cast", lambda *a, **k: casts.append(a[2]) or original(*a, **k))
    for step in range(3):
        env.step([torch.zeros(3, env.get_agent_action_size(a)) for a in env.agents])
        assert casts == [scenario_lidars], "the scenario's lidars, together"
        snap = published.take(step % 3)
        assert casts == [scenario_lidars, node_lidars], "then the node's own, together"
        casts.clear()
        n = len(world.entities)
        for k, entity in enumerate(world.entities):
            np.testing.assert_array_equal(snap.pos[k], entity.state.pos[step % 3].numpy())
            assert snap.rot[k] == entity.state.rot[step % 3, 0].item()
        for i, sensors in lidars.items():
            for sensor, scan in zip(sensors, snap.scans[i], strict=True):
                np.testing.assert_array_equal(scan, sensor.cast_alone()[step % 3].numpy())
        assert snap.all_finite() and snap.host.shape == (6 * n + sum(s.n_rays for ls in lidars.values() for s in ls),)
