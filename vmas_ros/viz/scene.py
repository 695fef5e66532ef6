"""Render one environment of a batched world to an RGB array, headless.

This is what ``Environment.render(mode="rgb_array")`` needs: the same picture
VMAS draws (white background, grey world bounds, entities in their colours,
sensor rays, the scenario's extra geoms), produced with Pillow so it works on
machines without a display or OpenGL.

The world is duck-typed so rendering does not depend on engine internals:
``world.entities`` / ``world.agents`` with ``.shape``, ``.state.pos [B, 2]``,
``.state.rot [B, 1]``, ``.color``, optional ``.alpha`` and ``.is_rendering
[B]``; ``world.x_semidim`` / ``world.y_semidim``; ``world.dim_c``.
"""
from __future__ import annotations

from typing import Iterable, List, Optional, Sequence, Tuple

import numpy as np

from vmas_ros.simulator import rendering
from vmas_ros.simulator.rendering import Geom, Viewer, shape_geom

__all__ = ["render_world", "view_bounds", "entity_geoms", "bounds_geoms", "comm_geoms"]

Bounds = Tuple[float, float, float, float]

_BOUNDS_COLOR = (0.25, 0.25, 0.25)  # VMAS draws world limits in its GRAY
_FAR = 100.0  # how far an unbounded axis's limit lines reach


def _vec(t, env_index: int) -> np.ndarray:
    """Row ``env_index`` of a [B, ...] tensor or array as a flat float numpy array."""
    row = t[env_index]
    if hasattr(row, "detach"):
        row = row.detach().cpu().numpy()
    return np.asarray(row, dtype=np.float64).reshape(-1)


def _color(entity, env_index: int) -> Tuple[float, ...]:
    """An entity's RGB: a tuple, an enum member holding one, or a per-env tensor."""
    color = getattr(entity, "color", (0.25, 0.25, 0.25))
    color = getattr(color, "value", color)
    if hasattr(color, "detach") and color.dim() > 1:
        color = color[env_index]
    if hasattr(color, "detach"):
        color = color.detach().cpu().tolist()
    return tuple(float(c) for c in color)[:3]


def _is_rendering(entity, env_index: int) -> bool:
    flags = getattr(entity, "is_rendering", None)
    return True if flags is None else bool(flags[env_index])


def _radius(entity) -> float:
    shape = entity.shape
    if hasattr(shape, "circumscribed_radius"):
        return float(shape.circumscribed_radius())
    return 0.0


def view_bounds(
    world,
    env_index: int = 0,
    width: int = 700,
    height: int = 700,
    zoom: float = 1.2,
    shared_viewer: bool = True,
    agent_index_focus: Optional[int] = None,
    render_origin: Sequence[float] = (0.0, 0.0),
) -> Bounds:
    """The ``(xmin, xmax, ymin, ymax)`` VMAS would show for this frame.

    The camera's half-extent on the shorter image side starts at ``zoom``
    (the other side follows the aspect ratio). With a shared viewer VMAS then
    scales it by ``max(zoom, fit / half_extent)`` where ``fit`` is the largest
    ``|pos - render_origin|`` of any agent plus twice the biggest agent
    radius, so every agent stays in view. Note that this multiplies by ``zoom`` a second time: with
    everybody near the origin the half-extent is ``zoom**2``. We keep that so
    frames match upstream's. With ``agent_index_focus`` the camera follows
    that agent at the base half-extent; with neither it stays on
    ``render_origin`` (VMAS's ``Scenario.render_origin``).
    """
    if zoom <= 0:
        raise ValueError(f"zoom must be > 0, got {zoom}")
    aspect = width / height
    half = np.array([zoom * aspect, zoom] if aspect >= 1 else [zoom, zoom / aspect], dtype=np.float64)
    agents = list(getattr(world, "agents", []))
    origin = np.array([float(render_origin[0]), float(render_origin[1])])
    if agent_index_focus is not None:
        cx, cy = _vec(agents[agent_index_focus].state.pos, env_index)[:2]
        return (cx - half[0], cx + half[0], cy - half[1], cy + half[1])
    if shared_viewer:
        if agents:
            pos = np.stack([_vec(a.state.pos, env_index)[:2] for a in agents])
            fit = np.abs(pos - origin).max(axis=0) + 2 * max(_radius(a) for a in agents)
            half = half * max(zoom, float((fit / half).max()))
        else:
            half = half * zoom
    return (origin[0] - half[0], origin[0] + half[0], origin[1] - half[1], origin[1] + half[1])


def bounds_geoms(world) -> List[Geom]:
    """Grey lines at the world's limits: a rectangle, or two lines if one axis is open."""
    xs, ys = getattr(world, "x_semidim", None), getattr(world, "y_semidim", None)
    if xs is None and ys is None:
        return []
    x, y = float(xs if xs is not None else _FAR), float(ys if ys is not None else _FAR)
    if xs is not None and ys is not None:
        segments = [((-x, y), (x, y)), ((x, y), (x, -y)), ((x, -y), (-x, -y)), ((-x, -y), (-x, y))]
    elif xs is not None:
        segments = [((-x, -y), (-x, y)), ((x, -y), (x, y))]
    else:
        segments = [((-x, -y), (x, -y)), ((-x, y), (x, y))]
    lines = []
    for start, end in segments:
        line = rendering.Line(start, end, width=1)
        line.set_color(*_BOUNDS_COLOR)
        lines.append(line)
    return lines


def entity_geoms(entity, env_index: int = 0) -> List[Geom]:
    """The entity's shape placed at its pose in ``env_index``, or nothing if hidden.

    Agents with ``render_action`` also get their force drawn as a line, as in VMAS.
    """
    if not _is_rendering(entity, env_index):
        return []
    shape = entity.shape
    geom = shape.get_geometry() if hasattr(shape, "get_geometry") else shape_geom(shape)
    xform = rendering.Transform()
    pos = _vec(entity.state.pos, env_index)
    xform.set_translation(pos[0], pos[1])
    rot = getattr(entity.state, "rot", None)
    if rot is not None:
        xform.set_rotation(_vec(rot, env_index)[0])
    geom.add_attr(xform)
    color = _color(entity, env_index)
    alpha = getattr(entity, "alpha", getattr(entity, "_alpha", 1.0))  # _alpha: upstream agents
    geom.set_color(*color, alpha=float(alpha))
    geoms = [geom]
    force = getattr(entity.state, "force", None)
    if getattr(entity, "render_action", False) and force is not None:
        tip = pos[:2] + _vec(force, env_index)[:2] * 10 * _radius(entity)
        arrow = rendering.Line(tuple(pos[:2]), tuple(tip), width=2)
        arrow.set_color(*color)
        geoms.append(arrow)
    return geoms


class _WorldLabel(Geom):
    """Text anchored at a world point (unlike TextLine, which lives in window pixels)."""

    def __init__(self, text: str, x: float, y: float, font_size: int = 10):
        super().__init__()
        self.text, self.x, self.y, self.font_size = text, x, y, font_size

    def _paint(self, canvas, ctx) -> None:
        xy = ctx.apply(np.array([[self.x, self.y]]))[0]
        canvas.text(xy, self.text, ctx.color, self.font_size, anchor="lb")


def _format_message(c: np.ndarray, max_items: int = 4) -> str:
    items = ",".join(f"{v:.2f}" for v in c[:max_items].tolist())
    return f"[{items}{',...' if c.size > max_items else ''}]"


def comm_geoms(world, env_index: int = 0) -> List[Geom]:
    """A short label with each speaking agent's message, up and right of the agent."""
    if int(getattr(world, "dim_c", 0) or 0) <= 0:
        return []
    labels: List[Geom] = []
    for agent in getattr(world, "agents", []):
        c = getattr(agent.state, "c", None)
        if c is None or getattr(agent, "silent", False) or not _is_rendering(agent, env_index):
            continue
        pos = _vec(agent.state.pos, env_index)
        r = _radius(agent)
        labels.append(_WorldLabel(_format_message(_vec(c, env_index)), pos[0] + r, pos[1] + r))
    return labels


def render_world(
    world,
    env_index: int = 0,
    extra_geoms: Iterable[Geom] = (),
    width: int = 700,
    height: int = 700,
    zoom: float = 1.2,
    shared_viewer: bool = True,
    visible_bounds: Optional[Sequence[float]] = None,
    plot_bounds: bool = True,
    agent_index_focus: Optional[int] = None,
    render_origin: Sequence[float] = (0.0, 0.0),
    extra_on_top: bool = False,
) -> np.ndarray:
    """Draw environment ``env_index`` of ``world``; returns ``[height, width, 3]`` uint8.

    Order, bottom to top: world bounds (if ``plot_bounds``), ``extra_geoms``
    (a scenario's ``extra_render(env_index)``), entities in ``world.entities``
    order, agents' sensors, communication labels; any
    :class:`~vmas_ros.simulator.rendering.TextLine` goes last. Extra geoms go
    *under* the entities because that is VMAS's order and scenarios rely on
    it (football paints its pitch in ``extra_render``); ``extra_on_top=True``
    puts them above entities and sensors instead, for overlays.

    The view is ``visible_bounds=(xmin, xmax, ymin, ymax)`` if given, else
    :func:`view_bounds` (``zoom`` is VMAS's ``Scenario.viewer_zoom``,
    ``render_origin`` its ``Scenario.render_origin``).
    """
    if visible_bounds is not None:
        xmin, xmax, ymin, ymax = (float(v) for v in visible_bounds)
    else:
        xmin, xmax, ymin, ymax = view_bounds(
            world, env_index, width, height, zoom, shared_viewer, agent_index_focus, render_origin
        )
    viewer = Viewer(width, height)
    viewer.set_bounds(xmin, xmax, ymin, ymax)
    if plot_bounds:
        viewer.add_onetime_list(bounds_geoms(world))
    extra_geoms = list(extra_geoms)
    if not extra_on_top:
        viewer.add_onetime_list(extra_geoms)
    for entity in world.entities:
        viewer.add_onetime_list(entity_geoms(entity, env_index))
    for agent in getattr(world, "agents", []):
        if not _is_rendering(agent, env_index):
            continue
        for sensor in getattr(agent, "sensors", None) or []:
            viewer.add_onetime_list(sensor.render(env_index=env_index))
    if extra_on_top:
        viewer.add_onetime_list(extra_geoms)
    viewer.add_onetime_list(comm_geoms(world, env_index))
    return viewer.render(return_rgb_array=True)
