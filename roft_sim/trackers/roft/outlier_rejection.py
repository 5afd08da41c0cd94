"""Depth-based rejection of outlier poses (paper section III-C-6; reference report section 6).

Two candidate corrections are computed from the same prediction: A with the pose (and the
velocity), B without the pose. The object's depth is rendered at both candidate poses at a
reduced resolution, and compared with the measured depth of the frame the pose was computed on,
at every 2nd pixel of that frame's (synchronised) mask:
``e = mean |D(u, v) - D_render(u // div, v // div)|`` over pixels with ``0 < D < 2 m`` and a
non-zero render (``e = inf`` if none). The pose is rejected when ``e_A > gamma * e_B``.

The samples of the measured depth are taken when the frame is processed and kept per frame
(:class:`DepthSamples`), so replays of delayed poses use the right frame without buffering
whole images.

Deviation: the reduced camera is ``CameraIntrinsics.resized`` (exact for pixel centres at integer
coordinates) rather than the reference's plain division of the intrinsics by the divider, which
shifts the render by half a low-resolution pixel minus half a pixel.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.records import DepthRenderer
from roft_sim.trackers.roft.config import OutlierRejectionConfig
from roft_sim.trackers.roft.mask_sync import PixelSet

F64 = NDArray[np.float64]

__all__ = ["DepthSamples", "depth_samples", "render_divider", "DepthOutlierTest"]


@dataclass(frozen=True, slots=True)
class DepthSamples:
    """Measured depth at the pixels the outlier test uses, for one camera frame.

    Taken every frame (one gather), filtered and converted only when a pose captured at that
    frame is tested.
    """

    index: NDArray[np.int64]
    """(N,) row-major linear indices ``v * W + u`` of every n-th mask pixel."""
    depth_m: NDArray[np.floating]
    """(N,) measured z-depth there [m] (not yet filtered)."""
    width_px: int
    """Image width W [px]."""

    def __len__(self) -> int:
        return int(self.depth_m.shape[0])


def depth_samples(
    pixels: PixelSet, depth_m: NDArray[np.floating], config: OutlierRejectionConfig
) -> DepthSamples:
    """Every ``pixel_stride``-th mask pixel (row-major) and the measured depth there."""
    index = pixels.strided(config.pixel_stride)[0]
    return DepthSamples(index, np.take(depth_m.reshape(-1), index), pixels.shape[1])


def render_divider(intrinsics: CameraIntrinsics, config: OutlierRejectionConfig) -> int:
    """The configured divider, or the reference's rule: 2 for 640-wide images, else 4."""
    if config.render_divider:
        return config.render_divider
    return 2 if intrinsics.width_px == 640 else 4


class DepthOutlierTest:
    """Renders candidate poses and compares them with measured depth samples."""

    def __init__(
        self,
        renderer: DepthRenderer,
        intrinsics: CameraIntrinsics,
        config: OutlierRejectionConfig,
    ):
        div = render_divider(intrinsics, config)
        w = max(1, intrinsics.width_px // div)
        h = max(1, intrinsics.height_px // div)
        self._renderer = renderer
        self._small = intrinsics.resized(w, h)
        self._sx = w / intrinsics.width_px
        self._sy = h / intrinsics.height_px
        self._gamma = config.gamma
        self._depth_maximum_m = config.depth_maximum_m
        self.render_s = 0.0
        """Seconds spent in the depth renderer so far (the tracker's stage timing)."""

    @property
    def render_intrinsics(self) -> CameraIntrinsics:
        """The reduced camera the candidates are rendered with."""
        return self._small

    def errors(self, T_cam_obj: F64, samples: DepthSamples) -> F64:
        """Mean absolute depth errors ``(N,)`` [m] of the poses ``(N, 4, 4)`` (inf: no pixel)."""
        return self.errors_and_coverage(T_cam_obj, samples)[0]

    def errors_and_coverage(self, T_cam_obj: F64, samples: DepthSamples) -> tuple[F64, F64]:
        """Mean absolute depth errors ``(N,)`` [m] of the poses ``(N, 4, 4)`` (inf: no pixel)
        and the fraction ``(N,)`` of the valid samples each pose's render covers (0 when
        there is no valid sample)."""
        T = np.asarray(T_cam_obj, dtype=np.float64)
        start = time.perf_counter()
        rendered = self._renderer.render_depth(T, self._small)
        self.render_s += time.perf_counter() - start
        if rendered.shape != (T.shape[0],) + self._small.shape:
            raise ValueError(
                f"depth renderer returned shape {rendered.shape}, expected "
                f"{(T.shape[0],) + self._small.shape}"
            )
        d = samples.depth_m.astype(np.float64)
        ok = (d > 0.0) & (d < self._depth_maximum_m)
        if not ok.any():
            return np.full(T.shape[0], np.inf), np.zeros(T.shape[0])
        index, d = samples.index[ok], d[ok]
        v_px = index // samples.width_px
        u_px = index - v_px * samples.width_px
        h, w = self._small.shape
        cols = np.minimum(np.floor((u_px + 0.5) * self._sx).astype(np.int64), w - 1)
        rows = np.minimum(np.floor((v_px + 0.5) * self._sy).astype(np.int64), h - 1)
        r = rendered[:, rows, cols].astype(np.float64)  # (N, S)
        seen = np.isfinite(r) & (r != 0.0)
        count = seen.sum(axis=1)
        total = np.where(seen, np.abs(d[None, :] - r), 0.0).sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            errors = np.where(count > 0, total / np.maximum(count, 1), np.inf)
        return errors, count / float(d.shape[0])

    def reject(self, T_with_pose: F64, T_without_pose: F64, samples: DepthSamples | None) -> bool:
        """True when the candidate with the pose fits the depth gamma times worse than without.

        No samples (no mask or depth for the pose's frame): the pose is accepted, as the
        reference does when data is missing.
        """
        if samples is None or len(samples) == 0:
            return False
        e = self.errors(np.stack([T_with_pose, T_without_pose]), samples)
        e_a, e_b = float(e[0]), float(e[1])
        if np.isinf(e_a) and np.isinf(e_b):
            return False
        return e_a > self._gamma * e_b
