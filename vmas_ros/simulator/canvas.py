"""A headless 2D drawing surface in world coordinates, backed by Pillow.

VMAS draws with OpenGL, which needs a display (or EGL) and a GPU-ish stack that
servers, CI runners and containers rarely have. A frame of a 2D simulator is a
handful of polygons, so Pillow is enough: we draw into an RGB image and hand
back a numpy array, which is all ``render(mode="rgb_array")`` and video
writers need. It sits beside :mod:`vmas_ros.simulator.rendering` (VMAS's
module of drawing primitives), whose ``Viewer`` draws onto it; ``vmas_ros.viz``
re-exports it.

Conventions
-----------
* World coordinates have y pointing up; ``x_range`` / ``y_range`` are the
  world interval shown across the width / height of the image.
* Colours are sequences of 3 or 4 floats in ``0..1`` (RGB or RGBA), the same
  convention the geoms and VMAS use. Alpha blends over what is already drawn.
* Line widths and font sizes are in output pixels, never world units: this is
  how OpenGL line widths behave, so scenario code written for VMAS keeps its
  look at any zoom.
* Antialiasing: everything is drawn at ``supersample`` times the resolution
  and box-filtered down in :meth:`Canvas.to_array`.
"""
from __future__ import annotations

from typing import Dict, Optional, Sequence, Tuple

import numpy as np
from PIL import Image, ImageDraw, ImageFont

__all__ = ["Canvas", "ColorLike"]

ColorLike = Sequence[float]

# pyglet (hence VMAS) treats font sizes as points at 96 dpi
_POINTS_TO_PIXELS = 96.0 / 72.0


def _rgba(color: ColorLike) -> Tuple[int, int, int, int]:
    """Float RGB(A) in 0..1 -> the 8-bit RGBA tuple Pillow blends with."""
    vals = [float(c) for c in color]
    if len(vals) == 3:
        vals.append(1.0)
    if len(vals) != 4:
        raise ValueError(f"a colour needs 3 or 4 components, got {len(vals)}")
    return tuple(int(round(min(max(v, 0.0), 1.0) * 255)) for v in vals)  # type: ignore[return-value]


class Canvas:
    """An image onto which world-space shapes are drawn.

    Args:
        width, height: output size in pixels.
        x_range, y_range: ``(min, max)`` world interval mapped onto the image;
            ``x_range[0]`` is the left edge and ``y_range[1]`` the top edge.
        background: RGB floats of the empty canvas (white like VMAS).
        supersample: internal resolution factor used for antialiasing
            (1 disables it).
    """

    def __init__(
        self,
        width: int,
        height: int,
        x_range: Tuple[float, float],
        y_range: Tuple[float, float],
        background: ColorLike = (1.0, 1.0, 1.0),
        supersample: int = 2,
    ):
        if width <= 0 or height <= 0:
            raise ValueError(f"canvas size must be positive, got {width}x{height}")
        x0, x1 = (float(v) for v in x_range)
        y0, y1 = (float(v) for v in y_range)
        if not (x1 > x0 and y1 > y0):
            raise ValueError(f"empty view: x_range={x_range}, y_range={y_range}")
        if int(supersample) < 1:
            raise ValueError(f"supersample must be >= 1, got {supersample}")
        self.width = int(width)
        self.height = int(height)
        self.x_range = (x0, x1)
        self.y_range = (y0, y1)
        self.supersample = int(supersample)
        ss = self.supersample
        self._image = Image.new("RGB", (self.width * ss, self.height * ss), _rgba(background)[:3])
        # drawing through an RGBA context onto an RGB image alpha-blends each call
        self._draw = ImageDraw.Draw(self._image, "RGBA")
        self._fonts: Dict[int, ImageFont.ImageFont] = {}

    # ----------------------------------------------------------------- mapping
    @property
    def pixels_per_unit(self) -> Tuple[float, float]:
        """Output pixels per world unit along x and y (equal when the aspect matches)."""
        return (
            self.width / (self.x_range[1] - self.x_range[0]),
            self.height / (self.y_range[1] - self.y_range[0]),
        )

    def world_to_pixel(self, points: "np.ndarray | Sequence[Sequence[float]]") -> np.ndarray:
        """Map world points ``[N, 2]`` (or one ``[2]`` point) to output pixel coordinates.

        Pixel ``(i, j)`` covers ``[i, i+1) x [j, j+1)``, so the world's left
        edge maps to ``x = 0`` and its top edge to ``y = 0`` (rows grow downward).
        """
        pts = np.asarray(points, dtype=np.float64)
        sx, sy = self.pixels_per_unit
        out = np.empty_like(pts)
        out[..., 0] = (pts[..., 0] - self.x_range[0]) * sx
        out[..., 1] = (self.y_range[1] - pts[..., 1]) * sy
        return out

    def _to_draw_space(self, points: "np.ndarray | Sequence[Sequence[float]]") -> list:
        """World points -> the supersampled coordinates Pillow draws with.

        Pillow puts pixel centres on integers, hence the half-pixel shift.
        """
        pts = self.world_to_pixel(np.reshape(np.asarray(points, dtype=np.float64), (-1, 2)))
        pts = pts * self.supersample - 0.5
        return [tuple(p) for p in pts.tolist()]

    def _width(self, width_px: float) -> int:
        """Output-pixel line width -> supersampled width (at least one sub-pixel, as GL)."""
        return max(1, int(round(float(width_px) * self.supersample)))

    # ---------------------------------------------------------------- drawing
    def polygon(
        self,
        points: "np.ndarray | Sequence[Sequence[float]]",
        fill: Optional[ColorLike] = None,
        outline: Optional[ColorLike] = None,
        width: float = 1.0,
    ) -> None:
        """Fill and/or outline a polygon given by world vertices ``[N, 2]``."""
        xy = self._to_draw_space(points)
        if len(xy) < 2:
            return
        if fill is not None and len(xy) >= 3:
            self._draw.polygon(xy, fill=_rgba(fill))
        if outline is not None:
            self._stroke(xy + [xy[0]], outline, width)

    def polyline(
        self,
        points: "np.ndarray | Sequence[Sequence[float]]",
        color: ColorLike,
        width: float = 1.0,
        closed: bool = False,
    ) -> None:
        """Stroke a polyline through world vertices with a width in output pixels."""
        xy = self._to_draw_space(points)
        if closed and len(xy) > 2:
            xy = xy + [xy[0]]
        self._stroke(xy, color, width)

    def _stroke(self, xy: list, color: ColorLike, width: float) -> None:
        if len(xy) == 0:
            return
        w = self._width(width)
        if len(xy) == 1 or all(p == xy[0] for p in xy):
            # a degenerate line still marks its spot, as GL does
            self._dot(xy[0], w, color)
            return
        self._draw.line(xy, fill=_rgba(color), width=w, joint="curve" if w > 2 else None)

    def circle(
        self,
        center: Sequence[float],
        radius: float,
        fill: Optional[ColorLike] = None,
        outline: Optional[ColorLike] = None,
        width: float = 1.0,
    ) -> None:
        """Draw a world-space circle (an ellipse in pixels if the axes scale differently)."""
        (cx, cy), = self._to_draw_space([center])
        sx, sy = self.pixels_per_unit
        rx = float(radius) * sx * self.supersample
        ry = float(radius) * sy * self.supersample
        box = (cx - rx, cy - ry, cx + rx, cy + ry)
        if fill is not None:
            self._draw.ellipse(box, fill=_rgba(fill))
        if outline is not None:
            self._draw.ellipse(box, outline=_rgba(outline), width=self._width(width))

    def point(self, xy: Sequence[float], color: ColorLike, size: float = 1.0) -> None:
        """Mark a world point with a dot ``size`` output pixels wide."""
        self._dot(self._to_draw_space([xy])[0], self._width(size), color)

    def _dot(self, center: Tuple[float, float], diameter: int, color: ColorLike) -> None:
        r = diameter / 2.0
        cx, cy = center
        if diameter <= 2:
            self._draw.rectangle((cx - r + 0.5, cy - r + 0.5, cx + r - 0.5, cy + r - 0.5), fill=_rgba(color))
        else:
            self._draw.ellipse((cx - r, cy - r, cx + r, cy + r), fill=_rgba(color))

    def text(
        self,
        xy: Sequence[float],
        text: str,
        color: ColorLike = (0.0, 0.0, 0.0),
        font_size: float = 15,
        pixel: bool = False,
        anchor: str = "ld",
    ) -> None:
        """Write ``text`` with its ``anchor`` (Pillow anchor codes) at ``xy``.

        ``font_size`` is in points at 96 dpi like pyglet's. With ``pixel=True``
        ``xy`` is in output pixels measured from the *bottom-left* corner (the
        OpenGL window convention VMAS's ``TextLine`` uses); otherwise it is a
        world point.
        """
        if not text:
            return
        ss = self.supersample
        if pixel:
            x, y = float(xy[0]) * ss, (self.height - float(xy[1])) * ss
        else:
            (x, y), = self._to_draw_space([xy])
        font = self._font(max(1, int(round(float(font_size) * _POINTS_TO_PIXELS * ss))))
        self._draw.text((x, y), str(text), fill=_rgba(color), font=font, anchor=anchor)

    def _font(self, size_px: int) -> ImageFont.ImageFont:
        """Pillow's bundled scalable font (no system fonts needed), cached per size."""
        font = self._fonts.get(size_px)
        if font is None:
            try:
                font = ImageFont.load_default(size=size_px)
            except TypeError:  # Pillow < 10.1 has only the fixed bitmap font
                font = ImageFont.load_default()
            self._fonts[size_px] = font
        return font

    def image(
        self,
        rgba: np.ndarray,
        x_range: Tuple[float, float],
        y_range: Tuple[float, float],
    ) -> None:
        """Alpha-composite an ``[H, W, 4]`` (or ``[H, W, 3]``) array over a world rectangle.

        Row 0 of ``rgba`` is the *bottom* of the rectangle (OpenGL image
        order, as VMAS's function plots produce); values are 0..255.
        """
        arr = np.asarray(rgba)
        if arr.ndim != 3 or arr.shape[2] not in (3, 4):
            raise ValueError(f"expected an [H, W, 3|4] image, got shape {arr.shape}")
        arr = np.clip(arr, 0, 255).astype(np.uint8)[::-1]
        if arr.shape[2] == 3:
            arr = np.concatenate([arr, np.full(arr.shape[:2] + (1,), 255, np.uint8)], axis=2)
        (l, t), (r, b) = self._to_draw_space([(x_range[0], y_range[1]), (x_range[1], y_range[0])])
        left, top = int(round(l + 0.5)), int(round(t + 0.5))
        size = (int(round(r + 0.5)) - left, int(round(b + 0.5)) - top)
        if size[0] <= 0 or size[1] <= 0:
            return
        patch = Image.fromarray(np.ascontiguousarray(arr), "RGBA").resize(size, Image.NEAREST)
        self._image.paste(patch, (left, top), patch)

    # ----------------------------------------------------------------- output
    def to_image(self) -> Image.Image:
        """The frame at output resolution as a Pillow RGB image (box-filtered down)."""
        if self.supersample == 1:
            return self._image.copy()
        return self._image.reduce(self.supersample)

    def to_array(self) -> np.ndarray:
        """The frame as a ``[height, width, 3]`` uint8 array, row 0 at the top."""
        return np.asarray(self.to_image(), dtype=np.uint8).copy()
