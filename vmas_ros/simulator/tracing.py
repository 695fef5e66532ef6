"""Whether engine code is being traced into a graph rather than run step by step.

Some engine helpers have two forms: one that runs well eagerly (Python
loops over shapes, complex-number copies, host reads that pick a kernel) and
one that a compiler can fuse. :func:`tracing` picks the second while
``torch.compile`` traces the code, or while :mod:`vmas_ros.simulator.direct_graph`
does. The flag is per thread: a background compile traces while the stepping
thread keeps running the eager forms.
"""
from __future__ import annotations

import threading
from contextlib import contextmanager
from typing import Iterator

import torch

__all__ = ["traced", "tracing"]

_flag = threading.local()


def tracing() -> bool:
    """True inside a trace (ours or torch.compile's), where the graph-friendly form of the code is wanted."""
    return getattr(_flag, "on", False) or torch.compiler.is_dynamo_compiling()


@contextmanager
def traced() -> Iterator[None]:
    """Mark this thread as tracing for the duration of the block."""
    before = getattr(_flag, "on", False)
    _flag.on = True
    try:
        yield
    finally:
        _flag.on = before
