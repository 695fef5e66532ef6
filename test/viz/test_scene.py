"""render_world on a tiny duck-typed world, plus frame export."""
from enum import Enum
from types import SimpleNamespace as NS

import numpy as np
import pytest
import torch
from PIL import Image

from vmas_ros.simulator import rendering
from vmas_ros.simulator.shapes import Box, Line, Sphere
from vmas_ros.viz import render_world, save_frames, view_bounds

B = 3


class _Palette(Enum):
    RED = (1.0, 0.0, 0.0)
    BLUE = (0.0, 0.0, 1.0)


def _entity(shape, pos, rot=0.0, color=(1.0, 0.0, 0.0), alpha=1.0, name="e"):
    return NS(
        name=name,
        shape=shape,
        color=color,
        alpha=alpha,
        state=NS(pos=torch.tensor([list(pos)] * B), rot=torch.full((B, 1), float(rot)), c=None, force=None),
        is_rendering=torch.ones(B, dtype=torch.bool),
    )


def _world(entities, agents=(), x_semidim=None, y_semidim=None, dim_c=0):
    return NS(entities=list(entities), agents=list(agents), x_semidim=x_semidim, y_semidim=y_semidim, dim_c=dim_c)


def _bounds(half=1.0):
    return (-half, half, -half, half)


def _painted(img, tol=30):
    return np.abs(img.astype(int) - 255).sum(-1) > tol


def test_landmark_circle_at_centre_with_its_colour():
    lm = _entity(Sphere(0.2), (0.0, 0.0), color=_Palette.RED)
    img = render_world(_world([lm]), width=100, height=100, visible_bounds=_bounds())
    assert img.shape == (100, 100, 3) and img.dtype == np.uint8
    assert tuple(img[50, 50]) == (255, 0, 0)
    assert tuple(img[5, 5]) == (255, 255, 255)


def test_agent_alpha_blends():
    agent = _entity(Sphere(0.2), (0.0, 0.0), color=(0.0, 0.0, 1.0), alpha=0.5)
    img = render_world(_world([agent], [agent]), width=100, height=100, visible_bounds=_bounds())
    r, g, b = (int(v) for v in img[50, 50])
    assert b == 255 and abs(r - 128) <= 2 and abs(g - 128) <= 2


def test_moving_entity_changes_image_and_env_index_selects_row():
    agent = _entity(Sphere(0.1), (0.0, 0.0))
    world = _world([agent], [agent])
    before = render_world(world, visible_bounds=_bounds(), width=100, height=100)
    agent.state.pos[0] = torch.tensor([0.5, 0.5])
    after = render_world(world, visible_bounds=_bounds(), width=100, height=100)
    assert not np.array_equal(before, after)
    assert tuple(after[25, 75]) == (255, 0, 0) and tuple(after[50, 50]) == (255, 255, 255)
    other_env = render_world(world, env_index=1, visible_bounds=_bounds(), width=100, height=100)
    np.testing.assert_array_equal(other_env, before)


def test_is_rendering_false_hides_entity_in_that_env_only():
    lm = _entity(Box(0.5, 0.5), (0.0, 0.0))
    lm.is_rendering[1] = False
    world = _world([lm])
    shown = render_world(world, env_index=0, visible_bounds=_bounds(), width=80, height=80)
    hidden = render_world(world, env_index=1, visible_bounds=_bounds(), width=80, height=80)
    assert _painted(shown).any()
    assert not _painted(hidden).any()


def test_rotated_box_entity():
    lm = _entity(Box(1.0, 0.2), (0.0, 0.0), rot=np.pi / 2, color=(0.0, 0.6, 0.0))
    img = render_world(_world([lm]), visible_bounds=_bounds(), width=200, height=200)
    ys, xs = np.nonzero(_painted(img))
    assert 19 <= xs.max() - xs.min() + 1 <= 23 and 99 <= ys.max() - ys.min() + 1 <= 103


def test_line_and_hollow_box_entities():
    wall = _entity(Line(1.0), (0.0, 0.5), color=(0.0, 0.0, 0.0))
    room = _entity(Box(0.8, 0.8, hollow=True), (0.0, -0.4), color=(0.0, 0.0, 1.0))
    img = render_world(_world([wall, room]), visible_bounds=_bounds(), width=200, height=200)
    mask = _painted(img)
    ys, xs = np.nonzero(mask[:60])
    assert 99 <= xs.max() - xs.min() + 1 <= 102
    # the box spans pixels x 60..140, y 100..180: outline only, empty inside
    assert not mask[105:175, 65:135].any()
    assert mask[140, 59:61].any() and mask[140, 139:141].any() and mask[179:181, 100].any()


def test_world_bounds_outline_drawn_only_when_asked():
    world = _world([], x_semidim=0.5, y_semidim=0.5)
    img = render_world(world, visible_bounds=_bounds(), width=100, height=100)
    mask = _painted(img, tol=10)
    # a 1-px line on a pixel boundary (world +-0.5 -> pixel 25 / 75) may land on either side
    assert mask[24:26, 50].any() and mask[50, 24:26].any() and mask[74:76, 50].any() and mask[50, 74:76].any()
    assert not mask[30:70, 30:70].any()
    plain = render_world(world, visible_bounds=_bounds(), width=100, height=100, plot_bounds=False)
    assert not _painted(plain, tol=10).any()
    only_x = render_world(_world([], x_semidim=0.5), visible_bounds=_bounds(), width=100, height=100)
    m = _painted(only_x, tol=10)
    assert m[50, 24:26].any() and m[50, 74:76].any() and not m[24:26, 50].any()


def test_view_zooms_out_to_keep_agents_visible():
    near = _entity(Sphere(0.05), (0.1, 0.1))
    far = _entity(Sphere(0.05), (3.0, 0.0))
    xmin, xmax, ymin, ymax = view_bounds(_world([near], [near]), zoom=1.0)
    assert (xmin, xmax, ymin, ymax) == (-1.0, 1.0, -1.0, 1.0)
    xmin, xmax, ymin, ymax = view_bounds(_world([near, far], [near, far]), zoom=1.0)
    assert xmax >= 3.0 + 0.05 and xmax == -xmin and ymax == xmax  # square image keeps aspect
    # wide image: x extent follows the aspect ratio
    xmin, xmax, ymin, ymax = view_bounds(_world([near], [near]), width=200, height=100, zoom=1.0)
    assert xmax == pytest.approx(2.0) and ymax == pytest.approx(1.0)
    img = render_world(_world([near, far], [near, far]), width=200, height=200, zoom=1.0)
    ys, xs = np.nonzero(_painted(img))
    assert xs.max() < 200 and xs.max() > 180  # far agent inside the frame near the right edge


def test_extra_geoms_under_entities_like_vmas():
    agent = _entity(Sphere(0.2), (0.0, 0.0), color=(1.0, 0.0, 0.0))
    pitch = rendering.make_polygon([(-1, -1), (-1, 1), (1, 1), (1, -1)], draw_border=False)
    pitch.set_color(0.0, 1.0, 0.0)
    img = render_world(_world([agent], [agent]), extra_geoms=[pitch], visible_bounds=_bounds(), width=100, height=100)
    assert tuple(img[50, 50]) == (255, 0, 0) and tuple(img[5, 5]) == (0, 255, 0)


def test_render_origin_recentres_view():
    agent = _entity(Sphere(0.1), (5.0, 3.0))
    xmin, xmax, ymin, ymax = view_bounds(_world([agent], [agent]), zoom=1.0, render_origin=(5.0, 3.0))
    assert (xmin, xmax, ymin, ymax) == (4.0, 6.0, 2.0, 4.0)
    img = render_world(_world([agent], [agent]), width=100, height=100, zoom=1.0, render_origin=(5.0, 3.0))
    assert tuple(img[50, 50]) == (255, 0, 0)


def test_sensors_and_extra_geoms_drawn_on_top():
    agent = _entity(Sphere(0.3), (0.0, 0.0), color=(1.0, 0.0, 0.0))

    def sensor_render(env_index=0):
        ray = rendering.Line((0.0, 0.0), (0.9, 0.0), width=3)
        ray.set_color(0.0, 0.0, 0.0)
        return [ray]

    agent.sensors = [NS(render=sensor_render)]
    dot = rendering.make_circle(0.05)
    dot.set_color(0.0, 1.0, 0.0)
    img = render_world(
        _world([agent], [agent]), extra_geoms=[dot], visible_bounds=_bounds(), width=100, height=100, extra_on_top=True
    )
    assert tuple(img[50, 50]) == (0, 255, 0)  # extra geom over the agent when asked
    assert img[50, 70].max() < 60  # sensor ray over the agent body
    assert img[50, 90].max() < 60  # and beyond it


def test_comm_label_drawn_when_dim_c():
    agent = _entity(Sphere(0.1), (0.0, 0.0))
    agent.state.c = torch.tensor([[0.25, 0.75]] * B)
    silent = render_world(_world([agent], [agent], dim_c=0), visible_bounds=_bounds(), width=200, height=200)
    talking = render_world(_world([agent], [agent], dim_c=2), visible_bounds=_bounds(), width=200, height=200)
    diff = np.abs(talking.astype(int) - silent.astype(int)).sum(-1) > 0
    ys, xs = np.nonzero(diff)
    assert diff.any() and xs.min() >= 105 and ys.max() <= 95  # up-right of the agent


def test_gif_written_and_reread(tmp_path):
    agent = _entity(Sphere(0.1), (0.0, 0.0))
    world = _world([agent], [agent])
    frames = []
    for k in range(5):
        agent.state.pos[0, 0] = -0.6 + 0.3 * k
        frames.append(render_world(world, visible_bounds=_bounds(), width=64, height=48))
    path = save_frames(frames, tmp_path / "out" / "roll.gif", fps=5)
    with Image.open(path) as im:
        assert im.n_frames == 5
        assert im.size == (64, 48)
        assert im.info["duration"] == 200
        im.seek(2)
        rgb = np.asarray(im.convert("RGB"))
    assert rgb[24, 32, 0] > 200 and rgb[24, 32, 1] < 60  # the middle frame has the agent at the centre


def test_png_saves_last_frame_by_default(tmp_path):
    a = np.zeros((10, 12, 3), np.uint8)
    b = np.full((10, 12, 3), 200, np.uint8)
    save_frames([a, b], tmp_path / "still.png")
    with Image.open(tmp_path / "still.png") as im:
        assert (np.asarray(im) == 200).all()
    save_frames([a, b], tmp_path / "first.PNG", png_frame=0)
    with Image.open(tmp_path / "first.PNG") as im:
        assert (np.asarray(im) == 0).all()


def test_bad_suffix_and_empty_frames(tmp_path):
    with pytest.raises(ValueError, match=r"\.avi.*\.gif.*\.png.*\.mp4"):
        save_frames([np.zeros((4, 4, 3), np.uint8)], tmp_path / "x.avi")
    with pytest.raises(ValueError):
        save_frames([], tmp_path / "x.gif")


def test_mp4_needs_imageio_or_says_how_to_get_it(tmp_path):
    frames = [np.zeros((16, 16, 3), np.uint8)] * 3
    try:
        import imageio  # noqa: F401
        import imageio_ffmpeg  # noqa: F401
    except ImportError:
        with pytest.raises(ImportError, match="pip install imageio imageio-ffmpeg"):
            save_frames(frames, tmp_path / "x.mp4")
    else:
        assert save_frames(frames, tmp_path / "x.mp4").stat().st_size > 0


def test_no_pyglet_import():
    """Rendering a scenario never loads pyglet (checked in a fresh interpreter: other tests import VMAS's
    renderer, which does)."""
    import subprocess
    import sys

    code = ("import sys, vmas_ros; env = vmas_ros.make_env('simple_spread', num_envs=1); env.render(); "
            "assert 'pyglet' not in sys.modules, 'pyglet was imported'")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
