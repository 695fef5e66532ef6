"""Write rendered frames to disk: animated GIF, a PNG still, or MP4.

GIF and PNG only need Pillow (a core dependency) so recording a rollout works
everywhere. MP4 needs an ffmpeg binary, which we do not want to require; it is
used through ``imageio`` + ``imageio-ffmpeg`` when those are installed.
It sits in the simulator because VMAS's ``simulator.utils.save_video`` writes
through it; ``vmas_ros.viz`` re-exports :func:`save_frames`.
"""
from __future__ import annotations

from pathlib import Path
from typing import List, Sequence, Union

import numpy as np
from PIL import Image

__all__ = ["save_frames", "VIDEO_SUFFIXES"]

#: suffixes :func:`save_frames` understands
VIDEO_SUFFIXES = (".gif", ".png", ".mp4")


def _as_uint8_rgb(frame: np.ndarray) -> np.ndarray:
    """Validate one frame: ``[H, W, 3]`` (or RGBA, whose alpha is dropped) uint8."""
    arr = np.asarray(frame)
    if arr.ndim != 3 or arr.shape[2] not in (3, 4):
        raise ValueError(f"frames must be [H, W, 3] arrays, got shape {arr.shape}")
    if arr.dtype != np.uint8:
        arr = np.clip(arr, 0, 255).astype(np.uint8)
    return np.ascontiguousarray(arr[..., :3])


def save_frames(
    frames: Sequence[np.ndarray],
    path: Union[str, Path],
    fps: float = 10,
    png_frame: int = -1,
) -> Path:
    """Save ``frames`` (``[H, W, 3]`` uint8 arrays, e.g. from ``render_world``) to ``path``.

    The format follows the suffix:

    * ``.gif``: every frame, ``1000 / fps`` ms each, looping forever. Pillow
      merges consecutive identical frames into one longer frame, so the file
      may hold fewer frames than given while lasting just as long.
    * ``.png``: a single still, by default the **last** frame (the final state
      of a rollout is usually what one wants to look at); ``png_frame``
      picks another index.
    * ``.mp4``: H.264 via ``imageio`` + ``imageio-ffmpeg`` (optional deps).

    Parent directories are created. Returns the path written.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in VIDEO_SUFFIXES:
        raise ValueError(
            f"unsupported file suffix {path.suffix!r} for {str(path)!r}; use one of {', '.join(VIDEO_SUFFIXES)}"
        )
    if len(frames) == 0:
        raise ValueError("no frames to save")
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    path.parent.mkdir(parents=True, exist_ok=True)

    if suffix == ".png":
        Image.fromarray(_as_uint8_rgb(frames[png_frame]), "RGB").save(path)
    elif suffix == ".gif":
        images: List[Image.Image] = [
            Image.fromarray(_as_uint8_rgb(f), "RGB").convert("P", palette=Image.Palette.ADAPTIVE, colors=256)
            for f in frames
        ]
        images[0].save(
            path,
            save_all=True,
            append_images=images[1:],
            duration=max(1, int(round(1000.0 / fps))),
            loop=0,
        )
    else:
        _save_mp4([_as_uint8_rgb(f) for f in frames], path, fps)
    return path


def _save_mp4(frames: List[np.ndarray], path: Path, fps: float) -> None:
    try:
        import imageio.v2 as imageio
        import imageio_ffmpeg  # noqa: F401  (imageio's ffmpeg backend; fail early and clearly)
    except ImportError as err:
        raise ImportError(
            f"writing {path.name} needs imageio with its ffmpeg backend: pip install imageio imageio-ffmpeg "
            "(or save as .gif, which only needs Pillow)"
        ) from err
    h, w = frames[0].shape[:2]
    if h % 2 or w % 2:  # yuv420p needs even sizes; pad by one edge pixel rather than rescale
        frames = [np.pad(f, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge") for f in frames]
    # macro_block_size=1 keeps imageio from resizing frames to multiples of 16
    with imageio.get_writer(str(path), format="FFMPEG", mode="I", fps=fps, codec="libx264",
                            pixelformat="yuv420p", macro_block_size=1) as writer:
        for frame in frames:
            writer.append_data(frame)
