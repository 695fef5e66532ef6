"""Interactive play: drive agents of a scenario with the keyboard in a pygame window.

This is the "interactive rendering" of the VMAS paper (``vmas.render_interactively``),
rebuilt on our headless renderer: every frame comes from ``env.render()`` (a
Pillow-drawn RGB array) and pygame is only used to show it and read the
keyboard. That keeps OpenGL/pyglet out of the project and lets the same code
run on a desktop, under Xvfb and under SDL's ``dummy`` video driver (CI).

Keys (as in VMAS): arrows move the selected agent along x/y with its full
``u_range``, ``M``/``N`` rotate it (when its action has a third component),
``TAB`` selects the next agent, ``R`` resets, ``ESC`` or closing the window
quits. With ``control_two_agents`` a second agent follows ``W``/``A``/``S``/``D``
and ``Q``/``E`` and ``LSHIFT`` changes which agent that is.

The game logic lives in :class:`InteractivePlayer`, which knows nothing about
pygame (keys are plain names), so it is unit-testable without a window; the
pygame loop in :func:`render_interactively` only translates events and draws.
pygame is an optional dependency (``pip install vmas_ros[play]``).

It lives at VMAS's module path ``vmas.interactive_rendering``, in the top
layer of the package: it builds its env with ``make_env`` (vmas_ros.envs),
whose ``render`` draws through vmas_ros.viz. ``InteractiveEnv`` is VMAS's name
for the player class; ours is :class:`InteractivePlayer`.
"""
from __future__ import annotations

import argparse
import json
import os
import warnings
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Set, Tuple, Union

import torch

from vmas_ros.simulator.scenario import BaseScenario

__all__ = ["InteractiveEnv", "InteractivePlayer", "render_interactively", "add_play_arguments", "run_play_command"]

#: key name -> (action component, sign) for the first and the second controlled agent.
#: Signs follow VMAS: M and E turn counter-clockwise (+), N and Q clockwise (-).
PRIMARY_KEYS: Dict[str, Tuple[int, int]] = {"right": (0, 1), "left": (0, -1), "up": (1, 1), "down": (1, -1),
                                             "m": (2, 1), "n": (2, -1)}
SECONDARY_KEYS: Dict[str, Tuple[int, int]] = {"d": (0, 1), "a": (0, -1), "w": (1, 1), "s": (1, -1),
                                               "e": (2, 1), "q": (2, -1)}


def _first_env(value: Any) -> Any:
    """Env 0 of a batched tensor (or of a nested dict of them), on the CPU."""
    if isinstance(value, dict):
        return {k: _first_env(v) for k, v in value.items()}
    if isinstance(value, torch.Tensor):
        return value[0].detach().cpu()
    return value


def format_observation(obs: Any, decimals: int = 2, max_chars: int = 160) -> str:
    """Env 0's observation, rounded, as a string cut to ``max_chars`` (long ones would flood the screen)."""

    def rounded(value: Any) -> Any:
        if isinstance(value, dict):
            return {k: rounded(v) for k, v in value.items()}
        if isinstance(value, torch.Tensor):
            flat = value.float().flatten().tolist()
            return [round(x, decimals) + 0.0 for x in flat]  # + 0.0 turns -0.0 into 0.0
        return value

    text = str(rounded(_first_env(obs)))
    return text if len(text) <= max_chars else text[: max(0, max_chars - 3)] + "..."


class InteractivePlayer:
    """Keyboard state -> actions, agent selection, stepping and the info text, without pygame.

    Keys are lower-case names (``"right"``, ``"tab"``, ``"r"``, ``"left shift"``...);
    :meth:`key_down` / :meth:`key_up` mirror press and release, and an action
    lasts exactly as long as its key is held, which is how a human expects to
    steer. When an episode ends (``done``) the env is reset at the next step, so
    the frame showing ``Done: True`` is still seen.
    """

    def __init__(self, env, control_two_agents: bool = False, obs_chars: int = 160) -> None:
        if env.num_envs != 1:
            raise ValueError(f"interactive play drives a single env, got num_envs={env.num_envs}")
        if not env.continuous_actions:
            raise ValueError("interactive play needs continuous_actions=True (keys set action magnitudes)")
        if control_two_agents and env.n_agents < 2:
            raise ValueError(f"control_two_agents needs at least 2 agents, the scenario has {env.n_agents}")
        self.env = env
        self.control_two_agents = control_two_agents
        self.obs_chars = obs_chars
        self.selected = 0
        self.selected2: Optional[int] = 1 if control_two_agents else None
        self.held: Set[str] = set()
        self.quit_requested = False
        self.total_steps = 0  # steps played since the window opened, resets included
        self._reset_state(env.reset())

    # ----------------------------------------------------------------- state
    def _reset_state(self, obs: Any) -> None:
        self.steps = 0  # steps since the last reset
        self.obs = obs
        self.rewards: Optional[List[float]] = None
        self.total_rewards = [0.0] * self.env.n_agents
        self.done = False

    def reset(self) -> None:
        """Reset the env (key R) and the per-episode counters."""
        self._reset_state(self.env.reset())

    @property
    def agent_names(self) -> List[str]:
        return [a.name for a in self.env.agents]

    def _per_agent(self, values: Any, index: int) -> Any:
        """Pick one agent out of a list or (``dict_spaces=True``) a dict by name."""
        return values[self.agent_names[index]] if isinstance(values, dict) else values[index]

    # ------------------------------------------------------------------ keys
    def key_down(self, key: str) -> None:
        """A key was pressed: movement keys are held, others act once."""
        key = key.lower()
        if key == "escape":
            self.quit_requested = True
        elif key == "tab":
            self.selected = self._next_agent(self.selected, self.selected2)
        elif key == "left shift" and self.selected2 is not None:
            self.selected2 = self._next_agent(self.selected2, self.selected)
        elif key == "r":
            self.reset()
        else:
            self.held.add(key)

    def key_up(self, key: str) -> None:
        """A key was released: its action stops."""
        self.held.discard(key.lower())

    def release_all(self) -> None:
        """Forget held keys (e.g. the window lost focus and will not report releases)."""
        self.held.clear()

    def _next_agent(self, index: int, taken: Optional[int]) -> int:
        """The next agent after ``index``, skipping the one the other player drives."""
        n = self.env.n_agents
        index = (index + 1) % n
        if taken is not None and index == taken and n > 1:
            index = (index + 1) % n
        return index

    # --------------------------------------------------------------- actions
    def _action_for(self, agent_index: int, bindings: Dict[str, Tuple[int, int]]) -> torch.Tensor:
        agent = self.env.agents[agent_index]
        action = torch.zeros(1, self.env.get_agent_action_size(agent), device=self.env.device)
        u_range = agent.action.u_range_tensor
        for key, (component, sign) in bindings.items():
            if key in self.held and component < agent.action.action_size:
                action[0, component] += sign * u_range[component]
        return action

    def actions(self) -> List[torch.Tensor]:
        """One ``[1, action_size]`` tensor per agent: zeros except for the driven ones."""
        result = [torch.zeros(1, self.env.get_agent_action_size(a), device=self.env.device) for a in self.env.agents]
        result[self.selected] = self._action_for(self.selected, PRIMARY_KEYS)
        if self.selected2 is not None:
            result[self.selected2] = self._action_for(self.selected2, SECONDARY_KEYS)
        return result

    def step(self) -> None:
        """Advance the env one step with the current keys (resetting first if the episode had ended)."""
        if self.done:
            self.reset()
        result = self.env.step(self.actions())
        if len(result) == 5:  # terminated_truncated=True
            obs, rews, terminated, truncated, _ = result
            dones = terminated | truncated
        else:
            obs, rews, dones, _ = result
        self.obs = obs
        self.rewards = [float(_first_env(self._per_agent(rews, i))) for i in range(self.env.n_agents)]
        self.total_rewards = [t + r for t, r in zip(self.total_rewards, self.rewards)]
        self.done = bool(dones[0])
        self.steps += 1
        self.total_steps += 1

    # ------------------------------------------------------------------ text
    def info_lines(self) -> List[str]:
        """The overlay: selected agent(s), its observation, reward, done and step count."""
        i = self.selected
        lines = [f"Selected: {self.agent_names[i]}  (arrows, M/N; TAB next, R reset, ESC quit)"]
        if self.selected2 is not None:
            lines.append(f"Second: {self.agent_names[self.selected2]}  (W/A/S/D, Q/E; LSHIFT next)")
        lines.append(f"Obs: {format_observation(self._per_agent(self.obs, i), max_chars=self.obs_chars)}")
        reward = "-" if self.rewards is None else f"{self.rewards[i]:.3f}"
        lines.append(f"Rew: {reward}   Total rew: {self.total_rewards[i]:.3f}")
        lines.append(f"Done: {self.done}   Step: {self.steps}")
        return lines


# ------------------------------------------------------------------ pygame part
def _import_pygame():
    """Import pygame quietly, or explain how to get it (it is an optional extra)."""
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    try:
        import pygame
    except ImportError as err:
        raise ImportError("interactive play needs pygame: pip install 'vmas_ros[play]' (or: pip install pygame)") \
            from err
    return pygame


#: VMAS's name for the player class
InteractiveEnv = InteractivePlayer


def _key_names(pygame) -> Dict[int, str]:
    """pygame key codes -> the names InteractivePlayer understands (independent of SDL's key-name strings)."""
    names = {pygame.K_ESCAPE: "escape", pygame.K_TAB: "tab", pygame.K_LSHIFT: "left shift"}
    names.update({getattr(pygame, f"K_{k.upper()}"): k for k in ("left", "right", "up", "down")})
    names.update({getattr(pygame, f"K_{k}"): k for k in "mnrwasdqe"})
    return names


def _wrap(text: str, font, width: int) -> List[str]:
    """Split ``text`` into pieces that fit ``width`` pixels (observations are long single lines)."""
    pieces: List[str] = []
    while text:
        lo, hi = 1, len(text)  # binary search: the longest prefix (at least 1 char) that fits
        while lo < hi:
            mid = (lo + hi + 1) // 2
            lo, hi = (mid, hi) if font.size(text[:mid])[0] <= width else (lo, mid - 1)
        pieces.append(text[:lo])
        text = text[lo:]
    return pieces


def _draw_overlay(pygame, screen, font, lines: Sequence[str]) -> None:
    """Text on a translucent band at the top, readable over any scene colours."""
    margin = 6
    width = screen.get_width() - 2 * margin
    rows = [piece for line in lines for piece in _wrap(line, font, width)]
    height = font.get_linesize() * len(rows) + 2 * margin
    band = pygame.Surface((screen.get_width(), height), pygame.SRCALPHA)
    band.fill((255, 255, 255, 200))
    screen.blit(band, (0, 0))
    for row, text in enumerate(rows):
        screen.blit(font.render(text, True, (20, 20, 20)), (margin, margin + row * font.get_linesize()))


def _gif_path(render_name: str) -> Path:
    from vmas_ros.simulator.video import VIDEO_SUFFIXES
    path = Path(render_name)
    return path if path.suffix.lower() in VIDEO_SUFFIXES else path.with_name(path.name + ".gif")


def render_interactively(
    scenario: Union[str, BaseScenario],
    control_two_agents: bool = False,
    display_info: bool = True,
    save_render: bool = False,
    render_name: str = "interactive",
    steps: Optional[int] = None,
    fps: float = 10,
    event_source: Optional[Callable[[int], Iterable[Any]]] = None,
    **kwargs,
) -> int:
    """Play ``scenario`` with the keyboard in a pygame window; returns the number of steps played.

    Args:
        scenario: a scenario name or a BaseScenario instance (as ``vmas.render_interactively``).
        control_two_agents: also drive a second agent with W/A/S/D and Q/E.
        display_info: overlay the selected agent's name, observation, reward, done and step.
        save_render: at the end, save the session (frames as shown, overlay included)
            with :func:`vmas_ros.simulator.video.save_frames` to ``render_name`` (``.gif`` added
            unless it already ends in ``.gif``/``.png``/``.mp4``).
        steps: stop after this many steps (scripts, tests); ``None`` plays until ESC/close.
        fps: steps (= frames) per second; ``<= 0`` runs as fast as possible.
        event_source: called before each step with the number of steps played so far;
            the pygame events it returns are posted to pygame's queue, so scripted input
            goes through exactly the path real key presses take (used by tests).
        **kwargs: passed to ``vmas_ros.make_env`` (``seed`` defaults to 0 and ``device``
            to ``"cpu"`` as in VMAS), then on to the scenario's ``make_world``.
    """
    from vmas_ros.envs.make_env import make_env

    if steps is not None and steps < 0:
        raise ValueError(f"steps must be None or >= 0, got {steps}")
    pygame = _import_pygame()
    kwargs.setdefault("seed", 0)
    kwargs.setdefault("device", "cpu")
    kwargs.setdefault("compile_physics", False)  # one env at frame rate: compiling would only delay the window
    env = make_env(scenario, num_envs=1, continuous_actions=True, **kwargs)
    player = InteractivePlayer(env, control_two_agents=control_two_agents)
    key_names = _key_names(pygame)
    frames: List[Any] = []

    pygame.display.init()
    try:
        frame = env.render(mode="rgb_array", env_index=0)
        try:
            screen = pygame.display.set_mode((frame.shape[1], frame.shape[0]))
        except pygame.error as err:
            raise RuntimeError(
                f"cannot open a pygame window ({err}); without a display run under `xvfb-run`, "
                "or set SDL_VIDEODRIVER=dummy to play headless (e.g. with steps=... and save_render=True)"
            ) from err
        driver = pygame.display.get_driver()
        if driver in ("dummy", "offscreen") and steps is None:
            # SDL silently falls back to an invisible window when there is no display
            warnings.warn(f"SDL video driver {driver!r}: the window is invisible; play until ESC/QUIT or "
                          "Ctrl-C (use steps=... for scripted runs, or xvfb-run / a desktop to see it)",
                          RuntimeWarning, stacklevel=2)
        name = scenario if isinstance(scenario, str) else type(scenario).__name__
        pygame.display.set_caption(f"vmas_ros: {name}")
        font = None
        if display_info:
            try:
                pygame.font.init()
                font = pygame.font.Font(None, 20)
            except (pygame.error, ImportError, NotImplementedError):  # pygame built without SDL_ttf
                font = None
        clock = pygame.time.Clock()

        while True:
            image = pygame.image.frombuffer(frame.tobytes(), (frame.shape[1], frame.shape[0]), "RGB")
            if image.get_size() != screen.get_size():
                screen = pygame.display.set_mode(image.get_size())
            screen.blit(image, (0, 0))
            if font is not None:
                _draw_overlay(pygame, screen, font, player.info_lines())
            pygame.display.flip()
            if save_render:
                frames.append(pygame.surfarray.array3d(screen).swapaxes(0, 1).copy())
            if steps is not None and player.total_steps >= steps:
                break
            for event in event_source(player.total_steps) if event_source is not None else ():
                pygame.event.post(event)
            for event in pygame.event.get():
                if event.type == pygame.QUIT:
                    player.quit_requested = True
                elif event.type == pygame.KEYDOWN and event.key in key_names:
                    player.key_down(key_names[event.key])
                elif event.type == pygame.KEYUP and event.key in key_names:
                    player.key_up(key_names[event.key])
                elif event.type == pygame.WINDOWFOCUSLOST:
                    player.release_all()  # releases while unfocused never arrive
            if player.quit_requested:
                break
            player.step()
            frame = env.render(mode="rgb_array", env_index=0)
            if fps > 0:
                clock.tick(fps)
    except KeyboardInterrupt:  # Ctrl-C in the terminal ends the session like ESC (and still saves it)
        pass
    finally:
        pygame.quit()
        env.close()

    if save_render and frames:
        from vmas_ros.simulator.video import save_frames

        path = save_frames(frames, _gif_path(render_name), fps=fps if fps > 0 else 10)
        print(f"saved the interactive session ({len(frames)} frames) to {path}")
    return player.total_steps


# ----------------------------------------------------------------- CLI helpers
def add_play_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Options of ``vmas-ros play`` (kept here so the CLI only has to register the subcommand)."""
    parser.add_argument("--scenario", default="simple_spread", help="scenario name (see `vmas-ros list`)")
    parser.add_argument("--scenario-kwargs", default=None, help="JSON object of scenario kwargs")
    parser.add_argument("--two-agents", action="store_true", help="also drive a second agent with W/A/S/D, Q/E")
    parser.add_argument("--no-info", action="store_true", help="hide the text overlay")
    parser.add_argument("--save", default=None, metavar="NAME",
                        help="save the session as NAME (.gif added unless NAME ends in .gif/.png/.mp4)")
    parser.add_argument("--steps", type=int, default=None, help="quit after this many steps (default: until ESC)")
    parser.add_argument("--fps", type=float, default=10, help="steps per second (default 10; <= 0: unthrottled)")
    parser.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    return parser


def run_play_command(args: argparse.Namespace) -> int:
    """Run ``vmas-ros play`` from parsed :func:`add_play_arguments` options; returns the exit code."""
    import sys
    kwargs: Dict[str, Any] = {}
    if args.scenario_kwargs:
        try:
            kwargs = json.loads(args.scenario_kwargs)
        except json.JSONDecodeError as error:
            print(f"vmas-ros play: --scenario-kwargs must be a JSON object: {error}", file=sys.stderr)
            return 2
        if not isinstance(kwargs, dict):
            print("vmas-ros play: --scenario-kwargs must be a JSON object", file=sys.stderr)
            return 2
    if args.steps is not None and args.steps < 0:
        print("vmas-ros play: --steps must be >= 0", file=sys.stderr)
        return 2
    try:
        played = render_interactively(
            args.scenario, control_two_agents=args.two_agents, display_info=not args.no_info,
            save_render=args.save is not None, render_name=args.save or "interactive",
            steps=args.steps, fps=args.fps, seed=args.seed, **kwargs,
        )
    except (ValueError, RuntimeError, ImportError) as error:
        print(f"vmas-ros play: {error}", file=sys.stderr)
        return 2
    print(f"played {played} steps")
    return 0
