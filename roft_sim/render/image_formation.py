"""The colour camera's image formation: exposure, gamma, Poisson-Gaussian sensor noise and the
row times of a rolling shutter (:class:`roft_sim.scene.config.ImageFormationConfig`).

The renderer's rgb is taken as a gamma-encoded image of the scene irradiance. Per pixel and
channel, with ``x = rgb / 255``:

1. linear irradiance ``L = exposure_gain * x ** gamma``, clipped to [0, 1] (saturation);
2. electrons ``e = full_well_e * L``; the sensor reports ``Poisson(e) + N(0, read_noise_e^2)``
   (Poisson-Gaussian model: variance ``e + read_noise_e^2``, linear in the signal), clipped to
   [0, full_well_e];
3. encoded back: ``255 * (e / full_well_e) ** (1 / gamma)``, rounded to uint8.

The rolling shutter is applied by the renderer (:class:`roft_sim.render.SceneRenderer`), which
renders each band of rows at its own time (:func:`rolling_shutter_band_times`) and composes the
image; noise comes afterwards, on the composed image.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from roft_sim.scene.config import ImageFormationConfig

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]

__all__ = ["apply_image_formation", "row_times_s", "rolling_shutter_band_times"]


def apply_image_formation(rgb: U8, config: ImageFormationConfig, rng: np.random.Generator) -> U8:
    """The sensor image of a rendered one (module doc); the input itself when disabled.

    Args:
        rgb: (H, W, 3) uint8 rendered image.
        config: the model.
        rng: noise source (one stream per frame).

    Returns:
        (H, W, 3) uint8 sensor image (a new array unless the model is off).
    """
    if not config.enabled:
        return rgb
    x = rgb.astype(np.float64) / 255.0
    linear = np.clip(config.exposure_gain * x**config.gamma, 0.0, 1.0)
    electrons = config.full_well_e * linear
    if config.shot_noise:
        electrons = rng.poisson(electrons).astype(np.float64)
    if config.read_noise_e > 0:
        electrons = electrons + rng.normal(0.0, config.read_noise_e, electrons.shape)
    linear = np.clip(electrons / config.full_well_e, 0.0, 1.0)
    return np.rint(255.0 * linear ** (1.0 / config.gamma)).astype(np.uint8)


def row_times_s(height_px: int, t_s: float, readout_s: float) -> F64:
    """(H,) exposure time of each row [s]: ``t_s + (r / (H - 1) - 0.5) * readout_s`` (the
    middle row at ``t_s``; a one-row image at ``t_s``)."""
    if height_px == 1:
        return np.array([t_s])
    return t_s + (np.arange(height_px) / (height_px - 1) - 0.5) * readout_s


def rolling_shutter_band_times(
    height_px: int, t_s: float, readout_s: float, bands: int
) -> tuple[F64, NDArray[np.int64]]:
    """Render times of the row bands and the band of each row.

    Args:
        height_px: image rows H.
        t_s: frame time [s] (the middle row's exposure time).
        readout_s: first-to-last row readout time [s].
        bands: number of bands (0 or >= H: one per row).

    Returns:
        ``(times_s (B,), band_of_row (H,))``: each band is rendered at the mean exposure time of
        its rows; row r takes band ``band_of_row[r]``.
    """
    rows = row_times_s(height_px, t_s, readout_s)
    n = height_px if bands <= 0 or bands >= height_px else bands
    band_of_row = (np.arange(height_px) * n) // height_px
    times = np.array([rows[band_of_row == b].mean() for b in range(n)])
    return times, band_of_row.astype(np.int64)
