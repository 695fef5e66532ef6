"""A small, shared timer for the benchmarks.

``time_callable(fn, repeats, warmup)`` runs ``fn`` ``warmup`` times untimed, then
``repeats`` times timed, and returns a ``Timing`` (median/min/max seconds, the
torch thread count it ran with, the process's peak RSS and, on CUDA, torch's
peak allocated memory). ``time_alternating`` does the same for several cases at
once, interleaving them inside each repeat (A B C, A B C, ...) so that noise
from other work on a shared machine hits all of them alike: compare the ratios
measured in one such run, not absolute times across runs.

What is timed is exactly one call of ``run``: the optional ``setup`` (e.g. a
reset) runs untimed before each call, the garbage collector is disabled during
the call (as ``timeit`` does) and CUDA is synchronised before the clock stops.
"""
from __future__ import annotations

import contextlib
import gc
import statistics
import sys
import time
from dataclasses import asdict, dataclass, field
from typing import Callable, Dict, Iterator, List, Mapping, Optional

import torch

from vmas_ros.bench.common import DEFAULT_MODE_WARMUP_MAX_STEPS

__all__ = ["Case", "Timing", "pinned_threads", "peak_rss_mb", "through_the_switch", "time_alternating",
           "time_callable"]


@dataclass
class Case:
    """One thing to time: ``run`` is timed; ``setup`` runs untimed before every call
    (warm-up and timed); ``warmup_run`` (default: ``run``) is what a warm-up call runs."""

    run: Callable[[], object]
    setup: Optional[Callable[[], object]] = None
    warmup_run: Optional[Callable[[], object]] = None
    device: Optional[str] = None  # "cuda..." adds synchronisation and torch peak memory


def through_the_switch(env, run: Callable[[], object], actions: list,
                       on_done: Callable[[bool], object]) -> Callable[[], None]:
    """A warm-up for a vmas_ros env of the default mode: ``run``, then steps of ``actions`` (cycled) until
    the compiled step has taken over, when it comes within ``DEFAULT_MODE_WARMUP_MAX_STEPS`` steps; then a
    reset. ``on_done(compiled)`` says whether the timed runs that follow are compiled."""
    def warmup_run() -> None:
        run()
        world = env.world
        switch = world.compiled_from_step
        if switch is not None and switch <= DEFAULT_MODE_WARMUP_MAX_STEPS:
            step = 0
            while not world.physics_compiled and world.compiled_from_step is not None:
                env.step(actions[step % len(actions)])
                step += 1
            env.reset()
        on_done(world.physics_compiled)

    return warmup_run


@dataclass
class Timing:
    """Result of timing one case: seconds per call of ``run``."""

    times_s: List[float]
    median_s: float
    min_s: float
    max_s: float
    repeats: int
    warmup: int
    threads: int  # torch.get_num_threads() during the runs
    peak_rss_mb: Optional[float] = None  # the whole process's high-water mark when timing ended
    torch_peak_mb: Optional[float] = None  # CUDA only: max torch memory allocated during the runs
    first_run_s: Optional[float] = None  # the first (untimed) warm-up call: what a fresh env costs, compiling included
    extra: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)


def peak_rss_mb() -> Optional[float]:
    """The process's peak resident set size so far, in MiB (None where unavailable)."""
    try:
        import resource
    except ImportError:  # Windows
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 1024  # bytes on macOS, KiB on Linux


@contextlib.contextmanager
def pinned_threads(threads: Optional[int]) -> Iterator[int]:
    """Run the block with ``torch.set_num_threads(threads)`` (unchanged if None); yields
    the thread count in effect and restores the previous one afterwards."""
    previous = torch.get_num_threads()
    if threads is not None:
        if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
            raise ValueError(f"threads must be None or a positive int, got {threads!r}")
        torch.set_num_threads(threads)
    try:
        yield torch.get_num_threads()
    finally:
        torch.set_num_threads(previous)


def _is_cuda(device: Optional[str]) -> bool:
    return device is not None and str(device).startswith("cuda")


def _sync(device: Optional[str]) -> None:
    if _is_cuda(device):
        torch.cuda.synchronize(device)


def _call(case: Case, fn: Callable[[], object]) -> float:
    if case.setup is not None:
        case.setup()
    _sync(case.device)
    gc.collect()
    gc_was_enabled = gc.isenabled()
    gc.disable()
    try:
        start = time.perf_counter()
        fn()
        _sync(case.device)
        return time.perf_counter() - start
    finally:
        if gc_was_enabled:
            gc.enable()


def time_alternating(
    cases: Mapping[str, Case],
    repeats: int = 3,
    warmup: int = 1,
    threads: Optional[int] = None,
    on_run: Optional[Callable[[str, int, float], None]] = None,
) -> Dict[str, Timing]:
    """Time several cases, alternating them inside each repeat (A B C, A B C, ...).

    ``on_run(name, repeat_index, seconds)`` is called after every timed call (for
    progress bars). Returns a ``Timing`` per case name.
    """
    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        raise ValueError(f"repeats must be a positive int, got {repeats!r}")
    if isinstance(warmup, bool) or not isinstance(warmup, int) or warmup < 0:
        raise ValueError(f"warmup must be a non-negative int, got {warmup!r}")
    times: Dict[str, List[float]] = {name: [] for name in cases}
    torch_peak: Dict[str, Optional[float]] = {name: None for name in cases}
    first: Dict[str, Optional[float]] = {name: None for name in cases}
    with pinned_threads(threads) as in_effect:
        for _ in range(warmup):
            for name, case in cases.items():
                seconds = _call(case, case.warmup_run or case.run)
                first[name] = seconds if first[name] is None else first[name]
        for index in range(repeats):
            for name, case in cases.items():
                if _is_cuda(case.device):
                    torch.cuda.reset_peak_memory_stats(case.device)
                seconds = _call(case, case.run)
                times[name].append(seconds)
                if _is_cuda(case.device):
                    peak = torch.cuda.max_memory_allocated(case.device) / 2**20
                    torch_peak[name] = max(peak, torch_peak[name] or 0.0)
                if on_run is not None:
                    on_run(name, index, seconds)
    rss = peak_rss_mb()
    return {
        name: Timing(
            times_s=list(values),
            median_s=statistics.median(values),
            min_s=min(values),
            max_s=max(values),
            repeats=repeats,
            warmup=warmup,
            threads=in_effect,
            peak_rss_mb=rss,
            torch_peak_mb=torch_peak[name],
            first_run_s=first[name],
        )
        for name, values in times.items()
    }


def time_callable(
    fn: Callable[[], object],
    repeats: int = 3,
    warmup: int = 1,
    setup: Optional[Callable[[], object]] = None,
    threads: Optional[int] = None,
    device: Optional[str] = None,
) -> Timing:
    """Time ``fn`` ``repeats`` times after ``warmup`` untimed calls (``setup`` untimed before each)."""
    return time_alternating({"fn": Case(run=fn, setup=setup, device=device)}, repeats, warmup, threads)["fn"]
