"""Multi-agent PPO training (the VMAS paper's CPPO, MAPPO, IPPO, HetIPPO) on TorchRL, and ONNX export.

Modules: ``config`` (TrainConfig), ``models`` (networks), ``algorithms`` (the four
variants + ClipPPOLoss), ``trainer`` (collect / update / log / checkpoint / evaluate),
``export`` (ONNX + JSON), ``checkpoint``, ``cli`` (``vmas-ros train`` / ``export``),
``suite`` + ``suite_report`` (``vmas-ros train-suite``: the paper's Figure 3, all variants on several scenarios).
"""
from vmas_ros.train.config import ALGORITHM_NAMES, TrainConfig

__all__ = ["TrainConfig", "ALGORITHM_NAMES"]
