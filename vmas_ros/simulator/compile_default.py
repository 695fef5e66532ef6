"""Whether and when a world compiles its physics when its maker did not say: the default mode.

``make_env`` without ``compile_physics`` steps eagerly first and compiles only
once the run has shown it is long: after ``thresholds.DEFAULT_COMPILE_AFTER_WORK``
entity-env-steps (steps x envs x entities, each step counting as at least
``DEFAULT_COMPILE_MIN_STEP_WORK``), counted from ``make_env``
(:func:`default_switch_step`). A short script never pays the compiler, not
even its import; a long run pays it once and then steps compiled. Very large
batches step eagerly throughout (``thresholds.DEFAULT_COMPILE_MAX_ENVS``), and
so does a device with no working compiler, saying so once per process.

The compiled step equals the eager one to float rounding, not bit for bit
(the compiler fuses and reorders float operations). So the switch step is a
function of the workload alone, never of the clock: a seeded run gives the
same bits on every run and every machine, eager up to that step and compiled
after it. Bit parity with VMAS holds on the eager path.

``VMAS_ROS_COMPILE`` sets that default for a process and the processes it
starts: ``auto`` (the above), ``1`` (compile from the first step) or ``0``
(always eager: what the test suite uses). An explicit
``compile_physics=True/False`` wins over both. sim_node's default differs, and
why: docs/node.md.
"""
from __future__ import annotations

import functools
import logging
import math
import os
from typing import Optional

import torch

from vmas_ros.simulator.thresholds import (DEFAULT_COMPILE_AFTER_WORK, DEFAULT_COMPILE_MAX_ENVS,
                                           DEFAULT_COMPILE_MIN_STEP_WORK)

__all__ = ["ENV_VAR", "MODES", "compile_by_default", "compiler_missing", "compiler_ready", "default_switch_step",
           "resolve_compile", "note_fallback"]

ENV_VAR = "VMAS_ROS_COMPILE"
#: what ``VMAS_ROS_COMPILE`` may hold, and what each means for a world nobody asked about
MODES = {"auto": None, "1": True, "0": False}

_log = logging.getLogger("vmas_ros")
_said: set = set()  # the one-line notes already given in this process


def env_mode() -> str:
    """``VMAS_ROS_COMPILE`` (``auto`` when unset); anything else is refused, naming the value."""
    value = os.environ.get(ENV_VAR, "auto").strip().lower() or "auto"
    if value not in MODES:
        raise ValueError(f"{ENV_VAR}={value!r}: expected one of {', '.join(MODES)}")
    return value


def compiler_missing(device) -> Optional[str]:
    """Why ``torch.compile`` cannot build code for ``device`` here, or None when it can."""
    device_type = torch.device(device).type
    if device_type == "cuda":
        return None if _has_triton() else "Triton is not installed (torch.compile needs it on CUDA)"
    if device_type != "cpu":
        return f"torch.compile is not used on {device_type!r} devices"
    return _cpu_compiler_missing()


@functools.lru_cache(maxsize=1)
def _cpu_compiler_missing() -> Optional[str]:
    from torch._inductor import cpp_builder

    try:
        cpp_builder.get_cpp_compiler()  # runs `<compiler> --version` for each candidate inductor would use
    except Exception as error:  # InvalidCxxCompiler, or a broken toolchain
        return f"no working C++ compiler ({type(error).__name__}); install g++ or set CXX"
    return None


@functools.lru_cache(maxsize=1)
def _has_triton() -> bool:
    from torch.utils._triton import has_triton

    return has_triton()


def compile_by_default(device, num_envs: int) -> bool:
    """What ``num_envs`` envs on ``device`` do when nobody said: ``VMAS_ROS_COMPILE``, else compile where
    possible, up to ``thresholds.DEFAULT_COMPILE_MAX_ENVS`` envs.

    The first time it decides not to compile for lack of a compiler, it logs one line saying why.
    """
    forced = MODES[env_mode()]
    if forced is not None:
        return forced
    if isinstance(num_envs, int) and num_envs > DEFAULT_COMPILE_MAX_ENVS:  # a bad count: the env says so
        return False
    return compiler_ready(device)


def compiler_ready(device) -> bool:
    """Whether ``torch.compile`` can build code for ``device``; the first time it cannot, one log line
    says why (imports the compiler's code-building side: called only when a compile is due)."""
    reason = compiler_missing(device)
    if reason is None:
        return True
    _say_once(f"eager:{reason}", f"vmas_ros: physics runs eagerly (slower): {reason}; "
                                 f"{ENV_VAR}=0 hides this note")
    return False


def resolve_compile(compile_physics: Optional[bool], num_envs: int) -> Optional[bool]:
    """What ``make_env`` does: True compiles from the first step, False steps eagerly, None is the default
    mode's switch (:func:`default_switch_step`). ``compile_physics`` as given, else ``VMAS_ROS_COMPILE``.

    Nothing here imports the compiler: whether it works is checked when a compile is due."""
    if compile_physics is None:
        forced = MODES[env_mode()]
        if forced is not None:
            return forced
        if isinstance(num_envs, int) and num_envs > DEFAULT_COMPILE_MAX_ENVS:  # a bad count: the env says so
            return False
        return None
    if not isinstance(compile_physics, bool):
        raise TypeError(f"compile_physics must be True, False or None (the default mode), got {compile_physics!r}")
    return compile_physics


def default_switch_step(num_envs: int, n_entities: int) -> int:
    """How many eager steps the default mode takes before the compiled step takes over: enough that
    ``steps * num_envs * n_entities`` reaches ``DEFAULT_COMPILE_AFTER_WORK``, each step counting as at
    least ``DEFAULT_COMPILE_MIN_STEP_WORK`` (at least one step)."""
    work_per_step = max(DEFAULT_COMPILE_MIN_STEP_WORK, max(1, int(num_envs)) * max(1, int(n_entities)))
    return max(1, math.ceil(DEFAULT_COMPILE_AFTER_WORK / work_per_step))


def note_fallback(error: BaseException) -> None:
    """Log, once per process, that compiling failed and the physics went on eagerly."""
    first_line = (str(error).strip().splitlines() or [type(error).__name__])[0][:200]
    _say_once("fallback", f"vmas_ros: compiling the physics step failed ({type(error).__name__}: {first_line}); "
                          f"it runs eagerly")


def _say_once(key: str, message: str) -> None:
    if key not in _said:
        _said.add(key)
        _log.warning(message)
