"""Saving rendered frames: PNG files and animated GIFs (imageio; no pygame here)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _check_frame(frame, k: int) -> np.ndarray:
    a = np.asarray(frame)
    if a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8:
        raise ValueError(f"frame {k}: expected an (H, W, 3) uint8 array, got {a.shape} {a.dtype}")
    return a


def save_frames(frames, directory, prefix: str = "frame") -> list[Path]:
    """Write each frame as ``<directory>/<prefix>_00000.png``; returns the paths.

    ``frames`` is an iterable of (H, W, 3) uint8 arrays (as :meth:`Renderer.render`
    returns). The directory is created if needed.
    """
    import imageio.v3 as iio

    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for k, frame in enumerate(frames):
        path = directory / f"{prefix}_{k:05d}.png"
        iio.imwrite(path, _check_frame(frame, k))
        paths.append(path)
    return paths


def write_gif(frames, path, fps: float = 10.0, loop: int = 0) -> Path:
    """Write frames as an animated GIF at ``fps`` frames per second; returns the path.

    ``loop=0`` repeats forever. All frames must have the same shape.
    """
    import imageio.v3 as iio

    frames = [_check_frame(f, k) for k, f in enumerate(frames)]
    if not frames:
        raise ValueError("write_gif: no frames")
    if fps <= 0:
        raise ValueError(f"write_gif: fps must be positive, got {fps}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    iio.imwrite(path, np.stack(frames), extension=".gif", duration=1000.0 / fps, loop=loop)
    return path
