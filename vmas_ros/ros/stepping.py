"""sim_node's step loop: actions, ``env.step``, the published env's snapshot, then its messages.

A step is computed (actions, ``env.step``, the snapshot of env ``env_index``
checked for finiteness) and then emitted (messages filled and published, the
bag written). Unpaced, a timer callback steps for the ``unpaced_batch_ms``
parameter's wall time, computing up to ``UNPACED_BURST`` steps back to back
before it emits them, in order, each with its own stamp: a step interleaved
with publishing runs slower than back to back (the publishing between steps
evicts the step's code and data from the caches), and subscribers receive
every step either way. A step that fails is reported (``SimulationFault``,
naming the step and the part) only after the steps computed before it went
out, so the bag and the subscribers end at the last good step, as they would
one step at a time.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import List, Optional

import numpy as np
import torch

from vmas_ros.simulator import env_snapshot
from vmas_ros.ros.lifecycle import SimulationFault

#: unpaced: at most this many steps are computed back to back before their messages go out
UNPACED_BURST = 16


@dataclass
class ComputedStep:
    """What one step publishes: its number, the snapshot of the published env and the observations/rewards."""

    steps: int
    snap: env_snapshot.Snapshot
    obs: list
    rewards: Optional[list]
    colours: Optional[list]


class StepLoop:
    """The stepping half of ``SimNode`` (a mixin: the node owns the env, the publishers and the recorder)."""

    def _tick(self) -> None:
        if not self.context.ok():  # shutting down (SIGINT/SIGTERM): publish nothing more
            return
        if self.paused:
            return
        if self._timer.timer_period_ns != 0:
            self.step_once()
            return
        # unpaced: one executor round is dear next to a step, so keep stepping for about
        # unpaced_batch_ms of wall time; commands and services wait about that long at most
        end = time.perf_counter() + self.params.unpaced_batch_ms / 1000.0
        while True:
            self._run_steps(UNPACED_BURST, end)
            if time.perf_counter() >= end or self.paused or not self.context.ok():
                return

    def step_once(self) -> None:
        """One step: actions, ``env.step``, publish. A failure in any part raises
        SimulationFault saying which part and whether anything of the step went out,
        so that the node stops (exit code 3) instead of publishing garbage."""
        self._run_steps(1, None)

    def _run_steps(self, count: int, end: Optional[float]) -> None:
        """Compute up to ``count`` steps (fewer once ``perf_counter()`` passes ``end``), then emit each."""
        computed: List[ComputedStep] = []
        try:
            for _ in range(count):
                computed.append(self._compute_step())
                if end is not None and time.perf_counter() >= end:
                    break
        except Exception:
            # the steps computed before a failing one go out first: its fault is raised after them
            # (a signal, KeyboardInterrupt, stops at once: those steps were never published)
            for step in computed:
                self._emit_step(step)
            raise
        for step in computed:
            self._emit_step(step)

    def _compute_step(self) -> ComputedStep:
        stage = "actions"
        try:
            phases = self.phases
            start = time.perf_counter() if phases is not None else 0.0
            actions = self._actions()
            if phases is not None:
                phases.add("actions", start)
                start = time.perf_counter()
            stage = "engine"
            self.obs, self.rewards, _, _ = self.env.step(self._engine_actions(actions))
            self.steps += 1
            if not self._compile_reported:
                self._report_compiled()
            if phases is not None:
                phases.add("engine", start)
            stage = "publish"
            return self._gather()
        except Exception as error:
            self._raise_fault(stage, error, self.steps if stage == "publish" else self.steps + 1)

    def _engine_actions(self, actions: List[torch.Tensor]):
        """What ``env.step`` gets: a swarm's (no per-agent topics) actions stacked in one tensor, so that
        neither the step nor its observations and rewards cost a call per agent (they come back stacked
        too, and are read row by row like the lists); a small team's list, as VMAS takes it."""
        if self.per_agent or not actions:
            return actions
        try:
            return torch.stack(actions)
        except RuntimeError:  # sizes differ between agents (or one is wrong): the list, checked agent by agent
            return actions

    def _emit_step(self, step: ComputedStep) -> None:
        try:
            self._emit(step)
        except Exception as error:
            self._raise_fault("publish", error, step.steps)
        self._check_recording()  # a bag that could not be written: no fault of the step (record_on_error)

    def _raise_fault(self, stage: str, error: Exception, step: int) -> None:
        """Re-raise ``error`` as the SimulationFault of ``step`` (as it is while a signal shuts the node down:
        a publish that raced the shutdown is no fault)."""
        if not self.context.ok():
            raise error
        raise self._fault(stage, error, step) from (error.__cause__ if isinstance(error, SimulationFault) else error)

    def _fault(self, stage: str, error: Exception, step: int) -> SimulationFault:
        """A SimulationFault naming the step, the failing part and what was published."""
        p = self.params
        part = {
            "actions": f"computing the actions (control: {p.control}"
                       + (f", policy {p.policy_path}" if p.control == "policy" else "") + ")",
            "engine": f"the scenario {p.scenario!r} (Environment.step)",
            "publish": f"the state scenario {p.scenario!r} produced" if isinstance(error, SimulationFault)
                       else "publishing the new state",
        }[stage]
        what = str(error) if isinstance(error, SimulationFault) else f"{type(error).__name__}: {error}"
        what = " ".join(what.split())  # one line: onnxruntime's messages span several
        if stage != "publish":
            kept = "nothing of this step was published or recorded"
        elif isinstance(error, SimulationFault):  # our own finiteness checks run before the values go out
            kept = "no non-finite value was published; this step was not recorded"
        else:
            kept = "part of this step may have been published; none of it was recorded"
        return SimulationFault(f"step {step} (t={step * self._dt_ns / 1e9:.3f} s) failed in {part}: {what}; {kept}")

    # ------------------------------------------------------------ publishing
    def _publish(self) -> None:
        """Publish the current state (at start-up and after a reset: no step in between)."""
        self._emit(self._gather())
        self._check_recording()

    def _gather(self) -> ComputedStep:
        """The published env's snapshot of the current state (refused if not finite), with what goes with it."""
        p, phases = self.params, self.phases
        world = self.env.world
        start = time.perf_counter() if phases is not None else 0.0
        snap = self.snapshot.take(p.env_index)  # computed by a compiled step, or gathered now
        if phases is not None:
            phases.add("lidar", start)
            start = time.perf_counter()
        self._check_finite(snap)
        colours = None
        if self._per_env_colours:  # e.g. goal colours drawn per env at reset
            colours = [c for k in self._per_env_colours for c in env_snapshot.rgb(world.entities[k].color, p.env_index)]
        if phases is not None:
            phases.add("convert", start)
        return ComputedStep(self.steps, snap, self.obs, self.rewards, colours)

    def _emit(self, step: ComputedStep) -> None:
        """Fill, publish and record one computed step."""
        stamp_ns = step.steps * self._dt_ns
        self._step_records = []
        self._publish_all(step, stamp_ns)
        if self.recorder is not None:
            # the whole step goes into the bag at once (signals deferred meanwhile), so a
            # SIGINT/SIGTERM that interrupts publishing never leaves half a step in the bag
            with self.recorder.batch():
                for topic, kind, payload in self._step_records:
                    if isinstance(payload, bytes):  # the pre-serialised state messages
                        self.recorder.write_raw(topic, kind, payload, stamp_ns)
                    else:
                        self._record(topic, payload, stamp_ns=stamp_ns)
                if self._tf_bytes is not None:
                    from vmas_ros.record import TF_MESSAGE_TYPE

                    self.recorder.write_raw("/tf", TF_MESSAGE_TYPE, self._tf_bytes, stamp_ns)

    def _publish_all(self, step: ComputedStep, stamp_ns: int) -> None:
        p, phases = self.params, self.phases
        start = time.perf_counter() if phases is not None else 0.0
        snap = step.snap
        self.state_messages.fill(snap, stamp_ns, step.colours)
        if phases is not None:
            phases.add("convert", start)
            start = time.perf_counter()
        self.state_pub.publish(self._record_payload if self.recorder is not None else None)
        self._publish_tf(snap, stamp_ns)
        self.agent_topics.publish(step.obs, step.rewards, p.env_index, always=self.recorder is not None)
        if self.foxglove is not None:
            self.foxglove.publish(snap, self.env.world.entities, self.scan_geometry, stamp_ns, env_index=p.env_index)
            if step.rewards is not None:
                values = {name: float(r[p.env_index]) for name, r in zip(self.agent_names, step.rewards)}
                values["total"] = sum(values.values())
                self.foxglove.log_json("/rewards", values, stamp_ns)
        if phases is not None:
            phases.add("publish", start)
            phases.steps += 1

    def _check_finite(self, snap: env_snapshot.Snapshot) -> None:
        """Refuse (SimulationFault) a NaN/inf pose or velocity, or a NaN scan, before any is published."""
        if snap.all_finite():
            return
        entities = self.env.world.entities
        bad = [entities[k].name for k in range(len(entities))
               if not (np.isfinite(snap.pos[k]).all() and np.isfinite(snap.vel[k]).all()
                       and np.isfinite(snap.rot[k]) and np.isfinite(snap.ang_vel[k]))]
        bad += [f"{self.agent_names[i]}'s scan" for i, ss in snap.scans.items() if any(np.isnan(s).any() for s in ss)]
        raise SimulationFault(f"non-finite state in env {self.params.env_index}: {', '.join(bad)}")
