"""Whether a world compiles its physics when its maker did not say: the default mode.

``make_env`` and sim_node compile the physics step by default wherever
``torch.compile`` can build code for the device (a C++ compiler for the CPU,
Triton for CUDA), and run it eagerly elsewhere, saying so once per process.
Very large batches step eagerly too (``thresholds.DEFAULT_COMPILE_MAX_ENVS``).
Compiling is what makes the step fast at every batch size (docs/bench), and
most users never look for a flag.

``VMAS_ROS_COMPILE`` sets that default for a process and the processes it
starts: ``auto`` (the above), ``1`` (always compile) or ``0`` (always eager:
what the test suite uses, so that it does not pay a compile for every env).
An explicit ``compile_physics=True/False`` wins over both.

The compiled step equals the eager one to float rounding, not bit for bit
(the compiler fuses and reorders float operations), so bit parity with VMAS
holds on the eager path only. A seeded run is reproducible in either mode:
``make_env`` builds the compiled step on the first step, before any state
depends on it.
"""
from __future__ import annotations

import functools
import logging
import os
from typing import Optional

import torch

from vmas_ros.simulator.thresholds import DEFAULT_COMPILE_MAX_ENVS

__all__ = ["ENV_VAR", "MODES", "compile_by_default", "compiler_missing", "resolve_compile", "note_fallback"]

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
    reason = compiler_missing(device)
    if reason is None:
        return True
    _say_once(f"eager:{reason}", f"vmas_ros: physics runs eagerly (slower): {reason}; "
                                 f"{ENV_VAR}=0 hides this note")
    return False


def resolve_compile(compile_physics: Optional[bool], device, num_envs: int) -> bool:
    """``compile_physics`` as given, or the default mode's choice when it is None."""
    if compile_physics is None:
        return compile_by_default(device, num_envs)
    if not isinstance(compile_physics, bool):
        raise TypeError(f"compile_physics must be True, False or None (the default mode), got {compile_physics!r}")
    return compile_physics


def note_fallback(error: BaseException) -> None:
    """Log, once per process, that compiling failed and the physics went on eagerly."""
    first_line = (str(error).strip().splitlines() or [type(error).__name__])[0][:200]
    _say_once("fallback", f"vmas_ros: compiling the physics step failed ({type(error).__name__}: {first_line}); "
                          f"it runs eagerly")


def _say_once(key: str, message: str) -> None:
    if key not in _said:
        _said.add(key)
        _log.warning(message)
