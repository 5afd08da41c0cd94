"""Renders a scenario frame by frame with exact ground truth.

:class:`SceneRenderer` builds the MuJoCo scene of a :class:`roft_sim.scenario.Scenario` once, owns
one offscreen OpenGL renderer, and renders any frame ``k`` on demand (frames are independent: the
replay is kinematic, so frames may be rendered in any order, in parallel processes, or again,
with identical results on the same backend).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError
from roft_sim.geometry import (
    CameraIntrinsics,
    invert_transform,
    matrix_from_rotvec,
    relative_motion,
    v_o_from_v_obj,
)
from roft_sim.render.articulated_hand import FingerMotion, HandGrasp, synthesise_grasp
from roft_sim.render.ground_truth import RenderedFrame
from roft_sim.render.image_formation import apply_image_formation, rolling_shutter_band_times
from roft_sim.render.mocap import set_mocap_pose
from roft_sim.render.offscreen import OffscreenRenderer
from roft_sim.render.scene_builder import BuiltScene, DistractorMesh, build_scene
from roft_sim.scene.camera_motion import camera_poses
from roft_sim.scene.config import DistractorConfig
from roft_sim.sensors.depth_noise import apply_depth_noise

if TYPE_CHECKING:
    from roft_sim.scenario import Scenario
    from roft_sim.trajectories.base import Trajectory

F64 = NDArray[np.float64]

__all__ = ["SceneRenderer", "SceneState"]


@dataclass(frozen=True, slots=True, kw_only=True)
class SceneState:
    """Poses and relative velocities of the scene's bodies at one time."""

    t_s: float
    """Scenario time [s]."""
    T_world_cam: F64
    """(4, 4) camera pose (OpenCV frame) in the world [m]."""
    T_world_obj: F64
    """(4, 4) object pose in the world [m]."""
    T_cam_obj: F64
    """(4, 4) object pose in the camera frame [m]."""
    v_obj_mps: F64
    """(3,) object-origin velocity relative to the camera, camera frame [m/s]."""
    w_radps: F64
    """(3,) object angular velocity relative to the camera, camera frame [rad/s]."""
    camera_v_world_mps: F64
    """(3,) the camera's own velocity (its origin), world frame [m/s]."""
    camera_w_world_radps: F64
    """(3,) the camera's own angular velocity, world frame [rad/s]."""


@dataclass(frozen=True, slots=True)
class _Distractor:
    """A loaded distractor: its mesh and its pose over time (resting or moving)."""

    name: str
    mesh: Any
    T_world_rest: F64 | None
    """(4, 4) resting pose on the table [m], or None when it moves."""
    trajectory: Any
    """Its trajectory (``sample(t_s)`` -> ``T_ref_obj`` in the world), or None at rest."""

    @classmethod
    def load(
        cls,
        config: DistractorConfig,
        index: int,
        scenario: Scenario,
        assets_dir: Any,
        cache_dir: Any,
    ) -> _Distractor:
        from roft_sim.assets import load_object

        mesh = load_object(config.name, assets_dir=assets_dir, cache_dir=cache_dir).mesh
        vertices = np.asarray(mesh.vertices_m, dtype=np.float64)
        if config.trajectory is not None:
            from roft_sim.trajectories import build_trajectory

            radius = float(np.linalg.norm(vertices, axis=1).max())
            trajectory = build_trajectory(
                config.trajectory, scenario.intrinsics, object_radius_m=radius
            )
            return cls(name=config.name, mesh=mesh, T_world_rest=None, trajectory=trajectory)
        # Object +z up (world -y, the OpenCV world's y points down), then the yaw about y.
        R_up = matrix_from_rotvec(np.array([np.pi / 2, 0.0, 0.0]))
        R = matrix_from_rotvec(np.array([0.0, config.yaw_rad, 0.0])) @ R_up
        lowest = float((vertices @ R.T)[:, 1].max())  # largest y = lowest point
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = [
            config.position_m[0],
            scenario.scene.table.height_m - lowest,
            config.position_m[1],
        ]
        return cls(name=config.name, mesh=mesh, T_world_rest=T, trajectory=None)

    def T_world_d(self, t_s: float) -> F64:
        """(4, 4) pose in the world at scenario time ``t_s`` [s] (clamped onto its trajectory)."""
        if self.trajectory is None:
            assert self.T_world_rest is not None
            return self.T_world_rest
        traj = self.trajectory
        t = float(np.clip(float(traj.start_s) + t_s, traj.start_s, traj.end_s))
        return np.asarray(traj.sample(np.array([t])).T_ref_obj[0], dtype=np.float64)


class SceneRenderer:
    """Renders the frames of one scenario. A context manager (frees the OpenGL context).

    Args:
        scenario: what to render.
        assets_dir: folder of real object meshes (passed to ``roft_sim.assets.load_object``).
        cache_dir: asset cache folder (idem).
        object_assets: an already loaded ``ObjectAssets`` (anything with ``.mesh``, a textured
            mesh in the object frame); skips loading ``scenario.object``.
        trajectory: an already built object trajectory (``sample(t_s)`` giving ``T_ref_obj`` in
            the world frame, i.e. the camera frame at rest); skips building
            ``scenario.trajectory``.
        segmentation: render segmentation (object mask, geom ids and the body index that
            ground-truth flow needs). Off: rgb and depth only (faster).

    Raises:
        ConfigError: the trajectory is shorter than the scenario, or the scene is invalid.
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        assets_dir: Any = None,
        cache_dir: Any = None,
        object_assets: Any = None,
        trajectory: Trajectory | None = None,
        segmentation: bool = True,
    ) -> None:
        self._renderer: OffscreenRenderer | None = None
        self.scenario = scenario
        intrinsics = scenario.intrinsics
        if object_assets is None:
            from roft_sim.assets import load_object

            object_assets = load_object(
                scenario.object.name_or_path, assets_dir=assets_dir, cache_dir=cache_dir
            )
        self.object_assets = object_assets
        mesh = object_assets.mesh
        if trajectory is None:
            from roft_sim.trajectories import build_trajectory

            radius = float(np.linalg.norm(np.asarray(mesh.vertices_m), axis=1).max())
            trajectory = build_trajectory(scenario.trajectory, intrinsics, object_radius_m=radius)
        self.trajectory = trajectory
        last_s = float(trajectory.start_s) + (scenario.n_frames - 1) / scenario.fps
        if last_s > float(trajectory.end_s) + 1e-9:
            raise ConfigError(
                f"scenario {scenario.name!r} needs {scenario.n_frames} frames at {scenario.fps} "
                f"fps (until {last_s:.3f} s) but its trajectory ends at "
                f"{float(trajectory.end_s):.3f} s; shorten duration_s/frames or lengthen the "
                "trajectory"
            )
        self.distractors = tuple(
            _Distractor.load(d, i, scenario, assets_dir, cache_dir)
            for i, d in enumerate(scenario.scene.distractors)
        )
        """The distractor objects (meshes and motions), in ``distractor<i>`` order."""
        self.built: BuiltScene = build_scene(
            intrinsics=intrinsics,
            object_mesh=mesh,
            scene=scenario.scene,
            render=scenario.render,
            rng=scenario.rng("scene_textures"),
            texture_cache_dir=cache_dir,
            distractors=tuple(DistractorMesh(name=d.name, mesh=d.mesh) for d in self.distractors),
        )
        self._data = mujoco.MjData(self.built.model)
        self._segmentation = segmentation
        self._body_names = self.built.body_names
        self.grasp: HandGrasp | None = None
        """The articulated hand's synthesised grasp (None without one)."""
        self.finger_motion: FingerMotion | None = None
        """The articulated hand's finger motion (None without one)."""
        if self.built.hand is not None:
            self.grasp, self.finger_motion = self._plan_hand(scenario)
        self._renderer = OffscreenRenderer(
            self.built.model, intrinsics.width_px, intrinsics.height_px
        )

    # -- properties ---------------------------------------------------------------------------
    @property
    def intrinsics(self) -> CameraIntrinsics:
        """The camera's intrinsics."""
        return self.scenario.intrinsics

    @property
    def n_frames(self) -> int:
        """Number of frames of the scenario."""
        return self.scenario.n_frames

    @property
    def model(self) -> mujoco.MjModel:
        """The compiled MuJoCo model."""
        return self.built.model

    @property
    def body_names(self) -> tuple[str, ...]:
        """Rigid bodies of the scene, in ``RenderedFrame.T_cam_bodies`` order."""
        return self._body_names

    # -- kinematics ---------------------------------------------------------------------------
    def _plan_hand(self, scenario: Scenario) -> tuple[HandGrasp, FingerMotion]:
        """Synthesises the articulated hand's grasp and draws its finger motion, both from the
        scenario's ``hand`` stream (so per object and trajectory seed)."""
        b = self.built
        assert b.hand is not None
        rng = scenario.rng("hand")
        config = scenario.scene.hand
        grasp = synthesise_grasp(
            b.model,
            self._data,
            b.hand,
            b.object_geom_id,
            b.object_mocap,
            b.object_half_extents_m,
            config,
            rng,
            camera_dirs_obj=self._camera_dirs_obj() if config.side == "away_from_camera" else None,
        )
        duration_s = scenario.n_frames / scenario.fps
        return grasp, FingerMotion(scenario.scene.hand.motion, grasp, duration_s, rng)

    def state_at(self, t_s: float) -> SceneState:
        """Exact poses and velocities at scenario time ``t_s`` [s] (``0 <= t_s`` and within the
        trajectory; times just outside are clamped onto it)."""
        traj = self.trajectory
        t_traj = float(np.clip(float(traj.start_s) + t_s, traj.start_s, traj.end_s))
        sample = traj.sample(np.array([t_traj]))
        cam = camera_poses(self.scenario.camera.motion, np.array([t_s]))
        T_cam_obj, v_obj, w = relative_motion(
            cam.T_world_cam[0],
            cam.v_world_mps[0],
            cam.w_world_radps[0],
            sample.T_ref_obj[0],
            sample.v_mps[0],
            sample.w_radps[0],
        )
        return SceneState(
            t_s=t_s,
            T_world_cam=cam.T_world_cam[0],
            T_world_obj=sample.T_ref_obj[0],
            T_cam_obj=T_cam_obj,
            v_obj_mps=v_obj,
            w_radps=w,
            camera_v_world_mps=cam.v_world_mps[0],
            camera_w_world_radps=cam.w_world_radps[0],
        )

    def _pose_scene(self, state: SceneState) -> None:
        b, d = self.built, self._data
        set_mocap_pose(d, b.camera_mocap, state.T_world_cam)
        set_mocap_pose(d, b.object_mocap, state.T_world_obj)
        if self.grasp is not None:
            assert b.hand_mocap is not None
            set_mocap_pose(d, b.hand_mocap, state.T_world_obj @ self.grasp.T_obj_hand)
        elif b.hand_mocap is not None:  # the proxy's frame is the object's (fixed grasp)
            set_mocap_pose(d, b.hand_mocap, state.T_world_obj)
        for mocap, distractor in zip(b.distractor_mocaps, self.distractors, strict=True):
            set_mocap_pose(d, mocap, distractor.T_world_d(state.t_s))
        mujoco.mj_kinematics(b.model, d)
        if self.finger_motion is not None:
            assert b.hand is not None
            self.finger_motion.pose(b.model, d, b.hand, b.object_geom_id, state.t_s)
        mujoco.mj_camlight(b.model, d)
        assert self._renderer is not None
        self._renderer.update(d, b.camera_id)

    # -- rendering ----------------------------------------------------------------------------
    def render_frame(self, k: int) -> RenderedFrame:
        """Renders frame ``k`` (0 <= k < n_frames) with its ground truth."""
        if self._renderer is None:
            raise RuntimeError("SceneRenderer used after close()")
        if not 0 <= k < self.n_frames:
            raise IndexError(f"frame {k} outside 0..{self.n_frames - 1}")
        opts = self.scenario.render
        t_s = self.scenario.frame_time_s(k)
        state = self.state_at(t_s)
        self._pose_scene(state)
        T_cam_bodies = self._body_poses_cam(state)
        blur = opts.motion_blur_subframes > 1
        rolling = opts.image_formation.rolling_shutter
        out = self._renderer.render(
            rgb=not (blur or rolling),
            depth=True,
            segmentation=self._segmentation,
            shadows=opts.shadows,
        )
        rgb = out.rgb
        if blur:
            rgb = self._blurred_rgb(t_s)
        elif rolling:
            rgb = self._rolling_shutter_rgb(t_s)
        assert rgb is not None and out.depth_m is not None
        depth = out.depth_m
        sensor_depth = apply_depth_noise(
            opts.depth_noise,
            depth,
            self.scenario.rng("depth_noise", k),
            fx_px=self.intrinsics.fx_px,
            rgb=rgb,
        )
        rgb = apply_image_formation(
            rgb, opts.image_formation, self.scenario.rng("image_formation", k)
        )
        mask = seg = body = None
        if out.geom_id is not None:
            seg = out.geom_id
            mask = seg == self.built.object_geom_id
            lut = np.append(self.built.geom_body, np.int8(-1))  # index -1 -> -1
            body = lut[seg]
        return RenderedFrame(
            k=k,
            t_s=t_s,
            rgb=rgb,
            depth_m=depth,
            sensor_depth_m=sensor_depth,
            object_mask=mask,
            segmentation=seg,
            body_index=body,
            T_cam_obj=state.T_cam_obj,
            v_obj_mps=state.v_obj_mps,
            w_radps=state.w_radps,
            v_o_mps=v_o_from_v_obj(state.v_obj_mps, state.w_radps, state.T_cam_obj[:3, 3]),
            T_world_cam=state.T_world_cam,
            camera_v_world_mps=state.camera_v_world_mps,
            camera_w_world_radps=state.camera_w_world_radps,
            T_cam_bodies=T_cam_bodies,
            distractor_names=tuple(d.name for d in self.distractors),
            body_names=self._body_names,
        )

    def _camera_dirs_obj(self) -> F64:
        """(N, 3) unit directions from the object's origin to the camera at every frame, object
        frame."""
        t_s = np.arange(self.n_frames, dtype=np.float64) / self.scenario.fps
        traj = self.trajectory
        T_world_obj = traj.sample(np.clip(float(traj.start_s) + t_s, traj.start_s, traj.end_s))
        T_world_cam = camera_poses(self.scenario.camera.motion, t_s).T_world_cam
        T_obj_cam = invert_transform(T_world_obj.T_ref_obj) @ T_world_cam
        p: F64 = T_obj_cam[:, :3, 3]
        dirs: F64 = p / np.maximum(np.linalg.norm(p, axis=1, keepdims=True), 1e-12)
        return dirs

    def _body_poses_cam(self, state: SceneState) -> F64:
        """(B, 4, 4) pose of every rigid body of :attr:`body_names` in the camera frame [m]: the
        static world and the object exactly from the trajectories, the proxy hand as the object,
        the articulated hand's links where MuJoCo's kinematics put them (call after
        :meth:`_pose_scene`)."""
        T_cam_world = invert_transform(state.T_world_cam)
        bodies = [T_cam_world, state.T_cam_obj]
        if self.built.hand is not None:
            for body_id in self.built.hand.body_ids:
                bodies.append(T_cam_world @ self._body_pose_world(body_id))
        elif self.built.hand_mocap is not None:
            bodies.append(state.T_cam_obj)  # proxy frame = object frame
        for distractor in self.distractors:
            bodies.append(T_cam_world @ distractor.T_world_d(state.t_s))
        return np.stack(bodies)

    def _body_pose_world(self, body_id: int) -> F64:
        """(4, 4) pose of MuJoCo body ``body_id`` in the world after the last kinematics [m]."""
        T = np.eye(4)
        T[:3, :3] = self._data.xmat[body_id].reshape(3, 3)
        T[:3, 3] = self._data.xpos[body_id]
        return T

    def _rolling_shutter_rgb(self, t_s: float) -> NDArray[np.uint8]:
        """The rolling-shutter image: each band of rows rendered at its own exposure time
        (:func:`~roft_sim.render.image_formation.rolling_shutter_band_times`; times before 0 are
        clamped to 0 like the motion blur's)."""
        config = self.scenario.render.image_formation
        height = self.intrinsics.height_px
        times, band_of_row = rolling_shutter_band_times(
            height, t_s, config.rolling_shutter_readout_s, config.rolling_shutter_bands
        )
        out = np.empty(self.intrinsics.shape + (3,), dtype=np.uint8)
        assert self._renderer is not None
        for band, t_band in enumerate(times):
            self._pose_scene(self.state_at(max(0.0, float(t_band))))
            sub = self._renderer.render(
                rgb=True, depth=False, shadows=self.scenario.render.shadows
            ).rgb
            assert sub is not None
            rows = band_of_row == band
            out[rows] = sub[rows]
        return out

    def _blurred_rgb(self, t_s: float) -> NDArray[np.uint8]:
        """Mean of ``n`` renders at sub-frame times spread evenly over the exposure, centred on
        ``t_s``: ``t_s + exposure * ((i + 0.5) / n - 0.5)``.

        Sub-frame times before 0 are clamped to 0 (the trajectory starts there), so the blur of
        the first frame is one-sided: its mean time is about an eighth of the exposure late.
        """
        opts = self.scenario.render
        n = opts.motion_blur_subframes
        exposure_s = opts.exposure_fraction / self.scenario.fps
        acc = np.zeros(self.intrinsics.shape + (3,), dtype=np.float64)
        assert self._renderer is not None
        for i in range(n):
            t_i = max(0.0, t_s + exposure_s * ((i + 0.5) / n - 0.5))
            self._pose_scene(self.state_at(t_i))
            sub = self._renderer.render(rgb=True, depth=False, shadows=opts.shadows).rgb
            assert sub is not None
            acc += sub
        return np.clip(np.rint(acc / n), 0, 255).astype(np.uint8)

    def frames(self, start: int = 0, stop: int | None = None) -> Iterator[RenderedFrame]:
        """Renders frames ``start`` ... ``stop - 1`` (default: to the end) in order."""
        stop = self.n_frames if stop is None else min(stop, self.n_frames)
        for k in range(start, stop):
            yield self.render_frame(k)

    # -- lifetime -----------------------------------------------------------------------------
    def close(self) -> None:
        """Frees the OpenGL context (idempotent)."""
        if self._renderer is not None:
            self._renderer.close()
        self._renderer = None

    def __enter__(self) -> SceneRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
