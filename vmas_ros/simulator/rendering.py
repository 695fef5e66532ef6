"""Drawing primitives for ``Scenario.extra_render`` that need no display.

The public names and call signatures follow VMAS 1.5's ``vmas.simulator.rendering``
so a VMAS scenario keeps working after its imports are re-prefixed. The
implementation is ours: geoms are plain descriptions that draw themselves onto a
:class:`vmas_ros.simulator.canvas.Canvas` (Pillow) instead of issuing OpenGL calls.

Semantics kept from VMAS because scenarios rely on them:

* Attributes (:class:`Transform`, :class:`Color`, :class:`LineWidth`) attach
  with ``add_attr``; the transform added *first* acts on the vertices first
  (innermost), later ones wrap it.
* A :class:`Compound` paints every child in the compound's colour.
* Line widths and :class:`TextLine` coordinates/sizes are in pixels; everything
  else is in world units. Text lines are drawn last, in window pixels measured
  from the bottom-left corner.
* A :class:`FilledPolygon` gets a border in half its colour and half its alpha.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Iterable, List, Optional, Tuple, Union

import numpy as np

if TYPE_CHECKING:  # the canvas imports nothing from here; keep import cycles impossible
    from vmas_ros.simulator.canvas import Canvas

__all__ = [
    "Geom", "Attr", "Transform", "Color", "LineStyle", "LineWidth", "TextLine", "Point",
    "Image", "FilledPolygon", "Compound", "PolyLine", "Line", "Grid", "Viewer",
    "make_circle", "make_ellipse", "make_polygon", "make_polyline", "make_capsule",
    "render_function_util", "shape_geom", "DrawContext",
]

# the default stroke of polygon borders and hollow shapes, in pixels
_BORDER_WIDTH = 1.0


def _scalar(value) -> float:
    """float() that also accepts 0-d / one-element tensors and arrays (VMAS passes those)."""
    if isinstance(value, (int, float)):
        return float(value)
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    arr = np.asarray(value, dtype=np.float64)
    if arr.size != 1:
        raise ValueError(f"expected a single number, got shape {arr.shape}")
    return float(arr.reshape(-1)[0])


def _points(v) -> np.ndarray:
    """Vertices given as a tensor, an array or a list of pairs -> float64 ``[N, 2]``."""
    if hasattr(v, "detach"):
        return v.detach().cpu().numpy().astype(np.float64).reshape(-1, 2)
    try:
        return np.asarray(v, dtype=np.float64).reshape(-1, 2)
    except (TypeError, ValueError):  # pairs of tensors
        return np.array([[_scalar(p[0]), _scalar(p[1])] for p in v], dtype=np.float64).reshape(-1, 2)


@dataclass(frozen=True)
class DrawContext:
    """What a geom inherits from its parents: placement, colour and line style."""

    matrix: np.ndarray  # 3x3 homogeneous local -> world (or pixel, for text)
    color: Tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    line_width: Optional[float] = None

    def apply(self, pts: np.ndarray) -> np.ndarray:
        """Map local points ``[N, 2]`` through the accumulated transform."""
        return pts @ self.matrix[:2, :2].T + self.matrix[:2, 2]


_ROOT = DrawContext(np.eye(3))


class Attr:
    """Something attached to a geom that changes how it is drawn."""


class Transform(Attr):
    """Scale, then rotate (radians, counter-clockwise), then translate."""

    def __init__(self, translation=(0.0, 0.0), rotation=0.0, scale=(1, 1)):
        self.set_translation(*translation)
        self.set_rotation(rotation)
        self.set_scale(*scale)

    def set_translation(self, newx, newy) -> None:
        self.translation = (_scalar(newx), _scalar(newy))

    def set_rotation(self, new) -> None:
        self.rotation = _scalar(new)

    def set_scale(self, newx, newy) -> None:
        self.scale = (_scalar(newx), _scalar(newy))

    def matrix(self) -> np.ndarray:
        """The 3x3 homogeneous matrix ``T @ R @ S`` of this transform."""
        c, s = math.cos(self.rotation), math.sin(self.rotation)
        sx, sy = self.scale
        tx, ty = self.translation
        return np.array([[c * sx, -s * sy, tx], [s * sx, c * sy, ty], [0.0, 0.0, 1.0]])


class Color(Attr):
    """An RGBA colour (floats 0..1) carried as an attribute, as in VMAS."""

    def __init__(self, vec4):
        self.vec4 = tuple(vec4)


class LineStyle(Attr):
    """A 16-bit stipple pattern. Accepted for compatibility; lines are drawn solid."""

    def __init__(self, style):
        self.style = style


class LineWidth(Attr):
    """Stroke width in pixels for the geom (and children that set none)."""

    def __init__(self, stroke):
        self.stroke = stroke


class Geom:
    """Base of every drawable: a list of attributes plus how to paint itself."""

    def __init__(self):
        self._color = Color((0.0, 0.0, 0.0, 1.0))
        self.attrs: List[Attr] = [self._color]

    def add_attr(self, attr: Attr) -> None:
        self.attrs.append(attr)

    def set_color(self, r, g, b, alpha=1) -> None:
        self._color.vec4 = (_scalar(r), _scalar(g), _scalar(b), _scalar(alpha))

    def context(self, parent: Optional[DrawContext] = None) -> DrawContext:
        """Combine the parent's context with this geom's own attributes."""
        parent = parent or _ROOT
        local = np.eye(3)
        color, width = None, None
        for attr in self.attrs:
            if isinstance(attr, Transform):
                local = attr.matrix() @ local  # later transforms wrap earlier ones
            elif isinstance(attr, Color) and color is None:
                color = tuple(_scalar(c) for c in attr.vec4)
            elif isinstance(attr, LineWidth) and width is None:
                width = _scalar(attr.stroke)
        if color is not None and len(color) == 3:
            color = color + (1.0,)
        return DrawContext(
            parent.matrix @ local,
            color if color is not None else parent.color,
            width if width is not None else parent.line_width,
        )

    def draw(self, canvas: "Canvas", parent: Optional[DrawContext] = None) -> None:
        """Paint this geom on ``canvas`` inside the parent's context."""
        self._paint(canvas, self.context(parent))

    def _paint(self, canvas: "Canvas", ctx: DrawContext) -> None:
        raise NotImplementedError(f"{type(self).__name__} cannot draw itself")


class FilledPolygon(Geom):
    """A filled polygon; ``draw_border`` adds an outline in half colour and alpha."""

    def __init__(self, v, draw_border: float = True):
        super().__init__()
        self.draw_border = draw_border
        self.v = v

    def _paint(self, canvas: "Canvas", ctx: DrawContext) -> None:
        pts = ctx.apply(_points(self.v))
        canvas.polygon(pts, fill=ctx.color)
        if self.draw_border:
            canvas.polygon(pts, outline=tuple(c * 0.5 for c in ctx.color), width=ctx.line_width or _BORDER_WIDTH)


class _Stroked(Geom):
    """A geom drawn with lines, owning a :class:`LineWidth` (pixels) from the start."""

    def __init__(self, width: float = 1):
        super().__init__()
        self.linewidth = LineWidth(width)
        self.add_attr(self.linewidth)

    def set_linewidth(self, x) -> None:
        self.linewidth.stroke = x


class PolyLine(_Stroked):
    """A stroked chain of vertices, closed into a loop when ``close``."""

    def __init__(self, v, close):
        super().__init__(1)
        self.v = v
        self.close = close

    def _paint(self, canvas: "Canvas", ctx: DrawContext) -> None:
        canvas.polyline(ctx.apply(_points(self.v)), ctx.color, ctx.line_width or 1.0, closed=bool(self.close))


class Line(_Stroked):
    """A segment from ``start`` to ``end``; ``width`` in pixels."""

    def __init__(self, start=(0.0, 0.0), end=(0.0, 0.0), width: float = 1):
        super().__init__(width)
        self.start = start
        self.end = end

    def _paint(self, canvas: "Canvas", ctx: DrawContext) -> None:
        pts = ctx.apply(np.concatenate([_points(self.start), _points(self.end)]))
        canvas.polyline(pts, ctx.color, ctx.line_width or 1.0)


class Point(Geom):
    """A one-pixel dot at the local origin."""

    def _paint(self, canvas: "Canvas", ctx: DrawContext) -> None:
        canvas.point(ctx.apply(np.zeros((1, 2)))[0], ctx.color, size=1.0)


class Compound(Geom):
    """Several geoms moved and coloured as one; children lose their own colour."""

    def __init__(self, gs):
        super().__init__()
        self.gs = gs
        for g in self.gs:
            g.attrs = [a for a in g.attrs if not isinstance(a, Color)]

    def _paint(self, canvas: "Canvas", ctx: DrawContext) -> None:
        for g in self.gs:
            g.draw(canvas, ctx)


class TextLine(Geom):
    """A line of text at window pixel ``(x, y)`` from the bottom-left, drawn on top."""

    def __init__(self, text: str = "", font_size: int = 15, x: float = 0.0, y: float = 0.0):
        super().__init__()
        self.text = text
        self.font_size = font_size
        self.x = x
        self.y = y

    def set_text(self, text, font_size: Optional[int] = None) -> None:
        self.text = text
        if font_size is not None:
            self.font_size = font_size

    def _paint(self, canvas: "Canvas", ctx: DrawContext) -> None:
        xy = ctx.apply(np.array([[_scalar(self.x), _scalar(self.y)]]))[0]
        canvas.text(xy, self.text, ctx.color, self.font_size, pixel=True, anchor="ld")


class Image(Geom):
    """An RGBA array (0..255, row 0 at the bottom) with its lower-left corner at ``(x, y)``.

    ``scale`` is the world size of one image pixel. Only the translation and
    scale of attached transforms are honoured (the image stays axis-aligned).
    """

    def __init__(self, img, x, y, scale):
        super().__init__()
        self.img = np.asarray(img)
        self.x = x
        self.y = y
        self.scale = scale

    def _paint(self, canvas: "Canvas", ctx: DrawContext) -> None:
        h, w = self.img.shape[:2]
        x0, y0, s = _scalar(self.x), _scalar(self.y), _scalar(self.scale)
        corners = ctx.apply(np.array([[x0, y0], [x0 + w * s, y0 + h * s]]))
        (xa, ya), (xb, yb) = corners
        canvas.image(self.img, (min(xa, xb), max(xa, xb)), (min(ya, yb), max(ya, yb)))


class Grid(_Stroked):
    """Evenly spaced horizontal and vertical lines over a ``length``-wide square."""

    def __init__(self, spacing: float = 0.1, length: float = 50, width: float = 0.5):
        super().__init__(width)
        self.spacing = spacing
        self.length = length

    def _paint(self, canvas: "Canvas", ctx: DrawContext) -> None:
        half = self.length / 2
        for c in np.arange(-half, half, self.spacing):
            for seg in (((c, -half), (c, half)), ((-half, c), (half, c))):
                canvas.polyline(ctx.apply(np.array(seg, dtype=np.float64)), ctx.color, ctx.line_width or 1.0)


# ---------------------------------------------------------------- factories
def make_ellipse(
    radius_x: float = 10, radius_y: float = 5, res: int = 30, filled: bool = True, angle: float = 2 * math.pi
) -> Geom:
    """An ellipse (or a sector of ``angle`` radians centred on +x) as ``res`` vertices."""
    ts = -angle / 2 + angle * np.arange(res) / res
    pts = [(math.cos(t) * radius_x, math.sin(t) * radius_y) for t in ts.tolist()]
    if angle % (2 * math.pi) != 0:
        pts.append((0.0, 0.0))  # close the sector through the centre
    return FilledPolygon(pts) if filled else PolyLine(pts, True)


def make_circle(radius: float = 10, res: int = 30, filled: bool = True, angle: float = 2 * math.pi) -> Geom:
    """A circle of ``radius`` centred at the origin (see :func:`make_ellipse`)."""
    return make_ellipse(radius_x=radius, radius_y=radius, res=res, filled=filled, angle=angle)


def make_polygon(v, filled: bool = True, draw_border: float = True) -> Geom:
    """A filled polygon, or its closed outline when not ``filled``."""
    return FilledPolygon(v, draw_border=draw_border) if filled else PolyLine(v, True)


def make_polyline(v) -> Geom:
    """An open chain of segments through ``v``."""
    return PolyLine(v, False)


def make_capsule(length: float, width: float) -> Geom:
    """A stadium from ``x=0`` to ``x=length`` with round caps of diameter ``width``."""
    body = make_polygon([(0, -width / 2), (0, width / 2), (length, width / 2), (length, -width / 2)])
    tail = make_circle(width / 2)
    head = make_circle(width / 2)
    head.add_attr(Transform(translation=(length, 0)))
    return Compound([body, tail, head])


def shape_geom(shape) -> Geom:
    """The geom of a collision shape, centred at the origin in the body frame.

    Entities and scenes place it with a :class:`Transform`. Boxes span
    ``length`` along body x; hollow boxes are drawn as outlines so what lives
    inside them stays visible; lines use their pixel ``width``.
    """
    kind = getattr(shape, "kind", type(shape).__name__.lower())
    if kind == "sphere":
        return make_circle(shape.radius)
    if kind == "box":
        hl, hw = shape.length / 2, shape.width / 2
        corners = [(-hl, -hw), (-hl, hw), (hl, hw), (hl, -hw)]
        if getattr(shape, "hollow", False):
            outline = make_polygon(corners, filled=False)
            outline.set_linewidth(2)
            return outline
        return make_polygon(corners)
    if kind == "line":
        return Line((-shape.length / 2, 0.0), (shape.length / 2, 0.0), width=getattr(shape, "width", 2))
    raise TypeError(f"no geometry for shape {shape!r} (kind {kind!r})")


def render_function_util(
    f: Callable,
    plot_range: Union[float, Tuple[float, float], Tuple[Tuple[float, float], Tuple[float, float]]],
    precision: float = 0.01,
    cmap_range: Optional[Tuple[float, float]] = None,
    cmap_alpha: float = 1.0,
    cmap_name: str = "viridis",
) -> Image:
    """Sample ``f(points [N, 2]) -> [N] | [N, 1] | [N, 4]`` on a grid and return it as an Image.

    Scalar outputs are coloured with a matplotlib colormap (matplotlib must be
    installed for that case); ``[N, 4]`` outputs are RGBA in 0..1.
    """
    if isinstance(plot_range, (int, float)):
        (x_min, x_max), (y_min, y_max) = (-plot_range, plot_range), (-plot_range, plot_range)
    elif isinstance(plot_range[0], (int, float)):
        (x_min, x_max), (y_min, y_max) = (-plot_range[0], plot_range[0]), (-plot_range[1], plot_range[1])
    else:
        (x_min, x_max), (y_min, y_max) = plot_range
    xs = np.arange(x_min, x_max, precision)
    ys = np.arange(y_min, y_max, precision)
    gx, gy = np.meshgrid(xs, ys)  # [len(ys), len(xs)]: row index grows with y
    out = f(np.stack([gx.ravel(), gy.ravel()], axis=-1))
    if hasattr(out, "detach"):
        out = out.detach().cpu().numpy()
    out = np.asarray(out, dtype=np.float64)
    if out.ndim == 2 and out.shape[1] == 1:
        out = out[:, 0]
    if out.ndim == 1:
        try:
            from matplotlib import colormaps
        except ImportError as err:
            raise ImportError("render_function_util needs matplotlib for scalar fields: pip install matplotlib") from err
        lo = out.min() if cmap_range is None or cmap_range[0] is None else cmap_range[0]
        hi = out.max() if cmap_range is None or cmap_range[1] is None else cmap_range[1]
        norm = np.clip((out - lo) / (hi - lo if hi > lo else 1.0), 0.0, 1.0)
        out = colormaps[cmap_name](norm)
        out[:, 3] = cmap_alpha
    img = out.reshape(len(ys), len(xs), 4) * 255
    return Image(img, x=x_min, y=y_min, scale=precision)


# ------------------------------------------------------------------- viewer
class Viewer:
    """A headless stand-in for VMAS's window: collects geoms, renders arrays.

    ``display`` and ``visible`` are accepted for signature compatibility and
    ignored: there is never a window.
    """

    def __init__(self, width: int, height: int, display=None, visible: bool = False):
        self.width = int(width)
        self.height = int(height)
        self.geoms: List[Geom] = []
        self.onetime_geoms: List[Geom] = []
        self.bounds: Optional[Tuple[float, float, float, float]] = None
        self._last: Optional[np.ndarray] = None

    def set_bounds(self, left, right, bottom, top) -> None:
        """Set the world rectangle shown by the image."""
        left, right, bottom, top = (_scalar(v) for v in (left, right, bottom, top))
        if not (right > left and top > bottom):
            raise ValueError(f"invalid bounds {(left, right, bottom, top)}")
        self.bounds = (left, right, bottom, top)

    def add_geom(self, geom: Geom) -> None:
        self.geoms.append(geom)

    def add_onetime(self, geom: Geom) -> None:
        self.onetime_geoms.append(geom)

    def add_onetime_list(self, geoms: Iterable[Geom]) -> None:
        self.onetime_geoms.extend(geoms)

    def render(self, return_rgb_array: bool = False) -> Optional[np.ndarray]:
        """Draw permanent then one-time geoms, text last; clear the one-time ones."""
        from vmas_ros.simulator.canvas import Canvas

        left, right, bottom, top = self.bounds or (-1.0, 1.0, -1.0, 1.0)
        canvas = Canvas(self.width, self.height, (left, right), (bottom, top))
        texts = []
        for geom in self.geoms + self.onetime_geoms:
            if isinstance(geom, TextLine):
                texts.append(geom)
            else:
                geom.draw(canvas)
        for geom in texts:
            geom.draw(canvas)
        self.onetime_geoms = []
        self._last = canvas.to_array()
        return self._last if return_rgb_array else None

    def get_array(self) -> Optional[np.ndarray]:
        """The last rendered frame (``[H, W, 3]`` uint8), or None before the first."""
        return self._last

    def close(self) -> None:
        """Nothing to release; kept so VMAS-style teardown code runs."""
