"""CDR padding bytes are zero: identical messages give identical bytes, and no heap memory leaks out.

rclpy's serialiser (rmw_fastrtps) skips the alignment padding without writing
it, so those bytes are whatever the C heap held. To make that visible, each
test first fills freed heap blocks of every small size with a marker byte
(libc ``malloc``/``memset``/``free`` through ctypes): a serialiser that leaves
padding unwritten then hands out marker bytes instead of fresh zeros.

The reference is ``rosbags``' own CDR serialiser (an independent
implementation that writes zeros into padding): our bytes must equal its
serialisation of the same message, plus the zero bytes rmw appends to round
small messages up to 4 bytes.
"""
from __future__ import annotations

import ctypes
import math
from typing import List

import pytest
import torch
from geometry_msgs.msg import Pose, PoseArray, PoseStamped, TransformStamped, Twist
from mcap.reader import make_reader
from nav_msgs.msg import Odometry
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Bool, Empty, Float32MultiArray, MultiArrayDimension
from visualization_msgs.msg import Marker, MarkerArray

import vmas_ros
from vmas_ros.record import McapRecorder
from vmas_ros.ros import convert
from vmas_ros.simulator import env_snapshot
from vmas_ros.record.cdr import padding_ranges, serialize_zeroed
from vmas_ros.ros.message_types import type_name
from vmas_ros.ros.publish import StateMessages
from vmas_ros.simulator.sensors import Lidar

JAZZY = get_typestore(Stores.ROS2_JAZZY)
_LIBC = ctypes.CDLL(None)
_LIBC.malloc.restype, _LIBC.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
_LIBC.free.argtypes = [ctypes.c_void_p]


def dirty_heap(fill: int) -> None:
    """Leave freed C heap blocks of 8 ... 4 KiB full of ``fill`` for the next mallocs to reuse."""
    blocks = []
    for size in list(range(8, 4096, 8)) * 2:
        block = _LIBC.malloc(size)
        ctypes.memset(block, fill, size)
        blocks.append(block)
    for block in blocks:
        _LIBC.free(block)


def assert_zero_padded(data: bytes, kind: str) -> None:
    """``data`` equals rosbags' serialisation of the message it holds, byte for byte (padding 0)."""
    reference = JAZZY.serialize_cdr(JAZZY.deserialize_cdr(data, kind), kind)
    assert data[:len(reference)] == reference, (
        f"{kind}: bytes differ from a zero-padded serialisation at "
        f"{[i for i, (a, b) in enumerate(zip(data, reference)) if a != b]}")
    assert len(data) - len(reference) < 4 and not any(data[len(reference):]), f"{kind}: non-zero tail"


def _messages() -> List[object]:
    """Messages whose string and sequence lengths put padding in every possible place."""
    out: List[object] = []
    for frame in ("", "w", "wo", "wor", "worl", "world", "world1", "world12"):  # 0 ... 7 bytes of padding
        pose = PoseStamped()
        pose.header.frame_id = frame
        pose.pose.position.x, pose.pose.orientation.w = 1.5, 1.0
        out.append(pose)
    odom = Odometry()
    odom.header.frame_id, odom.child_frame_id = "world", "agent_0/base_link"
    odom.twist.twist.linear.x = -0.25
    out.append(odom)
    for rays in (0, 1, 3):
        scan = LaserScan()
        scan.header.frame_id, scan.ranges, scan.range_max = "ab", [1.0] * rays, 2.0
        out.append(scan)
    markers = MarkerArray()
    for k in range(3):
        marker = Marker()
        marker.header.frame_id, marker.ns, marker.text, marker.mesh_resource = "map", "e" * k, "t" * k, "m" * (k + 1)
        marker.color.r, marker.scale.x = 0.5, 0.1
        markers.markers.append(marker)
    out += [markers, MarkerArray()]
    array = PoseArray()
    array.header.frame_id, array.poses = "w", [Pose(), Pose()]
    tf = TransformStamped()
    tf.header.frame_id, tf.child_frame_id = "abc", "d"
    observation = Float32MultiArray()
    observation.layout.dim = [MultiArrayDimension(label="obs", size=3, stride=3)]
    observation.data = [1.0, -2.0, math.inf]
    return out + [array, tf, observation, Bool(data=True), Empty(), Twist()]


@pytest.mark.parametrize("index", range(len(_messages())))
def test_serialize_zeroed_matches_an_independent_serialiser(index):
    message = _messages()[index]
    kind = type_name(type(message))
    for fill in (0xA5, 0x5A):
        dirty_heap(fill)
        assert_zero_padded(serialize_zeroed(message), kind)


def test_a_layout_that_does_not_fit_the_bytes_is_refused():
    pose = PoseStamped()
    pose.header.frame_id = "world"
    with pytest.raises(ValueError, match=r"PoseStamped: the CDR layout ends at byte 84, but the serialised "
                                         r"message has 100 bytes"):
        padding_ranges(pose, 100)
    assert padding_ranges(pose, 84) == [(22, 28)]  # after "world\0": 6 bytes up to the float64s


def _state_messages(env) -> StateMessages:
    """sim_node's pre-serialised state messages of ``env`` (as SimNode._build_io makes them)."""
    world = env.world
    lidars = env_snapshot.agent_lidars(world)
    markers = MarkerArray()
    for k, entity in enumerate(world.entities):
        marker = Marker()
        convert.shape_marker(marker, entity, k, "world")
        markers.markers.append(marker)
    geometry = {i: [env_snapshot.ScanGeometry.of(s) for s in ls] for i, ls in lidars.items()}
    return StateMessages(env_snapshot.unique_names([a.name for a in world.agents]), len(world.landmarks),
                         len(world.entities), geometry,
                         {i: [s.n_rays for s in ls] for i, ls in lidars.items()}, "world", markers)


@pytest.mark.parametrize("scenario, kwargs", [("simple_spread", {"n_agents": 4}), ("waterfall", {})])
def test_state_messages_are_byte_identical_and_zero_padded(scenario, kwargs):
    """Two nodes publishing the same state send the same bytes, whatever their heaps held."""
    env = vmas_ros.make_env(scenario, num_envs=2, seed=4, **kwargs)
    for agent in env.world.agents:
        agent.add_sensor(Lidar(env.world, n_rays=12, max_range=2.0,
                               entity_filter=lambda e, me=agent: e.collides(me) and me.collides(e)))
    snap = env_snapshot.Snapshot.take(env.world, 1, env_snapshot.agent_lidars(env.world))
    arenas = []
    for fill in (0xA5, 0x5A):
        dirty_heap(fill)
        messages = _state_messages(env)
        per_env = [k for k, e in enumerate(env.world.entities) if isinstance(e.color, torch.Tensor)]
        if per_env:
            messages.set_colour_fields(per_env)
        messages.fill(snap, 12_345_000_000, [0.5] * 3 * len(per_env) if per_env else None)
        for topic, kind, payload in messages.payloads():
            assert_zero_padded(payload, kind)
        arenas.append(messages.payloads())
    assert arenas[0] == arenas[1]


def test_recorder_serialises_with_zero_padding(tmp_path):
    """A message given to McapRecorder.write (not pre-serialised) reaches the bag zero-padded."""
    path = tmp_path / "padded.mcap"
    with McapRecorder(path) as recorder:
        for k, fill in enumerate((0xA5, 0x5A, 0xA5)):
            dirty_heap(fill)
            pose = PoseStamped()
            pose.header.frame_id = "w" * (k + 1)
            recorder.write("/pose", "geometry_msgs/msg/PoseStamped", pose, k)
    with open(path, "rb") as stream:
        datas = [message.data for _, _, message in make_reader(stream).iter_messages()]
    assert len(datas) == 3
    for data in datas:
        assert_zero_padded(data, "geometry_msgs/msg/PoseStamped")
