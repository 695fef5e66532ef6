"""Speed tricks live inside the engine: scenarios and the ROS nodes name no compile internals.

A scenario that branches on ``torch.compiler.is_compiling()``, registers a
state kernel or wraps itself in a ``WorldKernel`` ties its behaviour to how
the engine happens to step; the engine's seams (``batched_outputs``, the
layout helpers) are there so that it need not.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2] / "vmas_ros"
FORBIDDEN = re.compile(r"is_compiling|WorldKernel|state_kernel|torch\.compiler|_dynamo")


@pytest.mark.parametrize("folder", ["scenarios", "ros"])
def test_no_compile_internals_outside_the_engine(folder):
    offending = [f"{path.relative_to(ROOT.parent)}:{number}: {line.strip()}"
                 for path in sorted((ROOT / folder).rglob("*.py"))
                 for number, line in enumerate(path.read_text().splitlines(), 1) if FORBIDDEN.search(line)]
    assert not offending, "compile internals outside the engine:\n" + "\n".join(offending)
