"""The one video writer: RGB frames to ``.mp4``, ``.avi`` or ``.gif`` with OpenCV, used by the
report's overlay videos and by ``roft-sim preview``.

``.mp4`` uses the ``mp4v`` (MPEG-4 part 2) codec and ``.avi`` Motion-JPEG, the codecs of the
opencv-python-headless wheels (H.264, ``avc1``, is not available there). ``.gif`` goes through
``cv2.imwriteanimation`` (OpenCV's VideoWriter has no GIF codec; the animated-image writer does,
with a 256-colour palette and dithering), so its frames are kept in memory until :meth:`close`.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError

U8 = NDArray[np.uint8]

__all__ = ["VIDEO_SUFFIXES", "VideoWriter"]

VIDEO_SUFFIXES = (".mp4", ".avi", ".gif")
"""Video file types :class:`VideoWriter` writes."""


class VideoWriter:
    """Writes RGB frames to a video file; a context manager (the file is finished on exit).

    Args:
        path: ``.mp4``, ``.avi`` or ``.gif`` file; its folder is created on the first frame.
        fps: frames per second (> 0).

    Raises:
        ConfigError: unsupported suffix, fps <= 0, or OpenCV cannot open the writer.
    """

    def __init__(self, path: str | Path, fps: float) -> None:
        self.path = Path(path)
        suffix = self.path.suffix.lower()
        if suffix not in VIDEO_SUFFIXES:
            raise ConfigError(
                f"cannot write video {str(self.path)!r}: use one of {', '.join(VIDEO_SUFFIXES)}"
            )
        if not fps > 0:
            raise ConfigError(f"video fps must be > 0, got {fps}")
        self.fps = float(fps)
        self._suffix = suffix
        self._writer: cv2.VideoWriter | None = None
        self._gif_frames: list[U8] = []
        self._size: tuple[int, int] | None = None
        self.frames_written = 0
        """Frames appended so far."""

    def write(self, rgb: U8) -> None:
        """Appends one ``(H, W, 3)`` uint8 RGB frame; every frame must have the first one's size.

        Raises:
            ValueError: a frame whose size differs from the first frame's.
        """
        h, w = rgb.shape[:2]
        if self._size is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._size = (w, h)
        elif (w, h) != self._size:
            raise ValueError(f"frame size {w}x{h} differs from the first frame's {self._size}")
        bgr = np.ascontiguousarray(rgb[..., ::-1])
        if self._suffix == ".gif":
            self._gif_frames.append(bgr)
        else:
            if self._writer is None:
                code = "mp4v" if self._suffix == ".mp4" else "MJPG"
                self._writer = cv2.VideoWriter(
                    str(self.path), cv2.VideoWriter.fourcc(*code), self.fps, (w, h)
                )
                if not self._writer.isOpened():
                    raise ConfigError(
                        f"OpenCV could not open a {self._suffix} writer for {str(self.path)!r}; "
                        "check that the folder is writable, or try .avi or .gif"
                    )
            self._writer.write(bgr)
        self.frames_written += 1

    def close(self) -> None:
        """Finishes the file (idempotent)."""
        if self._writer is not None:
            self._writer.release()
            self._writer = None
        if self._gif_frames:
            animation = cv2.Animation()
            animation.frames = self._gif_frames
            animation.durations = [int(round(1000 / self.fps))] * len(self._gif_frames)
            params = [cv2.IMWRITE_GIF_DITHER, 1]
            if not cv2.imwriteanimation(str(self.path), animation, params):
                raise ConfigError(f"OpenCV could not write the GIF {str(self.path)!r}")
            self._gif_frames = []

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
