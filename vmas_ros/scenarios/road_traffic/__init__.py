"""road_traffic: car-like robots drive their routes around the CPM Lab road map without crashing.

Description
    ``n_agents`` cars (0.16 x 0.08 boxes, kinematic bicycle model integrated
    with RK4; actions are speed in [-max_speed, max_speed] and steering angle
    in [-35 deg, 35 deg]) drive on the 1:18 CPM Lab map (4.5 m x 4 m: an urban
    ring, a highway loop, merges and an eight-way intersection; Xu et al.,
    2024, "A sample efficient and generalizable multi-agent reinforcement
    learning framework for motion planning"). Each car has a route: one of 40
    closed loops of lanelets. Cars do not physically collide; overlaps of
    their outlines, and crossings of the route's lane boundaries, are detected
    geometrically and end the episode. The map is VMAS's data and is read at
    run time (see ``map_data``).
Observation (per agent, in this order; "ego view" = in the agent's own frame)
    Own: with ``is_ego_view`` the speed (1), else position (2, / world size),
    heading (1, / 2 pi) and velocity (2); then the ``n_points_short_term``
    look-ahead points of the route, every ``sample_interval_ref_path`` points
    from the nearest one ahead (2 each, / 10 agent lengths in ego view, / world
    size in bird view); the distance to the route's centre line (1, if
    ``is_observe_distance_to_center_line``); the distances to the left and to
    the right lane boundary (1 + 1, over the centre and the 4 corners), or
    without ``is_observe_distance_to_boundaries`` ``n_points_nearing_boundary``
    points of each boundary (2 each). Distances are / (3 lane widths).
    Others: with ``is_partial_observation`` the ``n_nearing_agents_observed``
    nearest cars, nearest first (else every car, ego view only, laid out as
    VMAS does), each: its 4 corners (8) or, without ``is_observe_vertices``,
    position (2) and heading (1); its velocity (2: speed along its heading,
    turned into the observer's frame in ego view); its distance (1, if
    ``is_observe_distance_to_agents``); its look-ahead points (2 each, if
    ``is_observe_ref_path_other_agents``). With ``is_apply_mask`` neighbours
    10 agent lengths away or more are masked (positions, corners, points and
    distances 1; headings and velocities 0). With ``is_add_noise`` every entry
    gets uniform noise in [0, ``noise_level``).
Reward (per agent; VMAS's values, divided by 100)
    progress: the last move projected on the vectors to the previous
    look-ahead points (weights 1 .. 0.2, normalised) over max_speed * dt, x
    ``reward_progress``; speed: velocity projected likewise (mean), x
    ``reward_vel`` (doubled when negative); ``reward_reach_goal`` on crossing
    the route's exit (open routes only); -0.2 x a fading weight of the distance
    to the lane boundaries (between ``threshold_near_boundary_low`` and
    ``_high``) and of every other car's centre distance (summed, between the
    ``threshold_near_other_agents_c2c`` bounds); -0.02 x distance to the centre
    line / (half the map's mean lane width); -0.02 x the change between the last
    two observed steering commands beyond ``threshold_change_steering`` degrees
    (scaled by its range); -1 for overlapping another car, -1 for crossing a
    lane boundary; +-0.05 x speed / max_speed (sign of the speed term).
Starting state
    Each car on a random route at a random centre-line point (index in
    [6, points / 2) or, when ``scenario_probabilities`` gives merges a chance,
    [3, points - 5)), heading along the route, moving forward at a speed uniform
    in [0, max_speed); cars at least 1.2 diagonals apart (redrawn until so).
Episode termination
    When two cars overlap or a car crosses its lane boundaries (per env).
Kwargs (VMAS 1.5.2's names and defaults)
    Supported: ``n_agents`` (20), ``dt`` (0.05), ``world_x_dim`` (4.5),
    ``world_y_dim`` (4.0), ``agent_width`` (0.08), ``agent_length`` (0.16),
    ``l_f`` (length / 2), ``l_r`` (length - l_f), ``lane_width`` (0.15),
    ``max_speed`` (1.0), ``max_steering_angle`` (35 deg in rad),
    ``map_file_path`` (None: the installed vmas's map), ``scenario_probabilities``
    ((1, 0, 0); only picks the start-point range on map type "1"),
    ``reward_progress`` (10), ``reward_vel`` (5), ``reward_reach_goal`` (0),
    ``threshold_change_steering`` (10 deg), ``threshold_near_boundary_high``
    ((lane - width) / 2 * 0.9), ``threshold_near_boundary_low`` (0),
    ``threshold_near_other_agents_c2c_high`` (length + width),
    ``threshold_near_other_agents_c2c_low`` ((length + width) / 2),
    ``sample_interval_ref_path`` (2), ``n_points_short_term`` (3),
    ``n_points_nearing_boundary`` (5), ``noise_level`` (0.2 * width),
    ``n_stored_steps`` (5; below 2 the steering penalty is always 0),
    ``is_partial_observation`` (True), ``n_nearing_agents_observed`` (2),
    ``is_ego_view``, ``is_apply_mask``, ``is_observe_vertices``,
    ``is_observe_distance_to_agents``, ``is_observe_distance_to_boundaries``,
    ``is_observe_distance_to_center_line``, ``is_add_noise`` (all True),
    ``is_observe_ref_path_other_agents`` (False).
    Accepted but without effect, as in VMAS: ``threshold_deviate_from_ref_path``,
    ``threshold_reach_goal``, ``threshold_no_reward_if_too_close_to_*``,
    ``max_ref_path_points``, ``n_observed_steps``, ``n_steps_stored``,
    ``n_steps_before_recording``, ``probability_use_recording`` and the
    rendering kwargs (``resolution_factor``, ``render_origin``, ``viewer_size``,
    ``viewer_zoom``, ``is_visualize_short_term_path``, ``is_real_time_rendering``,
    ``is_visualize_extra_info``, ``render_title``).
    Refused (ValueError): ``map_type`` other than "1" (the initial-state buffer
    of "2" and the intersection/merge sub-maps of "3" are not ported),
    ``is_testing_mode=True`` (per-agent resets inside ``done``), a
    ``parameters`` object, and ``is_partial_observation=False`` with the bird
    view (VMAS's layout cannot be built there).
Deviations from VMAS 1.5.2
    Resets are batched (one draw per env and agent, redrawn where too close)
    and so use the random stream differently; agent colours are fixed per
    index instead of random; the history VMAS keeps for map type "2" is not
    kept. Kept on purpose for parity: a car i is tested for overlap with car
    j > i using j's outline of the previous step, boundary look-ahead points
    start at the nearest point after a reset but two points behind it during an
    episode, and the diagonal of the distance matrix holds the batch's largest
    distance + 1.
"""
from vmas_ros.scenarios.road_traffic.heuristic import HeuristicPolicy
from vmas_ros.scenarios.road_traffic.scenario import Scenario

__all__ = ["HeuristicPolicy", "Scenario"]
