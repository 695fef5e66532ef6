"""Small stand-ins for the ``ros2`` command line, for installs from the PyPI wheels.

The ROS 2 wheels bring rclpy and the message packages but no ``ros2`` CLI, so
``vmas-ros`` offers the few commands a new user needs to look at and steer any
ROS 2 graph (not only sim_node's). Each one is a module of its own:

- :mod:`.echo`: print a topic's messages (``ros2 topic echo``);
- :mod:`.drive`: publish a ``geometry_msgs/Twist`` on an agent's ``cmd_vel``
  for a while, once a subscriber listens (``ros2 topic pub``);
- :mod:`.dds_clean`: remove Fast DDS shared memory that a killed process left
  half made, which hangs every later node (``fastdds shm clean``);

:mod:`.graph` holds what they share: a short-lived node, name resolution as
``ros2`` does it, and waiting on the graph. With a full ROS install the ``ros2``
commands named above do the same.
"""
