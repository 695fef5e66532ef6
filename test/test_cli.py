"""The `vmas-ros` command line: render, demo, list and argument errors (run in-process)."""
from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from vmas_ros.cli import main


def test_render_gif_is_decodable_and_moves(tmp_path):
    out = tmp_path / "spread.gif"
    assert main(["render", "--scenario", "simple_spread", "--steps", "6", "--size", "160", "--quiet", "--out", str(out)]) == 0
    with Image.open(out) as gif:
        frames = []
        for index in range(gif.n_frames):
            gif.seek(index)
            frames.append(np.asarray(gif.convert("RGB")))
    assert frames[0].shape == (160, 160, 3)
    assert len(frames) >= 2 and not np.array_equal(frames[0], frames[-1]), "agents move between frames"
    assert (frames[0] != 255).any(), "not blank"


def test_render_png_writes_the_last_frame(tmp_path):
    out = tmp_path / "fall.png"
    assert main(["render", "--scenario", "waterfall", "--steps", "3", "--random", "--quiet", "--out", str(out)]) == 0
    image = np.asarray(Image.open(out).convert("RGB"))
    assert image.shape == (700, 700, 3) and (image != 255).any()


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["render", "--steps", "2", "--out", "x.avi"], ".gif"),
        (["render", "--scenario", "nope", "--out", "x.gif"], "valid scenarios"),
        (["demo", "--scenario", "nope"], "valid scenarios"),
        (["demo", "--scenario-kwargs", "[1]"], None),
    ],
)
def test_bad_arguments_are_refused_with_a_reason(argv, needle, capsys):
    if needle is None:
        with pytest.raises(SystemExit, match="JSON object"):
            main(argv)
        return
    assert main(argv) == 2
    assert needle in capsys.readouterr().err


def test_demo_reports_heuristic_beats_random(capsys):
    assert main(["demo", "--num-envs", "8", "--steps", "20", "--quiet"]) == 0
    out = capsys.readouterr().out
    values = {line.split()[0]: float(line.split()[-1]) for line in out.splitlines() if "mean return" in line}
    assert values["heuristic"] > values["random"]


def test_list_names_the_scenarios(capsys):
    assert main(["list"]) == 0
    assert {"simple_spread", "waterfall"} <= set(capsys.readouterr().out.split())


@pytest.mark.parametrize("scenario", __import__("vmas_ros").list_scenarios())
def test_every_scenario_renders(scenario, tmp_path):
    out = tmp_path / f"{scenario}.png"
    assert main(["render", "--scenario", scenario, "--steps", "2", "--size", "120", "--quiet", "--out", str(out)]) == 0
    image = np.asarray(Image.open(out).convert("RGB"))
    # width as asked; height follows the scenario's viewer aspect (give_way is wide)
    assert image.shape[1:] == (120, 3) and 20 <= image.shape[0] <= 240 and (image != 255).any()
