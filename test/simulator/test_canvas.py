"""Canvas mapping and the VMAS-compatible geoms, checked pixel by pixel."""
import math

import numpy as np
import pytest
import torch

from vmas_ros.simulator import rendering
from vmas_ros.simulator.shapes import Box, Line, Sphere
from vmas_ros.simulator.canvas import Canvas

WHITE = np.array([255, 255, 255])


def _canvas(size=200, half=1.0, ss=2):
    return Canvas(size, size, (-half, half), (-half, half), supersample=ss)


def _painted(img, tol=30):
    """Mask of pixels that differ from the white background."""
    return np.abs(img.astype(int) - WHITE).sum(-1) > tol


def test_world_to_pixel_corners_and_centre():
    c = Canvas(400, 200, (-2.0, 2.0), (-1.0, 1.0))
    px = c.world_to_pixel([(-2, 1), (2, -1), (0, 0), (-2, -1), (2, 1)])
    np.testing.assert_allclose(px, [(0, 0), (400, 200), (200, 100), (0, 200), (400, 0)])
    assert c.pixels_per_unit == (100.0, 100.0)


def test_empty_canvas_is_white_uint8():
    img = _canvas(50).to_array()
    assert img.shape == (50, 50, 3) and img.dtype == np.uint8
    assert (img == 255).all()


def test_invalid_ranges_raise():
    with pytest.raises(ValueError):
        Canvas(10, 10, (1, 1), (0, 1))


def test_red_circle_at_origin_lands_at_centre():
    c = _canvas(200)
    g = rendering.make_circle(0.2)
    g.set_color(1, 0, 0)
    g.draw(c)
    img = c.to_array()
    assert tuple(img[100, 100]) == (255, 0, 0)
    mask = _painted(img)
    ys, xs = np.nonzero(mask)
    # radius 0.2 world = 20 px; centroid at the image centre
    assert abs(xs.mean() - 99.5) < 0.5 and abs(ys.mean() - 99.5) < 0.5
    assert 18 <= (xs.max() - xs.min() + 1) / 2 <= 21
    assert tuple(img[100, 125]) == (255, 255, 255)


def test_canvas_circle_primitive_and_alpha_blend():
    c = _canvas(100)
    c.circle((0.5, 0.5), 0.2, fill=(0, 0, 1, 0.5))
    img = c.to_array()
    # (0.5, 0.5) world -> pixel (75, 25); half-alpha blue over white
    r, g, b = img[25, 75]
    assert b == 255 and abs(int(r) - 128) <= 2 and abs(int(g) - 128) <= 2


def test_box_rotated_90_degrees_covers_rotated_rectangle():
    c = _canvas(200, ss=1)
    g = rendering.shape_geom(Box(length=1.0, width=0.2))
    xf = rendering.Transform()
    xf.set_rotation(math.pi / 2)
    g.add_attr(xf)
    g.set_color(0, 0, 1)
    g.draw(c)
    mask = _painted(c.to_array())
    ys, xs = np.nonzero(mask)
    # after rotation: 0.2 wide in x (20 px), 1.0 tall in y (100 px)
    assert 19 <= xs.max() - xs.min() + 1 <= 22
    assert 99 <= ys.max() - ys.min() + 1 <= 102
    assert mask[60:140, 95:105].all()
    assert not mask[100, 20:80].any() and not mask[100, 120:180].any()


def test_line_shape_has_its_length():
    c = _canvas(200, ss=1)
    g = rendering.shape_geom(Line(length=1.0))
    g.set_color(0, 0, 0)
    g.draw(c)
    mask = _painted(c.to_array())
    ys, xs = np.nonzero(mask)
    assert 99 <= xs.max() - xs.min() + 1 <= 102  # 1.0 world = 100 px
    assert ys.max() - ys.min() + 1 <= 3  # a thin horizontal stroke (width 2 px)


def test_line_width_is_in_pixels():
    thin, thick = _canvas(100, ss=1), _canvas(100, ss=1)
    rendering.Line((-0.5, 0), (0.5, 0), width=1).draw(thin)
    rendering.Line((-0.5, 0), (0.5, 0), width=7).draw(thick)
    rows = lambda cv: np.unique(np.nonzero(_painted(cv.to_array()))[0]).size
    assert rows(thin) <= 2 and 6 <= rows(thick) <= 8


def test_hollow_box_has_empty_interior():
    c = _canvas(200)
    g = rendering.shape_geom(Box(1.0, 1.0, hollow=True))
    g.set_color(1, 0, 0)
    g.draw(c)
    img = c.to_array()
    mask = _painted(img)
    assert not mask[60:140, 60:140].any()
    assert mask[50, 100] and mask[100, 50] and mask[149, 100] and mask[100, 149]


def test_solid_box_is_filled():
    c = _canvas(200)
    g = rendering.shape_geom(Box(1.0, 1.0))
    g.set_color(1, 0, 0)
    g.draw(c)
    assert (c.to_array()[60:140, 60:140] == (255, 0, 0)).all()


def test_sphere_shape_geom_radius():
    c = _canvas(200)
    g = rendering.shape_geom(Sphere(0.5))
    g.draw(c)
    ys, xs = np.nonzero(_painted(c.to_array()))
    assert 97 <= xs.max() - xs.min() + 1 <= 101


def test_transform_scale_rotate_translate_order():
    xf = rendering.Transform(translation=(1.0, 2.0), rotation=math.pi / 2, scale=(2.0, 1.0))
    p = xf.matrix() @ np.array([1.0, 0.0, 1.0])
    # scale (2, 0), rotate to (0, 2), translate to (1, 4)
    np.testing.assert_allclose(p[:2], (1.0, 4.0), atol=1e-12)


def test_transforms_compose_first_added_is_innermost():
    g = rendering.Point()
    rot = rendering.Transform()
    rot.set_rotation(math.pi / 2)
    move = rendering.Transform()
    move.set_translation(1.0, 0.0)
    g.add_attr(move)
    g.add_attr(rot)  # added last: applied to the already translated point
    ctx = g.context()
    np.testing.assert_allclose(ctx.apply(np.zeros((1, 2)))[0], (0.0, 1.0), atol=1e-12)
    g2 = rendering.Point()
    g2.add_attr(rot)
    g2.add_attr(move)
    np.testing.assert_allclose(g2.context().apply(np.zeros((1, 2)))[0], (1.0, 0.0), atol=1e-12)


def test_translation_moves_pixels():
    c = _canvas(200)
    g = rendering.make_circle(0.1)
    g.set_color(0, 1, 0)
    xf = rendering.Transform()
    xf.set_translation(torch.tensor(0.5), torch.tensor(-0.5))  # tensors are accepted
    xf.set_rotation(torch.tensor([0.3]))
    g.add_attr(xf)
    g.draw(c)
    img = c.to_array()
    assert tuple(img[150, 150]) == (0, 255, 0)
    assert tuple(img[100, 100]) == (255, 255, 255)


def test_compound_children_take_the_compound_colour_and_transform():
    a = rendering.make_circle(0.1)
    a.set_color(1, 0, 0)
    b = rendering.make_circle(0.1)
    b.add_attr(rendering.Transform(translation=(0.5, 0)))
    comp = rendering.Compound([a, b])
    comp.set_color(0, 0, 1)
    comp.add_attr(rendering.Transform(translation=(0, 0.5)))
    c = _canvas(200)
    comp.draw(c)
    img = c.to_array()
    assert tuple(img[50, 100]) == (0, 0, 255)  # (0, 0.5)
    assert tuple(img[50, 150]) == (0, 0, 255)  # (0.5, 0.5)


def test_polyline_accepts_tensor_vertices():
    c = _canvas(100, ss=1)
    g = rendering.PolyLine(torch.tensor([[-0.5, -0.5], [0.5, 0.5]]), close=False)
    g.set_linewidth(3)
    g.draw(c)
    mask = _painted(c.to_array())
    assert mask[50, 50] and mask[26, 74] and not mask[26, 26]


def test_partial_circle_sector():
    c = _canvas(200, ss=1)
    g = rendering.make_circle(0.5, angle=math.pi, filled=True)  # half disc facing +x
    g.draw(c)
    mask = _painted(c.to_array())
    assert mask[100, 130] and not mask[100, 70]


def test_text_and_textline_draw_something():
    c = _canvas(200)
    c.text((0.0, 0.0), "hi", color=(0, 0, 0), font_size=12)
    assert _painted(c.to_array()).any()
    v = rendering.Viewer(200, 100)
    v.set_bounds(-1.0, 1.0, -0.5, 0.5)
    t = rendering.TextLine("abc", font_size=12, x=5, y=5)
    v.add_onetime(t)
    img = v.render(return_rgb_array=True)
    ys, xs = np.nonzero(_painted(img))
    assert ys.min() > 60 and xs.min() >= 4  # bottom-left corner, pixel coordinates


def test_image_geom_and_function_plot_rgba():
    rgba = np.zeros((2, 2, 4))
    rgba[0, :, 0] = 255  # bottom row red
    rgba[1, :, 2] = 255  # top row blue
    rgba[..., 3] = 255
    g = rendering.Image(rgba, x=-1.0, y=-1.0, scale=1.0)
    c = _canvas(100)
    g.draw(c)
    img = c.to_array()
    assert tuple(img[80, 50]) == (255, 0, 0) and tuple(img[20, 50]) == (0, 0, 255)

    def f(pos):
        out = np.zeros((pos.shape[0], 4))
        out[:, 1] = 1.0
        out[:, 3] = 1.0
        return out

    geom = rendering.render_function_util(f, plot_range=1.0, precision=0.1)
    c2 = _canvas(100)
    geom.draw(c2)
    assert tuple(c2.to_array()[50, 50]) == (0, 255, 0)


def test_viewer_clears_onetime_geoms():
    v = rendering.Viewer(50, 50)
    v.set_bounds(-1, 1, -1, 1)
    v.add_onetime(rendering.make_circle(0.5))
    first = v.render(return_rgb_array=True)
    second = v.render(return_rgb_array=True)
    assert _painted(first).any() and not _painted(second).any()
    assert v.render() is None and v.get_array() is not None
