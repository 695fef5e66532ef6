"""Launch sim_node with a scenario and a parameter file: ``ros2 launch vmas_ros sim.launch.py``.

Arguments: ``scenario`` (default simple_spread) and ``config`` (a parameter
file; default the package's config/<scenario>.yaml when it exists). Where
``ros2 launch`` is not installed (PyPI wheels), use ``vmas-ros sim`` instead.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _node(context):
    scenario = LaunchConfiguration("scenario").perform(context)
    config = LaunchConfiguration("config").perform(context)
    if not config:
        candidate = os.path.join(get_package_share_directory("vmas_ros"), "config", f"{scenario}.yaml")
        config = candidate if os.path.isfile(candidate) else ""
    parameters = ([config] if config else []) + [{"scenario": scenario}]
    return [Node(package="vmas_ros", executable="sim_node", name="sim_node", parameters=parameters, output="screen")]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription([
        DeclareLaunchArgument("scenario", default_value="simple_spread", description="scenario name"),
        DeclareLaunchArgument("config", default_value="", description="parameter file (optional)"),
        OpaqueFunction(function=_node),
    ])
