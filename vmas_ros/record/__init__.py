"""Recording what the simulator publishes to rosbag2-compatible MCAP files.

* :class:`McapRecorder` writes ROS 2 messages (CDR) with full ``ros2msg``
  schemas and rosbag2's channel metadata, splits by size or duration and
  closes itself at interpreter exit;
* :func:`serialize_tf_message` builds /tf's ``tf2_msgs/msg/TFMessage`` CDR
  without the (wheel-less) tf2_msgs package;
* :func:`message_definition` gives the schema text of an installed message type;
* :mod:`vmas_ros.record.cdr` serialises messages with their CDR padding
  zeroed, so identical messages give identical bytes (the node's bulk
  publishers use it too);
* :func:`recover` turns the file of a killed recorder into a valid MCAP;
* :mod:`vmas_ros.record.rosbag2` lays a recording out as one file or as a
  rosbag2 bag folder with its ``metadata.yaml``.

Needs the ``record`` extra (``mcap``, ``mcap-ros2-support``) and rclpy for
serialising messages.
"""
from vmas_ros.record._io import TF_MESSAGE_TYPE, qos_profile_yaml, serialize_tf_message, split_path
from vmas_ros.record.claim import RecordingInUse
from vmas_ros.record.mcap_recorder import DEFAULT_COMPRESSION, McapRecorder, RecordingFailed
from vmas_ros.record.recover import recover
from vmas_ros.record.rosbag2 import RecordingExists
from vmas_ros.record.schemas import message_definition

__all__ = [
    "DEFAULT_COMPRESSION",
    "McapRecorder",
    "RecordingExists",
    "RecordingFailed",
    "RecordingInUse",
    "TF_MESSAGE_TYPE",
    "message_definition",
    "qos_profile_yaml",
    "recover",
    "serialize_tf_message",
    "split_path",
]
