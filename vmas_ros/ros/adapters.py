"""Observation adapters under their ROS-side name: ``-p adapter:=vmas_ros.ros.adapters:SimpleSpreadAdapter``.

The adapters live in :mod:`vmas_ros.adapters` (no rclpy or torch at import);
this module re-exports their public names so both paths name the same classes.
"""
from vmas_ros.adapters import (  # noqa: F401 - re-exported
    ADAPTER_NAMES, DiffDriveAdapter, GoalAdapter, NavigationAdapter, ObservationAdapter, ScanResampler,
    SimpleSpreadAdapter, TopicObservations, load_adapter, odometry_state, pose_array_positions, pose_position,
    read_odometry,
)

__all__ = [
    "ADAPTER_NAMES", "DiffDriveAdapter", "GoalAdapter", "NavigationAdapter", "ObservationAdapter", "ScanResampler",
    "SimpleSpreadAdapter", "TopicObservations", "load_adapter", "odometry_state", "pose_array_positions",
    "pose_position", "read_odometry",
]
