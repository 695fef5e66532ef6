"""Interactive play: the InteractivePlayer logic, the real pygame loop (SDL dummy video
driver, scripted events) and a subprocess under Xvfb."""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from PIL import Image

import vmas_ros
from vmas_ros.scenarios import load
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.dynamics.holonomic_with_rot import HolonomicWithRotation
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.interactive_rendering import (
    InteractivePlayer,
    add_play_arguments,
    format_observation,
    render_interactively,
    run_play_command,
)

pygame = pytest.importorskip("pygame")

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def headless_sdl(monkeypatch):
    """No real display or sound card in tests: SDL's dummy drivers, set before pygame initialises."""
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    monkeypatch.setenv("SDL_AUDIODRIVER", "dummy")
    yield
    pygame.quit()


class _RotScenario(BaseScenario):
    """Two agents: one with (fx, fy, torque) actions, one plain holonomic; no episode end."""

    def make_world(self, batch_dim, device, **kwargs):
        world = World(batch_dim, device)
        world.add_agent(Agent("rot", shape=Sphere(0.05), dynamics=HolonomicWithRotation(), u_range=[1.0, 0.5, 0.3]))
        world.add_agent(Agent("plain", shape=Sphere(0.05), u_range=2.0))
        world.add_landmark(Landmark("goal", collide=False))
        return world

    def reset_world_at(self, env_index=None):
        for i, entity in enumerate(self.world.entities):
            pos = torch.tensor([[-0.5 + 0.5 * i, 0.0]], device=self.world.device)
            entity.set_pos(pos.expand(self.world.batch_dim, 2) if env_index is None else pos[0], batch_index=env_index)

    def observation(self, agent):
        return torch.cat([agent.state.pos, agent.state.vel], dim=-1)

    def reward(self, agent):
        return -agent.state.pos.norm(dim=-1)


def _player(scenario="simple_spread", control_two_agents=False, **kwargs) -> InteractivePlayer:
    env = vmas_ros.make_env(scenario, num_envs=1, continuous_actions=True, seed=0, **kwargs)
    return InteractivePlayer(env, control_two_agents=control_two_agents)


# ----------------------------------------------------------------- InteractivePlayer
def test_right_gives_the_selected_agent_full_positive_x():
    player = _player()
    player.key_down("right")
    actions = player.actions()
    u_range = player.env.agents[0].action.u_range_tensor
    assert torch.equal(actions[0], torch.tensor([[u_range[0].item(), 0.0]]))
    assert all(torch.count_nonzero(a) == 0 for a in actions[1:])
    player.key_down("up")
    assert torch.equal(player.actions()[0], torch.tensor([[u_range[0].item(), u_range[1].item()]]))
    player.key_up("right")
    player.key_up("up")
    assert torch.count_nonzero(player.actions()[0]) == 0, "releasing the keys must stop the action"


def test_opposite_keys_cancel_and_rotation_uses_the_third_component():
    player = _player(_RotScenario())
    player.key_down("left")
    player.key_down("right")
    player.key_down("m")
    assert torch.allclose(player.actions()[0], torch.tensor([[0.0, 0.0, 0.3]]))
    player.key_up("m")
    player.key_down("n")
    player.key_down("down")
    assert torch.allclose(player.actions()[0], torch.tensor([[0.0, -0.5, -0.3]]))
    player.key_down("tab")  # the holonomic agent has no third component: M/N are ignored, not an error
    assert player.selected == 1
    assert torch.allclose(player.actions()[1], torch.tensor([[0.0, -2.0]]))
    player.step()


def test_tab_cycles_the_selected_agent():
    player = _player()
    n = player.env.n_agents
    seen = [player.selected]
    for _ in range(n):
        player.key_down("tab")
        player.key_up("tab")
        seen.append(player.selected)
    assert seen == list(range(n)) + [0]
    player.key_down("tab")
    player.key_down("right")
    assert [torch.count_nonzero(a).item() for a in player.actions()] == [0, 1] + [0] * (n - 2)
    assert "agent_1" in player.info_lines()[0]
    player.key_down("tab")
    player.key_down("tab")
    assert "agent_0" in player.info_lines()[0]


def test_holding_right_moves_the_agent_right_and_r_resets():
    player = _player()
    x0 = player.env.agents[0].state.pos[0, 0].item()
    player.key_down("right")
    for _ in range(5):
        player.step()
    assert player.steps == 5 and player.total_steps == 5
    assert player.env.agents[0].state.pos[0, 0].item() > x0 + 0.05
    assert player.env.agents[1].state.vel.abs().max().item() == 0.0, "undriven agents get zero actions"
    player.key_down("r")
    assert player.steps == 0 and player.total_steps == 5
    assert player.rewards is None and player.total_rewards == [0.0] * player.env.n_agents
    assert player.env.agents[0].state.vel.abs().max().item() == 0.0, "R really reset the world"


def test_second_agent_follows_wasd_and_selection_never_collides():
    player = _player(control_two_agents=True)
    assert (player.selected, player.selected2) == (0, 1)
    player.key_down("d")
    player.key_down("e")  # simple_spread agents have 2 action components: ignored
    actions = player.actions()
    assert torch.count_nonzero(actions[0]) == 0 and actions[1][0, 0].item() == 1.0
    player.key_down("tab")
    assert player.selected == 2, "TAB skips the agent the second player drives"
    player.key_down("left shift")
    assert player.selected2 == 0, "LSHIFT skips the agent the first player drives"
    assert any(line.startswith("Second: agent_0") for line in player.info_lines())
    with pytest.raises(ValueError, match="at least 2 agents"):
        InteractivePlayer(vmas_ros.make_env(_OneAgent(), num_envs=1), control_two_agents=True)


class _OneAgent(_RotScenario):
    def make_world(self, batch_dim, device, **kwargs):
        world = World(batch_dim, device)
        world.add_agent(Agent("solo", shape=Sphere(0.05)))
        return world


def test_done_is_shown_then_the_episode_resets():
    player = _player(max_steps=3)
    for _ in range(3):
        player.step()
    assert player.done and "Done: True" in player.info_lines()[-1]
    player.step()
    assert not player.done and player.steps == 1 and player.total_steps == 4


def test_info_lines_and_observation_formatting():
    player = _player()
    player.step()
    text = "\n".join(player.info_lines())
    for part in ("Selected: agent_0", "Obs: [", "Rew: ", "Done: False", "Step: 1"):
        assert part in text
    long_obs = format_observation(torch.arange(200.0).unsqueeze(0) / 3, max_chars=50)
    assert len(long_obs) == 50 and long_obs.endswith("...")
    assert format_observation(torch.tensor([[-0.0001, 1.23456]])) == "[0.0, 1.23]"
    assert format_observation({"pos": torch.tensor([[1.0, 2.0]])}) == "{'pos': [1.0, 2.0]}"
    with pytest.raises(ValueError, match="single env"):
        InteractivePlayer(vmas_ros.make_env("simple_spread", num_envs=2))


# ------------------------------------------------------------- the real pygame loop
def _script(events_at):
    """An event_source: the pygame events to post when ``steps`` have been played."""
    return lambda steps: [pygame.event.Event(kind, key=key) if key is not None else pygame.event.Event(kind)
                          for kind, key in events_at.get(steps, [])]


def _final_x(events_at, steps=None) -> tuple:
    scenario = load("simple_spread")
    played = render_interactively(scenario, steps=steps, fps=0, event_source=_script(events_at))
    return played, scenario.world.agents[0].state.pos[0, 0].item()


def test_pygame_loop_reacts_to_posted_keys():
    _, x_idle = _final_x({}, steps=8)
    played, x_right = _final_x({0: [(pygame.KEYDOWN, pygame.K_RIGHT)]}, steps=8)
    assert played == 8
    assert x_right > x_idle + 0.1
    # released after 2 steps: moves less than when held for all 8
    _, x_tap = _final_x({0: [(pygame.KEYDOWN, pygame.K_RIGHT)], 2: [(pygame.KEYUP, pygame.K_RIGHT)]}, steps=8)
    assert x_idle < x_tap < x_right


@pytest.mark.parametrize("stop", [(pygame.QUIT, None), (pygame.KEYDOWN, pygame.K_ESCAPE)], ids=["quit", "escape"])
def test_pygame_loop_exits_cleanly_on_quit_and_escape(stop):
    with pytest.warns(RuntimeWarning, match="invisible"):  # dummy driver and no step limit
        played, _ = _final_x({0: [(pygame.KEYDOWN, pygame.K_LEFT)], 4: [stop]})
    assert played == 4
    assert not pygame.display.get_init(), "the window is closed on exit"


def test_pygame_loop_tab_and_reset_keys():
    scenario = load("simple_spread")
    events = {0: [(pygame.KEYDOWN, pygame.K_TAB), (pygame.KEYDOWN, pygame.K_UP)],
              3: [(pygame.KEYDOWN, pygame.K_r)]}
    assert render_interactively(scenario, steps=5, fps=0, event_source=_script(events)) == 5
    vel = scenario.world.agents[1].state.vel[0]
    assert vel[1].item() > 0 and scenario.world.agents[0].state.vel.abs().max().item() == 0.0


def test_save_render_writes_a_decodable_gif(tmp_path):
    name = tmp_path / "session"
    played = render_interactively("simple_spread", save_render=True, render_name=str(name), steps=4, fps=0,
                                  event_source=_script({0: [(pygame.KEYDOWN, pygame.K_DOWN)]}))
    assert played == 4
    gif = tmp_path / "session.gif"
    with Image.open(gif) as image:
        assert image.format == "GIF" and image.size == (700, 700)
        assert 2 <= image.n_frames <= 5  # initial frame + one per step (identical frames may merge)
        image.seek(image.n_frames - 1)
        assert image.convert("RGB").getextrema() != ((255, 255), (255, 255), (255, 255))


def test_play_command_helpers(tmp_path, capsys):
    parser = add_play_arguments(argparse.ArgumentParser())
    out = tmp_path / "cli.gif"
    args = parser.parse_args(["--scenario", "simple_spread", "--scenario-kwargs", '{"n_agents": 2}',
                              "--steps", "2", "--fps", "0", "--save", str(out), "--two-agents"])
    assert run_play_command(args) == 0
    assert out.is_file() and "played 2 steps" in capsys.readouterr().out
    assert run_play_command(parser.parse_args(["--scenario-kwargs", "[1]", "--steps", "1"])) == 2
    assert run_play_command(parser.parse_args(["--scenario", "no_such_scenario", "--steps", "1"])) == 2


# ------------------------------------------------------------------- a real X server
def test_subprocess_under_xvfb_or_dummy():
    """A real display (Xvfb) when xvfb-run exists; otherwise the same run on SDL's dummy driver."""
    code = "from vmas_ros.interactive_rendering import render_interactively; render_interactively('simple_spread', steps=5)"
    # report which SDL video driver really ran (the window is closed by then, so ask SDL's env choice)
    code += "; import pygame; pygame.display.init(); print('driver', pygame.display.get_driver())"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    xvfb = shutil.which("xvfb-run")
    if xvfb:
        env.pop("SDL_VIDEODRIVER")  # let SDL pick x11 on the virtual display
        cmd = [xvfb, "-a", "-s", "-screen 0 1024x768x24", sys.executable, "-c", code]
    else:
        cmd = [sys.executable, "-c", code]
    result = subprocess.run(cmd, env=env, cwd=REPO, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    assert ("driver x11" if xvfb else "driver dummy") in result.stdout, result.stdout
