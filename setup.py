"""Packaging for vmas_ros: a pip-installable Python package and a ROS 2
ament_python package (``colcon build``) at the same time."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "vmas_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    description="Vectorized 2D multi-robot simulator in PyTorch (VMAS-compatible) with a ROS 2 node",
    maintainer="vmas_ros team",
    maintainer_email="vmas-ros@example.com",
    license="Apache-2.0",
    python_requires=">=3.10",
    packages=find_packages(include=[PACKAGE, f"{PACKAGE}.*"], exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", sorted(glob("config/*.yaml") + glob("config/*.json") + glob("config/*.rviz"))),
        (f"share/{PACKAGE}/config/train", sorted(glob("config/train/*.yaml"))),
        (f"share/{PACKAGE}/launch", sorted(glob("launch_scripts/*.py"))),
        (f"share/{PACKAGE}/policies", sorted(glob("policies/*.onnx") + glob("policies/*.json"))),
    ],
    # torch is deliberately unpinned here; scripts/setup.sh installs the pinned
    # CPU build first (see docs/install.md).
    install_requires=["numpy", "torch", "gymnasium", "pillow", "pyyaml", "tqdm"],
    extras_require={
        "ros": [
            "ros-jazzy-rclpy",
            "ros-jazzy-common-interfaces",
            "ros-jazzy-rmw-fastrtps-cpp",
            "ros-jazzy-std-srvs",
            "ros-jazzy-rosgraph-msgs",
        ],
        "foxglove": ["foxglove-sdk>=0.30"],
        "record": ["mcap", "mcap-ros2-support"],
        # torchrl 0.14 is the release that matches torch 2.13 (a newer one would pull a newer torch)
        "train": ["torchrl>=0.14,<0.15", "tensordict>=0.14,<0.15", "onnx", "onnxscript", "onnxruntime",
                  "pettingzoo>=1.24", "matplotlib"],
        "rllib": ["ray[rllib]"],
        # legacy gym, for wrapper="gym" (VMAS's GymWrapper) and TorchRL's VMAS spaces
        "gym": ["gym==0.26.2"],
        "play": ["pygame"],
        "bench": ["matplotlib"],
        "test": [
            "pytest",
            "pytest-timeout",
            "pytest-xdist",
            "vmas==1.5.2",
            "mpe2",
            "rosbags",
            "colcon-common-extensions",
            "hypothesis",
            "websockets",
            "pygame",
            "matplotlib",
        ],
    },
    entry_points={
        "console_scripts": [
            "vmas-ros = vmas_ros.cli:main",
            # the startup modules install the signal handlers, then import the node (torch, rclpy)
            "sim_node = vmas_ros.ros.startup:sim_node_main",
            "policy_node = vmas_ros.ros.startup:policy_node_main",
            "robot_fleet = vmas_ros.fleet.startup:fleet_main",
        ],
    },
    zip_safe=False,
)
