"""Observation adapters: a trained policy's observation rebuilt from standard ROS messages.

``policy_node`` selects one with ``-p adapter:=<name>``: a short name of
:data:`ADAPTER_NAMES` or ``package.module:Class``. The hook and the default
are in :mod:`~vmas_ros.adapters.base`, the reusable pieces (odometry, scans,
goals) in :mod:`~vmas_ros.adapters.pieces`, the shipped adapters in
:mod:`~vmas_ros.adapters.tasks`. Nothing here imports rclpy or torch when it
is imported (docs/policy_node.md#observation-adapters).
"""
from vmas_ros.adapters.base import ADAPTER_NAMES, ObservationAdapter, TopicObservations, load_adapter
from vmas_ros.adapters.pieces import (
    ScanResampler, odometry_state, pose_array_positions, pose_position, read_odometry,
)
from vmas_ros.adapters.tasks import DiffDriveAdapter, GoalAdapter, NavigationAdapter, SimpleSpreadAdapter

__all__ = [
    "ADAPTER_NAMES", "DiffDriveAdapter", "GoalAdapter", "NavigationAdapter", "ObservationAdapter", "ScanResampler",
    "SimpleSpreadAdapter", "TopicObservations", "load_adapter", "odometry_state", "pose_array_positions",
    "pose_position", "read_odometry",
]
