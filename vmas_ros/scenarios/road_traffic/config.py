"""Kwargs of ``road_traffic``: names, defaults (VMAS 1.5.2's) and validation.

Defaults that VMAS derives from other kwargs (``l_f`` from ``agent_length``,
thresholds from ``lane_width`` and the agent's size, ...) are ``None`` here
and resolved by :func:`resolve`.
"""
from __future__ import annotations

import math
from numbers import Real

import torch

#: name -> default of every kwarg
DEFAULTS = {
    # world and vehicles
    "n_agents": 20, "dt": 0.05, "world_x_dim": 4.5, "world_y_dim": 4.0,
    "agent_width": 0.08, "agent_length": 0.16, "l_f": None, "l_r": None, "lane_width": 0.15,
    "max_speed": 1.0, "max_steering_angle": math.radians(35),
    "map_type": "1", "map_file_path": None, "scenario_probabilities": (1.0, 0.0, 0.0),
    "is_testing_mode": False,
    # rewards (divided by 100, as VMAS does)
    "reward_progress": 10.0, "reward_vel": 5.0, "reward_reach_goal": 0.0,
    "threshold_deviate_from_ref_path": None, "threshold_reach_goal": None,
    "threshold_change_steering": 10.0, "threshold_near_boundary_high": None, "threshold_near_boundary_low": 0.0,
    "threshold_near_other_agents_c2c_high": None, "threshold_near_other_agents_c2c_low": None,
    "threshold_no_reward_if_too_close_to_boundaries": None,
    "threshold_no_reward_if_too_close_to_other_agents": None,
    # observation
    "sample_interval_ref_path": 2, "max_ref_path_points": 200, "n_points_short_term": 3,
    "n_points_nearing_boundary": 5, "noise_level": None, "n_stored_steps": 5, "n_observed_steps": 1,
    "is_partial_observation": True, "n_nearing_agents_observed": 2,
    "is_ego_view": True, "is_apply_mask": True, "is_observe_vertices": True,
    "is_observe_distance_to_agents": True, "is_observe_distance_to_boundaries": True,
    "is_observe_distance_to_center_line": True, "is_add_noise": True,
    "is_observe_ref_path_other_agents": False,
    # not VMAS's: True clears an env's steering history when it resets, so that a seeded reset repeats its
    # episode (gymnasium's convention); VMAS keeps it (False), and so the first reward after a reset
    # depends on the episode before
    "reset_steering_history": False,
    # only used by VMAS's map type "2" (refused here) and by rendering
    "n_steps_stored": 10, "n_steps_before_recording": 10, "probability_use_recording": 0.2,
    "resolution_factor": 200, "render_origin": None, "viewer_size": None, "viewer_zoom": 1.44,
    "is_visualize_short_term_path": True, "is_real_time_rendering": False, "is_visualize_extra_info": False,
    "render_title": "Multi-Agent Reinforcement Learning for Road Traffic (CPM Lab Scenario)",
    "parameters": None,
}
FLAGS = (
    "is_partial_observation", "is_ego_view", "is_apply_mask", "is_observe_vertices",
    "is_observe_distance_to_agents", "is_observe_distance_to_boundaries",
    "is_observe_distance_to_center_line", "is_add_noise", "is_observe_ref_path_other_agents",
    "reset_steering_history", "is_visualize_short_term_path", "is_real_time_rendering", "is_visualize_extra_info",
)


def _fail(name, value, expected) -> None:
    raise ValueError(f"road_traffic: {name} must be {expected}, got {value!r}")


def _number(value) -> bool:
    return isinstance(value, Real) and not isinstance(value, bool) and math.isfinite(float(value))


def _count(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def resolve(config: dict) -> dict:
    """Validate ``config`` (kwargs completed with ``DEFAULTS``) and fill the derived defaults."""
    c = dict(config)
    if torch.is_tensor(c["max_steering_angle"]) and c["max_steering_angle"].numel() == 1:
        c["max_steering_angle"] = float(c["max_steering_angle"])
    if c["parameters"] is not None:
        _fail("parameters", c["parameters"], "None (pass each parameter as its own kwarg)")
    if c["map_type"] not in ("1", 1):
        _fail("map_type", c["map_type"], '"1" (the whole map; map types "2" and "3" are not supported)')
    c["map_type"] = "1"
    if c["is_testing_mode"] is not False:
        _fail("is_testing_mode", c["is_testing_mode"], "False (testing mode, with per-agent resets, is not supported)")
    for name in FLAGS:
        if not isinstance(c[name], bool):
            _fail(name, c[name], "a bool")
    if not _count(c["n_agents"]) or c["n_agents"] < 2:
        _fail("n_agents", c["n_agents"], "an int >= 2")
    if not _count(c["n_nearing_agents_observed"]) or not 1 <= c["n_nearing_agents_observed"] < c["n_agents"]:
        _fail("n_nearing_agents_observed", c["n_nearing_agents_observed"], f"an int in [1, n_agents - 1 = {c['n_agents'] - 1}]")
    for name in ("n_points_short_term", "n_points_nearing_boundary", "sample_interval_ref_path", "n_stored_steps",
                 "n_observed_steps", "max_ref_path_points", "n_steps_stored", "n_steps_before_recording"):
        if not _count(c[name]) or c[name] < 1:
            _fail(name, c[name], "an int >= 1")
    for name in ("dt", "world_x_dim", "world_y_dim", "agent_width", "agent_length", "lane_width", "max_speed",
                 "max_steering_angle"):
        if not _number(c[name]) or not c[name] > 0:
            _fail(name, c[name], "a number > 0")
    probabilities = c["scenario_probabilities"]
    if (not isinstance(probabilities, (list, tuple)) or len(probabilities) != 3
            or not all(_number(p) and p >= 0 for p in probabilities) or sum(probabilities) <= 0):
        _fail("scenario_probabilities", probabilities, "three numbers >= 0 with a positive sum")
    c["scenario_probabilities"] = tuple(float(p) for p in probabilities)
    if c["map_file_path"] is not None and not isinstance(c["map_file_path"], (str, bytes)) and not hasattr(c["map_file_path"], "__fspath__"):
        _fail("map_file_path", c["map_file_path"], "None or a path to road_traffic_cpm_lab.xml")

    width, length, lane = c["agent_width"], c["agent_length"], c["lane_width"]
    derived = {
        "l_f": length / 2,
        "threshold_deviate_from_ref_path": (lane - width) / 2,
        "threshold_reach_goal": width / 2,
        "threshold_near_boundary_high": (lane - width) / 2 * 0.9,
        "threshold_near_other_agents_c2c_high": length + width,
        "threshold_near_other_agents_c2c_low": (length + width) / 2,
        "threshold_no_reward_if_too_close_to_boundaries": width / 10,
        "threshold_no_reward_if_too_close_to_other_agents": width / 6,
        "noise_level": 0.2 * width,
    }
    for name, value in derived.items():
        if c[name] is None:
            c[name] = value
    if c["l_r"] is None:
        c["l_r"] = length - c["l_f"]
    for name in ("l_f", "l_r", "threshold_change_steering", "noise_level", "reward_progress", "reward_vel",
                 "reward_reach_goal", "threshold_near_boundary_low", "threshold_near_boundary_high",
                 "threshold_near_other_agents_c2c_low", "threshold_near_other_agents_c2c_high",
                 "threshold_deviate_from_ref_path", "threshold_reach_goal", "probability_use_recording",
                 "threshold_no_reward_if_too_close_to_boundaries", "threshold_no_reward_if_too_close_to_other_agents"):
        if not _number(c[name]):
            _fail(name, c[name], "a finite number")
    for name in ("l_f", "l_r", "noise_level", "threshold_change_steering"):
        if c[name] < 0:
            _fail(name, c[name], "a number >= 0")
    for low, high in (("threshold_near_boundary_low", "threshold_near_boundary_high"),
                      ("threshold_near_other_agents_c2c_low", "threshold_near_other_agents_c2c_high")):
        if not c[low] < c[high]:
            _fail(high, c[high], f"> {low} = {c[low]!r}")
    if not math.radians(c["threshold_change_steering"]) < c["max_steering_angle"]:
        _fail("threshold_change_steering", c["threshold_change_steering"], "degrees below max_steering_angle")
    if c["render_origin"] is None:
        c["render_origin"] = [c["world_x_dim"] / 2, c["world_y_dim"] / 2]
    if c["viewer_size"] is None:
        c["viewer_size"] = (int(c["world_x_dim"] * c["resolution_factor"]), int(c["world_y_dim"] * c["resolution_factor"]))
    return c
