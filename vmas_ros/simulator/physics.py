"""The batched physics step: pure functions over planar ``[3, n_entities, batch]`` tensors.

Entity-major and planar on purpose: the state is ``q`` = (x, y, angle) and
``v`` = (vx, vy, angular velocity), each ``[3, N, B]`` (:class:`PlanarState`),
so per-entity constants (mass, limits, masks) broadcast as ``[3, N, 1]``
columns over each entity's contiguous batch, one elementwise op updates every
coordinate, and gathering a pair's members copies whole blocks. Batch-major
``[batch, n, 2]`` made every broadcast op run two floats at a time, 3x slower
than VMAS at 30,000 envs, and ops over a trailing dim of 2 do not vectorise.

One call of :func:`step_planar` advances every env by ``dt`` with ``substeps``
semi-implicit Euler substeps (paper, "The VMAS platform"):

    f_i   = f_action + f_gravity + f_friction + sum_j f_contact(i, j) + f_joint
    v_i' = (1 - drag) v_i + f_i / m_i * dt          (drag on the first substep)
    x_i' = x_i + v_i' * dt

with the same update for the angle using torques and the moment of inertia.
Contact forces are the soft penetration force of MPE/VMAS:
``c * n * k * log(1 + exp(-(d - d_min) / k))`` while ``d <= d_min``.

The contact and joint kernels (:mod:`vmas_ros.simulator.contacts`) work on
planar ``[P, B]`` components and hand back forces that :func:`_add_pairs`
adds into the ``[3, N, B]`` force in pair order.

Nothing here loops over envs or entity pairs in Python, and nothing reads a
tensor back to the host: the number of kernels per step depends only on how
many shape-pair kinds and joints the world has. That also makes :func:`step_planar`
a fixed-shape function that ``torch.compile`` can fuse (``World.compile_physics``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator import contacts
from vmas_ros.simulator.layout import join_xy, split_xy_stacked
from vmas_ros.simulator.tables import PairTable, WorldTables
from vmas_ros.simulator.utils import TorchUtils

#: r x f with a trailing size-1 dim, the torque of force f applied at lever arm r
cross = TorchUtils.cross


#: below this many envs, pair forces are scattered through a transposed view (see _add_pairs);
#: measured crossover on the CPU: ~16 envs
SCATTER_TRANSPOSE_BELOW = 16

#: pair forces are scattered with one GEMM against a dense [N, P] incidence matrix up to this many
#: (entity, pair) cells (see scatter_by_gemm)
GEMM_SCATTER_MAX_CELLS = 1 << 14

#: eager steps over many envs scatter by GEMM only from this many pairs of one kernel (see scatter_by_gemm)
GEMM_SCATTER_MIN_PAIRS = 8

#: up to this many state elements the step keeps held entities still with one ``torch.where`` (per-call
#: cost dominates); above, by copying their rows back (``torch.where`` is slow per element on the CPU)
SMALL_BATCH_ELEMENTS = 8192


@dataclass
class StepParams:
    """World-level constants of the step."""

    dt: float
    substeps: int
    collision_force: float
    joint_force: float
    torque_constraint_force: float
    contact_margin: float
    x_semidim: Optional[float]
    y_semidim: Optional[float]
    #: "batch": a pair near in any env interacts in every env (VMAS 1.5, bit parity);
    #: "env": each env decides for itself (envs independent of each other)
    broad_phase: str = "batch"


@dataclass
class BodyState:
    """State of all entities: pos/vel [N, B, 2], rot/ang_vel [N, B, 1]."""

    pos: Tensor
    vel: Tensor
    rot: Tensor
    ang_vel: Tensor


@dataclass
class PlanarState:
    """State of all entities as stacked planar components.

    ``q`` is ``[3, N, B]``: x, y and angle; ``v`` is ``[3, N, B]``: vx, vy and
    angular velocity. One elementwise op then integrates all three
    coordinates, with per-coordinate constants as ``[3, N, 1]`` columns.
    """

    q: Tensor
    v: Tensor

    @classmethod
    def from_vectors(cls, state: BodyState) -> "PlanarState":
        q = torch.cat([split_xy_stacked(state.pos.contiguous()), state.rot[..., 0].unsqueeze(0)])
        v = torch.cat([split_xy_stacked(state.vel.contiguous()), state.ang_vel[..., 0].unsqueeze(0)])
        return cls(q, v)

    def to_vectors(self) -> BodyState:
        q, v = self.q, self.v
        return BodyState(join_xy(q[0], q[1]), join_xy(v[0], v[1]), q[2].unsqueeze(-1), v[2].unsqueeze(-1))


def stack_actions(force: Tensor, torque: Tensor) -> Tensor:
    """Per-entity force ``[N, B, 2]`` and torque ``[N, B, 1]`` as one ``[3, N, B]`` (fx, fy, torque)."""
    return torch.cat([split_xy_stacked(force.contiguous()), torque[..., 0].unsqueeze(0)])


def pair_forces(pair: PairTable, state: BodyState, params: StepParams) -> Tuple[Tensor, Tensor, Tensor, Tensor]:
    """Contact forces [P, B, 2] and torques [P, B, 1] on both members of each pair of one kernel.

    A vector-layout view of :func:`vmas_ros.simulator.contacts.pair_contact`, for
    tests and tools. Broad phase: see :class:`StepParams` (``broad_phase``).
    """
    x, y = state.pos[..., 0].contiguous(), state.pos[..., 1].contiguous()
    fax, fay, fbx, fby, t_a, t_b = contacts.pair_contact(pair, x, y, state.rot[..., 0].contiguous(), params)
    zero = torch.zeros_like(fax)
    t_a, t_b = (zero if t is None else t for t in (t_a, t_b))
    return (torch.stack([fax, fay], dim=-1), torch.stack([fbx, fby], dim=-1), t_a.unsqueeze(-1), t_b.unsqueeze(-1))


def clamp_norm(vec: Tensor, max_norm) -> Tensor:
    """Scale vectors longer than ``max_norm`` back onto it (``inf`` means no limit).

    Rounds like VMAS (``vec / norm * max``) so speed-limited agents stay in
    bit parity, and keeps gradients finite: the unused branch never divides by
    zero or multiplies by ``inf``.
    """
    norm = torch.linalg.vector_norm(vec, dim=-1, keepdim=True)
    over = norm > max_norm
    finite_max = torch.where(torch.isfinite(torch.as_tensor(max_norm, device=vec.device)), max_norm, 0.0)
    return torch.where(over, vec / torch.where(over, norm, 1.0) * finite_max, vec)


def step(
    state: BodyState,
    tables: WorldTables,
    params: StepParams,
    action_force: Tensor,
    action_torque: Tensor,
    fixed_rotation: Optional[Tensor],
) -> BodyState:
    """Advance all envs by one ``dt``. ``action_*`` are per entity ([N, B, 2] / [N, B, 1]).

    The vector-layout face of :func:`step_planar` (tools and tests);
    ``World.step`` calls :func:`step_planar` directly and keeps the planar state between steps.
    """
    actions = stack_actions(action_force, action_torque)
    return step_planar(PlanarState.from_vectors(state), tables, params, actions, fixed_rotation).to_vectors()


def step_planar(
    state: PlanarState, tables: WorldTables, params: StepParams, actions: Tensor, fixed_rotation: Optional[Tensor],
    actions_writable: bool = False,
) -> PlanarState:
    """Advance all envs by one ``dt``; ``actions`` is ``[3, N, B]`` (fx, fy, torque, see :func:`stack_actions`).

    Pair and joint forces are added with ``index_add`` straight into the
    ``[3, N, B]`` force, so no per-pair ``[P, B, 2]`` vector is ever
    assembled. ``fixed_rotation`` is the joints' ``[J, B, 1]`` target angles.
    ``actions_writable``: the caller hands ``actions`` over, so the last
    substep may add contact forces into it instead of into a copy.
    """
    c = step_constants(tables, params)
    q, v = state.q, state.v
    v0 = v
    fixed = None if fixed_rotation is None else fixed_rotation[..., 0]
    for substep in range(params.substeps):
        force = actions
        if tables.has_friction:
            force = force + _friction(v, c, c["sub_dt"])
        if tables.has_gravity:
            force = force + c["gravity"]
        if tables.joints is not None or tables.pairs:
            if force is actions and not (actions_writable and substep == params.substeps - 1):
                force = force.clone()  # written in place below
            x, y, rot = q[0], q[1], q[2]
        if tables.joints is not None:
            jt = tables.joints
            jfx, jfy, t_a, t_b = contacts.joint_forces(jt, x, y, rot, fixed, params)
            _add_pairs(force, jt, torch.stack([jfx, jfy, t_a]), torch.stack([-jfx, -jfy, t_b]))
        for pair in tables.pairs:
            if pair.kind == ("sphere", "sphere"):
                exact = tables.joints is not None
                on_a = contacts.sphere_pair_forces(pair, q[:2], params, exact=exact)
                if exact:
                    _add_pairs(force[:2], pair, on_a, -on_a)
                else:
                    _add_pairs_opposite(force[:2], pair, on_a)
                continue
            fax, fay, fbx, fby, t_a, t_b = contacts.pair_contact(pair, x, y, rot, params, exact=tables.joints is not None)
            if t_a is None and t_b is None:
                _add_pairs(force[:2], pair, torch.stack([fax, fay]), torch.stack([fbx, fby]))
            else:
                zero = torch.zeros_like(fax)
                t_a, t_b = (zero if t is None else t for t in (t_a, t_b))
                _add_pairs(force, pair, torch.stack([fax, fay, t_a]), torch.stack([fbx, fby, t_b]))

        span = c["free_span"]
        if span is not None and q.numel() > SMALL_BATCH_ELEMENTS:
            # held entities (landmarks) are one block at an end: integrate only the free block and
            # put the held rows back with one copy, instead of blending every row with 0/1 masks
            lo, hi = span
            # (compiled: the same cat, which the compiler fuses; out= into row slices would break its graph)
            if _differentiable(q, v, force) or torch.compiler.is_compiling():
                free_q, free_v = _integrate(q[:, lo:hi], v[:, lo:hi], force[:, lo:hi], c["free_block"], substep == 0)
                q = torch.cat([q[:, :lo], free_q] if lo else [free_q, q[:, hi:]], dim=1)
                v = torch.cat([v[:, :lo], free_v] if lo else [free_v, v[:, hi:]], dim=1)
                continue
            # the free block integrates straight into its rows of the new state (no block-sized temporaries)
            new_q, new_v = torch.empty_like(q), torch.empty_like(v)
            held = slice(0, lo) if lo else slice(hi, None)
            new_q[:, held], new_v[:, held] = q[:, held], v[:, held]
            _integrate(q[:, lo:hi], v[:, lo:hi], force[:, lo:hi], c["free_block"], substep == 0,
                       out=(new_q[:, lo:hi], new_v[:, lo:hi]))
            q, v = new_q, new_v
            continue
        new_q, new_v = _integrate(q, v, force, c, substep == 0)
        if c["all_free"]:
            q, v = new_q, new_v
        elif new_q.numel() <= SMALL_BATCH_ELEMENTS:
            free = c["free_bool"]
            q, v = torch.where(free, new_q, q), torch.where(free, new_v, v0)
        else:
            # copy the held (coordinate, entity) rows back: one pass, where 0/1 float masks took six
            held, shape = c["held_rows"], new_q.shape
            q = new_q.flatten(0, 1).index_copy(0, held, q.flatten(0, 1).index_select(0, held)).view(shape)
            v = new_v.flatten(0, 1).index_copy(0, held, v0.flatten(0, 1).index_select(0, held)).view(shape)
    return PlanarState(q, v)


def _differentiable(*tensors: Tensor) -> bool:
    """Whether autograd must see these (then no ``out=`` writes: they refuse tensors that need a gradient)."""
    return torch.is_grad_enabled() and any(t.requires_grad for t in tensors)


def _integrate(q: Tensor, v: Tensor, force: Tensor, c: dict, first_substep: bool,
               out: Optional[Tuple[Tensor, Tensor]] = None) -> Tuple[Tensor, Tensor]:
    """One semi-implicit Euler substep of the rows in ``q``/``v`` (``c``: their constants), limits applied.

    ``out``: ``(q, v)`` slots to write the result into (the caller checked that no gradient is kept).
    """
    # (v * keep) + force / mass * dt in VMAS's rounding (addition commutes exactly)
    if out is None:
        # in one fresh tensor: the in-place steps only touch the quotient, whose gradient needs
        # neither it nor its inputs
        new_v = (force / c["mass"]).mul_(c["sub_dt"]).add_(v * c["keep"] if first_substep else v)
    else:
        # no temporaries: the quotient goes where the positions will, the damped velocity where the
        # velocities will
        quotient = torch.div(force, c["mass"], out=out[0]).mul_(c["sub_dt"])
        new_v = (torch.mul(v, c["keep"], out=out[1]) if first_substep else out[1].copy_(v)).add_(quotient)
    if c["limits_speed"]:
        speed = contacts.norm(new_v[0], new_v[1])
        over = contacts.mask_gt(speed, c["max_speed"])
        # VMAS's rounding: v / |v| * max where over the limit
        limited = new_v[:2] / (speed + (1 - over)) * c["finite_max_speed"]
        new_v = torch.cat([contacts.select(over, limited, new_v[:2]), new_v[2:]])
    if c["limits_velocity"]:
        new_v = torch.clamp(new_v, -c["v_range"], c["v_range"])
    if out is None:
        new_q = (new_v * c["sub_dt"]).add_(q)
        if c["semidims"] is not None:
            new_q = torch.clamp(new_q, -c["semidims"], c["semidims"])
        return new_q, new_v
    if new_v is not out[1]:  # a limit made a new tensor
        out[1].copy_(new_v)
    new_q = torch.mul(out[1], c["sub_dt"], out=out[0]).add_(q)
    if c["semidims"] is not None:
        new_q.clamp_(-c["semidims"], c["semidims"])
    return out


def scatter_by_gemm(n_entities: int, n_pairs: int, batch: int) -> bool:
    """Whether per-pair forces are added onto entities by one batched GEMM with a dense incidence matrix.

    ``index_add_`` pays per index at a few envs (~4 us for 15 pairs at one
    env, where the GEMM takes ~1 us), runs on one thread, and under
    ``torch.compile`` lowers to a serial scatter of atomic adds (3.5 ms per
    substep for flocking at 10,000 envs, ~30x its eager time); a GEMM is one
    vectorised, multi-threaded call everywhere. With one thread and many envs
    ``index_add_`` is faster (1.6x at 10,000 envs), and with a few pairs over
    many envs the two run level (simple_spread's 3 pairs at 30,000 envs, 2
    threads), so there the BLAS kernel is not worth its ~1 MB of resident code.
    The GEMM sums in its own order, so kernels that promise VMAS's summation
    order use it only when compiled (see :func:`_add_pairs`).
    """
    if n_entities * n_pairs > GEMM_SCATTER_MAX_CELLS:
        return False
    return (torch.compiler.is_compiling() or batch < SCATTER_TRANSPOSE_BELOW
            or (n_pairs >= GEMM_SCATTER_MIN_PAIRS and torch.get_num_threads() > 1))


def _add_pairs(force: Tensor, table, on_a: Tensor, on_b: Tensor) -> None:
    """Add per-pair values ``[C, P, B]`` onto ``force`` ``[C, N, B]`` in place, in pair order (a0, b0, a1, b1, ...).

    The same summation order as VMAS, so kernels that compute their forces as
    VMAS does (joints, boxes, lines) stay bit-identical to it: stiff joints
    amplify a one-ulp difference within a few steps. Compiled steps promise
    float rounding only, and scatter with a GEMM (see :func:`scatter_by_gemm`).
    """
    n_entities, n_pairs = force.shape[1], on_a.shape[1]
    if torch.compiler.is_compiling() and n_entities * n_pairs <= GEMM_SCATTER_MAX_CELLS:
        first, second = table.incidence_ab(n_entities, force.dtype)
        force.baddbmm_(first.expand(force.shape[0], -1, -1), on_a)
        force.baddbmm_(second.expand(force.shape[0], -1, -1), on_b)
        return
    values = torch.stack([on_a, on_b], dim=2).flatten(1, 2)
    if torch.compiler.is_compiling():  # too many (entity, pair) cells for a dense matrix
        scatter_rows(force, table.index_ab, values)
    elif force.shape[-1] < SCATTER_TRANSPOSE_BELOW:
        # few envs: CPU index_add along dim 1 pays per index (~50 us per 1,000 pairs at one env);
        # along dim 0 of the transposed view it runs as one loop. Same order, same sums.
        force.transpose(0, 1).index_add_(0, table.index_ab, values.transpose(0, 1))
    else:
        force.index_add_(1, table.index_ab, values)


def _add_pairs_opposite(force: Tensor, table, on_a: Tensor) -> None:
    """Add ``on_a`` ``[C, P, B]`` onto the first members and ``-on_a`` onto the second, in place.

    No ``[C, 2P, B]`` stack or negated copy: one GEMM (see
    :func:`scatter_by_gemm`) or two scatters, in an order VMAS does not use,
    so only for kernels that do not promise bit parity (see :func:`_add_pairs`).
    """
    n_entities, n_pairs, batch = force.shape[1], on_a.shape[1], force.shape[2]
    if scatter_by_gemm(n_entities, n_pairs, batch):
        signed = table.incidence_opposite(n_entities, force.dtype)
        force.baddbmm_(signed.expand(force.shape[0], -1, -1), on_a)
    elif torch.compiler.is_compiling():  # too many (entity, pair) cells for a dense matrix
        scatter_rows(force, table.index_a, on_a)
        scatter_rows(force, table.index_b, on_a.neg())
    elif batch < SCATTER_TRANSPOSE_BELOW:
        target, values = force.transpose(0, 1), on_a.transpose(0, 1)
        target.index_add_(0, table.index_a, values)
        target.index_add_(0, table.index_b, values.neg())  # alpha=-1 takes a slow path here (~9x at 1,000 agents)
    else:
        force.index_add_(1, table.index_a, on_a)
        force.index_add_(1, table.index_b, on_a, alpha=-1)


@torch.library.custom_op("vmas_ros::scatter_rows", mutates_args=("target",))
def scatter_rows(target: Tensor, index: Tensor, values: Tensor) -> None:
    """``target.index_add_(1, index, values)`` as an op the compiler leaves to ATen.

    For compiled steps with more pairs than a dense incidence matrix can hold:
    inductor lowers ``index_add_`` to a serial loop of atomic adds (100
    colliding spheres in 32 envs: 5x slower than eager), while the eager
    kernel is one vectorised pass (transposed at a few envs, see :func:`_add_pairs`).
    """
    if target.shape[-1] < SCATTER_TRANSPOSE_BELOW:
        target.transpose(0, 1).index_add_(0, index, values.transpose(0, 1))
    else:
        target.index_add_(1, index, values)


@scatter_rows.register_fake
def _(target: Tensor, index: Tensor, values: Tensor) -> None:
    return None


def _friction(v: Tensor, c: dict, sub_dt: float) -> Tensor:
    """Coulomb-like friction ``[3, N, B]`` opposing the velocity, never reversing it within one substep."""
    speed = contacts.norm(v[0], v[1])
    speed = torch.stack([speed, speed, v[2].abs()])
    moving = contacts.mask_ne(speed, 0.0)
    inv = moving / (speed + (1 - moving))  # 1 / speed where moving, 0 elsewhere (exact)
    return -(v * inv) * torch.minimum(c["friction_cap"], v.abs() * c["mass_over_dt"])


def step_constants(tables: WorldTables, params: StepParams) -> dict:
    """Per-coordinate constants of :func:`step_planar` as ``[3, N, 1]`` columns, computed once per tables.

    Rows are (x, y, angle): mass for the first two, moment of inertia for the
    angle. Held entities are kept still with a bool mask for small batches
    (one ``torch.where`` call) and, for large ones, by copying their rows
    back (``held_rows``) or integrating only the free block (``free_span``):
    ``torch.where`` is much slower per element than a copy on the CPU.
    """
    sub_dt = params.dt / params.substeps
    key = (sub_dt, params.x_semidim, params.y_semidim)
    cached = getattr(tables, "_planar_cache", None)
    if cached is not None and cached["key"] == key:
        return cached
    col = lambda t: t[..., 0]  # noqa: E731  [N, 1, 1] -> [N, 1]
    per_coord = lambda lin, ang: torch.stack([lin, lin, ang])  # noqa: E731
    mass, inertia = col(tables.mass), col(tables.inertia)
    movable, rotatable = col(tables.movable), col(tables.rotatable)
    free_bool = per_coord(movable, rotatable)
    max_speed = col(tables.max_speed)
    v_range = col(tables.v_range)
    inf = float("inf")
    no_limit = torch.full_like(v_range, inf)
    bounds = [inf if b is None else b for b in (params.x_semidim, params.y_semidim)] + [inf]
    cached = {
        "key": key, "sub_dt": sub_dt,
        "keep": col(1 - tables.drag),
        "mass": per_coord(mass, inertia),
        "friction_cap": per_coord(col(tables.linear_friction) * mass, col(tables.angular_friction) * inertia),
        "mass_over_dt": per_coord(mass, inertia) / sub_dt,
        "gravity": torch.cat([split_xy_stacked(tables.gravity_force.contiguous()),
                              torch.zeros_like(tables.gravity_force[..., 0]).unsqueeze(0)]),
        "max_speed": max_speed, "finite_max_speed": torch.where(torch.isfinite(max_speed), max_speed, 0.0),
        "v_range": torch.stack([v_range, v_range, no_limit]),
        "free_bool": free_bool, "all_free": bool(free_bool.all()),
        "semidims": (None if params.x_semidim is None and params.y_semidim is None
                     else torch.tensor(bounds, dtype=mass.dtype, device=mass.device).reshape(3, 1, 1)),
        "limits_speed": tables.limits_speed, "limits_velocity": tables.limits_velocity,
    }
    cached["free_span"] = span = _free_span(free_bool)
    #: held rows of the flattened [3 * N, B] state (coordinate-major), for the index_copy path
    cached["held_rows"] = (~free_bool[..., 0]).flatten().nonzero()[:, 0]
    cached["free_block"] = None if span is None else _block_constants(cached, *span)
    # the tables' lazily built helpers too: filling a cache inside a compiled step breaks its graph
    # (six graphs instead of one at one env, 1.5x slower than eager)
    n_entities = tables.n_entities
    contacts._zero(mass)
    for table in tables.pairs + ([tables.joints] if tables.joints is not None else []):
        if n_entities * len(table.index_a) <= GEMM_SCATTER_MAX_CELLS:  # never used above (1,000 spheres: 6 GB)
            table.incidence_ab(n_entities, mass.dtype)
            table.incidence_opposite(n_entities, mass.dtype)
        table.index_ab
        if table in tables.pairs and table.kind == ("sphere", "sphere"):
            table.contact_distance
    tables._planar_cache = cached
    return cached


def _free_span(free_bool: Tensor) -> Optional[Tuple[int, int]]:
    """``(lo, hi)`` when entities ``lo:hi`` are free in all three coordinates and every other
    entity is held in all three, with the held ones one block at an end; else None (also when all are free)."""
    per_entity = free_bool[..., 0]  # [3, N]
    whole = per_entity.all(dim=0)
    if not bool((per_entity == whole).all()) or bool(whole.all()) or not bool(whole.any()):
        return None
    rows = whole.nonzero()[:, 0].tolist()
    lo, hi = rows[0], rows[-1] + 1
    if hi - lo != len(rows) or (lo != 0 and hi != whole.numel()):
        return None
    return lo, hi


def _block_constants(c: dict, lo: int, hi: int) -> dict:
    """The constants of :func:`_integrate` for entities ``lo:hi`` only."""
    block = dict(c)
    for name in ("keep", "max_speed", "finite_max_speed"):  # [N, 1]
        block[name] = c[name][lo:hi]
    for name in ("mass", "v_range"):  # [3, N, 1]
        block[name] = c[name][:, lo:hi]
    return block
