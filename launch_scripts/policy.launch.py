"""Launch sim_node and policy_node together: ``ros2 launch vmas_ros policy.launch.py policy_path:=/abs/stem.json``.

Arguments: ``scenario`` (default simple_spread), ``config`` (sim_node's
parameter file; default the package's config/<scenario>.yaml when it exists),
``policy_path`` (the exported policy's .json; required), ``output``
(``action`` or ``cmd_vel``), ``adapter`` (``package.module:Class``; empty:
sim_node's observation topics) and ``rate_hz`` (policy_node's rate). sim_node
runs with ``control: zero``, so every motion comes from policy_node. Where
``ros2 launch`` is not installed (PyPI wheels), start the two processes by
hand (docs/policy_node.md).
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _nodes(context):
    scenario = LaunchConfiguration("scenario").perform(context)
    config = LaunchConfiguration("config").perform(context)
    if not config:
        candidate = os.path.join(get_package_share_directory("vmas_ros"), "config", f"{scenario}.yaml")
        config = candidate if os.path.isfile(candidate) else ""
    sim_parameters = ([config] if config else []) + [{"scenario": scenario, "control": "zero"}]
    policy_parameters = [{
        "policy_path": LaunchConfiguration("policy_path").perform(context),
        "output": LaunchConfiguration("output").perform(context),
        "adapter": LaunchConfiguration("adapter").perform(context),
        "rate_hz": float(LaunchConfiguration("rate_hz").perform(context)),
    }]
    return [
        Node(package="vmas_ros", executable="sim_node", name="sim_node", parameters=sim_parameters, output="screen"),
        Node(package="vmas_ros", executable="policy_node", name="policy_node", parameters=policy_parameters,
             output="screen"),
    ]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription([
        DeclareLaunchArgument("scenario", default_value="simple_spread", description="scenario name"),
        DeclareLaunchArgument("config", default_value="", description="sim_node parameter file (optional)"),
        DeclareLaunchArgument("policy_path", description="exported policy (<stem>.json), absolute path"),
        DeclareLaunchArgument("output", default_value="action", description="action or cmd_vel"),
        DeclareLaunchArgument("adapter", default_value="", description="observation adapter module:Class"),
        DeclareLaunchArgument("rate_hz", default_value="10.0", description="policy_node actions per second"),
        OpaqueFunction(function=_nodes),
    ])
