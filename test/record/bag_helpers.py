"""Shared pieces of the McapRecorder tests (test_mcap_*.py): a sample recording and two readers.

Every bag is checked with two independent readers: ``rosbags`` (AnyReader on the
``.mcap`` path, which builds its types from the embedded schemas, plus the
ROS2_JAZZY typestore) and ``mcap_ros2.reader.read_ros2_messages``.
"""
from __future__ import annotations

import math
import warnings
from pathlib import Path

import pytest

# the record extra and rclpy are part of the test set-up: without them these tests must fail
from mcap.reader import make_reader

with warnings.catch_warnings():  # the module warns it is deprecated; read_ros2_messages is the brief's reader
    warnings.simplefilter("ignore", DeprecationWarning)
    from mcap_ros2.reader import read_ros2_messages
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TransformStamped, Twist
from nav_msgs.msg import Odometry
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan
from visualization_msgs.msg import Marker, MarkerArray

from vmas_ros.record import TF_MESSAGE_TYPE, McapRecorder, serialize_tf_message

REPO = Path(__file__).resolve().parents[2]
JAZZY = get_typestore(Stores.ROS2_JAZZY)
MS = 1_000_000  # ns

# ----------------------------------------------------------------- helpers
def _stamp(t_ns: int) -> Time:
    return Time(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)


def _transforms(step: int, n: int = 3):
    out = []
    for k in range(n):
        tf = TransformStamped()
        tf.header.stamp = _stamp(step * 50 * MS)
        tf.header.frame_id = "w" * (k + step % 5)  # varying lengths: both CDR paddings occur
        tf.child_frame_id = f"agent_{k}/base_link"[: 1 + (k + step) % 17]
        tf.transform.translation.x = step + 0.25 * k
        tf.transform.translation.y = -1.5 * k
        tf.transform.rotation.z = math.sin(0.1 * k)
        tf.transform.rotation.w = math.cos(0.1 * k)
        out.append(tf)
    return out


STEPS = 20
TOPICS = {
    "/agent_0/pose": "geometry_msgs/msg/PoseStamped",
    "/agent_0/odom": "nav_msgs/msg/Odometry",
    "/agent_0/scan": "sensor_msgs/msg/LaserScan",
    "/world/markers": "visualization_msgs/msg/MarkerArray",
    "/clock": "rosgraph_msgs/msg/Clock",
    "/agent_0/cmd_vel": "geometry_msgs/msg/Twist",
    "/tf": "tf2_msgs/msg/TFMessage",
}


def _write_sample(path: Path, **kwargs) -> McapRecorder:
    """STEPS steps of every sample topic, 50 ms apart; returns the closed recorder."""
    with McapRecorder(path, **kwargs) as rec:
        for step in range(STEPS):
            t = step * 50 * MS
            clock = Clock(clock=_stamp(t))
            rec.write("/clock", "rosgraph_msgs/msg/Clock", clock, t)
            pose = PoseStamped()
            pose.header.stamp, pose.header.frame_id = _stamp(t), "world"
            pose.pose.position.x, pose.pose.position.y = 0.5 * step, -0.25 * step
            pose.pose.orientation.w = 1.0
            rec.write("/agent_0/pose", "geometry_msgs/msg/PoseStamped", pose, t)
            odom = Odometry()
            odom.header.stamp, odom.header.frame_id, odom.child_frame_id = _stamp(t), "world", "agent_0/base_link"
            odom.twist.twist.linear.x = 0.1 * step
            rec.write("/agent_0/odom", "nav_msgs/msg/Odometry", odom, t)
            scan = LaserScan()
            scan.header.stamp, scan.header.frame_id = _stamp(t), "agent_0/base_link"
            scan.angle_min, scan.angle_max, scan.range_max = -math.pi, math.pi, 5.0
            scan.ranges = [1.0 + step, math.inf, 2.5, math.inf]
            rec.write("/agent_0/scan", "sensor_msgs/msg/LaserScan", scan, t)
            markers = MarkerArray()
            for k in range(2):
                m = Marker()
                m.header.frame_id, m.ns, m.id, m.type = "world", "entities", k, Marker.SPHERE
                m.pose.position.x = step + 10.0 * k
                m.scale.x = m.scale.y = m.scale.z = 0.1
                m.color.a = 1.0
                markers.markers.append(m)
            rec.write("/world/markers", "visualization_msgs/msg/MarkerArray", markers, t)
            twist = Twist()
            twist.angular.z = -0.5 * step
            # serialized bytes given: no second serialisation
            rec.write("/agent_0/cmd_vel", "geometry_msgs/msg/Twist", None, t, qos="best_effort",
                      serialized=serialize_message(twist))
            rec.write_raw("/tf", TF_MESSAGE_TYPE, serialize_tf_message(_transforms(step)), t + 1)
    return rec


def _check_sample_values(topic: str, step: int, msg) -> None:
    if topic == "/agent_0/pose":
        assert msg.pose.position.x == 0.5 * step and msg.pose.position.y == -0.25 * step
        assert msg.header.frame_id == "world"
    elif topic == "/agent_0/odom":
        assert msg.twist.twist.linear.x == pytest.approx(0.1 * step) and msg.child_frame_id == "agent_0/base_link"
    elif topic == "/agent_0/scan":
        ranges = list(msg.ranges)
        assert ranges[0] == 1.0 + step and ranges[2] == 2.5
        assert math.isinf(ranges[1]) and ranges[1] > 0 and math.isinf(ranges[3])
    elif topic == "/world/markers":
        assert [m.id for m in msg.markers] == [0, 1]
        assert [m.pose.position.x for m in msg.markers] == [step, step + 10.0]
    elif topic == "/clock":
        assert msg.clock.sec * 10**9 + msg.clock.nanosec == step * 50 * MS
    elif topic == "/agent_0/cmd_vel":
        assert msg.angular.z == -0.5 * step
    elif topic == "/tf":
        want = _transforms(step)
        assert len(msg.transforms) == len(want)
        for got, exp in zip(msg.transforms, want):
            assert got.header.frame_id == exp.header.frame_id and got.child_frame_id == exp.child_frame_id
            assert got.transform.translation.x == exp.transform.translation.x
            assert got.transform.translation.y == exp.transform.translation.y
            assert got.transform.rotation.z == exp.transform.rotation.z
            assert got.transform.rotation.w == exp.transform.rotation.w
    else:  # pragma: no cover
        raise AssertionError(topic)


def _read_rosbags(path: Path):
    """[(topic, msgtype, log_time, msg)] via AnyReader, cross-checked with the Jazzy typestore."""
    out = []
    with AnyReader([Path(path)]) as reader:
        for conn, log_time, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)  # types from the embedded schemas
            JAZZY.deserialize_cdr(raw, conn.msgtype)  # and from rosbags' own Jazzy definitions
            out.append((conn.topic, conn.msgtype, log_time, msg))
    return out


def _read_mcap_ros2(path: Path):
    return [(m.channel.topic, m.schema.name, m.log_time_ns, m.ros_msg)
            for m in read_ros2_messages(str(path), log_time_order=False)]


def _summary(path: Path):
    with open(path, "rb") as f:
        reader = make_reader(f)
        return reader.get_header(), reader.get_summary()


def _pose_bytes(i: int) -> bytes:
    pose = PoseStamped()
    pose.header.frame_id = "world"
    pose.pose.position.x = float(i)
    return serialize_message(pose)


def _recovered_xs(path: Path) -> list:
    got = _read_rosbags(path)
    assert len(_read_mcap_ros2(path)) == len(got)
    return [msg.pose.position.x for _, _, _, msg in got]
