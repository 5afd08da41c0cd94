"""Flow sources against independent oracles: plane-induced homographies, a textured translation,
NVOF quantisation bounds, noise statistics and determinism per (seed, from_k, to_k)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from roft_sim.datasets.base import InMemorySequence
from roft_sim.errors import ConfigError
from roft_sim.geometry import CameraIntrinsics, matrix_from_rotvec, transform_from_rt
from roft_sim.records import FlowField, PoseTrack
from roft_sim.sensors.flow_sources import (
    NVOF_PRECISION_PX,
    DisFlowSource,
    FlowNoiseConfig,
    FlowSource,
    GroundTruthFlowSource,
    NoisyGroundTruthFlowSource,
    NvofLikeFlowSource,
    StoredFlowSource,
    block_cells,
    block_mean_flow,
    flow_px_from_s10_5,
    frame_rng,
    make_dis,
    make_flow_source,
    one_motion_per_block,
    s10_5_from_flow_px,
)

CAM = CameraIntrinsics(
    fx_px=150.0, fy_px=150.0, cx_px=79.5, cy_px=59.5, width_px=160, height_px=120
)
HALF_SIDE_M = 0.12
"""Half side of the square planar object (object frame: the z = 0 plane)."""
WALL_Z_M = 2.0
"""Static background wall: the plane z = WALL_Z_M of the WORLD frame."""


def _rays() -> np.ndarray:
    v, u = np.mgrid[0 : CAM.height_px, 0 : CAM.width_px].astype(np.float64)
    return np.stack([(u - CAM.cx_px) / CAM.fx_px, (v - CAM.cy_px) / CAM.fy_px, np.ones_like(u)], -1)


def _render(T_cam_obj: np.ndarray, T_world_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ray-cast z-depth and object mask of the square and the world wall (closed form)."""
    d = _rays()
    n = T_cam_obj[:3, 2]
    s_obj = (n @ T_cam_obj[:3, 3]) / (d @ n)
    X_obj = (s_obj[..., None] * d - T_cam_obj[:3, 3]) @ T_cam_obj[:3, :3]  # object-frame point
    hit = (s_obj > 0) & (np.abs(X_obj[..., :2]) <= HALF_SIDE_M).all(-1)
    # Wall in camera coordinates: n_w . X = d_w with n_w = R_cw e_z, d_w = WALL_Z_M - e_z.t_wc
    n_w = T_world_cam[2, :3]
    d_w = WALL_Z_M - T_world_cam[2, 3]
    s_wall = d_w / (d @ n_w)
    mask = hit & (s_obj < s_wall)
    depth = np.where(mask, s_obj, s_wall).astype(np.float32)
    return depth, mask


def _plane_flow(n_from: np.ndarray, d_from: float, M: np.ndarray) -> np.ndarray:
    """Flow of every pixel on the plane {n.X = d} (from-camera frame) under the point motion M,
    by the plane-induced homography H = K (R + t n^T / d) K^-1 (no depth images involved)."""
    H = CAM.K @ (M[:3, :3] + np.outer(M[:3, 3], n_from) / d_from) @ np.linalg.inv(CAM.K)
    v, u = np.mgrid[0 : CAM.height_px, 0 : CAM.width_px].astype(np.float64)
    p = np.stack([u, v, np.ones_like(u)], -1) @ H.T
    return p[..., :2] / p[..., 2:] - np.stack([u, v], -1)


def _exact_flow(T_obj: np.ndarray, T_wc: np.ndarray, a: int, b: int) -> FlowField:
    """Oracle flow a -> b from the homographies of the two planes, with the occlusion rule."""
    depth_a, mask_a = _render(T_obj[a], T_wc[a])
    _, mask_b = _render(T_obj[b], T_wc[b])
    M_obj = T_obj[b] @ np.linalg.inv(T_obj[a])
    M_wall = np.linalg.inv(T_wc[b]) @ T_wc[a]
    f_obj = _plane_flow(T_obj[a][:3, 2], T_obj[a][:3, 2] @ T_obj[a][:3, 3], M_obj)
    f_wall = _plane_flow(T_wc[a][2, :3], WALL_Z_M - T_wc[a][2, 3], M_wall)
    flow = np.where(mask_a[..., None], f_obj, f_wall)
    v, u = np.mgrid[0 : CAM.height_px, 0 : CAM.width_px].astype(np.float64)
    tu, tv = u + flow[..., 0], v + flow[..., 1]
    inside = (tu >= -0.5) & (tu < CAM.width_px - 0.5) & (tv >= -0.5) & (tv < CAM.height_px - 0.5)
    ti = np.clip(np.rint(tv), 0, CAM.height_px - 1).astype(int)
    tj = np.clip(np.rint(tu), 0, CAM.width_px - 1).astype(int)
    covered = ~mask_a & mask_b[ti, tj]  # wall point lands behind the object
    valid = inside & ~covered & (depth_a > 0)
    return FlowField(
        flow_px=np.where(valid[..., None], flow, 0).astype(np.float32),
        from_k=a,
        to_k=b,
        valid=valid,
    )


def _texture(rgb_seed: int = 0) -> np.ndarray:
    return np.random.default_rng(rgb_seed).integers(
        0, 255, (CAM.height_px, CAM.width_px, 3), dtype=np.uint8
    )


def planar_sequence(n: int = 4, *, moving_camera: bool = False) -> InMemorySequence:
    t = np.arange(n)
    R = matrix_from_rotvec(np.stack([0.03 * t, -0.02 * t + 0.3, 0.05 * t], 1))
    p = np.stack([0.01 * t - 0.02, 0.008 * t, 0.8 + 0.01 * t], 1)
    T_obj = transform_from_rt(R, p)
    if moving_camera:
        T_wc = transform_from_rt(
            matrix_from_rotvec(np.stack([0 * t, 0.01 * t, 0 * t], 1)),
            np.stack([0.01 * t, 0 * t, 0 * t], 1),
        )
    else:
        T_wc = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    renders = [_render(T_obj[k], T_wc[k]) for k in range(n)]
    exact = [None] + [_exact_flow(T_obj, T_wc, k - 1, k) for k in range(1, n)]
    return InMemorySequence(
        name="plane",
        object_name="square",
        intrinsics=CAM,
        fps=30,
        rgb_frames=[_texture(k) for k in range(n)],
        depth_frames=[r[0] for r in renders],
        gt=PoseTrack(
            t_s=t / 30.0, T_cam_obj=T_obj, v_obj_mps=np.zeros((n, 3)), w_radps=np.zeros((n, 3))
        ),
        gt_masks=[r[1] for r in renders],
        flows={"exact": exact},
        T_world_cam=T_wc,
    )


@pytest.mark.parametrize("moving_camera", [False, True])
def test_gt_flow_matches_stored_exact_flow(moving_camera):
    seq = planar_sequence(moving_camera=moving_camera)
    gt, stored = GroundTruthFlowSource(), StoredFlowSource("exact")
    for k in range(1, len(seq)):
        a, b = gt.flow(seq, k - 1, k), stored.flow(seq, k - 1, k)
        assert b is not None and a.valid is not None and b.valid is not None
        assert a.valid.sum() > 0.9 * CAM.width_px * CAM.height_px
        np.testing.assert_array_equal(a.valid, b.valid)
        np.testing.assert_allclose(a.flow_px[a.valid], b.flow_px[b.valid], atol=1e-3)
        mask = seq.mask(k - 1, "gt")
        assert np.abs(a.flow_px[mask & a.valid]).max() > 0.5  # the object does move
        if not moving_camera:
            assert np.abs(a.flow_px[~mask & a.valid]).max() < 1e-9  # static wall, static camera


def test_gt_flow_any_stride_and_backward():
    seq = planar_sequence(4)
    T_obj, T_wc = seq.gt.T_cam_obj, seq.camera_poses()
    gt = GroundTruthFlowSource()
    for a, b in [(0, 2), (0, 3), (3, 1)]:
        ours, oracle = gt.flow(seq, a, b), _exact_flow(T_obj, T_wc, a, b)
        np.testing.assert_array_equal(ours.valid, oracle.valid)
        np.testing.assert_allclose(
            ours.flow_px[ours.valid], oracle.flow_px[oracle.valid], atol=1e-3
        )
        assert (ours.from_k, ours.to_k) == (a, b)


def test_stored_source_only_gives_stride_one_and_names_missing_sets():
    seq = planar_sequence(3)
    assert StoredFlowSource("exact").flow(seq, 0, 2) is None
    with pytest.raises(ConfigError, match="no stored flow set 'nvof_1_slow'.*'exact'"):
        StoredFlowSource("nvof_1_slow").flow(seq, 0, 1)
    with pytest.raises(ValueError, match="two different frames"):
        GroundTruthFlowSource().flow(seq, 1, 1)


def _sinusoid_image(shift_u: float, shift_v: float, h: int = 120, w: int = 160) -> np.ndarray:
    """A smooth, richly textured grey image I(u - du, v - dv): exact translation by (du, dv)."""
    rng = np.random.default_rng(7)
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    img = np.zeros((h, w))
    for _ in range(25):
        fu, fv = rng.uniform(-0.06, 0.06, 2)  # periods >= 16 px: no aliasing at these shifts
        img += np.cos(2 * np.pi * (fu * (u - shift_u) + fv * (v - shift_v)) + rng.uniform(0, 6.3))
    img = (img - img.min()) / (img.max() - img.min()) * 220 + 15
    return np.repeat(np.rint(img).astype(np.uint8)[..., None], 3, axis=2)


def _translating_sequence(du: float, dv: float) -> InMemorySequence:
    frames = [_sinusoid_image(k * du, k * dv) for k in range(3)]
    return InMemorySequence(
        name="shift",
        object_name="none",
        intrinsics=CAM,
        fps=30,
        rgb_frames=frames,
        depth_frames=[np.ones(CAM.shape, np.float32)] * 3,
    )


@pytest.mark.parametrize(
    ("preset", "max_median_epe_px"), [("fast", 0.15), ("medium", 0.05), ("medium4", 0.15)]
)
def test_dis_recovers_a_textured_translation(preset, max_median_epe_px):
    du, dv = 2.3, -1.4
    seq = _translating_sequence(du, dv)
    src = DisFlowSource(preset)
    for a, b, s in [(0, 1, 1), (0, 2, 2)]:
        f = src.flow(seq, a, b)
        inner = f.flow_px[10:-10, 10:-10].reshape(-1, 2)
        epe = np.linalg.norm(inner - [s * du, s * dv], axis=1)
        assert np.median(epe) < max_median_epe_px, np.median(epe)
    np.testing.assert_array_equal(src.flow(seq, 0, 1).flow_px, src.flow(seq, 0, 1).flow_px)
    with pytest.raises(ConfigError, match="unknown DIS preset 'slow'"):
        DisFlowSource("slow")


def test_medium4_is_medium_stopped_at_a_quarter_of_the_resolution():
    medium, quarter = make_dis("medium"), make_dis("medium4")
    assert (medium.getFinestScale(), quarter.getFinestScale()) == (1, 2)
    for getter in (
        "getPatchSize",
        "getPatchStride",
        "getGradientDescentIterations",
        "getVariationalRefinementIterations",
    ):
        assert getattr(quarter, getter)() == getattr(medium, getter)(), getter
    assert make_flow_source("nvof-like:dis:medium4", seed=0).name == "nvof-like:dis:medium4"
    seq = _translating_sequence(2.3, -1.4)
    assert not np.array_equal(
        DisFlowSource("medium4").flow(seq, 0, 1).flow_px,
        DisFlowSource("medium").flow(seq, 0, 1).flow_px,
    )


@pytest.mark.parametrize("precision_px", [NVOF_PRECISION_PX, 1 / 32])
def test_nvof_like_quantisation_and_block_bounds(precision_px):
    half_step = precision_px / 2
    seq = planar_sequence(3)
    holes = FlowNoiseConfig(
        sigma_px=0, relative_sigma=0, outlier_fraction=0, hole_fraction=0.2, hole_size_px=8
    )
    inner = NoisyGroundTruthFlowSource(holes, seed=1)  # exact flow with 8x8 holes
    nv = NvofLikeFlowSource(inner) if precision_px == NVOF_PRECISION_PX else None
    nv = nv or NvofLikeFlowSource(inner, precision_px=precision_px)
    assert nv.name == "nvof-like:gt+noise"
    f_in, f_nv = inner.flow(seq, 0, 1), nv.flow(seq, 0, 1)
    assert f_nv.grid_px == 4 and f_nv.flow_px.shape == (30, 40, 2)
    steps = f_nv.flow_px / precision_px  # whole steps of the hardware precision
    np.testing.assert_array_equal(steps, np.rint(steps))
    dense_in = f_in.dense(*CAM.shape).astype(np.float64)
    blocks = dense_in.reshape(30, 4, 40, 4, 2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN blocks
        block_mean = np.nanmean(blocks, axis=(1, 3))
        spread = np.nanmax(blocks, axis=(1, 3)) - np.nanmin(blocks, axis=(1, 3))
    ok = f_nv.valid
    assert ok is not None and 0 < (~ok).sum() < ok.size
    np.testing.assert_array_equal(~ok, np.isnan(block_mean).all(-1))  # no valid pixel -> invalid
    one_motion = ok & (spread.max(-1) <= precision_px)  # these get the block mean
    assert one_motion.sum() > ok.sum() // 2
    assert np.abs(f_nv.flow_px[one_motion] - block_mean[one_motion]).max() <= half_step + 1e-6
    # Per pixel: |nvof - inner| <= half a step + the inner flow's spread within the block.
    per_pixel = np.abs(f_nv.dense(*CAM.shape) - dense_in)
    bound = np.repeat(np.repeat(spread, 4, 0), 4, 1) + half_step + 1e-6
    finite = np.isfinite(per_pixel).all(-1)
    assert (per_pixel[finite] <= bound[finite]).all()
    assert NvofLikeFlowSource(StoredFlowSource("exact")).flow(seq, 0, 2) is None


def test_nvof_like_boundary_block_gets_one_of_its_motions_not_their_average():
    """NVOF matches blocks (one displacement per 4x4 block, with a matching cost), so a block on
    a motion boundary gets the motion of most of its pixels; the block mean gave a vector that
    belongs to neither (here (6, -2.25) px for an object moving (8, -3) px over a static
    background)."""

    class Boundary:
        name = "boundary"

        def flow(self, sequence, from_k, to_k):
            h, w = sequence.intrinsics.shape
            f = np.zeros((h, w, 2), np.float32)
            f[:, : w // 2 + 3, 0] = 8.0  # object (left) moving; 3 of 4 columns of a block
            f[:, : w // 2 + 3, 1] = -3.0
            return FlowField(flow_px=f, from_k=from_k, to_k=to_k)

    seq = planar_sequence(3)
    h, w = CAM.shape
    f = NvofLikeFlowSource(Boundary()).flow(seq, 0, 1)  # type: ignore[arg-type]
    col = (w // 2) // 4  # the block column holding the boundary: 3 object + 1 static column
    np.testing.assert_array_equal(f.flow_px[:, col - 1], np.tile([8.0, -3.0], (h // 4, 1)))
    np.testing.assert_array_equal(f.flow_px[:, col + 1], 0.0)
    np.testing.assert_array_equal(f.flow_px[:, col], np.tile([8.0, -3.0], (h // 4, 1)))


def test_nvof_like_precision_must_be_whole_s10_5_steps():
    with pytest.raises(ConfigError, match="precision_px"):
        NvofLikeFlowSource(GroundTruthFlowSource(), precision_px=0.1)


def test_s10_5_round_trip_and_saturation():
    f = np.array([0.0, 1 / 64 - 1e-9, 1 / 32, -3.3, 2000.0, -2000.0])
    q = s10_5_from_flow_px(f)
    assert q.dtype == np.int16
    assert q.tolist() == [0, 0, 1, -106, 32767, -32768]
    back = flow_px_from_s10_5(q)
    assert np.abs(back[:4] - f[:4]).max() <= 1 / 64


def test_noisy_gt_statistics_follow_the_config():
    seq = planar_sequence(2)
    exact = GroundTruthFlowSource().flow(seq, 0, 1)
    ok = exact.valid
    white = NoisyGroundTruthFlowSource(
        FlowNoiseConfig(sigma_px=0.5, relative_sigma=0, correlation_px=0, outlier_fraction=0), 1
    ).flow(seq, 0, 1)
    err = (white.flow_px - exact.flow_px)[ok]
    assert err.std(axis=0) == pytest.approx([0.5, 0.5], rel=0.03)
    corr = NoisyGroundTruthFlowSource(
        FlowNoiseConfig(sigma_px=0.5, relative_sigma=0, correlation_px=3, outlier_fraction=0), 1
    ).flow(seq, 0, 1)
    e = corr.flow_px - exact.flow_px
    inner = e[20:-20, 20:-20, 0]
    assert inner.std() == pytest.approx(0.5, rel=0.25)  # correlated: fewer independent samples
    assert np.corrcoef(inner[:, :-1].ravel(), inner[:, 1:].ravel())[0, 1] > 0.8
    out = NoisyGroundTruthFlowSource(
        FlowNoiseConfig(
            sigma_px=0, relative_sigma=0, outlier_fraction=0.2, hole_fraction=0.25, hole_size_px=4
        ),
        2,
    ).flow(seq, 0, 1)
    moved = (np.abs(out.flow_px - exact.flow_px) > 0).any(-1) & out.valid
    n = int(out.valid.sum())
    frac = moved.sum() / n
    assert abs(frac - 0.2) < 3 * np.sqrt(0.2 * 0.8 / n)
    assert np.linalg.norm((out.flow_px - exact.flow_px)[moved], axis=1).max() <= 20.0 + 1e-4
    holes = 1 - out.valid[ok].mean()
    assert 0.15 < holes < 0.35  # 300 4x4 blocks at 25 %
    rel = NoisyGroundTruthFlowSource(
        FlowNoiseConfig(sigma_px=0, relative_sigma=0.1, correlation_px=0, outlier_fraction=0), 3
    ).flow(seq, 0, 1)
    mag = np.linalg.norm(exact.flow_px[ok], axis=1)
    moving = mag > 0.5
    z = (rel.flow_px - exact.flow_px)[ok][moving] / (0.1 * mag[moving, None])
    assert z.std() == pytest.approx(1.0, rel=0.05)
    with pytest.raises(ConfigError, match="outlier_fraction must be in"):
        FlowNoiseConfig(outlier_fraction=1.5)


def test_stochastic_sources_are_deterministic_per_seed_and_frame_pair():
    seq = planar_sequence(4)
    a = NoisyGroundTruthFlowSource(seed=5)
    b = NoisyGroundTruthFlowSource(seed=5)
    later = a.flow(seq, 2, 3)  # ask for another pair first: must not change (0, 1)
    np.testing.assert_array_equal(a.flow(seq, 0, 1).flow_px, b.flow(seq, 0, 1).flow_px)
    np.testing.assert_array_equal(later.flow_px, b.flow(seq, 2, 3).flow_px)
    assert not np.array_equal(
        a.flow(seq, 0, 1).flow_px, NoisyGroundTruthFlowSource(seed=6).flow(seq, 0, 1).flow_px
    )
    assert not np.array_equal(a.flow(seq, 0, 1).flow_px, a.flow(seq, 0, 2).flow_px)
    assert frame_rng(1, 2, 3).random() == frame_rng(1, 2, 3).random()
    with pytest.raises(ValueError, match=">= 0"):
        frame_rng(-1, 0)


def test_make_flow_source_specs():
    assert isinstance(make_flow_source("gt", seed=0), GroundTruthFlowSource)
    assert make_flow_source("gt+noise", seed=3).seed == 3
    assert make_flow_source("dis", seed=0).name == "dis:medium"
    assert make_flow_source("dis:ultrafast", seed=0).name == "dis:ultrafast"
    nv = make_flow_source("nvof-like:gt+noise", seed=4)
    assert nv.name == "nvof-like:gt+noise" and nv.inner.seed == 4
    assert make_flow_source("stored:nvof_1_slow", seed=0).name == "stored:nvof_1_slow"
    for spec in ("gt", "gt+noise", "dis", "nvof-like:dis", "stored:x"):
        assert isinstance(make_flow_source(spec, seed=0), FlowSource)
    with pytest.raises(ConfigError, match="needs an inner source"):
        make_flow_source("nvof-like", seed=0)
    with pytest.raises(ConfigError, match="unknown flow source 'raft'.*gt\\+noise"):
        make_flow_source("raft", seed=0)


def test_gt_source_needs_ground_truth():
    seq = _translating_sequence(1.0, 0.0)
    with pytest.raises(ConfigError, match="no ground-truth poses"):
        GroundTruthFlowSource().flow(seq, 0, 1)


def _block_mean_by_reduction(flow_px: np.ndarray, g: int) -> tuple[np.ndarray, np.ndarray]:
    """The NVOF-like block mean as numpy's multi-axis reduction writes it (the oracle)."""
    h, w = flow_px.shape[:2]
    hg, wg = -(-h // g), -(-w // g)
    dense = np.full((hg * g, wg * g, 2), np.nan, dtype=np.float64)
    dense[:h, :w] = flow_px
    blocks = dense.reshape(hg, g, wg, g, 2)
    ok = np.isfinite(blocks).all(axis=4)
    count = ok.sum(axis=(1, 3))
    total = np.where(ok[..., None], blocks, 0.0).sum(axis=(1, 3))
    valid = count > 0
    return np.where(valid[..., None], total / np.maximum(count, 1)[..., None], 0.0), valid


@pytest.mark.parametrize(
    ("shape", "holes"), [((48, 64), False), ((48, 64), True), ((50, 61), False), ((50, 61), True)]
)
def test_block_mean_flow_is_bit_identical_to_the_reduction(shape, holes):
    # Magnitudes over 24 decades make float64 sums of float32 values depend on their order:
    # the block mean must add in the reduction's order to give the same bits.
    rng = np.random.default_rng(5)
    for _ in range(10):
        scale = 10.0 ** rng.integers(-12, 12, shape + (2,))
        flow = (rng.standard_normal(shape + (2,)) * scale).astype(np.float32)
        if holes:
            flow[rng.random(shape) < 0.3] = np.nan
            flow[:8, :8] = np.inf  # whole blocks without a finite pixel
        mean, valid = block_mean_flow(flow, 4)
        want_mean, want_valid = _block_mean_by_reduction(flow, 4)
        assert mean.dtype == np.float64 and mean.shape == want_mean.shape
        np.testing.assert_array_equal(valid, want_valid)
        np.testing.assert_array_equal(mean, want_mean)
        cells = block_cells(flow, 4)
        assert (cells is None) == (holes or shape != (48, 64))
        if cells is not None:  # the shared copy adds in the same order: the same bits
            assert cells.shape == (16, 12, 16, 2) and cells.flags.c_contiguous
            np.testing.assert_array_equal(cells[1 * 4 + 2, 3, 5], flow[3 * 4 + 1, 5 * 4 + 2])
            np.testing.assert_array_equal(block_mean_flow(flow, 4, cells=cells)[0], want_mean)
        if holes:
            assert not valid[:2, :2].any() and (mean[:2, :2] == 0).all()


@pytest.mark.parametrize("shape", [(32, 48), (30, 45)])
def test_one_motion_per_block_matches_a_block_by_block_oracle(shape):
    """Against a plain loop over blocks: the mean where the finite vectors agree within the
    spread, else the L1 medoid (first in row-major order on ties); NaN holes and partial
    border blocks included."""
    rng = np.random.default_rng(11)
    h, w = shape
    flow = np.zeros((h, w, 2), dtype=np.float32)
    flow[..., 0] = np.where(np.arange(w)[None, :] < w // 2 + 1, 2.0, -3.0)  # a motion boundary
    flow += rng.normal(scale=0.05, size=flow.shape).astype(np.float32)
    flow[rng.random((h, w)) < 0.1] = np.nan
    g, spread = 4, 0.25
    mean, valid = block_mean_flow(flow, g)
    got = one_motion_per_block(flow, mean, g, spread)
    for bi in range(mean.shape[0]):
        for bj in range(mean.shape[1]):
            v = flow[bi * g : (bi + 1) * g, bj * g : (bj + 1) * g].reshape(-1, 2).astype(np.float64)
            v = v[np.isfinite(v).all(axis=1)]
            if v.size == 0:
                np.testing.assert_array_equal(got[bi, bj], 0.0)
                continue
            if (v.max(axis=0) - v.min(axis=0)).max() <= spread:
                np.testing.assert_array_equal(got[bi, bj], mean[bi, bj])
            else:
                cost = np.abs(v[:, None, :] - v[None, :, :]).sum(axis=(1, 2))
                np.testing.assert_allclose(got[bi, bj], v[np.argmin(cost)], atol=1e-6)
    assert (np.abs(got[..., 0] - 2.0) < 0.3).sum() + (np.abs(got[..., 0] + 3.0) < 0.3).sum() == int(
        valid.sum()
    )


def test_one_motion_per_block_with_shared_cells_gives_the_same_blocks():
    """The NVOF-like source computes :func:`block_cells` once for the mean and the spread: the
    blocks are those of the two functions on their own (a motion boundary, divisible size)."""
    rng = np.random.default_rng(12)
    h, w, g = 32, 48, 4
    flow = np.zeros((h, w, 2), dtype=np.float32)
    flow[..., 0] = np.where(np.arange(w)[None, :] < w // 2 + 1, 2.0, -3.0)
    flow += rng.normal(scale=0.05, size=flow.shape).astype(np.float32)
    cells = block_cells(flow, g)
    assert cells is not None
    mean, _ = block_mean_flow(flow, g)
    want = one_motion_per_block(flow, mean, g, 0.25)
    shared_mean, _ = block_mean_flow(flow, g, cells=cells)
    np.testing.assert_array_equal(shared_mean, mean)
    np.testing.assert_array_equal(one_motion_per_block(flow, mean, g, 0.25, cells=cells), want)
