"""Compiling a world's functions on a thread of their own, while the world keeps stepping eagerly.

What sim_node's default mode uses (``World.compile_physics(background=True)``):
a node must not stop publishing for the seconds a compile takes. Each
compiled function of the world (the step, the LIDAR's ray kernels, the
scenario's kernels; :class:`vmas_ros.simulator.compiling._OneGraph`) is
handed to :class:`BackgroundCompiler` on its first call, with copies of that
call's tensors, and runs eagerly until its compiled code is ready. When every
compile handed over so far is done, the world releases them all at once,
before its next step (``released``; ``World.compiled_from_step`` names that
step), so one step is wholly eager or wholly compiled, and the caller never
waits for a compile. A function first called after the release (a new
layout) runs compiled as soon as its own compile is done.

The compile runs with the caller's grad mode and torch thread count (the
compiled code is specialised for both), and touches only the copies it was
given. Eager and compiled results agree to float rounding, not bit for bit.
A compile that fails leaves that function eager for good, with one log line.
"""
from __future__ import annotations

import dataclasses
import logging
import queue
import sys
import threading
import time
from typing import Callable, Optional

import torch

__all__ = ["BackgroundCompiler", "copy_inputs"]

_log = logging.getLogger("vmas_ros")

#: how often (seconds) the interpreter offers the GIL to another thread while a compile runs: the compile is
#: Python-heavy, and at the interpreter's default the stepping thread would wait that long at every handover
_SWITCH_INTERVAL_WHILE_COMPILING = 0.0005


def copy_inputs(value):
    """``value`` with every tensor in it cloned (through tuples, lists, dicts and dataclasses made of tensors
    only, such as a state); other objects (tables, parameters, functions) are shared, as the compiled code
    only reads them, and what they cache lazily stays theirs."""
    if isinstance(value, torch.Tensor):
        return value.detach().clone()
    if isinstance(value, tuple) and not hasattr(value, "_fields"):
        return tuple(copy_inputs(v) for v in value)
    if isinstance(value, list):
        return [copy_inputs(v) for v in value]
    if isinstance(value, dict):
        return {k: copy_inputs(v) for k, v in value.items()}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        fields = {f.name: getattr(value, f.name) for f in dataclasses.fields(value) if f.init}
        if fields and all(v is None or isinstance(v, torch.Tensor) for v in fields.values()):
            return dataclasses.replace(value, **{k: copy_inputs(v) for k, v in fields.items()})
    return value


class BackgroundCompiler:
    """One daemon thread that runs compile jobs in the order they were submitted.

    ``submit(compile_now, args, kwargs, on_done)`` queues ``compile_now(*args,
    **kwargs)``, which must be copies of the call's inputs (:func:`copy_inputs`)
    that nothing else touches; ``on_done(ok)`` is called on the compile
    thread when it finished. ``idle`` is True when nothing is queued or
    compiling; ``first_ready_s`` the seconds from the first submission until
    the queue first ran empty.
    """

    def __init__(self) -> None:
        self._jobs: "queue.Queue" = queue.Queue()
        self._thread: Optional[threading.Thread] = None
        self._pending = 0
        self._lock = threading.Lock()
        self._started_at: Optional[float] = None
        self.first_ready_s: Optional[float] = None
        self.compiled = 0  # jobs that compiled
        #: set by the world between two steps once the first compiles are done: compiled functions in use
        self.released = False
        self.failed = 0  # jobs whose compile failed (their functions stay eager)

    @property
    def idle(self) -> bool:
        return self._pending == 0

    @property
    def started(self) -> bool:
        return self._started_at is not None

    def submit(self, compile_now: Callable, args: tuple, kwargs: dict, on_done: Callable[[bool], None]) -> None:
        state = (torch.is_grad_enabled(), torch.get_num_threads())
        job = (compile_now, args, kwargs, on_done, state)
        with self._lock:
            self._pending += 1
            if self._started_at is None:
                self._started_at = time.perf_counter()
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="vmas_ros-compile", daemon=True)
                self._thread.start()
        self._jobs.put(job)

    def wait(self, timeout: Optional[float] = None) -> bool:
        """Block until every submitted job is done (tests and tools; a node never waits). True if idle."""
        end = None if timeout is None else time.perf_counter() + timeout
        while not self.idle:
            if end is not None and time.perf_counter() > end:
                return False
            time.sleep(0.01)
        return True

    def _run(self) -> None:
        while True:
            compile_now, args, kwargs, on_done, (grad, threads) = self._jobs.get()
            interval = sys.getswitchinterval()
            sys.setswitchinterval(min(interval, _SWITCH_INTERVAL_WHILE_COMPILING))
            ok = False
            try:
                torch.set_num_threads(threads)  # inductor generates code for the caller's thread count
                with torch.set_grad_enabled(grad):
                    compile_now(*args, **kwargs)
                ok = True
            except Exception as error:  # noqa: BLE001 - the function stays eager; the node goes on
                from vmas_ros.simulator.compile_default import note_fallback

                note_fallback(error)
            finally:
                sys.setswitchinterval(interval)
                self.compiled += ok
                self.failed += not ok
                on_done(ok)
                with self._lock:
                    self._pending -= 1
                    if self._pending == 0 and self.first_ready_s is None:
                        self.first_ready_s = time.perf_counter() - self._started_at
