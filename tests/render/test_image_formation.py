"""Image formation: the noise follows the Poisson-Gaussian model (variance linear in the
signal, slope 1 in electrons, intercept the read noise), exposure and gamma act as stated, and a
rolling shutter skews a moving edge by the speed times the readout time."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from stand_ins import small_scenario

from roft_sim.errors import ConfigError
from roft_sim.render.image_formation import apply_image_formation, rolling_shutter_band_times
from roft_sim.scene.config import (
    BackgroundConfig,
    ImageFormationConfig,
    RenderConfig,
    SceneConfig,
    TableConfig,
)


def test_noise_variance_grows_linearly_with_the_signal_as_poisson_gaussian():
    full_well, read = 1000.0, 6.0
    config = ImageFormationConfig(enabled=True, gamma=1.0, full_well_e=full_well, read_noise_e=read)
    levels = np.arange(10, 250, 16, dtype=np.uint8)
    flat = np.repeat(levels[:, None, None], 20000, axis=1)[..., None].repeat(3, axis=2)
    noisy = apply_image_formation(flat, config, np.random.default_rng(0))
    electrons = noisy.astype(np.float64) * full_well / 255.0
    mean = electrons.reshape(len(levels), -1).mean(axis=1)
    var = electrons.reshape(len(levels), -1).var(axis=1)
    slope, intercept = np.polyfit(mean, var, 1)
    quantisation = (full_well / 255.0) ** 2 / 12.0
    assert slope == pytest.approx(1.0, rel=0.05), "shot noise: variance = electrons"
    assert intercept == pytest.approx(read**2 + quantisation, rel=0.25)
    np.testing.assert_allclose(mean, levels * full_well / 255.0, atol=1.0)  # unbiased


def test_exposure_and_gamma_are_applied_without_noise():
    config = ImageFormationConfig(
        enabled=True, gamma=2.2, exposure_gain=2.0, shot_noise=False, read_noise_e=0.0
    )
    rgb = np.array([[[0, 64, 128], [180, 200, 255]]], dtype=np.uint8)
    out = apply_image_formation(rgb, config, np.random.default_rng(0))
    expected = 255 * np.clip(2.0 * (rgb / 255.0) ** 2.2, 0, 1) ** (1 / 2.2)
    np.testing.assert_array_equal(out, np.rint(expected).astype(np.uint8))
    assert out[0, 1, 2] == 255  # saturated
    off = ImageFormationConfig()
    assert apply_image_formation(rgb, off, np.random.default_rng(0)) is rgb


def test_band_times_are_centred_on_the_frame_time():
    times, band = rolling_shutter_band_times(120, 1.0, 0.03, 0)
    assert len(times) == 120 and times[0] == pytest.approx(0.985) and times[-1] == 1.015
    times, band = rolling_shutter_band_times(120, 1.0, 0.03, 4)
    assert len(times) == 4 and np.bincount(band).tolist() == [30] * 4
    assert times.mean() == pytest.approx(1.0)


def test_rolling_shutter_and_motion_blur_are_exclusive():
    with pytest.raises(ConfigError, match="cannot be combined"):
        RenderConfig(motion_blur_subframes=3, image_formation=ImageFormationConfig(enabled=True))


@dataclass(frozen=True)
class _Sample:
    T_ref_obj: np.ndarray
    v_mps: np.ndarray
    w_radps: np.ndarray


@dataclass(frozen=True)
class _SlidingBox:
    """A box sliding along +x at constant speed, facing the camera."""

    speed_mps: float = 0.5
    z_m: float = 0.5
    start_s: float = 0.0
    end_s: float = 5.0

    def sample(self, t_s):
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        T = np.broadcast_to(np.eye(4), (len(t), 4, 4)).copy()
        T[:, 0, 3] = -0.05 + self.speed_mps * (t - 0.2)
        T[:, 2, 3] = self.z_m
        v = np.zeros((len(t), 3))
        v[:, 0] = self.speed_mps
        return _Sample(T_ref_obj=T, v_mps=v, w_radps=np.zeros((len(t), 3)))


@dataclass(frozen=True)
class _PlainBox:
    vertices_m: np.ndarray
    faces: np.ndarray


def _plain_box(half=0.04):
    import trimesh

    box = trimesh.creation.box(extents=(2 * half, 2 * half, 2 * half))
    return _PlainBox(np.asarray(box.vertices, float), np.asarray(box.faces, np.int64))


class _Assets:
    def __init__(self, mesh):
        self.mesh = mesh


def _left_edge_columns(rgb):
    """Sub-pixel column of the box's left edge per row (the first bright pixel, interpolated)."""
    grey = rgb.astype(float).mean(axis=2)
    bright = grey > 0.5 * grey.max()
    cols = np.full(rgb.shape[0], np.nan)
    for r in np.flatnonzero(bright.any(axis=1)):
        c = int(np.argmax(bright[r]))
        if c > 0:
            lo, hi = grey[r, c - 1], grey[r, c]
            cols[r] = c - 0.5 + (0.5 * grey.max() - lo) / max(hi - lo, 1e-9) - 0.5
    return cols


@pytest.mark.render
def test_rolling_shutter_skews_a_moving_edge_by_speed_times_readout():
    from roft_sim.render import SceneRenderer

    readout_s = 0.1
    dark = SceneConfig(
        table=TableConfig(enabled=False, texture_px=16),
        background=BackgroundConfig(enabled=False, texture_px=16),
        lights=(),
        ambient=1.0,
    )
    traj = _SlidingBox()
    slopes = {}
    for readout in (0.0, readout_s):
        formation = ImageFormationConfig(
            enabled=True,
            shot_noise=False,
            read_noise_e=0.0,
            gamma=1.0,
            rolling_shutter_readout_s=readout,
        )
        scenario = small_scenario(
            scene=dark, render=RenderConfig(image_formation=formation), frames=12
        )
        with SceneRenderer(scenario, object_assets=_Assets(_plain_box()), trajectory=traj) as r:
            frame = r.render_frame(6)
        cols = _left_edge_columns(frame.rgb)
        rows = np.flatnonzero(np.isfinite(cols))
        assert len(rows) > 30
        slopes[readout] = np.polyfit(rows, cols[rows], 1)[0]
        k = scenario.intrinsics
        # The middle row sees the box at the frame time, as the ground truth says.
        T = frame.T_cam_obj
        edge_u = k.fx_px * (T[0, 3] - 0.04) / (T[2, 3] - 0.04) + k.cx_px
        mid = rows[np.argmin(np.abs(rows - (k.height_px - 1) / 2))]
        assert cols[mid] == pytest.approx(edge_u, abs=0.6)
    k = scenario.intrinsics
    speed_px_s = k.fx_px * traj.speed_mps / (traj.z_m - 0.04)  # the front face at z - half
    expected = speed_px_s * readout_s / (k.height_px - 1)  # px per row
    assert abs(slopes[0.0]) < 0.01
    assert slopes[readout_s] == pytest.approx(expected, rel=0.05)
