"""Sizes at which the simulator switches between equivalent ways of computing.

Every switch here picks between code paths that give the same results (to
float rounding, or bit for bit where noted); only their speed or memory
differs. Small batches are dominated by each call's fixed cost, so they take
the form with fewer calls; large batches are dominated by memory traffic, so
they take the form with fewer passes over memory. The values were set by
measuring both sides of each switch with the project's benchmark commands
(docs/bench/); the reasons are kept here, in one place, so a reader can see
every size-dependent choice the engine makes.
"""
from __future__ import annotations

__all__ = [
    "SCATTER_TRANSPOSE_BELOW", "GEMM_SCATTER_MAX_CELLS", "SUMMED_SCATTER_MAX_ELEMENTS", "GEMM_SCATTER_MIN_PAIRS", "SMALL_BATCH_ELEMENTS",
    "LIDAR_BATCH_MAX_ELEMENTS", "COMPILED_LIDAR_BATCH_MAX_ELEMENTS", "RIDE_ALONG_MAX_ELEMENTS",
    "SMALL_BATCH_MAX_ENVS", "DIRECT_TRIG_MAX_ELEMENTS", "STACKED_SIDES_MAX_ELEMENTS", "FEW_ENVS",
    "GRID_MIN_SPHERES", "GRID_START_CAPACITY", "GRID_MIN_LIDARS", "DEFAULT_COMPILE_MAX_ENVS",
    "DEFAULT_COMPILE_AFTER_WORK", "DEFAULT_COMPILE_MIN_STEP_WORK",
]

# --- the default mode -------------------------------------------------------------------------

#: Up to this many envs, the default mode (``make_env`` without ``compile_physics``) compiles the step
#: where a compiler is present; from here on it steps eagerly. At such batches each kernel is bound by
#: memory traffic, so compiling gains little on simple worlds, while the compiler itself stays resident
#: (torch._dynamo and inductor), which falls on exactly the users who raise
#: ``num_envs`` to fill their memory. ``compile_physics=True`` still compiles at any size
#: (docs/bench/default_mode.md has both sides).
DEFAULT_COMPILE_MAX_ENVS = 20_000

#: The default mode steps eagerly until a run has done this many entity-env-steps (steps x envs x
#: entities), then compiles once and steps compiled. Compiling costs seconds (more on a machine's first
#: compile) and saves a share of each step that grows with the batch, so a short run is faster
#: without it and a long one with it. Work, not time, decides, so the switch step is the same on every
#: machine. Set so that the short runs people time (a script's first thousands of steps at tens of envs,
#: a tutorial-size training loop) stay eager, while a batch of thousands compiles within its first
#: hundred steps (docs/bench/default_mode.md).
DEFAULT_COMPILE_AFTER_WORK = 5_000_000

#: ... and every step counts as at least this much work: a step's fixed cost (its Python and the launch of
#: each small kernel), which the compiled step cuts too, weighs most at a few envs. So a run of one env
#: compiles after ``DEFAULT_COMPILE_AFTER_WORK / DEFAULT_COMPILE_MIN_STEP_WORK`` steps, not never.
DEFAULT_COMPILE_MIN_STEP_WORK = 400

# --- physics step ---------------------------------------------------------------------------

#: From this many spheres that may all touch each other, their contacts are found through a grid
#: (``physics.collision.sphere_grid``) instead of a list of every pair: the pair list's cost grows
#: with the square of the count, the grid's about linearly. Below, the pair list's few large ops
#: beat the grid's sort and searches (docs/bench/swarm.md has both sides of the switch).
GRID_MIN_SPHERES = 256

#: Room per sphere in the grid's candidate list to start with (the sphere itself and its neighbours'
#: bucket mates); a step that meets more is computed again with more (never a lost contact). In a
#: sparse swarm most spheres meet only themselves.
GRID_START_CAPACITY = 2

#: From this many lidars cast together (same ray count and range, sphere targets seen by all), each
#: lidar's rays are tested only against the spheres within its reach, found through the same grid
#: (``lidar_grid``), instead of against every target: the all-target cast grows with the square of
#: the swarm. Below, the all-target cast's few large ops win (docs/bench/swarm.md).
GRID_MIN_LIDARS = 64

#: Below this many envs, pair forces are scattered along dim 0 of a transposed view: CPU
#: ``index_add_`` along an inner dim pays per index, which dominates when each index moves
#: only a few envs. Same order, same sums.
SCATTER_TRANSPOSE_BELOW = 16

#: Pair forces may be scattered with one GEMM against a dense ``[N, P]`` incidence matrix up to
#: this many (entity, pair) cells; above, the matrix would cost more memory than it saves time.
GEMM_SCATTER_MAX_CELLS = 1 << 14

#: A compiled step adds pair forces by multiplying with the incidence matrix and summing over the pairs,
#: instead of a GEMM, up to this many (entity, pair, env) elements: the compiler fuses that into its own
#: loops, where the GEMM is a library call whose fixed cost is most of a one-env step's scatter.
SUMMED_SCATTER_MAX_ELEMENTS = 1 << 10

#: Eager steps over many envs scatter by GEMM only from this many pairs of one kernel: with
#: fewer, ``index_add_`` runs level with it and the BLAS kernel is not worth its resident code.
GEMM_SCATTER_MIN_PAIRS = 8

#: Up to this many state elements, held entities are kept still with one ``torch.where`` (the
#: per-call cost dominates); above, by copying their rows back or integrating only the free
#: block (``torch.where`` is slow per element on the CPU). Also where the action input switches
#: from one strided copy to per-component copies.
SMALL_BATCH_ELEMENTS = 8192

#: Batches of at most this many envs step on one intra-op thread: waking torch's thread pool
#: costs more than the work it splits.
SMALL_BATCH_MAX_ENVS = 256

# --- geometry and sensors -------------------------------------------------------------------

#: Up to this many points, the closest point on a box's boundary is found with the four sides
#: stacked in one tensor (fewer calls); above, side by side (no stacked temporaries).
STACKED_SIDES_MAX_ELEMENTS = 256

#: A lidar takes cos/sin of every ray directly up to this many envs x rays (fewer calls); above,
#: it rotates its fixed ray fan by each env's heading (fewer transcendental evaluations).
DIRECT_TRIG_MAX_ELEMENTS = 4096

#: Eager worlds cast a layout's lidars together while envs x rays is at most this (one set of
#: calls for all lidars); above, each lidar alone (its temporaries stay in cache).
LIDAR_BATCH_MAX_ELEMENTS = 8192

#: The same for compiled worlds' one-graph cast: faster below; above, one lidar's temporaries
#: stay in cache where all lidars' together do not.
COMPILED_LIDAR_BATCH_MAX_ELEMENTS = 32768

#: Up to this many envs x rays a compiled step also gathers the env a node publishes (one graph
#: does it for free); above, it is gathered after the step (riding along would add one more pass
#: over the whole batch per step).
RIDE_ALONG_MAX_ELEMENTS = 4096

# --- scenario formulations ------------------------------------------------------------------

#: Below this many envs, a scenario that offers two formulations of its rewards and
#: observations takes the one with fewer calls (each call's fixed cost dominates); from it on,
#: the one with fewer passes over memory.
FEW_ENVS = 64
