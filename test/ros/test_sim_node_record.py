"""sim_node records a rosbag2-compatible MCAP bag; independent readers read it back after SIGTERM."""
from __future__ import annotations

import signal
import warnings

import pytest
from geometry_msgs.msg import Twist
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

pytestmark = pytest.mark.ros

EXPECTED_TYPES = {
    "/clock": "rosgraph_msgs/msg/Clock",
    "/agent_0/pose": "geometry_msgs/msg/PoseStamped",
    "/agent_0/odom": "nav_msgs/msg/Odometry",
    "/agent_0/scan": "sensor_msgs/msg/LaserScan",
    "/agents/poses": "geometry_msgs/msg/PoseArray",
    "/landmarks/poses": "geometry_msgs/msg/PoseArray",
    "/world/markers": "visualization_msgs/msg/MarkerArray",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/agent_0/cmd_vel": "geometry_msgs/msg/Twist",
}


@pytest.mark.parametrize("stop_signal", [signal.SIGTERM, signal.SIGINT], ids=["sigterm", "sigint"])
def test_bag_recorded_by_sim_node_reads_back(ros, sim_node, tmp_path, stop_signal):
    bag = tmp_path / "run.mcap"
    sim = sim_node(scenario_kwargs='{"n_agents": 2}', record_path=str(bag), real_time_factor=4.0, lidar_rays=8)
    command = Twist()
    command.linear.x = 0.2
    ros.publish_for(Twist, "/agent_0/cmd_vel", command, seconds=1.5)
    assert sim.stop(stop_signal) == 0
    assert bag.is_file()

    # 1. rosbags (independent of our writer and of rclpy)
    typestore = get_typestore(Stores.ROS2_JAZZY)
    counts, times = {}, {}
    with AnyReader([bag], default_typestore=typestore) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        for topic, msgtype in EXPECTED_TYPES.items():
            assert types.get(topic) == msgtype, (topic, types.get(topic))
        for connection, timestamp, raw in reader.messages():
            message = reader.deserialize(raw, connection.msgtype)
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
            times.setdefault(connection.topic, []).append(timestamp)
            if connection.topic == "/agent_0/scan":
                assert all(r > 0 for r in message.ranges), "ranges are distances or +inf (REP 117)"
                assert len(message.ranges) == 8
            if connection.topic == "/tf":
                assert [t.child_frame_id for t in message.transforms] == ["agent_0/base_link", "agent_1/base_link"]
            if connection.topic == "/clock":
                assert timestamp == message.clock.sec * 1_000_000_000 + message.clock.nanosec, "log time is sim time"
    steps = counts["/clock"]
    assert steps > 10
    for topic in ("/agent_0/pose", "/agent_1/odom", "/agent_0/scan", "/tf", "/world/markers", "/agents/poses"):
        assert counts[topic] == steps, f"{topic}: {counts[topic]} messages for {steps} steps"
    assert counts["/agent_0/cmd_vel"] >= 10, "received commands are recorded too"
    for topic, stamps in times.items():
        assert stamps == sorted(stamps), f"{topic} log times go backwards"

    # 2. mcap-ros2-support reads the same file, with summary and QoS metadata
    from mcap.reader import make_reader

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        from mcap_ros2.reader import read_ros2_messages

        decoded = sum(1 for _ in read_ros2_messages(str(bag)))
    assert decoded == sum(counts.values())
    with open(bag, "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and summary.statistics.message_count == decoded
    assert all("offered_qos_profiles" in c.metadata for c in summary.channels.values())
    assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
