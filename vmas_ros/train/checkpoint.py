"""Checkpoints: everything needed to resume training or export the policy, in one ``.pt`` file.

Saved as plain containers of tensors, numbers and strings, so they load with
``torch.load(..., weights_only=True)`` (no pickled code runs on load).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Dict, Union

import torch

__all__ = ["CHECKPOINT_FORMAT", "save_checkpoint", "load_checkpoint", "CHECKPOINT_NAME"]

CHECKPOINT_FORMAT = "vmas_ros.checkpoint"
CHECKPOINT_VERSION = 1
#: file name inside a run's output directory
CHECKPOINT_NAME = "checkpoint.pt"
_REQUIRED = ("config", "env_info", "iteration", "frames", "actor", "critic", "optimizer", "history")


def save_checkpoint(path: Union[str, Path], state: Dict[str, Any]) -> Path:
    """Write ``state`` atomically (temp file + rename) so a crash never leaves half a checkpoint."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save({"format": CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION, **state}, tmp)
    tmp.replace(path)
    return path


def load_checkpoint(path: Union[str, Path], map_location: Union[str, torch.device] = "cpu") -> Dict[str, Any]:
    """Load a checkpoint file, or ``<dir>/checkpoint.pt`` given a run directory, and check its keys."""
    path = Path(path)
    if path.is_dir():
        path = path / CHECKPOINT_NAME
    if not path.is_file():
        raise ValueError(f"checkpoint {str(path)!r} does not exist")
    try:
        state = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as error:  # torch raises several unpickling error types
        raise ValueError(f"{path}: not a loadable checkpoint: {error}") from error
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise ValueError(f"{path}: not a vmas_ros checkpoint (format {state.get('format') if isinstance(state, dict) else None!r})")
    if state.get("version") != CHECKPOINT_VERSION:
        raise ValueError(f"{path}: checkpoint version {state.get('version')!r}, expected {CHECKPOINT_VERSION}")
    missing = [key for key in _REQUIRED if key not in state]
    if missing:
        raise ValueError(f"{path}: checkpoint lacks {missing}")
    return state
