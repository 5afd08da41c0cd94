"""Seeded depth-sensor noise models, applied to exact rendered z-depth.

Pure numpy/OpenCV functions of a z-depth image ``(H, W)`` float32 [m] (0 = no measurement) and an
explicit ``rng``; they never modify their input, and 0 stays "no measurement". Models
(``../shared/reference/metrics_faults_flow.md`` section 6):

- :func:`realsense_depth_noise`: active stereo (Intel RealSense D4xx). Stereo matching errs in
  DISPARITY ``d = f b / z`` by about ``subpixel_px`` RMS, so the depth error grows as
  ``sigma_z ~ z^2 subpixel / (f b)`` (Intel's RMS-error formula). Depth is drawn through the
  disparity (so it is exact to all orders, not only the first), and clipped to the sensor range.
- :func:`kinect_azure_depth_noise`: time of flight (Azure Kinect), BlenderProc's model: Gaussian
  pixel shifts (sigma 1/4 px) resampled bilinearly, additive noise
  ``(0.5 mm + max(0, z - 0.5 m) * 1e-3) * N(0, 1)``, holes where the depth range in a 3x3
  neighbourhood exceeds 0.8 m, and holes on dark surfaces (grey < 15) when an rgb image is given.
  Unlike BlenderProc, bilinear resampling never mixes a measurement with "no measurement":
  pixels whose footprint touches a hole take the nearest sample instead.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError

F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]

__all__ = [
    "NoDepthNoise",
    "RealSenseDepthNoise",
    "KinectAzureDepthNoise",
    "DepthNoiseConfig",
    "realsense_depth_noise",
    "realsense_depth_sigma_m",
    "kinect_azure_depth_noise",
    "kinect_azure_depth_sigma_m",
    "apply_depth_noise",
]


def _positive(owner: str, **values: float) -> None:
    for name, value in values.items():
        if not (np.isfinite(value) and value > 0):
            raise ConfigError(f"{owner}.{name} must be a positive number, got {value}")


def _non_negative(owner: str, **values: float) -> None:
    for name, value in values.items():
        if not (np.isfinite(value) and value >= 0):
            raise ConfigError(f"{owner}.{name} must be >= 0, got {value}")


@dataclass(frozen=True, slots=True, kw_only=True)
class NoDepthNoise:
    """Exact depth (the default)."""

    kind: Literal["none"] = "none"
    """Model name."""


@dataclass(frozen=True, slots=True, kw_only=True)
class RealSenseDepthNoise:
    """Active-stereo depth noise (RealSense D4xx-like), see :func:`realsense_depth_noise`."""

    kind: Literal["realsense"] = "realsense"
    """Model name."""
    baseline_m: float = 0.055
    """Stereo baseline [m] (D415: 55 mm; D435: 50 mm)."""
    subpixel_px: float = 0.08
    """RMS disparity error [px] (Intel quotes about 0.08 for well-textured scenes)."""
    focal_px: float | None = None
    """Focal length of the depth imager [px]; None = the rendered camera's ``fx``."""
    min_range_m: float = 0.3
    """Closer depths are lost (0) [m]."""
    max_range_m: float = 10.0
    """Farther depths are lost (0) [m]."""

    def __post_init__(self) -> None:
        _positive("depth_noise", baseline_m=self.baseline_m, max_range_m=self.max_range_m)
        _non_negative("depth_noise", subpixel_px=self.subpixel_px, min_range_m=self.min_range_m)
        if self.focal_px is not None:
            _positive("depth_noise", focal_px=self.focal_px)
        if self.max_range_m <= self.min_range_m:
            raise ConfigError(
                f"depth_noise.max_range_m ({self.max_range_m}) must exceed min_range_m "
                f"({self.min_range_m})"
            )


@dataclass(frozen=True, slots=True, kw_only=True)
class KinectAzureDepthNoise:
    """Time-of-flight depth noise (Azure Kinect-like), see :func:`kinect_azure_depth_noise`."""

    kind: Literal["kinect_azure"] = "kinect_azure"
    """Model name."""
    shift_sigma_px: float = 0.25
    """Standard deviation of the random pixel shifts [px]."""
    base_sigma_m: float = 0.0005
    """Noise standard deviation up to ``sigma_start_m`` [m]."""
    sigma_slope: float = 0.001
    """Growth of the standard deviation beyond ``sigma_start_m`` [m per m]."""
    sigma_start_m: float = 0.5
    """Depth from which the noise grows [m]."""
    edge_hole_threshold_m: float = 0.8
    """Holes where max - min depth in a 3x3 neighbourhood exceeds this [m]."""
    dark_threshold: int = 15
    """Holes where the grey value of the rgb image is below this (0 disables)."""

    def __post_init__(self) -> None:
        _non_negative(
            "depth_noise",
            shift_sigma_px=self.shift_sigma_px,
            base_sigma_m=self.base_sigma_m,
            sigma_slope=self.sigma_slope,
            sigma_start_m=self.sigma_start_m,
        )
        _positive("depth_noise", edge_hole_threshold_m=self.edge_hole_threshold_m)
        if not 0 <= self.dark_threshold <= 255:
            raise ConfigError(
                f"depth_noise.dark_threshold must be 0 to 255, got {self.dark_threshold}"
            )


DepthNoiseConfig = NoDepthNoise | RealSenseDepthNoise | KinectAzureDepthNoise
"""Any depth-noise model; TOML picks one with ``kind``."""


def _as_depth(depth_m: np.ndarray) -> F32:
    depth = np.asarray(depth_m)
    if depth.ndim != 2:
        raise ValueError(f"depth must have shape (H, W), got {depth.shape}")
    if not np.isfinite(depth).all() or (depth < 0).any():
        raise ValueError("depth must be finite and >= 0 (0 = no measurement)")
    return depth.astype(np.float32, copy=False)


def realsense_depth_sigma_m(
    depth_m: np.ndarray, *, focal_px: float, baseline_m: float = 0.055, subpixel_px: float = 0.08
) -> np.ndarray:
    """First-order RMS depth error ``z^2 subpixel / (f b)`` [m] at depths ``depth_m`` [m]."""
    z = np.asarray(depth_m, dtype=np.float64)
    return z * z * subpixel_px / (focal_px * baseline_m)


def realsense_depth_noise(
    depth_m: np.ndarray,
    rng: np.random.Generator,
    *,
    focal_px: float,
    baseline_m: float = 0.055,
    subpixel_px: float = 0.08,
    min_range_m: float = 0.3,
    max_range_m: float = 10.0,
) -> F32:
    """Active-stereo noise: Gaussian disparity error, then range limits.

    Args:
        depth_m: (H, W) exact z-depth [m], 0 = none.
        rng: noise source.
        focal_px: focal length of the depth imager [px].
        baseline_m: stereo baseline [m].
        subpixel_px: RMS disparity error [px].
        min_range_m, max_range_m: measured depths outside this range become 0 [m].

    Returns:
        (H, W) float32 noisy z-depth [m], 0 = none.
    """
    depth = _as_depth(depth_m)
    z = depth.astype(np.float64)
    valid = z > 0
    fb = focal_px * baseline_m
    disparity = np.where(valid, fb / np.where(valid, z, 1.0), 0.0)
    disparity = disparity + subpixel_px * rng.standard_normal(z.shape)
    ok = valid & (disparity > 0)
    noisy = np.where(ok, fb / np.where(ok, disparity, 1.0), 0.0)
    noisy[(noisy < min_range_m) | (noisy > max_range_m)] = 0.0
    return noisy.astype(np.float32)


def kinect_azure_depth_sigma_m(
    depth_m: np.ndarray,
    *,
    base_sigma_m: float = 0.0005,
    sigma_slope: float = 0.001,
    sigma_start_m: float = 0.5,
) -> np.ndarray:
    """Standard deviation [m] of the additive time-of-flight noise at depths ``depth_m`` [m]."""
    z = np.asarray(depth_m, dtype=np.float64)
    return base_sigma_m + np.maximum(z - sigma_start_m, 0.0) * sigma_slope


def _gaussian_shift(depth: F32, sigma_px: float, rng: np.random.Generator) -> F32:
    """Resamples ``depth`` at pixel positions jittered by N(0, sigma^2) [px], bilinearly where
    all four neighbours are measurements, else nearest."""
    if sigma_px == 0:
        return depth.copy()
    h, w = depth.shape
    shifts = rng.normal(0.0, sigma_px, size=(h, w, 2)).astype(np.float32)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    map_x = np.clip(xx + shifts[..., 0], 0, w - 1)
    map_y = np.clip(yy + shifts[..., 1], 0, h - 1)
    linear = cv2.remap(depth, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    valid = (depth > 0).astype(np.float32)
    coverage = cv2.remap(valid, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    nearest = cv2.remap(depth, map_x, map_y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE)
    return np.where(coverage >= 1.0 - 1e-6, linear, nearest).astype(np.float32)


def kinect_azure_depth_noise(
    depth_m: np.ndarray,
    rng: np.random.Generator,
    *,
    rgb: U8 | None = None,
    shift_sigma_px: float = 0.25,
    base_sigma_m: float = 0.0005,
    sigma_slope: float = 0.001,
    sigma_start_m: float = 0.5,
    edge_hole_threshold_m: float = 0.8,
    dark_threshold: int = 15,
) -> F32:
    """Time-of-flight noise (BlenderProc's Azure Kinect model, see the module doc).

    Args:
        depth_m: (H, W) exact z-depth [m], 0 = none.
        rng: noise source.
        rgb: (H, W, 3) uint8 RGB image registered with the depth, for holes on dark surfaces;
            None skips that step.
        shift_sigma_px: standard deviation of the pixel shifts [px].
        base_sigma_m, sigma_slope, sigma_start_m: additive noise
            ``base + max(0, z - start) * slope`` [m].
        edge_hole_threshold_m: 3x3 depth range above which a pixel becomes a hole [m].
        dark_threshold: grey level below which a pixel becomes a hole (0 disables).

    Returns:
        (H, W) float32 noisy z-depth [m], 0 = none.
    """
    depth = _as_depth(depth_m)
    shifted = _gaussian_shift(depth, shift_sigma_px, rng)
    valid = shifted > 0
    sigma = kinect_azure_depth_sigma_m(
        shifted, base_sigma_m=base_sigma_m, sigma_slope=sigma_slope, sigma_start_m=sigma_start_m
    )
    noisy: NDArray[Any] = shifted.astype(np.float64) + sigma * rng.standard_normal(depth.shape)
    noisy = np.where(valid & (noisy > 0), noisy, 0.0).astype(np.float32)
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (3, 3))
    low = cv2.erode(np.where(noisy > 0, noisy, np.float32(np.inf)), kernel)
    high = cv2.dilate(noisy, kernel)
    edge = np.isfinite(low) & (high - low > edge_hole_threshold_m)
    noisy[edge] = 0.0
    if rgb is not None and dark_threshold > 0:
        if rgb.shape[:2] != depth.shape or rgb.dtype != np.uint8:
            raise ValueError(
                f"rgb must be uint8 (H, W, 3) matching depth {depth.shape}, got "
                f"{rgb.dtype} {rgb.shape}"
            )
        grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        noisy[grey < dark_threshold] = 0.0
    return noisy


def apply_depth_noise(
    config: DepthNoiseConfig,
    depth_m: np.ndarray,
    rng: np.random.Generator,
    *,
    fx_px: float,
    rgb: U8 | None = None,
) -> F32:
    """Applies the model ``config`` to an exact z-depth image.

    Args:
        config: the model and its parameters.
        depth_m: (H, W) exact z-depth [m], 0 = none.
        rng: noise source (unused by :class:`NoDepthNoise`).
        fx_px: focal length of the rendered camera [px] (RealSense default focal length).
        rgb: (H, W, 3) uint8 image registered with the depth (Kinect dark-surface holes).

    Returns:
        (H, W) float32 sensor z-depth [m], 0 = none (a copy; the input is not modified).
    """
    if isinstance(config, NoDepthNoise):
        return _as_depth(depth_m).copy()
    if isinstance(config, RealSenseDepthNoise):
        return realsense_depth_noise(
            depth_m,
            rng,
            focal_px=config.focal_px if config.focal_px is not None else fx_px,
            baseline_m=config.baseline_m,
            subpixel_px=config.subpixel_px,
            min_range_m=config.min_range_m,
            max_range_m=config.max_range_m,
        )
    if isinstance(config, KinectAzureDepthNoise):
        return kinect_azure_depth_noise(
            depth_m,
            rng,
            rgb=rgb,
            shift_sigma_px=config.shift_sigma_px,
            base_sigma_m=config.base_sigma_m,
            sigma_slope=config.sigma_slope,
            sigma_start_m=config.sigma_start_m,
            edge_hole_threshold_m=config.edge_hole_threshold_m,
            dark_threshold=config.dark_threshold,
        )
    raise ConfigError(f"unknown depth-noise model {config!r}; use none, realsense or kinect_azure")
