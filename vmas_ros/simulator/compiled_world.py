"""How one world's step and LIDAR ray kernels run: eagerly, compiled, or compiled in the background.

``World.compile_physics`` sets it; ``World.step`` and ``World.cast_rays``
call through it. One place also owns what happens when compiling turns out
not to work after all (no usable C++ compiler): the world logs it once and
goes on eagerly, redoing the call that failed, so no step is lost.

It also counts the world's steps, for the switch the default mode plans:
eager for a fixed number of steps, then compiled from one named step on
(:meth:`CompiledWorld.plan`). The compiler is not even imported before then.
Which step that is depends on the workload only, never on the clock, so a
seeded run gives the same bits on any machine.
"""
from __future__ import annotations

import logging
from typing import Callable, Optional

from vmas_ros.simulator import physics, rays
from vmas_ros.simulator.background_compile import BackgroundCompiler
from vmas_ros.simulator.compile_default import compiler_ready, note_fallback
from vmas_ros.simulator.compiling import LayoutCompiled, compile_failed, compile_for_world
from vmas_ros.simulator.physics.pipeline import advance

__all__ = ["CompiledWorld"]

_log = logging.getLogger("vmas_ros")


def _step_layout(state, tables, params: physics.StepParams, actions, fixed_rotation, kernels) -> tuple:
    """What a compiled step bakes in besides its tables (see ``LayoutCompiled``): the step parameters, the
    form of the action input, whether joints have target angles, and which state kernels ride along."""
    return (params.dt, params.substeps, params.collision_force, params.joint_force, params.torque_constraint_force,
            params.contact_margin, params.x_semidim, params.y_semidim, params.broad_phase,
            isinstance(actions, tuple), fixed_rotation is None, tuple(id(kernel) for kernel in kernels),
            tuple(group.capacity for group in tables.sphere_groups))


class CompiledWorld:
    """A world's step function and ray kernels, eager until :meth:`compile` says otherwise."""

    def __init__(self) -> None:
        #: the step as one function: advance, or a torch.compile'd copy of it
        self.step: Callable = advance
        #: shape kind -> ray kernel used by cast_rays (compiled copies when compiled)
        self.ray_kernels = rays.EAGER_KERNELS
        self.mode: Optional[str] = None
        self.background: Optional[BackgroundCompiler] = None
        #: the world's steps so far, counted from 0
        self.steps_taken = 0
        #: the first step that runs compiled (or is handed to the background compiler); None: none planned
        self.switch_at: Optional[int] = None
        self._planned_device = None  # where the planned compile will run: its compiler is checked then

    @property
    def compiled(self) -> bool:
        return self.step is not advance

    def compile(self, enabled: bool, mode: Optional[str], background: bool) -> None:
        """Compile (``enabled``) with torch.compile ``mode``, on a thread of its own with ``background``."""
        self.mode, self.background, self._planned_device = mode, None, None
        self.switch_at = self.steps_taken if enabled and not background else None
        if not enabled:
            self.step, self.ray_kernels = advance, rays.EAGER_KERNELS
            return
        self.background = BackgroundCompiler() if background else None
        # one compiled copy per layout, checking only the state and the actions on each call (LayoutCompiled)
        self.step = LayoutCompiled(advance, mode, key=_step_layout, checked=("state.", "actions", "fixed_rotation"),
                                   background=self.background)
        # the LIDAR's ray kernels too: each is a long chain of elementwise ops over [targets, envs, rays]
        self.ray_kernels = {kind: compile_for_world(fn, mode, arguments_only=True, background=self.background)
                            for kind, fn in rays.EAGER_KERNELS.items()}

    def request(self, enabled: bool, mode: Optional[str], background: bool, after_steps: int, device) -> None:
        """What ``World.compile_physics`` asked for: :meth:`compile` now, or :meth:`plan` it ``after_steps``
        steps from now; a bad ``after_steps`` is refused, naming it."""
        if isinstance(after_steps, bool) or not isinstance(after_steps, int) or after_steps < 0:
            raise ValueError(f"after_steps must be a whole number of steps >= 0, got {after_steps!r}")
        if after_steps and (background or not enabled):
            raise ValueError(f"after_steps={after_steps} needs enabled=True and background=False")
        if after_steps:
            self.plan(after_steps, mode, device)
        else:
            self.compile(enabled, mode, background)

    def plan(self, after_steps: int, mode: Optional[str], device) -> None:
        """Step eagerly for ``after_steps`` more steps, then compile (``mode``) and run compiled from the next
        one on. If ``device`` then has no working compiler, the world stays eager, saying so once."""
        self.compile(False, None, False)
        self.mode, self.switch_at, self._planned_device = mode, self.steps_taken + after_steps, device

    def tick(self) -> None:
        """Count one world step, called before it runs: at the planned step the compiled step takes over;
        in the background, at the first step after every compile handed over so far is done."""
        background = self.background
        if background is not None and not background.released and background.started and background.idle:
            background.released, self.switch_at = True, self.steps_taken
        if self.steps_taken == self.switch_at and self._planned_device is not None:
            device, self._planned_device = self._planned_device, None
            if compiler_ready(device):
                _log.info("vmas_ros: compiling the physics step after %d eager steps", self.steps_taken)
                self.compile(True, self.mode, False)
            else:
                self.switch_at = None
        self.steps_taken += 1

    def advance(self, state, tables, params, actions, fixed_rotation, kernels):
        """``(new state, kernel outputs)`` of one compiled step (``pipeline.advance``; the world calls the
        eager one directly)."""
        try:
            return self.step(tables, state, tables, params, actions, fixed_rotation, kernels)  # keyed on tables
        except Exception as error:
            if not compile_failed(error):
                raise
            self.fall_back(error)  # no working compiler after all: the step goes on eagerly
            return advance(state, tables, params, actions, fixed_rotation, kernels)

    def cast(self, cast: Callable[[dict], object]):
        """``cast(ray_kernels)``, again with the eager kernels if compiling them fails."""
        try:
            return cast(self.ray_kernels)
        except Exception as error:
            if not compile_failed(error):
                raise
            self.fall_back(error)
            return cast(self.ray_kernels)

    def fall_back(self, error: BaseException) -> None:
        """Compiling failed (``error``): log it once per process and run eagerly from now on."""
        note_fallback(error)
        self.compile(False, None, False)
