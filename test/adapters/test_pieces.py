"""The adapter pieces one by one: odometry, goals, and a LaserScan resampled to a training lidar's rays."""
from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from geometry_msgs.msg import Pose, PoseArray, PoseStamped
from nav_msgs.msg import Odometry

from test.adapters.robot_messages import scan_message
from vmas_ros.adapters.pieces import (
    ScanResampler, closing_margins, inflate, lead_problem, margin_problem, odometry_state, pose_array_positions, pose_position, read_odometry,
)
from vmas_ros.ros import convert
from vmas_ros.simulator import env_snapshot

DEGREE = 2 * math.pi / 360


def full_scan(ranges=None, n: int = 360, angle_min: float = -math.pi, **kwargs):
    """An n-ray scan all round from ``angle_min``; every ray reads 3.0 m unless ``ranges`` is given."""
    values = np.full(n, 3.0) if ranges is None else np.asarray(ranges, dtype=np.float64)
    return scan_message(angle_min, 2 * math.pi / n, values, **kwargs)


def training_lidar(**kwargs) -> ScanResampler:
    """navigation's default lidar: 12 rays all round, 0.35 m."""
    return ScanResampler(12, 0.35, **kwargs)


# ------------------------------------------------------------------- odometry
def test_odometry_turns_the_body_twist_into_the_world_frame():
    odom = Odometry()
    convert.fill_odometry(odom, 1.0, 2.0, math.pi / 2, 0.3, -0.1, 0.4)  # world velocity (0.3, -0.1), facing +y
    assert odom.twist.twist.linear.x == pytest.approx(-0.1) and odom.twist.twist.linear.y == pytest.approx(-0.3)
    state, problem = read_odometry(odom)
    assert problem is None
    np.testing.assert_allclose(state, [1.0, 2.0, math.pi / 2, 0.3, -0.1, 0.4], atol=1e-12)
    np.testing.assert_allclose(odometry_state(odom), [1.0, 2.0, 0.3, -0.1, math.pi / 2], atol=1e-12)


@pytest.mark.parametrize("field, value, problem", [
    ("pose.pose.position.x", math.nan, "NaN pose"), ("pose.pose.orientation.z", math.inf, "infinite pose"),
    ("twist.twist.linear.y", math.nan, "NaN twist"), ("twist.twist.angular.z", -math.inf, "infinite twist"),
    ("pose.pose.orientation.w", 0.0, "zero orientation quaternion"),
])
def test_odometry_with_unusable_values_is_refused(field, value, problem):
    odom = Odometry()  # orientation (0, 0, 0, 1): facing +x
    *path, name = field.split(".")
    target = odom
    for part in path:
        target = getattr(target, part)
    setattr(target, name, value)
    assert read_odometry(odom) == (None, problem)
    assert odometry_state(odom) is None


def test_odometry_yaw_ignores_the_quaternion_length():
    odom = Odometry()
    q = env_snapshot.yaw_to_quaternion(-2.5)
    odom.pose.pose.orientation.x, odom.pose.pose.orientation.y = q[0] * 3, q[1] * 3
    odom.pose.pose.orientation.z, odom.pose.pose.orientation.w = q[2] * 3, q[3] * 3
    assert read_odometry(odom)[0][2] == pytest.approx(-2.5)


# ---------------------------------------------------------------------- goals
def test_goal_positions_from_poses():
    stamped = PoseStamped()
    convert.set_pose(stamped.pose, 1.5, -0.5, 0.3)
    np.testing.assert_array_equal(pose_position(stamped)[0], [1.5, -0.5])
    np.testing.assert_array_equal(pose_position(stamped.pose)[0], [1.5, -0.5])  # a bare Pose too
    stamped.pose.position.y = math.nan
    assert pose_position(stamped) == (None, "NaN position")

    array = PoseArray()
    for x, y in ((0.0, 1.0), (2.0, 3.0)):
        array.poses.append(Pose())
        convert.set_pose(array.poses[-1], x, y, 0.0)
    positions, problem = pose_array_positions(array)
    assert problem is None and positions.shape == (2, 2)
    np.testing.assert_array_equal(positions, [[0.0, 1.0], [2.0, 3.0]])
    assert pose_array_positions(array, expected=3) == (None, "2 poses, expected 3")
    array.poses.append(Pose())
    array.poses[-1].position.x = math.inf
    assert pose_array_positions(array) == (None, "infinite position")


# ---------------------------------------------------------------------- scans
def test_training_rays_read_the_nearest_scan_ray():
    ranges = np.full(360, np.inf)
    ranges[180] = 0.1  # straight ahead (angle 0): training ray 0
    ranges[180 + 90] = 0.2  # 90 degrees: training ray 3
    ranges[180 + 14] = 0.05  # 14 degrees: nearest to ray 0, not to any training ray
    rays, problem = training_lidar().resample(full_scan(ranges))
    assert problem is None
    expected = np.zeros(12)
    expected[0], expected[3] = 0.35 - 0.1, 0.35 - 0.2
    np.testing.assert_allclose(rays, expected, atol=1e-7)  # the hit at 14 degrees is between two training rays
    distances, _ = training_lidar(encoding="distance").resample(full_scan(ranges))
    np.testing.assert_allclose(distances, 0.35 - expected, atol=1e-7)


def test_no_return_readings():
    ranges = np.full(360, np.inf)
    ranges[180 + 0] = 0.5  # beyond the training range
    ranges[180 + 30] = -np.inf  # too close to measure
    ranges[180 + 60] = 0.01  # below range_min
    ranges[180 + 90] = 3.2  # above the scan's range_max
    ranges[180 + 120] = 0.35  # exactly at the training range: the engine's own no-hit value
    ranges[180 + 150] = 0.02  # a real hit, just above range_min
    rays, problem = training_lidar().resample(full_scan(ranges, range_min=0.015, range_max=3.0))
    assert problem is None
    expected = np.zeros(12)
    expected[5] = 0.35 - 0.02
    np.testing.assert_allclose(rays, expected, atol=1e-7)


def test_world_fixed_rays_are_read_at_the_heading():
    """Holonomic training: ray 0 points along the world's +x. A robot facing +y sees +x on its right (-90
    degrees of its frame)."""
    ranges = np.full(360, np.inf)
    ranges[180 - 90] = 0.1
    world = training_lidar(frame="world")
    rays, _ = world.resample(full_scan(ranges), yaw=math.pi / 2)
    assert rays[0] == pytest.approx(0.25) and np.count_nonzero(rays) == 1
    body, _ = training_lidar().resample(full_scan(ranges), yaw=math.pi / 2)  # body rays ignore the heading
    assert body[9] == pytest.approx(0.25) and np.count_nonzero(body) == 1
    mounted, _ = training_lidar(mount_yaw=math.pi / 2).resample(full_scan(ranges))  # the scanner faces left
    assert mounted[0] == pytest.approx(0.25) and np.count_nonzero(mounted) == 1


def test_scans_of_other_conventions_and_partial_training_lidars():
    # angle_min 0 up to 359 degrees, the seam counted twice (-pi..pi with 361 rays): both read the same
    ranges = np.full(360, np.inf)
    ranges[90] = 0.2
    from_zero, _ = training_lidar().resample(scan_message(0.0, DEGREE, ranges))
    seam = np.concatenate([np.roll(ranges, 180), [np.inf]])
    twice, problem = training_lidar().resample(scan_message(-math.pi, DEGREE, seam))
    assert problem is None and from_zero[3] == pytest.approx(0.15)
    np.testing.assert_array_equal(from_zero, twice)
    # a forward-looking training lidar is fine with a forward-looking scan
    front = ScanResampler(5, 1.0, angle_start=-math.pi / 4, angle_end=math.pi / 4)
    assert not front.full_circle and front.spacing == pytest.approx(math.pi / 8)
    partial = scan_message(-math.pi / 2, DEGREE, np.full(181, 0.5))
    rays, problem = front.resample(partial)
    assert problem is None
    np.testing.assert_allclose(rays, 0.5)
    narrow = scan_message(-0.5, DEGREE, np.full(58, 0.5))  # -0.5 to 0.49 rad: misses the rays at +-pi/4
    assert front.resample(narrow)[0] is None
    assert "training rays at [-0.79, 0.79] rad of the scan's frame fall outside it" in front.resample(narrow)[1]


def test_nan_readings_take_a_near_neighbour_or_spoil_the_rays():
    ranges = np.full(360, np.inf)
    ranges[180 + 29] = 0.2
    ranges[180 + 30] = np.nan  # training ray 1 reads its nearest non-NaN neighbour
    rays, problem = training_lidar().resample(full_scan(ranges))
    assert problem is None and rays[1] == pytest.approx(0.15)
    ranges[180 + 16: 180 + 43] = np.nan  # a NaN sector from 16 to 42 degrees round training ray 1 (30)
    ranges[180 + 43] = 0.3  # 13 degrees from it: nearer than the free ray at 15, within half the spacing
    rays, problem = training_lidar().resample(full_scan(ranges))
    assert problem is None and rays[1] == pytest.approx(0.05)
    ranges[180 + 10: 180 + 50] = np.nan  # from 10 to 49 degrees: nothing within 15 of ray 1
    rays, problem = training_lidar().resample(full_scan(ranges))
    assert rays is None
    assert problem == "NaN readings with no valid scan ray within 0.262 rad for training rays [1]"


def margin_scan():
    """Hits and misses on the twelve training rays (ray k at 30 k degrees), range_min 0.015, range_max 3.0."""
    ranges = np.full(360, np.inf)  # ray 11 reads +inf: nothing in view
    for k, reading in enumerate([0.10, 0.03, 0.37, 0.45, -np.inf, 0.01, 3.2, 0.35, 0.3499, 0.2, 0.0151]):
        ranges[(180 + 30 * k) % 360] = reading
    return full_scan(ranges, range_min=0.015, range_max=3.0)


#: proximities (0.35 - distance) of margin_scan's rays without a margin (LaserScan ranges are float32: compare to 1e-6)
PLAIN = [0.25, 0.32, 0, 0, 0, 0, 0, 0, 0.0001, 0.15, 0.3349, 0]


def test_a_margin_reads_every_return_closer_and_leaves_no_return_alone():
    plain, problem = training_lidar().resample(margin_scan())
    assert problem is None
    np.testing.assert_allclose(plain, PLAIN, atol=1e-6)
    same, _ = training_lidar(margin=0.0).resample(margin_scan())
    np.testing.assert_array_equal(same, plain)  # margin 0: bit for bit the reading without one
    rays, problem = training_lidar(margin=0.05).resample(margin_scan())
    assert problem is None
    # hits 0.05 m closer: 0.10 -> 0.05; 0.03 -> 0 (clamped: contact); 0.37, beyond the training range, comes into
    # view at 0.32; 0.45 stays out of view; -inf, below range_min, above range_max and +inf stay no return;
    # 0.35 and 0.3499, at the range's edge, now read 0.30 and 0.2999
    expected = [0.30, 0.35, 0.03, 0, 0, 0, 0, 0.05, 0.0501, 0.20, 0.35, 0]
    np.testing.assert_allclose(rays, expected, atol=1e-6)
    distances, _ = training_lidar(margin=0.05, encoding="distance").resample(margin_scan())
    np.testing.assert_allclose(distances, 0.35 - np.asarray(expected), atol=1e-6)
    assert (rays >= np.asarray(PLAIN)).all() and rays.max() == pytest.approx(0.35)  # never farther, never past 0


def test_inflate_moves_distances_closer_down_to_zero():
    np.testing.assert_allclose(inflate(np.array([0.3, 0.05, 0.0, np.inf]), 0.08), [0.22, 0.0, 0.0, np.inf])
    values = np.array([0.3, -1.0])
    assert inflate(values, 0.0) is values
    np.testing.assert_allclose(inflate(np.array([0.3, 0.3, 0.3]), np.array([0.0, 0.1, 0.5])), [0.3, 0.2, 0.0])
    assert inflate(values, np.zeros(2)) is values


@pytest.mark.parametrize("margin, problem", [
    (-0.01, "margin must be >= 0 m and below the training lidar's range 0.35 m, got -0.01"),
    (0.35, "margin must be >= 0 m and below the training lidar's range 0.35 m, got 0.35"),
    (math.nan, "margin must be a finite number of metres, got nan"),
    (math.inf, "margin must be a finite number of metres, got inf"),
    ("0.05", "margin must be a finite number of metres, got '0.05'"),
    (True, "margin must be a finite number of metres, got True"),
])
def test_a_margin_that_is_not_a_distance_is_refused(margin, problem):
    assert margin_problem(margin, 0.35) == problem
    with pytest.raises(ValueError) as error:
        training_lidar(margin=margin)
    assert str(error.value) == problem
    assert margin_problem(0.0, 0.35) is None and margin_problem(np.float32(0.1), 0.35) is None



def test_closing_margins_count_only_the_speed_towards_each_ray():
    angles = np.array([0.0, math.pi / 3, math.pi / 2, math.pi, -math.pi / 2])
    margins = closing_margins(angles, (0.2, 0.0), 0.3)  # 0.2 m/s along +x, 0.3 s ahead
    np.testing.assert_allclose(margins, [0.06, 0.03, 0.0, 0.0, 0.0], atol=1e-12)  # across or away: no margin
    np.testing.assert_allclose(closing_margins(angles, (0.0, -0.1), 0.5), [0, 0, 0, 0, 0.05], atol=1e-12)
    assert not closing_margins(angles, (0.2, 0.0), 0.0).any()


def test_a_lead_reads_the_rays_ahead_closer_by_the_speed_towards_them():
    wall = full_scan(np.full(360, 0.2))  # every ray meets something 0.2 m away
    still, _ = training_lidar(frame="world").resample(wall, 0.0)
    np.testing.assert_allclose(still, 0.15, atol=1e-6)
    lead = training_lidar(frame="world", lead=0.3)
    np.testing.assert_array_equal(lead.resample(wall, 0.0)[0], still)  # no velocity: standing still
    np.testing.assert_array_equal(lead.resample(wall, 0.0, (0.0, 0.0))[0], still)
    moving, problem = lead.resample(wall, 1.0, (0.2, 0.0))  # world rays: the heading does not turn them
    assert problem is None
    ahead = 0.06 * np.maximum(np.cos(np.radians(30 * np.arange(12))), 0.0)
    np.testing.assert_allclose(moving, 0.15 + ahead, atol=1e-6)
    assert moving[0] == pytest.approx(0.21, abs=1e-6) and (moving[3:10] == still[3:10]).all()
    fast, _ = lead.resample(wall, 0.0, (2.0, 0.0))  # 0.6 m of lead: contact ahead, clamped at 0 m
    assert fast[0] == pytest.approx(0.35) and fast[6] == pytest.approx(0.15, abs=1e-6)
    with_margin, _ = training_lidar(frame="world", lead=0.3, margin=0.02).resample(wall, 0.0, (0.2, 0.0))
    np.testing.assert_allclose(with_margin, np.minimum(0.17 + ahead, 0.35), atol=1e-6)  # the two add up


def test_a_body_frame_lead_turns_the_rays_with_the_heading():
    wall = full_scan(np.full(360, 0.2))
    lead = training_lidar(frame="body", lead=0.3)
    rays, _ = lead.resample(wall, math.pi / 2, (0.0, 0.2))  # facing +y, driving forward at 0.2 m/s
    assert rays[0] == pytest.approx(0.21, abs=1e-6)  # the forward ray, whatever the world direction
    assert rays[6] == pytest.approx(0.15, abs=1e-6) and rays[3] == pytest.approx(0.15, abs=1e-6)
    np.testing.assert_allclose(lead.world_angles(math.pi / 2), lead.angles + math.pi / 2)


@pytest.mark.parametrize("lead, problem", [
    (-0.1, "lead must be >= 0 s, got -0.1"),
    (math.nan, "lead must be a finite number of seconds, got nan"),
    (math.inf, "lead must be a finite number of seconds, got inf"),
    ("0.3", "lead must be a finite number of seconds, got '0.3'"),
    (False, "lead must be a finite number of seconds, got False"),
])
def test_a_lead_that_is_not_a_time_is_refused(lead, problem):
    assert lead_problem(lead) == problem
    with pytest.raises(ValueError) as error:
        training_lidar(lead=lead)
    assert str(error.value) == problem
    assert lead_problem(0.0) is None and lead_problem(np.float64(0.3)) is None


REFUSALS = [
    ("half circle", lambda: scan_message(-math.pi / 2, DEGREE, np.full(181, 1.0)),
     "scan covers [-1.57, 1.57] rad, the training lidar needs rays all round the circle"),
    ("ten rays", lambda: full_scan(n=10),
     "scan rays are 0.6283 rad apart, coarser than the training lidar's 0.5236 rad: several training rays would "
     "read the same scan ray"),
    ("no increment", lambda: scan_message(-math.pi, 0.0, np.full(360, 1.0)),
     "scan angle_increment 0 is not a finite angle > 0"),
    ("NaN increment", lambda: scan_message(-math.pi, math.nan, np.full(360, 1.0)),
     "scan angle_increment nan is not a finite angle > 0"),
    ("negative increment", lambda: scan_message(math.pi, -DEGREE, np.full(360, 1.0)),
     "scan angle_increment -0.0174533 is not a finite angle > 0"),
    ("short range", lambda: full_scan(range_max=0.3),
     "scan range_max 0.3 m is below the training lidar's max_range 0.35 m: farther readings would look like "
     "free space"),
    ("blind near", lambda: full_scan(range_min=0.4),
     "scan range_min 0.4 m is not below the training lidar's max_range 0.35 m"),
    ("empty", lambda: scan_message(0.0, DEGREE, []), "scan has no ranges"),
]


@pytest.mark.parametrize("make, problem", [(m, p) for _, m, p in REFUSALS], ids=[name for name, _, _ in REFUSALS])
def test_scans_that_cannot_be_resampled_are_refused(make, problem):
    resampler = training_lidar()
    assert resampler.geometry_problem(make()) == problem
    assert resampler.resample(make()) == (None, problem)


def test_ranges_must_match_the_angles():
    scan = full_scan()
    scan.ranges = [3.0] * 358  # angle_max still says 360 rays
    assert training_lidar().geometry_problem(scan) == (
        "scan has 358 ranges, but angle_min -3.1416 + 357 x angle_increment 0.01745 = 3.0892 rad is not "
        "angle_max 3.1241 rad")
    scan.ranges = [3.0] * 360
    scan.angle_max = math.pi  # one increment past the last ray (a driver giving the span, not the last ray): taken
    assert training_lidar().geometry_problem(scan) is None
    scan.angle_max = math.pi + 2 * DEGREE
    assert "is not angle_max 3.1765 rad" in training_lidar().geometry_problem(scan)


def test_resampler_arguments_are_checked():
    for kwargs, fragment in [({"n_rays": 0}, "n_rays"), ({"max_range": -1.0}, "max_range"),
                             ({"frame": "map"}, "frame must be one of body, world, got 'map'"),
                             ({"encoding": "raw"}, "encoding must be one of proximity, distance"),
                             ({"angle_end": math.inf}, "angle_end")]:
        with pytest.raises(ValueError, match=fragment):
            ScanResampler(**{"n_rays": 12, "max_range": 0.35, **kwargs})
    assert np.allclose(training_lidar().angles, np.arange(12) * 2 * math.pi / 12)


def test_importing_the_adapters_loads_neither_rclpy_nor_torch():
    code = ("import sys, vmas_ros.adapters; "
            "print(sorted(m for m in ('rclpy', 'torch', 'nav_msgs', 'sensor_msgs') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
