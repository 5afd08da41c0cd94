"""Local stand-ins for the assets and trajectories modules, so rendering tests need neither.

Imported by the test modules of this folder as ``from stand_ins import ...``.

- :func:`grid_box_mesh`: a box whose faces are n x n vertex grids (interior vertices for the
  projection test), each face mapped to its own tile of a procedural texture.
- :class:`SinusoidalTrajectory`: an analytic object motion with exact derivatives.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from roft_sim.geometry import CameraIntrinsics, matrix_from_rotvec
from roft_sim.scene.textures import procedural_texture


@dataclass(frozen=True)
class StandInMesh:
    vertices_m: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    texture_rgb: np.ndarray


@dataclass(frozen=True)
class StandInAssets:
    mesh: StandInMesh


def grid_box_mesh(
    half_extents_m=(0.04, 0.06, 0.03), n: int = 12, texture_px: int = 512, seed: int = 3
) -> StandInMesh:
    """Closed box, outward counter-clockwise faces, (n+1)^2 split vertices per face."""
    e = np.asarray(half_extents_m, dtype=np.float64)
    verts, faces, uvs = [], [], []
    s = np.linspace(-1.0, 1.0, n + 1)
    a, b = np.meshgrid(s, s, indexing="xy")
    tiles = [(i % 3, i // 3) for i in range(6)]
    for f, (axis, sign) in enumerate([(ax, sg) for ax in range(3) for sg in (1.0, -1.0)]):
        u_ax, v_ax = [i for i in range(3) if i != axis]
        p = np.zeros((n + 1, n + 1, 3))
        p[..., axis] = sign * e[axis]
        p[..., u_ax] = a * e[u_ax]
        p[..., v_ax] = b * e[v_ax]
        base = sum(len(v) for v in verts)
        verts.append(p.reshape(-1, 3))
        tu, tv = tiles[f]
        uv = np.stack([(tu + (a + 1) / 2) / 3.0, 1.0 - (tv + (b + 1) / 2) / 2.0], axis=-1)
        uvs.append(uv.reshape(-1, 2))
        idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1) + base
        q0, q1, q2, q3 = idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]
        tri = np.concatenate(
            [np.stack([q0, q1, q2], -1).reshape(-1, 3), np.stack([q0, q2, q3], -1).reshape(-1, 3)]
        )
        faces.append(tri)
    V = np.concatenate(verts)
    F = np.concatenate(faces).astype(np.int64)
    tri = V[F]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    outward = np.einsum("ij,ij->i", normals, tri.mean(axis=1)) > 0
    F[~outward] = F[~outward][:, ::-1]  # orient every face outward (convex box)
    texture = procedural_texture("posters", texture_px, np.random.default_rng(seed))
    return StandInMesh(vertices_m=V, faces=F, uv=np.concatenate(uvs), texture_rgb=texture)


@dataclass(frozen=True)
class StandInSample:
    t_s: np.ndarray
    T_ref_obj: np.ndarray
    v_mps: np.ndarray
    w_radps: np.ndarray


@dataclass(frozen=True)
class SinusoidalTrajectory:
    """p(t) = p0 + A sin(2 pi f t + phi), R(t) = exp([axis * B sin(2 pi f t)]x) R0 (fixed axis, so
    w = axis * theta'(t) exactly)."""

    p0_m: tuple = (0.02, -0.01, 0.55)
    amplitude_m: tuple = (0.06, 0.04, 0.05)
    rot_axis: tuple = (0.3, 0.8, 0.5)
    rot_amplitude_rad: float = 0.8
    rotvec0: tuple = (0.4, -0.3, 0.2)
    frequency_hz: float = 0.5
    start_s: float = 0.0
    end_s: float = 10.0

    def sample(self, t_s) -> StandInSample:
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        om = 2 * np.pi * self.frequency_hz
        ph = np.array([0.0, 1.0, 2.0])
        A = np.asarray(self.amplitude_m)
        p = np.asarray(self.p0_m) + A * np.sin(om * t[:, None] + ph)
        v = A * om * np.cos(om * t[:, None] + ph)
        axis = np.asarray(self.rot_axis) / np.linalg.norm(self.rot_axis)
        theta = self.rot_amplitude_rad * np.sin(om * t)
        theta_dot = self.rot_amplitude_rad * om * np.cos(om * t)
        R = matrix_from_rotvec(axis * theta[:, None]) @ matrix_from_rotvec(self.rotvec0)
        T = np.broadcast_to(np.eye(4), (len(t), 4, 4)).copy()
        T[:, :3, :3] = R
        T[:, :3, 3] = p
        return StandInSample(t_s=t, T_ref_obj=T, v_mps=v, w_radps=axis * theta_dot[:, None])


SMALL_CAMERA = CameraIntrinsics(
    fx_px=180.0, fy_px=180.0, cx_px=79.5, cy_px=59.5, width_px=160, height_px=120
)
OFF_CENTRE_CAMERA = CameraIntrinsics(
    fx_px=150.0, fy_px=165.0, cx_px=52.3, cy_px=71.8, width_px=160, height_px=120
)

__all__ = [
    "StandInMesh",
    "StandInAssets",
    "grid_box_mesh",
    "SinusoidalTrajectory",
    "SMALL_CAMERA",
    "OFF_CENTRE_CAMERA",
    "render_posed",
    "small_scenario",
    "open_renderer",
]


def render_posed(intrinsics, mesh, T_cam_obj, *, scene=None, render=None, segmentation=True):
    """Builds a scene (static camera at the origin) with the object at ``T_cam_obj`` and renders
    it once. Returns (built scene, RenderBuffers)."""
    import mujoco

    from roft_sim.geometry import quat_from_matrix
    from roft_sim.render.offscreen import OffscreenRenderer
    from roft_sim.render.scene_builder import build_scene
    from roft_sim.scene.config import RenderConfig, SceneConfig

    built = build_scene(
        intrinsics=intrinsics,
        object_mesh=mesh,
        scene=scene or SceneConfig(),
        render=render or RenderConfig(),
        rng=np.random.default_rng(0),
    )
    data = mujoco.MjData(built.model)
    T = np.asarray(T_cam_obj, dtype=np.float64)
    for mocap in (built.object_mocap, built.hand_mocap):
        if mocap is not None:
            data.mocap_pos[mocap] = T[:3, 3]
            data.mocap_quat[mocap] = quat_from_matrix(T[:3, :3])
    mujoco.mj_kinematics(built.model, data)
    mujoco.mj_camlight(built.model, data)
    with OffscreenRenderer(built.model, intrinsics.width_px, intrinsics.height_px) as r:
        r.update(data, built.camera_id)
        out = r.render(rgb=True, depth=True, segmentation=segmentation)
    return built, out


def small_scenario(**overrides):
    """A 160x120 Scenario built in code; the trajectory config is a placeholder (tests pass a
    stand-in trajectory to the renderer)."""
    from roft_sim.scenario import CameraConfig, ObjectConfig, Scenario
    from roft_sim.scene.config import BackgroundConfig, SceneConfig, TableConfig
    from roft_sim.trajectories import SyntheticMotionConfig

    camera = overrides.pop(
        "camera",
        CameraConfig(
            width_px=160, height_px=120, fx_px=180.0, fy_px=180.0, cx_px=79.5, cy_px=59.5, fps=30
        ),
    )
    scene = overrides.pop(
        "scene",
        SceneConfig(
            table=TableConfig(texture_px=256, height_m=0.25),
            background=BackgroundConfig(texture_px=256, distance_m=1.2),
        ),
    )
    fields = dict(
        name="test",
        camera=camera,
        object=ObjectConfig(name="stand_in_box"),
        trajectory=SyntheticMotionConfig(),
        scene=scene,
        seed=11,
        frames=12,
    )
    fields.update(overrides)
    return Scenario(**fields)


def open_renderer(scenario, *, trajectory=None, mesh=None, **kwargs):
    from roft_sim.render import SceneRenderer

    return SceneRenderer(
        scenario,
        object_assets=StandInAssets(mesh if mesh is not None else grid_box_mesh()),
        trajectory=trajectory if trajectory is not None else SinusoidalTrajectory(),
        **kwargs,
    )


def textured_mesh_file(folder, name: str, mesh=None, texture_px: int = 32) -> str:
    """Writes ``mesh`` (a trimesh mesh, default a 6 x 6 x 10 cm box) as ``<folder>/<name>.obj``
    with its ``.mtl`` and a small PNG texture, so that ``roft_sim.assets.load_object`` uses the
    file's texture instead of generating a procedural one (which takes seconds). Returns the
    path."""
    import cv2
    import trimesh

    mesh = mesh if mesh is not None else trimesh.creation.box(extents=(0.06, 0.06, 0.1))
    uv = np.random.default_rng(0).uniform(size=(len(mesh.vertices), 2))
    texture = procedural_texture("stone", texture_px, np.random.default_rng(1))
    cv2.imwrite(str(folder / f"{name}.png"), texture[..., ::-1])
    (folder / f"{name}.mtl").write_text(f"newmtl skin\nmap_Kd {name}.png\n")
    lines = [f"mtllib {name}.mtl", "usemtl skin"]
    lines += [f"v {x:.9f} {y:.9f} {z:.9f}" for x, y, z in mesh.vertices]
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in uv]
    lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in np.asarray(mesh.faces) + 1]
    path = folder / f"{name}.obj"
    path.write_text("\n".join(lines) + "\n")
    return str(path)
