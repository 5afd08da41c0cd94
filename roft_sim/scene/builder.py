"""Builds the MuJoCo scene in code with ``mujoco.MjSpec``.

The scene (world frame = OpenCV optical frame of the camera at rest, see
:mod:`roft_sim.scene.config`):

- ``camera_rig``: a mocap body whose frame is the camera's OpenCV optical frame, carrying the
  MuJoCo camera ``camera`` (rotated by :data:`roft_sim.render.camera.QUAT_CV_MJ`) with the pinhole
  intrinsics set through MuJoCo's ``resolution`` / ``sensor_size`` / ``focal_pixel`` /
  ``principal_pixel`` (:func:`roft_sim.render.camera.mujoco_camera_params`);
- ``object``: a mocap body with the textured object mesh (per-vertex texture coordinates and a
  texture image passed from memory);
- ``hand`` (optional): a mocap body with the hand's capsules, in the object frame;
- the table top and the background wall: textured quads fixed in the world;
- lights, and MuJoCo's headlight reduced to ambient light.

No geom collides (contype = conaffinity = 0): the scene is replayed kinematically, never
simulated. ``stat.extent`` is fixed to 1 so that ``vis.map.znear/zfar`` are in metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import roft_sim.render  # noqa: F401  (chooses MUJOCO_GL before MuJoCo is imported)

# isort: split
import mujoco
import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError
from roft_sim.geometry import CameraIntrinsics
from roft_sim.render.camera import QUAT_CV_MJ, mujoco_camera_params
from roft_sim.scene.config import RenderConfig, SceneConfig
from roft_sim.scene.hand import hand_capsules
from roft_sim.scene.textures import procedural_texture

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
U8 = NDArray[np.uint8]

__all__ = [
    "BODY_NAMES",
    "STATIC_BODY",
    "OBJECT_BODY",
    "HAND_BODY",
    "MeshLike",
    "BuiltScene",
    "build_scene",
    "mujoco_texcoords_from_obj",
]

STATIC_BODY, OBJECT_BODY, HAND_BODY = 0, 1, 2
"""Indices of the rigid bodies of the scene, as used by :attr:`BuiltScene.geom_body`."""
BODY_NAMES = ("static", "object", "hand")
"""Body names by index: the static world (table, wall), the object, the hand occluder."""


class MeshLike(Protocol):
    """What the builder needs of an object mesh (``roft_sim.assets.TexturedMesh`` or
    ``roft_sim.records.ObjectModel``): vertices and faces, optionally ``uv`` and
    ``texture_rgb``."""

    @property
    def vertices_m(self) -> F64: ...

    @property
    def faces(self) -> I64: ...


@dataclass(frozen=True, slots=True)
class BuiltScene:
    """A compiled scene and the indices needed to drive and decode it."""

    model: mujoco.MjModel
    """The compiled model."""
    camera_id: int
    """Id of the rendering camera."""
    camera_mocap: int
    """Mocap index of ``camera_rig`` (its frame is the OpenCV camera frame)."""
    object_mocap: int
    """Mocap index of ``object``."""
    hand_mocap: int | None
    """Mocap index of ``hand``, or None without a hand."""
    object_geom_id: int
    """Geom id of the object mesh."""
    geom_body: NDArray[np.int8]
    """(ngeom,) body index (:data:`BODY_NAMES`) of each geom, -1 for none."""
    object_half_extents_m: F64
    """(3,) half extents of the object's bounding box about its origin [m]."""


def mujoco_texcoords_from_obj(uv: F64) -> F64:
    """MuJoCo texture coordinates ``(V, 2)`` from OBJ ones (v up): MuJoCo's v points down the
    texture image (row 0 at v = 0), so ``v_mj = 1 - v_obj``."""
    out = np.array(uv, dtype=np.float64)
    out[:, 1] = 1.0 - out[:, 1]
    return out


def _add_texture(spec: mujoco.MjSpec, name: str, image: U8) -> str:
    image = np.ascontiguousarray(image, dtype=np.uint8)
    h, w = image.shape[:2]
    tex = spec.add_texture(
        name=name, type=mujoco.mjtTexture.mjTEXTURE_2D, width=w, height=h, nchannel=3
    )
    tex.data = image.tobytes()
    return name


def _add_material(
    spec: mujoco.MjSpec,
    name: str,
    texture: str | None,
    *,
    rgba: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0),
    specular: float = 0.05,
    shininess: float = 0.1,
) -> str:
    mat = spec.add_material(name=name)
    if texture is not None:
        mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = texture
    mat.rgba = list(rgba)
    mat.specular = specular
    mat.shininess = shininess
    mat.reflectance = 0.0
    return name


def _add_mesh(
    spec: mujoco.MjSpec, name: str, vertices_m: F64, faces: I64, texcoords: F64 | None
) -> str:
    mesh = spec.add_mesh(name=name)
    mesh.uservert = np.asarray(vertices_m, dtype=np.float64).ravel().tolist()
    mesh.userface = np.asarray(faces, dtype=np.int64).ravel().tolist()
    if texcoords is not None:
        mesh.usertexcoord = np.asarray(texcoords, dtype=np.float64).ravel().tolist()
    # Open meshes (scans, quads) have no volume: use the surface for the (unused) inertia.
    mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL
    return name


def _visual_geom(body: mujoco.MjsBody, **kwargs: object) -> mujoco.MjsGeom:
    return body.add_geom(contype=0, conaffinity=0, **kwargs)


def _quad(
    spec: mujoco.MjSpec,
    name: str,
    corners_m: F64,
    texcoords: F64,
    texture: U8,
) -> mujoco.MjsGeom:
    """A textured quad; ``corners_m`` (4, 3) counter-clockwise seen from the visible side."""
    _add_texture(spec, f"{name}_tex", texture)
    _add_material(spec, f"{name}_mat", f"{name}_tex")
    _add_mesh(spec, f"{name}_mesh", corners_m, np.array([[0, 1, 2], [0, 2, 3]]), texcoords)
    return _visual_geom(
        spec.worldbody,
        name=name,
        type=mujoco.mjtGeom.mjGEOM_MESH,
        meshname=f"{name}_mesh",
        material=f"{name}_mat",
    )


def _frustum_half_extents(intrinsics: CameraIntrinsics, distance_m: float) -> tuple[F64, F64]:
    """Image borders at a distance [m]: x range (2,), y range (2,) in the camera frame."""
    x = distance_m * (np.array([-0.5, intrinsics.width_px - 0.5]) - intrinsics.cx_px)
    y = distance_m * (np.array([-0.5, intrinsics.height_px - 0.5]) - intrinsics.cy_px)
    return x / intrinsics.fx_px, y / intrinsics.fy_px


def build_scene(
    *,
    intrinsics: CameraIntrinsics,
    object_mesh: MeshLike,
    scene: SceneConfig,
    render: RenderConfig,
    rng: np.random.Generator,
    object_rgba: tuple[float, float, float, float] = (0.7, 0.7, 0.7, 1.0),
) -> BuiltScene:
    """Builds and compiles the scene.

    Args:
        intrinsics: the camera (any principal point); sets the offscreen buffer size too.
        object_mesh: the object's mesh in its object frame; textured when it has ``uv`` (OBJ
            convention) and ``texture_rgb``.
        scene: table, background, lights, hand.
        render: MSAA, clipping distances (the other options act at render time).
        rng: randomness of the procedural table and wall textures.
        object_rgba: colour of an untextured object mesh.

    Raises:
        ConfigError: the mesh is empty or MuJoCo rejects it (the message says why).
    """
    vertices = np.asarray(object_mesh.vertices_m, dtype=np.float64)
    faces = np.asarray(object_mesh.faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) < 4 or len(faces) < 1:
        raise ConfigError(
            f"object mesh needs >= 4 vertices (V, 3) and >= 1 face, got {vertices.shape} "
            f"vertices and {faces.shape} faces"
        )
    spec = mujoco.MjSpec()
    spec.modelname = "roft_sim_scene"
    spec.stat.extent = 1.0
    spec.stat.center = [0.0, 0.0, 1.0]
    vis = spec.visual
    vis.global_.offwidth = intrinsics.width_px
    vis.global_.offheight = intrinsics.height_px
    vis.quality.offsamples = render.msaa_samples
    vis.quality.shadowsize = 4096
    vis.map.znear = render.znear_m
    vis.map.zfar = render.zfar_m
    vis.map.shadowclip = 4.0
    vis.map.haze = 0.0
    vis.headlight.active = 1
    vis.headlight.ambient = [scene.ambient] * 3
    vis.headlight.diffuse = [0.0] * 3
    vis.headlight.specular = [0.0] * 3

    # Camera on its rig; the rig's frame is the OpenCV optical frame.
    rig = spec.worldbody.add_body(name="camera_rig", mocap=True)
    cam = rig.add_camera(name="camera", quat=list(QUAT_CV_MJ))
    params = mujoco_camera_params(intrinsics)
    cam.resolution = list(params.resolution)
    cam.sensor_size = list(params.sensor_size_m)
    cam.focal_pixel = list(params.focal_pixel)
    cam.principal_pixel = list(params.principal_pixel)

    # Object.
    obj = spec.worldbody.add_body(name="object", mocap=True)
    uv = getattr(object_mesh, "uv", None)
    texture = getattr(object_mesh, "texture_rgb", None)
    if uv is not None and texture is not None:
        _add_texture(spec, "object_tex", texture)
        material = _add_material(spec, "object_mat", "object_tex")
        texcoords = mujoco_texcoords_from_obj(np.asarray(uv))
    else:
        material = _add_material(spec, "object_mat", None, rgba=object_rgba)
        texcoords = None
    _add_mesh(spec, "object_mesh", vertices, faces, texcoords)
    _visual_geom(
        obj,
        name="object",
        type=mujoco.mjtGeom.mjGEOM_MESH,
        meshname="object_mesh",
        material=material,
    )
    half_extents = np.maximum(np.abs(vertices.min(axis=0)), np.abs(vertices.max(axis=0)))

    # Hand occluder.
    if scene.hand.enabled:
        hand = spec.worldbody.add_body(name="hand", mocap=True)
        rgba = [*scene.hand.skin_rgb, 1.0]
        for capsule in hand_capsules(scene.hand, half_extents):
            _visual_geom(
                hand,
                name=f"hand_{capsule.name}",
                type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                fromto=[*capsule.start_m, *capsule.end_m],
                size=[capsule.radius_m, 0.0, 0.0],
                rgba=rgba,
            )

    # Static world: wall and table.
    wall_z = scene.background.distance_m
    if scene.background.enabled:
        margin = 1.5
        xr, yr = _frustum_half_extents(intrinsics, wall_z)
        x0, x1 = xr[0] * margin - 0.5, xr[1] * margin + 0.5
        y0 = yr[0] * margin - 0.5
        y1 = scene.table.height_m + 0.01 if scene.table.enabled else yr[1] * margin + 0.5
        corners = np.array([[x0, y0, wall_z], [x0, y1, wall_z], [x1, y1, wall_z], [x1, y0, wall_z]])
        period = scene.background.texture_period_m
        texcoords = np.column_stack([corners[:, 0] / period, corners[:, 1] / period])
        image = procedural_texture(scene.background.style, scene.background.texture_px, rng)
        _quad(spec, "background", corners, texcoords, image)
    if scene.table.enabled:
        t = scene.table
        z0 = t.near_m
        z1 = wall_z if scene.background.enabled else t.near_m + 3.0
        if z1 <= z0:
            raise ConfigError(
                f"table.near_m ({t.near_m}) must be nearer than background.distance_m ({wall_z})"
            )
        x0, x1 = -t.width_m / 2, t.width_m / 2
        h = t.height_m
        corners = np.array([[x0, h, z0], [x1, h, z0], [x1, h, z1], [x0, h, z1]])
        texcoords = np.column_stack(
            [corners[:, 0] / t.texture_period_m, corners[:, 2] / t.texture_period_m]
        )
        image = procedural_texture(t.style, t.texture_px, rng)
        _quad(spec, "table", corners, texcoords, image)

    for i, light in enumerate(scene.lights):
        l = spec.worldbody.add_light(name=f"light{i}")
        l.type = (
            mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
            if light.kind == "directional"
            else mujoco.mjtLightType.mjLIGHT_SPOT
        )
        l.pos = list(light.position_m)
        d = np.asarray(light.direction, dtype=np.float64)
        l.dir = list(d / np.linalg.norm(d))
        l.diffuse = [light.diffuse] * 3
        l.specular = [light.specular] * 3
        l.ambient = [0.0] * 3
        l.castshadow = light.cast_shadow
        if light.kind == "spot":
            l.cutoff = 60.0
            l.exponent = 1.0

    try:
        model = spec.compile()
    except ValueError as e:
        raise ConfigError(f"MuJoCo could not compile the scene: {e}") from None

    geom_body = np.full(model.ngeom, -1, dtype=np.int8)
    for gid in range(model.ngeom):
        body_name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, model.geom_bodyid[gid])
        geom_body[gid] = {"world": STATIC_BODY, "object": OBJECT_BODY, "hand": HAND_BODY}.get(
            body_name or "world", -1
        )

    def mocap(name: str) -> int:
        return int(model.body_mocapid[model.body(name).id])

    return BuiltScene(
        model=model,
        camera_id=int(model.camera("camera").id),
        camera_mocap=mocap("camera_rig"),
        object_mocap=mocap("object"),
        hand_mocap=mocap("hand") if scene.hand.enabled else None,
        object_geom_id=int(model.geom("object").id),
        geom_body=geom_body,
        object_half_extents_m=half_extents,
    )
