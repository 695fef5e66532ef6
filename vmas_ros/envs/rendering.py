"""``Environment.render``: one env of the batch drawn headless, with VMAS's keywords."""
from __future__ import annotations

from typing import Optional

__all__ = ["render_env"]


def render_env(env, mode: str, env_index: int, agent_index_focus: Optional[int], plot_position_function, **kwargs):
    """Draw env ``env_index`` of ``env`` into an RGB array [H, W, 3] (no display needed).

    ``agent_index_focus`` centres the view on that agent. VMAS's
    ``visualize_when_rgb`` (show the frame in a window) has nothing to do here,
    since no window is ever opened, so the environment takes and drops it.
    VMAS's ``plot_position_function`` heat maps are not drawn: passing one
    raises. Other keywords go to :func:`vmas_ros.viz.scene.render_world`.
    """
    from vmas_ros.viz.scene import render_world

    if mode not in ("rgb_array", "human"):
        raise ValueError(f"render mode must be 'rgb_array' or 'human', got {mode!r}")
    if not 0 <= env_index < env.num_envs:
        raise ValueError(f"env_index {env_index} out of range for {env.num_envs} envs")
    if plot_position_function is not None:
        raise ValueError("render: plot_position_function (VMAS's heat map of a function of position) "
                         "is not supported by vmas_ros's renderer; pass None")
    if agent_index_focus is not None:
        kwargs = {**kwargs, "agent_index_focus": agent_index_focus}
    scenario = env.scenario
    return render_world(
        env.world, env_index=env_index, extra_geoms=scenario.extra_render(env_index),
        width=scenario.viewer_size[0], height=scenario.viewer_size[1], zoom=scenario.viewer_zoom,
        plot_bounds=scenario.visualize_semidims, render_origin=scenario.render_origin, **kwargs,
    )
