"""How many intra-op threads torch uses for a process that steps one small batch interactively.

Small batches gain nothing from torch's intra-op threads: each kernel is too
short to split. On a busy machine the threads contend, and a tiny kernel then
waits for all of them. A process that steps one env batch interactively
(sim_node, a viewer) calls :func:`limit_threads_for_small_batches` once, where
it builds the env; libraries and training leave the setting to the user.
"""
from __future__ import annotations

import torch

from vmas_ros.simulator.thresholds import SMALL_BATCH_MAX_ENVS

__all__ = ["limit_threads_for_small_batches"]


def limit_threads_for_small_batches(num_envs: int) -> int:
    """Keep torch to one intra-op thread when ``num_envs`` is at most :data:`SMALL_BATCH_MAX_ENVS`;
    returns torch's thread count afterwards. Process-wide, as torch's setting is."""
    if not isinstance(num_envs, int) or num_envs < 1:
        raise ValueError(f"num_envs must be an int >= 1, got {num_envs!r}")
    if num_envs <= SMALL_BATCH_MAX_ENVS and torch.get_num_threads() > 1:
        torch.set_num_threads(1)
    return torch.get_num_threads()
