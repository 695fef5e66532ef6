"""Constants, colours and small tensor helpers shared by the engine and scenarios.

The public names (``Color``, ``X``, ``Y``, ``TorchUtils``, ``ScenarioUtils`` and the
default constants) follow VMAS 1.5 so that scenarios written for VMAS import
them unchanged from ``vmas_ros.simulator.utils``.
"""
from __future__ import annotations

import warnings
from enum import Enum
from typing import Dict, List, Optional, Tuple, Union

import torch
from torch import Tensor

X = 0
Y = 1
Z = 2
ALPHABET = "ABCDEFGHIJKLMNOPQRSTUVWXYZ"
VIEWER_DEFAULT_ZOOM = 1.2
INITIAL_VIEWER_SIZE = (700, 700)
#: thickness given to lines and box outlines in contact computations
LINE_MIN_DIST = 4 / 6e2
COLLISION_FORCE = 100.0
JOINT_FORCE = 130.0
TORQUE_CONSTRAINT_FORCE = 1.0
DRAG = 0.25
LINEAR_FRICTION = 0.0
ANGULAR_FRICTION = 0.0

DEVICE_TYPING = Union[torch.device, str, int]
AGENT_OBS_TYPE = Union[Tensor, Dict[str, Tensor]]
AGENT_INFO_TYPE = Dict[str, Tensor]
AGENT_REWARD_TYPE = Tensor
OBS_TYPE = Union[List[AGENT_OBS_TYPE], Dict[str, AGENT_OBS_TYPE]]
INFO_TYPE = Union[List[AGENT_INFO_TYPE], Dict[str, AGENT_INFO_TYPE]]
REWARD_TYPE = Union[List[AGENT_REWARD_TYPE], Dict[str, AGENT_REWARD_TYPE]]
DONE_TYPE = Tensor


class Color(Enum):
    """Named RGB colours (0..1) used for entities; values match VMAS's palette."""

    RED = (0.75, 0.25, 0.25)
    GREEN = (0.25, 0.75, 0.25)
    BLUE = (0.25, 0.25, 0.75)
    LIGHT_GREEN = (0.45, 0.95, 0.45)
    WHITE = (0.75, 0.75, 0.75)
    GRAY = (0.25, 0.25, 0.25)
    BLACK = (0.15, 0.15, 0.15)
    ORANGE = (1.00, 0.50, 0)
    PINK = (0.97, 0.51, 0.75)
    PURPLE = (0.60, 0.31, 0.64)
    YELLOW = (0.87, 0.87, 0)


def override(cls):
    """Decorator that fails loudly if the decorated method overrides nothing in ``cls``."""

    def check(method):
        if method.__name__ not in dir(cls):
            raise NameError(f"{method} does not override any method of {cls}")
        return method

    return check


class Observable:
    """Minimal observer pattern: joints watch their entities to follow them."""

    def __init__(self) -> None:
        self._observers: list = []

    def subscribe(self, observer) -> None:
        if observer not in self._observers:
            self._observers.append(observer)

    def unsubscribe(self, observer) -> None:
        if observer in self._observers:
            self._observers.remove(observer)

    def notify_observers(self, *args, **kwargs) -> None:
        for observer in self._observers:
            observer.notify(self, *args, **kwargs)


class Observer:
    def notify(self, observable, *args, **kwargs) -> None:  # pragma: no cover - interface
        raise NotImplementedError


def as_index_tensor(index, batch_dim: int, device) -> Tensor:
    """Normalise an env selector (int, sequence, long tensor or bool mask) to a long tensor.

    Raises ValueError naming the bad value, so callers can report it to users.
    """
    if isinstance(index, bool):
        raise ValueError(f"env index must be an int, indices or a boolean mask, got {index!r}")
    if isinstance(index, int):
        if not -batch_dim <= index < batch_dim:
            raise ValueError(f"env index {index} out of range for {batch_dim} envs")
        return torch.tensor([index % batch_dim], device=device, dtype=torch.long)
    tensor = index if isinstance(index, Tensor) else torch.as_tensor(index)
    if tensor.dtype == torch.bool:
        if tensor.shape != (batch_dim,):
            raise ValueError(
                f"boolean env mask must have shape ({batch_dim},), got {tuple(tensor.shape)}"
            )
        return tensor.to(device).nonzero().squeeze(-1)
    if tensor.dtype.is_floating_point or tensor.dim() > 1:
        raise ValueError(
            f"env indices must be integers in a 1-D sequence, got dtype {tensor.dtype} "
            f"and shape {tuple(tensor.shape)}"
        )
    tensor = tensor.to(device=device, dtype=torch.long).reshape(-1)
    if tensor.numel() and (int(tensor.min()) < -batch_dim or int(tensor.max()) >= batch_dim):
        raise ValueError(
            f"env indices {tensor.tolist()} out of range for {batch_dim} envs"
        )
    return tensor % batch_dim


def save_video(name: str, frame_list: List, fps: int):
    """Write ``frame_list`` (``[H, W, 3]`` uint8 arrays from ``render(mode="rgb_array")``) as a video.

    VMAS's name and arguments; our own writer (vmas_ros/simulator/video.py) instead
    of OpenCV, so no ``cv2`` is needed: ``name + ".mp4"`` when ``imageio`` and
    ``imageio-ffmpeg`` are installed, otherwise ``name + ".gif"`` (Pillow, a core
    dependency). Returns the path written.
    """
    import importlib.util

    from vmas_ros.simulator.video import save_frames

    suffix = ".mp4" if importlib.util.find_spec("imageio") is not None else ".gif"
    return save_frames(frame_list, f"{name}{suffix}", fps=fps)


def extract_nested_with_index(data, index: int):
    """Env ``index`` of a batched tensor, or of every tensor in a (nested) dict of them.

    ``data`` is a ``[B, ...]`` tensor or a dict whose values are tensors or such
    dicts (dict observations); the result has the same nesting with ``[...]``
    leaves. Anything else raises ``TypeError`` naming its type.
    """
    if isinstance(data, Tensor):
        return data[index]
    if isinstance(data, dict):
        return {key: extract_nested_with_index(value, index) for key, value in data.items()}
    raise TypeError(f"extract_nested_with_index: expected a tensor or a dict of them, got {type(data).__name__}")


def clamp_norm(vec: Tensor, max_norm) -> Tensor:
    """Scale vectors longer than ``max_norm`` back onto it (``inf`` means no limit).

    Rounds like VMAS (``vec / norm * max``) so speed-limited agents stay in
    bit parity, and keeps gradients finite: the unused branch never divides by
    zero or multiplies by ``inf``.
    """
    norm = torch.linalg.vector_norm(vec, dim=-1, keepdim=True)
    over = norm > max_norm
    finite_max = torch.where(torch.isfinite(torch.as_tensor(max_norm, device=vec.device)), max_norm, 0.0)
    return torch.where(over, vec / torch.where(over, norm, 1.0) * finite_max, vec)


class TorchUtils:
    """Batched helpers scenarios use; all take and return tensors on the input's device."""

    @staticmethod
    def clamp_with_norm(tensor: Tensor, max_norm: Union[float, Tensor]) -> Tensor:
        """Scale vectors whose norm exceeds ``max_norm`` back onto that norm."""
        return clamp_norm(tensor, max_norm)

    @staticmethod
    def rotate_vector(vector: Tensor, angle: Tensor) -> Tensor:
        if angle.dim() == vector.dim():
            angle = angle.squeeze(-1)
        cos, sin = torch.cos(angle), torch.sin(angle)
        x, y = vector[..., X], vector[..., Y]
        return torch.stack([x * cos - y * sin, x * sin + y * cos], dim=-1)

    @staticmethod
    def cross(vector_a: Tensor, vector_b: Tensor) -> Tensor:
        """2D cross product, keeping a trailing dimension of size 1."""
        return (vector_a[..., X] * vector_b[..., Y] - vector_a[..., Y] * vector_b[..., X]).unsqueeze(-1)

    @staticmethod
    def compute_torque(f: Tensor, r: Tensor) -> Tensor:
        """Torque of force ``f`` applied at lever arm ``r`` (r x f)."""
        return TorchUtils.cross(r, f)

    @staticmethod
    def to_numpy(data):
        if isinstance(data, Tensor):
            return data.detach().cpu().numpy()
        if isinstance(data, dict):
            return {key: TorchUtils.to_numpy(value) for key, value in data.items()}
        if isinstance(data, (list, tuple)):
            return [TorchUtils.to_numpy(value) for value in data]
        raise TypeError(f"cannot convert {type(data).__name__} to numpy")

    @staticmethod
    def recursive_clone(value):
        if isinstance(value, Tensor):
            return value.clone()
        return {key: TorchUtils.recursive_clone(val) for key, val in value.items()}

    @staticmethod
    def recursive_require_grad_(value):
        if isinstance(value, Tensor) and torch.is_floating_point(value):
            value.requires_grad_(True)
        elif isinstance(value, dict):
            for val in value.values():
                TorchUtils.recursive_require_grad_(val)
        elif isinstance(value, (list, tuple)):
            for val in value:
                TorchUtils.recursive_require_grad_(val)

    @staticmethod
    def where_from_index(env_index, new_value, old_value: Tensor) -> Tensor:
        """``old_value`` with the rows selected by ``env_index`` replaced by ``new_value``."""
        mask = torch.zeros(old_value.shape[0], dtype=torch.bool, device=old_value.device)
        mask[env_index] = True
        mask = mask.view(-1, *([1] * (old_value.dim() - 1)))
        return torch.where(mask, new_value, old_value)


def selected_env_count(batch_dim: int, env_index) -> int:
    """How many envs a reset selector picks: None (all), an int, a sequence or tensor of
    indices, or a boolean mask over the batch (reset time only: a mask costs a host read)."""
    if env_index is None:
        return batch_dim
    if isinstance(env_index, int):
        return 1
    index = torch.as_tensor(env_index)
    if index.dim() == 0:
        return 1
    return int(index.sum()) if index.dtype == torch.bool else int(index.numel())


class ScenarioUtils:
    """Helpers for writing scenarios: random non-overlapping spawns and kwargs checks."""

    @staticmethod
    def spawn_entities_randomly(
        entities,
        world,
        env_index: Optional[int],
        min_dist_between_entities: float,
        x_bounds: Tuple[float, float],
        y_bounds: Tuple[float, float],
        occupied_positions: Optional[Tensor] = None,
        disable_warn: bool = False,
    ) -> None:
        """Place ``entities`` uniformly in the bounds, at least ``min_dist`` from each other.

        ``env_index`` selects the envs to place in: None, an int, indices or a mask
        (each selected env gets its own draw).
        """
        batch_size = selected_env_count(world.batch_dim, env_index)
        if occupied_positions is None:
            occupied_positions = torch.zeros((batch_size, 0, world.dim_p), device=world.device)
        for entity in entities:
            pos = ScenarioUtils.find_random_pos_for_entity(
                occupied_positions, env_index, world, min_dist_between_entities,
                x_bounds, y_bounds, disable_warn,
            )
            occupied_positions = torch.cat([occupied_positions, pos], dim=1)
            pos = pos.squeeze(1)
            entity.set_pos(pos.squeeze(0) if isinstance(env_index, int) else pos, batch_index=env_index)

    @staticmethod
    def find_random_positions(count: int, env_index, world, min_dist_between_entities: float,
                              x_bounds: Tuple[float, float], y_bounds: Tuple[float, float],
                              disable_warn: bool = False) -> Tensor:
        """``count`` positions per selected env, ``[envs, count, 2]``, uniform in the bounds, every two at least
        ``min_dist_between_entities`` apart.

        A few are drawn one by one, each clear of those before it (``find_random_pos_for_entity`` in a
        loop: VMAS's draws, from the same random stream). From ``GRID_MIN_SPHERES`` on they are drawn all at
        once, and each one too close to an earlier one is drawn again, round after round, until none is: the
        same rule, a few batched rounds instead of a Python call per position (a swarm's thousands).
        """
        from vmas_ros.simulator.neighbours import ClosePairs
        from vmas_ros.simulator.thresholds import GRID_MIN_SPHERES

        rows = selected_env_count(world.batch_dim, env_index)
        if count < GRID_MIN_SPHERES:
            placed = torch.zeros(rows, 0, world.dim_p, device=world.device)
            for _ in range(count):
                point = ScenarioUtils.find_random_pos_for_entity(
                    placed, env_index, world, min_dist_between_entities, x_bounds, y_bounds, disable_warn)
                placed = torch.cat([placed, point], dim=1)
            return placed
        low = torch.tensor([x_bounds[0], y_bounds[0]], device=world.device, dtype=torch.float32)
        high = torch.tensor([x_bounds[1], y_bounds[1]], device=world.device, dtype=torch.float32)
        placed = low + (high - low) * torch.rand(rows, count, 2, device=world.device)
        flat, close = placed.view(-1, 2), ClosePairs(min_dist_between_entities)
        for tries in range(1, 1_000_000):
            first, second = close(placed)
            too_close = torch.linalg.vector_norm(flat[first] - flat[second], dim=-1) < min_dist_between_entities
            again = torch.unique(second[too_close])  # the later of each pair too close
            if again.numel() == 0:
                return placed
            flat[again] = low + (high - low) * torch.rand(again.numel(), 2, device=world.device)
            if tries == 50_000 and not disable_warn:
                warnings.warn("Spawning is taking many tries: the bounds or min_dist_between_entities "
                              "may be too tight for all entities (disable_warn=True silences this).")
        raise RuntimeError(f"no room for {count} entities {min_dist_between_entities} apart in the bounds")

    @staticmethod
    def find_random_pos_for_entity(
        occupied_positions: Tensor,
        env_index: Optional[int],
        world,
        min_dist_between_entities: float,
        x_bounds: Tuple[float, float],
        y_bounds: Tuple[float, float],
        disable_warn: bool = False,
    ) -> Tensor:
        """Rejection-sample one position per env (shape [batch, 1, 2]) clear of occupied ones.

        Only the envs whose sample overlaps are redrawn, so the loop runs a handful
        of times regardless of the number of envs.
        """
        batch_size = selected_env_count(world.batch_dim, env_index)

        def draw() -> Tensor:
            low = torch.tensor([x_bounds[0], y_bounds[0]], device=world.device, dtype=torch.float32)
            high = torch.tensor([x_bounds[1], y_bounds[1]], device=world.device, dtype=torch.float32)
            return low + (high - low) * torch.rand((batch_size, 1, 2), device=world.device)

        pos = draw()
        if occupied_positions.shape[1] == 0:
            return pos
        tries = 0
        while True:
            too_close = (torch.cdist(occupied_positions, pos).squeeze(2) < min_dist_between_entities).any(dim=1)
            if not bool(too_close.any()):
                return pos
            pos = torch.where(too_close.view(-1, 1, 1), draw(), pos)
            tries += 1
            if tries == 50_000 and not disable_warn:
                warnings.warn(
                    "Spawning is taking many tries: the bounds or min_dist_between_entities "
                    "may be too tight for all entities (disable_warn=True silences this)."
                )

    @staticmethod
    def check_kwargs_consumed(dictionary_of_kwargs: Dict, warn: bool = True) -> None:
        """Warn (or raise ValueError) when a scenario was given kwargs it did not use."""
        if dictionary_of_kwargs:
            message = (
                f"Scenario kwargs {sorted(dictionary_of_kwargs)} were passed but not used "
                f"by the scenario (values: {dictionary_of_kwargs})."
            )
            if warn:
                warnings.warn(message)
            else:
                raise ValueError(message)

    @staticmethod
    def plot_entity_rotation(entity, env_index: int, length: float = 0.15):
        """A short line from the entity's centre along its heading, for extra_render."""
        from vmas_ros.simulator import rendering

        line = rendering.Line((0, 0), (length, 0), width=2)
        xform = rendering.Transform()
        xform.set_rotation(float(entity.state.rot[env_index]))
        xform.set_translation(*entity.state.pos[env_index].tolist())
        line.add_attr(xform)
        color = entity.color.value if isinstance(entity.color, Color) else entity.color
        line.set_color(*color)
        return line
