"""A deliberately slow ROS consumer for the fault tests: ``python -m test.ros.slow_subscriber SLEEP TOPIC...``.

Subscribes (reliable, depth 10, the QoS sim_node offers) to each TOPIC's
PoseArray/Odometry/LaserScan (picked by the topic's last part) and sleeps
SLEEP seconds in every callback, like a consumer doing heavy work on the
executor thread. Every second it prints ``received N`` so the test can tell
that it was attached and how much it took in; SIGINT/SIGTERM end it.
"""
from __future__ import annotations

import sys
import time

import rclpy
from geometry_msgs.msg import PoseArray
from nav_msgs.msg import Odometry
from rclpy.executors import ExternalShutdownException
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan

TYPES = {"poses": PoseArray, "odom": Odometry, "scan": LaserScan}


def main(argv: list) -> int:
    sleep, topics = float(argv[0]), argv[1:]
    rclpy.init()
    node = rclpy.create_node("slow_subscriber")
    received = [0]

    def on_message(_msg) -> None:
        received[0] += 1
        time.sleep(sleep)

    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    for topic in topics:
        node.create_subscription(TYPES[topic.rsplit("/", 1)[-1]], topic, on_message, qos)
    node.create_timer(1.0, lambda: print(f"received {received[0]}", flush=True))
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        print(f"received {received[0]}", flush=True)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
