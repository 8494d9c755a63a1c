"""Writing rendered frames: numbered PNG files plus an optional GIF or MP4 (no pygame here).

    from airspace_sim.rendering import FrameWriter
    with FrameWriter("out/demo", video="gif", fps=10) as frames:
        for snap in snapshots:
            frames.add(renderer.render(snap))
    frames.paths, frames.video        # the PNG paths, out/demo/run.gif

The one frame writer of the package: the ``run`` command and the env's users write frames
through it.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from airspace_sim.errors import UserError

VIDEOS = ("gif", "mp4")


def _check_frame(frame, k: int) -> np.ndarray:
    a = np.asarray(frame)
    if a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8:
        raise ValueError(f"frame {k}: expected an (H, W, 3) uint8 array, got {a.shape} {a.dtype}")
    return a


class FrameWriter:
    """Frames as ``<directory>/<prefix>_00000.png``, ... and, with ``video``, also
    ``<directory>/run.gif`` or ``run.mp4`` at ``fps`` frames per second.

    The directory is created if needed, and old ``<prefix>_*.png`` files in it are deleted
    first (a shorter rerun must not leave stale frames behind). Frames are (H, W, 3) uint8
    arrays of one shape (:meth:`Renderer.render`). The MP4 is encoded as frames arrive
    (needs ``imageio-ffmpeg``); the GIF is assembled from the PNG files at :meth:`close`,
    one frame in memory at a time. :class:`UserError` (one line) if the directory cannot
    be made or the MP4 encoder is missing.
    """

    def __init__(self, directory, video: str | None = None, fps: float = 10.0, prefix="frame"):
        if video not in (None, *VIDEOS):
            raise ValueError(f"video: expected None, 'gif' or 'mp4', got {video!r}")
        if not fps > 0:
            raise UserError(f"fps: expected a positive number of frames per second, got {fps}")
        self.directory = Path(directory)
        self.prefix = prefix
        self.video_kind = video
        self.fps = float(fps)
        self.paths: list[Path] = []
        #: path of the finished video, set by :meth:`close`
        self.video: Path | None = None
        self._closed = False
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise UserError(f"{self.directory}: cannot create folder: {exc}") from None
        for old in self.directory.glob(f"{prefix}_*.png"):
            old.unlink()
        self._mp4 = self._open_mp4() if video == "mp4" else None

    def _open_mp4(self):
        try:
            import imageio.v2 as iio2

            with warnings.catch_warnings():  # imageio's legacy plugin list warns on import
                warnings.simplefilter("ignore", DeprecationWarning)
                return iio2.get_writer(self.directory / "run.mp4", fps=self.fps, macro_block_size=1)
        except (ImportError, ValueError, RuntimeError) as exc:
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            raise UserError(
                f"mp4 video needs the ffmpeg plugin of imageio (pip install imageio-ffmpeg): {first}"
            ) from None

    def add(self, frame) -> Path:
        """Write one (H, W, 3) uint8 frame; returns its PNG path."""
        import imageio.v3 as iio

        if self._closed:
            raise ValueError("FrameWriter.add: the writer is closed")
        frame = _check_frame(frame, len(self.paths))
        if self.paths and frame.shape != self._shape:
            raise ValueError(
                f"frame {len(self.paths)}: shape {frame.shape} differs from the first {self._shape}"
            )
        self._shape = frame.shape
        path = self.directory / f"{self.prefix}_{len(self.paths):05d}.png"
        iio.imwrite(path, frame, compress_level=1)  # fast: ~2x quicker than the default 6
        self.paths.append(path)
        if self._mp4 is not None:
            self._mp4.append_data(frame)
        return path

    def close(self) -> Path | None:
        """Finish the video (if any); returns its path, or None. Safe to call twice."""
        if self._closed:
            return self.video
        self._closed = True
        if self._mp4 is not None:
            self._mp4.close()
            self.video = self.directory / "run.mp4"
        elif self.video_kind == "gif" and self.paths:
            self.video = self._write_gif(self.directory / "run.gif")
        return self.video

    def _write_gif(self, out: Path) -> Path:
        from PIL import Image

        def paletted(path):
            # Fast octree quantisation (~5x quicker than Pillow's default median cut);
            # frames have a few hundred colours, so 256 lose nothing visible.
            with Image.open(path) as im:
                return im.convert("RGB").quantize(
                    256, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE
                )

        paletted(self.paths[0]).save(
            out,
            save_all=True,
            append_images=(paletted(p) for p in self.paths[1:]),
            duration=int(round(1000 / self.fps)),
            loop=0,
        )
        return out

    def __enter__(self) -> FrameWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
