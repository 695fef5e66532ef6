"""Small pieces adapters are built from: odometry to world state, a LaserScan to training rays, goals from poses.

Each reader returns ``(value, None)`` or ``(None, reason)``: a message that
cannot be used (a NaN pose, a scan whose angles miss the training rays) is a
reason string the adapter puts in its ``problems``, never an exception.
Messages are read by their fields (duck typing): real rclpy messages or any
object with the same attributes.

Frames (REP 105): nav_msgs/Odometry's pose is in ``header.frame_id`` (the
world frame the policy was trained in), its twist in ``child_frame_id`` (the
robot's body). A LaserScan is in the robot's body frame, ray ``i`` at
``angle_min + i * angle_increment`` from its x axis.
"""
from __future__ import annotations

import math
import numbers
from typing import Optional, Sequence, Tuple

import numpy as np

__all__ = [
    "ANGLE_TOLERANCE", "ENCODINGS", "FRAMES", "ScanResampler", "closing_margins", "inflate", "lead_problem",
    "margin_problem", "odometry_state", "pose_array_positions", "pose_position", "read_odometry",
]

TWO_PI = 2 * math.pi
#: slack on angle comparisons [rad]: a driver's float32 angles are off by far less, a real gap by far more
ANGLE_TOLERANCE = 1e-4
#: how the training lidar's readings enter the observation (see ScanResampler)
ENCODINGS = ("proximity", "distance")
#: where the training lidar's rays point (see ScanResampler)
FRAMES = ("body", "world")


def _not_finite(what: str, values: Sequence[float]) -> Optional[str]:
    """``"NaN <what>"`` or ``"infinite <what>"`` when one of ``values`` is not finite, else None."""
    if any(math.isnan(v) for v in values):
        return f"NaN {what}"
    if any(math.isinf(v) for v in values):
        return f"infinite {what}"
    return None


# ------------------------------------------------------------------ odometry
def read_odometry(msg) -> Tuple[Optional[np.ndarray], Optional[str]]:
    """``[x, y, yaw, vx, vy, yaw_rate]`` of nav_msgs/Odometry with the velocity in the world frame, or a reason.

    The twist is in the body frame (REP 105), so its linear part is turned by
    the pose's yaw. Refused: a non-finite position, orientation or twist
    (``"NaN pose"``, ``"infinite twist"``, ...) and an orientation quaternion
    of zero length (no rotation at all).
    """
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    v, w = msg.twist.twist.linear, msg.twist.twist.angular
    pose = (float(p.x), float(p.y), float(q.x), float(q.y), float(q.z), float(q.w))
    twist = (float(v.x), float(v.y), float(w.z))
    problem = _not_finite("pose", pose) or _not_finite("twist", twist)
    if problem:
        return None, problem
    x, y, qx, qy, qz, qw = pose
    if qx * qx + qy * qy + qz * qz + qw * qw < 1e-12:
        return None, "zero orientation quaternion"
    # this form of the yaw holds for a quaternion of any length (some drivers do not normalise theirs)
    yaw = math.atan2(2.0 * (qw * qz + qx * qy), qw * qw + qx * qx - qy * qy - qz * qz)
    c, s = math.cos(yaw), math.sin(yaw)
    vx, vy, wz = twist
    return np.array([x, y, yaw, c * vx - s * vy, s * vx + c * vy, wz]), None


def odometry_state(msg) -> Optional[np.ndarray]:
    """``[x, y, vx, vy, yaw]`` (world-frame velocity) of nav_msgs/Odometry, or None when
    :func:`read_odometry` refuses it (which gives the reason)."""
    state, _ = read_odometry(msg)
    return None if state is None else state[[0, 1, 3, 4, 2]]


# --------------------------------------------------------------------- goals
def pose_position(msg) -> Tuple[Optional[np.ndarray], Optional[str]]:
    """``[x, y]`` of a geometry_msgs/PoseStamped (or a bare Pose), or a reason (``"NaN position"``, ...)."""
    point = getattr(msg, "pose", msg).position
    xy = (float(point.x), float(point.y))
    problem = _not_finite("position", xy)
    return (None, problem) if problem else (np.array(xy), None)


def pose_array_positions(msg, expected: Optional[int] = None) -> Tuple[Optional[np.ndarray], Optional[str]]:
    """``[n, 2]`` positions of a geometry_msgs/PoseArray's poses, or a reason: a non-finite position, or a
    count other than ``expected`` (when given)."""
    poses = msg.poses
    if expected is not None and len(poses) != expected:
        return None, f"{len(poses)} poses, expected {expected}"
    xy = np.array([[float(p.position.x), float(p.position.y)] for p in poses]).reshape(-1, 2)
    problem = _not_finite("position", xy.ravel().tolist())
    return (None, problem) if problem else (xy, None)


# ---------------------------------------------------------------------- scans
def margin_problem(margin, max_range: Optional[float] = None, name: str = "margin") -> Optional[str]:
    """Why ``margin`` is no safety margin for a lidar of range ``max_range`` (None: any range), or None.

    A margin is a finite number of metres, at least 0 and below ``max_range``
    (one as long as the range would show every neighbour in view as touching:
    a unit mistake, centimetres for metres).
    """
    if isinstance(margin, bool) or not isinstance(margin, numbers.Real) or not math.isfinite(margin):
        return f"{name} must be a finite number of metres, got {margin!r}"
    if max_range is None:
        return None if margin >= 0 else f"{name} must be >= 0 m, got {margin!r}"
    if not 0 <= margin < max_range:
        return f"{name} must be >= 0 m and below the training lidar's range {max_range:g} m, got {margin!r}"
    return None


def lead_problem(lead, name: str = "lead") -> Optional[str]:
    """Why ``lead`` is no look-ahead time for a scan's margin, or None: it must be a finite number of seconds >= 0."""
    if isinstance(lead, bool) or not isinstance(lead, numbers.Real) or not math.isfinite(lead):
        return f"{name} must be a finite number of seconds, got {lead!r}"
    return None if lead >= 0 else f"{name} must be >= 0 s, got {lead!r}"


def inflate(distances: np.ndarray, margin) -> np.ndarray:
    """``distances`` (m) ``margin`` closer, none below 0; a margin of 0 gives them back unchanged.

    ``margin``: one margin for every distance, or one per distance (the same
    shape). A costmap's inflation radius, for a policy's lidar: everything
    seen reads that much nearer, so the policy keeps that much more room.
    """
    return np.maximum(distances - margin, 0.0) if np.any(margin) else distances


def closing_margins(ray_angles: np.ndarray, velocity, lead: float) -> np.ndarray:
    """Per ray, the distance the robot closes along it within ``lead`` seconds: ``lead x max(0, v . u)``.

    ``ray_angles`` [R]: the rays' directions in the world frame (rad);
    ``velocity`` (2,): the robot's world-frame velocity (m/s). A ray the robot
    moves away from, or across, gets 0. Returns [R] metres.
    """
    vx, vy = float(velocity[0]), float(velocity[1])
    return lead * np.maximum(vx * np.cos(ray_angles) + vy * np.sin(ray_angles), 0.0)


def _angle_gap(a, b) -> np.ndarray:
    """|a - b| on the circle, in [0, pi]."""
    return np.abs(np.remainder(np.asarray(a) - b + math.pi, TWO_PI) - math.pi)


class ScanResampler:
    """A sensor_msgs/LaserScan turned into the readings of the lidar a policy was trained with.

    The training lidar is the engine's ``Lidar``: ``n_rays`` rays from
    ``angle_start`` to ``angle_end`` (a full circle puts ray ``k`` at
    ``angle_start + 2 pi k / n_rays``), range ``max_range``. ``frame``:
    ``"body"`` when the trained agents turn and their rays turn with them
    (diff-drive navigation; the scan's own frame, rotated by ``mount_yaw``,
    the scanner's yaw on the robot); ``"world"`` when the trained agents
    never turn (holonomic navigation), so the rays keep fixed directions in
    the world and the scan is read at the training angles minus the robot's
    heading. ``encoding``: ``"proximity"`` gives ``max_range - distance``, 0
    for no return (navigation's observation); ``"distance"`` the distance,
    ``max_range`` for no return (the raw ``Lidar.measure()``). ``margin``
    (m, default 0): a safety margin, every return read that much closer
    (:func:`inflate`). ``lead`` (s, default 0): a margin that grows with
    speed, as a velocity obstacle's time horizon: each ray's return also
    reads ``lead`` times the robot's speed towards that ray closer
    (:func:`closing_margins`), which covers what the robot will travel
    before its command takes effect.

    Rules, in :meth:`resample`:

    * Each training ray reads the scan ray nearest to it in angle. Not the
      minimum over a sector: the engine casts one thin ray per training ray,
      so a neighbour beside that ray is not seen in training either.
    * No return: +inf, readings above the scan's ``range_max`` or the training
      ``max_range``, readings below ``range_min`` (-inf included). A
      neighbour closer than the scanner's ``range_min`` therefore reads as
      free space: mind it on robots whose ``range_min`` exceeds the gap the
      policy must see.
    * With a ``margin``, every return the scanner vouches for (within its
      ``range_min`` and ``range_max``) is read ``margin`` closer, clamped at
      0, before it is compared with ``max_range``: a neighbour up to
      ``max_range + margin`` away comes into view at the edge of the
      training range, as it would if it were ``margin`` larger. No return
      stays no return. With a ``lead`` and the robot's velocity, each
      ray's margin grows by ``lead x`` the speed towards that ray.
    * NaN is a missing reading: the ray reads the nearest non-NaN scan ray
      within half the training rays' spacing instead; with none there, the
      observation cannot be built.
    * A scan the training rays cannot be read from is refused with a reason
      that names the problem (:meth:`geometry_problem`).
    """

    def __init__(self, n_rays: int, max_range: float, angle_start: float = 0.0, angle_end: float = TWO_PI,
                 frame: str = "body", encoding: str = "proximity", mount_yaw: float = 0.0,
                 margin: float = 0.0, lead: float = 0.0) -> None:
        if isinstance(n_rays, bool) or not isinstance(n_rays, int) or n_rays < 1:
            raise ValueError(f"n_rays must be an int >= 1, got {n_rays!r}")
        finite = {"max_range": max_range, "angle_start": angle_start, "angle_end": angle_end, "mount_yaw": mount_yaw}
        for name, value in finite.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
        if not max_range > 0:
            raise ValueError(f"max_range must be > 0, got {max_range!r}")
        if frame not in FRAMES:
            raise ValueError(f"frame must be one of {', '.join(FRAMES)}, got {frame!r}")
        if encoding not in ENCODINGS:
            raise ValueError(f"encoding must be one of {', '.join(ENCODINGS)}, got {encoding!r}")
        problem = margin_problem(margin, float(max_range)) or lead_problem(lead)
        if problem:
            raise ValueError(problem)
        self.n_rays, self.max_range, self.margin, self.lead = n_rays, float(max_range), float(margin), float(lead)
        self.frame, self.encoding, self.mount_yaw = frame, encoding, float(mount_yaw)
        # the engine's rule for a full circle, so the rays sit where its Lidar puts them
        self.full_circle = (angle_start - angle_end) % TWO_PI < 1e-5
        if self.full_circle:
            self.angles = angle_start + (angle_end - angle_start) * np.arange(n_rays) / n_rays
            self.spacing: Optional[float] = abs(angle_end - angle_start) / n_rays
        else:
            self.angles = np.linspace(angle_start, angle_end, n_rays)
            self.spacing = abs(angle_end - angle_start) / (n_rays - 1) if n_rays > 1 else None
        self._checked: Tuple[Optional[tuple], Optional[str]] = (None, None)  # the last geometry and its verdict

    def geometry_problem(self, scan, n_ranges: Optional[int] = None) -> Optional[str]:
        """Why the training rays cannot be read from ``scan``'s geometry (any robot's), or None.

        Refused: a non-finite or non-positive ``angle_increment``; angles that
        are not finite; ``angle_max`` not where ``angle_min`` plus the ranges'
        count of increments puts the last ray (one increment of slack, for
        drivers that count the seam twice); rays wider apart than the
        training rays (several training rays would read one scan ray); a
        training lidar all round the circle and a scan that leaves a gap
        wider than its increment; ``range_max`` below the training
        ``max_range`` (a reading beyond it would be indistinguishable from
        free space); ``range_min`` not below the training ``max_range``.
        """
        n = len(scan.ranges) if n_ranges is None else n_ranges
        key = (float(scan.angle_min), float(scan.angle_max), float(scan.angle_increment), n,
               float(scan.range_min), float(scan.range_max))
        if self._checked[0] == key:
            return self._checked[1]
        problem = self._geometry_problem(*key)
        self._checked = (key, problem)
        return problem

    def _geometry_problem(self, amin: float, amax: float, inc: float, n: int, rmin: float,
                          rmax: float) -> Optional[str]:
        if n < 1:
            return "scan has no ranges"
        if not math.isfinite(inc) or inc <= 0:
            return f"scan angle_increment {inc:g} is not a finite angle > 0"
        if not (math.isfinite(amin) and math.isfinite(amax)):
            return f"scan angles [{amin:g}, {amax:g}] are not finite"
        last = amin + (n - 1) * inc
        if abs(last - amax) > inc + ANGLE_TOLERANCE:
            return (f"scan has {n} ranges, but angle_min {amin:.4f} + {n - 1} x angle_increment {inc:.5f} = "
                    f"{last:.4f} rad is not angle_max {amax:.4f} rad")
        if self.spacing is not None and inc > self.spacing + ANGLE_TOLERANCE:
            return (f"scan rays are {inc:.4f} rad apart, coarser than the training lidar's {self.spacing:.4f} rad: "
                    f"several training rays would read the same scan ray")
        if self.full_circle and n * inc < TWO_PI - 2 * ANGLE_TOLERANCE:
            return f"scan covers [{amin:.2f}, {last:.2f}] rad, the training lidar needs rays all round the circle"
        if math.isnan(rmax) or rmax < self.max_range:
            return (f"scan range_max {rmax:g} m is below the training lidar's max_range {self.max_range:g} m: "
                    f"farther readings would look like free space")
        if math.isnan(rmin) or rmin >= self.max_range:
            return f"scan range_min {rmin:g} m is not below the training lidar's max_range {self.max_range:g} m"
        return None

    def _targets(self, yaw: float) -> np.ndarray:
        """The training rays' angles in the scan's frame [n_rays]."""
        turn = self.mount_yaw + (yaw if self.frame == "world" else 0.0)
        return self.angles - turn

    def world_angles(self, yaw: float) -> np.ndarray:
        """The training rays' directions in the world frame [n_rays], for a robot heading ``yaw``."""
        return self.angles + (yaw if self.frame == "body" else 0.0)

    def resample(self, scan, yaw: float = 0.0, velocity=None) -> Tuple[Optional[np.ndarray], Optional[str]]:
        """The training readings ``[n_rays]`` (float64, in ``encoding``) from ``scan``, or None and the reason.

        ``yaw``: the robot's heading in the world (from its odometry), used
        with ``frame="world"``, and with a ``lead``. ``velocity``: its
        world-frame velocity (vx, vy), m/s, for the ``lead``'s margins; None
        reads as standing still.
        """
        ranges = np.asarray(scan.ranges, dtype=np.float64)
        problem = self.geometry_problem(scan, ranges.size)
        if problem:
            return None, problem
        amin, inc = float(scan.angle_min), float(scan.angle_increment)
        targets = self._targets(yaw)
        index, gap = self._nearest(targets, amin, inc, ranges.size)
        outside = gap > inc / 2 + ANGLE_TOLERANCE
        if outside.any():
            last = amin + (ranges.size - 1) * inc
            return None, (f"scan covers [{amin:.2f}, {last:.2f}] rad, the training rays at "
                          f"{np.round(targets[outside], 2).tolist()} rad of the scan's frame fall outside it")
        readings = ranges[index]
        missing = np.isnan(readings)
        if missing.any():
            readings = self._fill(readings, missing, ranges, targets, amin, inc)
            still = np.flatnonzero(np.isnan(readings))
            if still.size:
                window = (self.spacing or 0.0) / 2
                return None, (f"NaN readings with no valid scan ray within {window:.3f} rad for training rays "
                              f"{still.tolist()}")
        seen = (readings >= float(scan.range_min)) & (readings <= float(scan.range_max))
        margin = self.margin
        if self.lead and velocity is not None:
            margin = margin + closing_margins(self.world_angles(yaw), velocity, self.lead)
        nearer = inflate(readings, margin)
        distances = np.where(seen & (nearer <= self.max_range), nearer, self.max_range)
        return (self.max_range - distances if self.encoding == "proximity" else distances), None

    @staticmethod
    def _nearest(targets: np.ndarray, amin: float, inc: float, n: int) -> Tuple[np.ndarray, np.ndarray]:
        """Index of the scan ray nearest each target angle on the circle, and the angle between them."""
        offset = np.remainder(targets - amin, TWO_PI)  # [R] in [0, 2 pi): the arc from the first ray
        # the nearest ray to the target or to it one turn on (scans of more than a turn), or an end ray
        candidates = np.stack([np.rint(offset / inc), np.rint((offset + TWO_PI) / inc),
                               np.zeros_like(offset), np.full_like(offset, n - 1)], axis=1)
        candidates = candidates.clip(0, n - 1).astype(np.int64)  # [R, 4]
        gaps = _angle_gap(amin + inc * candidates, targets[:, None])
        pick = gaps.argmin(axis=1)
        rows = np.arange(targets.size)
        return candidates[rows, pick], gaps[rows, pick]

    def _fill(self, readings, missing, ranges, targets, amin: float, inc: float) -> np.ndarray:
        """``readings`` with each missing one replaced by the nearest non-NaN scan ray within half the
        training spacing (NaN where there is none)."""
        window = (self.spacing or 0.0) / 2 + ANGLE_TOLERANCE
        gaps = _angle_gap(amin + inc * np.arange(ranges.size), targets[missing, None])  # [missing, S]
        gaps[:, np.isnan(ranges)] = np.inf
        nearest = gaps.argmin(axis=1)
        found = gaps[np.arange(nearest.size), nearest] <= window
        filled = readings.copy()
        filled[missing] = np.where(found, ranges[nearest], np.nan)
        return filled
