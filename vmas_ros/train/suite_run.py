"""One run of ``vmas-ros train-suite``: a (scenario, algorithm, seed) and its folder, trained, resumed or skipped.

Shared by the suite's local loop (:mod:`vmas_ros.train.suite`) and its Ray
tasks (:mod:`vmas_ros.train.suite_ray`), which both train runs this way.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict

from vmas_ros.train.config import TrainConfig

__all__ = ["DONE_MARKER", "SuiteRun", "check_same_settings", "run_name", "train_one"]

#: written into a run folder once the run is complete (training, final checkpoint, export)
DONE_MARKER = "suite_done.json"
#: fields that may differ between a run folder and the requested config without invalidating its curve
_MAY_DIFFER = ("iterations", "checkpoint_every", "eval_episodes", "gif", "device", "out", "ray_address", "collectors",
               "collector_cpus", "collector_device")


@dataclass
class SuiteRun:
    """One (scenario, algorithm, seed) training run and where it lives."""

    scenario: str
    algorithm: str
    seed: int
    config: TrainConfig

    @property
    def name(self) -> str:
        return run_name(self.scenario, self.algorithm, self.seed)

    @property
    def folder(self) -> Path:
        return Path(self.config.out)


def run_name(scenario: str, algorithm: str, seed: int) -> str:
    """The run's folder name under ``<out>/runs`` (and its key in the report)."""
    return f"{scenario}_{algorithm}_seed{seed}"


def check_same_settings(run: SuiteRun, stored: Dict[str, Any]) -> None:
    """Refuse to continue or reuse a folder trained with other settings: its curve would not be this run's."""
    wanted = run.config.to_dict()
    for key, value in wanted.items():
        if key not in _MAY_DIFFER and stored.get(key) != value:
            raise ValueError(f"{run.folder} was trained with {key}={stored.get(key)!r}, this suite asks for "
                             f"{value!r}; use another --out (or delete the folder)")


def train_one(run: SuiteRun, progress: bool = False, on_iteration=None) -> Dict[str, Any]:
    """Train (or resume, or skip) one run; returns ``{"status": trained|resumed|skipped, "history": [...]}``."""
    from vmas_ros.train.checkpoint import CHECKPOINT_NAME, load_checkpoint
    from vmas_ros.train.trainer import Trainer

    state = load_checkpoint(run.folder) if (run.folder / CHECKPOINT_NAME).is_file() else None
    if state is not None:
        check_same_settings(run, state["config"])
        if (run.folder / DONE_MARKER).is_file() and int(state["iteration"]) >= run.config.iterations:
            return {"status": "skipped", "history": state["history"][:run.config.iterations]}
    status = "trained" if state is None else "resumed"
    start = time.perf_counter()
    trainer = Trainer(run.config, resume_state=state, progress=progress)
    trainer.run(on_iteration=on_iteration)
    (run.folder / DONE_MARKER).write_text(json.dumps({
        "iterations": trainer.iteration, "frames": trainer.frames, "status": status,
        "wall_seconds_this_session": round(time.perf_counter() - start, 2)}, indent=2) + "\n")
    return {"status": status, "history": trainer.history}
