"""Run exported policies without torch: ``OnnxPolicy`` (numpy + onnxruntime).

The ROS node and deployment code load a trained policy through this package, so
it deliberately depends on nothing heavier than onnxruntime.
"""
from vmas_ros.policy.onnx_policy import POLICY_FORMAT, POLICY_VERSION, OnnxPolicy, validate_metadata

__all__ = ["OnnxPolicy", "POLICY_FORMAT", "POLICY_VERSION", "validate_metadata"]
