"""``robot_fleet``: N simulated robots behind the interface real ROS 2 bases expose, without the engine.

A stand-in for a fleet of real robots, for tests and for trying a trained
policy before the robots themselves: each robot speaks Jazzy's
diff_drive_controller interface (``<robot>/cmd_vel`` TwistStamped in,
``<robot>/odom`` Odometry and ``<robot>/scan`` LaserScan out), with the
imperfections of a real base as parameters (command latency, velocity lag,
acceleration limits, odometry and scan noise). It is written in numpy and
rclpy only, and imports nothing of vmas_ros's simulator: a policy that works
against it did not learn a quirk of our own engine.

Modules, one concern each, lowest first:

* :mod:`.kinematics`: the batched robot model (limiter, lag, pose integration);
* :mod:`.contacts`: discs that cannot overlap, arena walls, contact onsets;
* :mod:`.raycast`: LaserScan ranges by ray casting against discs and walls;
* :mod:`.commands`: the per-robot command queue (latency, timeout, bad values);
* :mod:`.episodes`: start poses and goals, validated;
* :mod:`.summary`: per-episode metrics and the summary file;
* :mod:`.world`: the pieces above as one fleet stepped in time (no ROS);
* :mod:`.params`: the node's parameter table;
* :mod:`.messages` and :mod:`.node`: the ROS 2 side;
* :mod:`.startup`: the ``robot_fleet`` console-script entry (signal guard first).

This package's ``__init__`` imports nothing, so that ``python -m
vmas_ros.fleet.node`` can install its signal guard before rclpy loads.
"""
