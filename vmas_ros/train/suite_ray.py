"""``vmas-ros train-suite --ray-address ADDR``: the suite's runs as Ray tasks across a cluster.

The runs are independent, so each becomes one task that trains in a scratch
folder on whichever node Ray picks (``SPREAD``), with its envs in the task's
own process. The task sends the finished folder's files back and this process
writes them into ``<out>/runs/<name>``: no filesystem is shared between nodes,
and the suite folder on the machine that runs the command stays the one
record. A run that already has a checkpoint sends it along, so it continues
instead of starting over; finished runs are skipped before any task starts.

A task that fails (its node left the cluster, or training raised) does not
stop the others; the command reports it by name and a rerun retries it.
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple

from vmas_ros.train.suite_run import DONE_MARKER, SuiteRun, check_same_settings, train_one

__all__ = ["train_runs_on_ray"]


def _train_in_scratch(config: Dict[str, Any], checkpoint: Optional[bytes], threads: int) -> Dict[str, Any]:
    """Train one run in a scratch folder of the node it lands on; return its files and history."""
    import ray
    import torch

    from vmas_ros.train.checkpoint import CHECKPOINT_NAME
    from vmas_ros.train.config import TrainConfig

    torch.set_num_threads(threads)
    scratch = Path(tempfile.mkdtemp(prefix="vmas_ros_run_"))
    try:
        if checkpoint is not None:
            (scratch / CHECKPOINT_NAME).write_bytes(checkpoint)
        local = TrainConfig.from_dict({**config, "out": str(scratch), "ray_address": "none", "collectors": 1})
        run = SuiteRun(local.scenario, local.algorithm, local.seed, local)
        result = train_one(run, progress=False)
        node = ray.get_runtime_context().get_node_id()
        done = json.loads((scratch / DONE_MARKER).read_text())
        (scratch / DONE_MARKER).write_text(json.dumps({**done, "node_id": node}, indent=2) + "\n")
        (scratch / "config.json").write_text(json.dumps(config, indent=2) + "\n")
        files = {path.name: path.read_bytes() for path in scratch.iterdir() if path.is_file()}
        return {"status": result["status"], "history": result["history"], "files": files, "node_id": node}
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def _write_files(folder: Path, files: Dict[str, bytes]) -> None:
    """Write a run's files atomically, the done marker last (it is what makes a run count as finished)."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in sorted(files, key=lambda n: n == DONE_MARKER):
        if os.sep in name or name.startswith("."):
            raise ValueError(f"a run task sent back an unexpected file name {name!r}")
        tmp = folder / (name + ".part")
        tmp.write_bytes(files[name])
        tmp.replace(folder / name)


def train_runs_on_ray(runs: List[SuiteRun], cpus: int,
                      on_done: Callable[[SuiteRun, Dict[str, Any]], None]) -> List[Tuple[SuiteRun, str]]:
    """Train ``runs`` as Ray tasks of ``cpus`` CPUs each (Ray must be connected); returns the failures.

    ``on_done(run, result)`` is called as each run finishes, in finishing order;
    ``result`` has ``status`` and ``history`` like :func:`~vmas_ros.train.suite_run.train_one`'s.
    """
    import ray

    from vmas_ros.train.checkpoint import CHECKPOINT_NAME, load_checkpoint

    task = ray.remote(num_cpus=cpus, max_retries=0, scheduling_strategy="SPREAD")(_train_in_scratch)
    pending: Dict[Any, SuiteRun] = {}
    for run in runs:
        checkpoint_path = run.folder / CHECKPOINT_NAME
        checkpoint = None
        if checkpoint_path.is_file():
            state = load_checkpoint(checkpoint_path)  # validated here, before any node reads it
            check_same_settings(run, state["config"])
            if (run.folder / DONE_MARKER).is_file() and int(state["iteration"]) >= run.config.iterations:
                on_done(run, {"status": "skipped", "history": state["history"][:run.config.iterations]})
                continue
            checkpoint = checkpoint_path.read_bytes()
        pending[task.remote(run.config.to_dict(), checkpoint, cpus)] = run
    failures: List[Tuple[SuiteRun, str]] = []
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        run = pending.pop(ready[0])
        try:
            result = ray.get(ready[0])
        except ray.exceptions.RayError as error:
            failures.append((run, f"{type(error).__name__}: {_first_line(error)}"))
            continue
        _write_files(run.folder, result.pop("files"))
        on_done(run, result)
    return failures


def _first_line(error: BaseException) -> str:
    lines = [line for line in str(error).splitlines() if line.strip()]
    return lines[-1] if lines else ""
