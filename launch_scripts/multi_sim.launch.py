"""Launch N namespaced sim_nodes in one graph: ``ros2 launch vmas_ros multi_sim.launch.py count:=3``.

Node ``i`` runs in namespace ``<prefix>_<i>`` (``sim_0``, ``sim_1``, ...), so its
topics, services and frames (``frame_prefix: auto``) stay apart from the
others'; node 0 owns ``/clock`` and the others run with ``publish_clock: false``;
seeds are ``seed + i``; with ``foxglove_port`` set, node ``i`` serves Foxglove on
``foxglove_port + i``. Arguments: ``count`` (default 2), ``prefix`` (default
``sim``), ``scenario`` (default simple_spread), ``config`` (a sim_node
parameter file for every node; default the package's config/<scenario>.yaml
when it exists), ``seed`` (default 0) and ``foxglove_port`` (default 0: off).
Where ``ros2 launch`` is not installed (PyPI wheels), start the nodes by hand
(docs/node.md, "Several simulators in one graph").
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _nodes(context):
    count = int(LaunchConfiguration("count").perform(context))
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    prefix = LaunchConfiguration("prefix").perform(context)
    scenario = LaunchConfiguration("scenario").perform(context)
    config = LaunchConfiguration("config").perform(context)
    seed = int(LaunchConfiguration("seed").perform(context))
    foxglove_port = int(LaunchConfiguration("foxglove_port").perform(context))
    if not config:
        candidate = os.path.join(get_package_share_directory("vmas_ros"), "config", f"{scenario}.yaml")
        config = candidate if os.path.isfile(candidate) else ""
    nodes = []
    for i in range(count):
        sim_parameters = ([config] if config else []) + [{
            "scenario": scenario, "seed": seed + i, "publish_clock": i == 0,
            "foxglove_port": foxglove_port + i if foxglove_port else 0,
        }]
        nodes.append(Node(package="vmas_ros", executable="sim_node", name="sim_node", namespace=f"{prefix}_{i}",
                          parameters=sim_parameters, output="screen"))
    return nodes


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription([
        DeclareLaunchArgument("count", default_value="2", description="how many sim_nodes"),
        DeclareLaunchArgument("prefix", default_value="sim", description="namespaces are <prefix>_<i>"),
        DeclareLaunchArgument("scenario", default_value="simple_spread", description="scenario name"),
        DeclareLaunchArgument("config", default_value="", description="sim_node parameter file (optional)"),
        DeclareLaunchArgument("seed", default_value="0", description="node i gets seed + i"),
        DeclareLaunchArgument("foxglove_port", default_value="0",
                              description="node i serves Foxglove on foxglove_port + i (0: off)"),
        OpaqueFunction(function=_nodes),
    ])
