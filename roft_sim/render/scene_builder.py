"""Builds the MuJoCo scene in code with ``mujoco.MjSpec``.

The scene (world frame = OpenCV optical frame of the camera at rest, see
:mod:`roft_sim.scene.config`):

- ``camera_rig``: a mocap body whose frame is the camera's OpenCV optical frame, carrying the
  MuJoCo camera ``camera`` (rotated by :data:`roft_sim.render.camera.QUAT_CV_MJ`) with the pinhole
  intrinsics set through MuJoCo's ``resolution`` / ``sensor_size`` / ``focal_pixel`` /
  ``principal_pixel`` (:func:`roft_sim.render.camera.mujoco_camera_params`);
- ``object``: a mocap body with the textured object mesh (per-vertex texture coordinates and a
  texture image passed from memory);
- ``hand`` (optional): the proxy, a mocap body with capsules in the object frame, or the
  articulated hand (:mod:`roft_sim.render.articulated_hand`), a mocap body with the palm and a
  chain of three jointed segments per digit;
- ``distractor0`` ... (optional): mocap bodies with further object meshes;
- the table top and the background wall: textured quads fixed in the world;
- lights, and MuJoCo's headlight reduced to ambient light.

No geom collides (contype = conaffinity = 0): the scene is replayed kinematically, never
simulated. ``stat.extent`` is fixed to 1 so that ``vis.map.znear/zfar`` are in metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import mujoco
import numpy as np
from numpy.typing import NDArray

import roft_sim.scene.textures
from roft_sim.assets.texture_cache import cached_texture
from roft_sim.errors import ConfigError
from roft_sim.geometry import CameraIntrinsics
from roft_sim.render.articulated_hand import HandModel, add_articulated_hand
from roft_sim.render.camera import QUAT_CV_MJ, mujoco_camera_params
from roft_sim.scene.config import HandConfig, RenderConfig, SceneConfig
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
    "DistractorMesh",
    "build_scene",
    "mujoco_texcoords_from_obj",
]

STATIC_BODY, OBJECT_BODY, HAND_BODY = 0, 1, 2
"""Indices of the first rigid bodies of the scene, as used by :attr:`BuiltScene.geom_body`
(``HAND_BODY`` is the proxy hand, or the articulated hand's palm)."""
BODY_NAMES = ("static", "object", "hand")
"""Names of the first bodies: the static world (table, wall), the object, the hand (its palm for
the articulated hand, whose segments and the distractors follow: :attr:`BuiltScene.body_names`)."""


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
    """(ngeom,) rigid-body index (into :attr:`body_names`) of each geom, -1 for none."""
    object_half_extents_m: F64
    """(3,) half extents of the object's bounding box about its origin [m]."""
    body_names: tuple[str, ...] = BODY_NAMES[:2]
    """Names of the rigid bodies of the ground truth, indexed by :attr:`geom_body`: ``static``,
    ``object``, the hand's links (``hand`` ...), the distractors (``distractor0`` ...)."""
    body_ids: tuple[int, ...] = (0, 1)
    """MuJoCo body id of each rigid body of :attr:`body_names` (0 = the world)."""
    hand: HandModel | None = None
    """The articulated hand's indices, None for none or the proxy."""
    distractor_mocaps: tuple[int, ...] = ()
    """Mocap index of each distractor body."""
    distractor_geom_ids: tuple[int, ...] = ()
    """Geom id of each distractor mesh."""


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


def _scene_texture(
    style: str, size_px: int, rng: np.random.Generator, cache_dir: Path | None
) -> NDArray[np.uint8]:
    """:func:`procedural_texture`, through the texture disk cache when there is one."""
    return cached_texture(
        cache_dir,
        f"scene-{style}-{size_px}",
        {"style": style, "size_px": size_px},
        rng,
        lambda r: procedural_texture(style, size_px, r),
        code=roft_sim.scene.textures,
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class DistractorMesh:
    """A distractor object to add to the scene: its mesh and its name."""

    name: str
    """Body name suffix and ground-truth name (``distractor<i>``'s object, e.g. the registry
    name)."""
    mesh: MeshLike
    """Its mesh in its own object frame (textured like the object's when it has ``uv`` and
    ``texture_rgb``)."""


def build_scene(
    *,
    intrinsics: CameraIntrinsics,
    object_mesh: MeshLike,
    scene: SceneConfig,
    render: RenderConfig,
    rng: np.random.Generator,
    object_rgba: tuple[float, float, float, float] = (0.7, 0.7, 0.7, 1.0),
    distractors: tuple[DistractorMesh, ...] = (),
    texture_cache_dir: Path | None = None,
) -> BuiltScene:
    """Builds and compiles the scene, step by step: visual options, the camera rig, the object,
    the hand, the wall and the table, the lights, the distractors; then compile and index.

    Args:
        intrinsics: the camera (any principal point); sets the offscreen buffer size too.
        object_mesh: the object's mesh in its object frame; textured when it has ``uv`` (OBJ
            convention) and ``texture_rgb``.
        scene: table, background, lights, hand.
        render: MSAA, clipping distances (the other options act at render time).
        rng: randomness of the procedural table and wall textures.
        object_rgba: colour of an untextured object mesh.
        distractors: further objects, each on its own mocap body ``distractor<i>``.
        texture_cache_dir: asset cache holding the drawn table and wall textures
            (:func:`roft_sim.assets.texture_cache.cached_texture`); None = draw them.

    Raises:
        ConfigError: a mesh is empty or MuJoCo rejects it (the message says why).
    """
    vertices, faces = _checked_mesh(object_mesh, "object")
    spec = mujoco.MjSpec()
    spec.modelname = "roft_sim_scene"
    _set_visual_options(spec, intrinsics, scene, render)
    _add_camera_rig(spec, intrinsics)
    obj = _add_textured_body(spec, "object", object_mesh, vertices, faces, object_rgba)
    if scene.hand.enabled and scene.hand.kind == "articulated":
        # Makes MuJoCo compute the mesh's convex hull, which the hand's distance queries use
        # (without it every query scans all vertices). Nothing collides: conaffinity stays 0
        # everywhere, and the replay is kinematic.
        obj.contype = 1
    half_extents = np.maximum(np.abs(vertices.min(axis=0)), np.abs(vertices.max(axis=0)))
    if scene.hand.enabled:
        _add_hand(spec, scene.hand, half_extents)
    _add_wall_and_table(spec, intrinsics, scene, rng, texture_cache_dir)
    _add_lights(spec, scene)
    for i, distractor in enumerate(distractors):
        d_vertices, d_faces = _checked_mesh(distractor.mesh, f"distractor {distractor.name!r}")
        _add_textured_body(
            spec, f"distractor{i}", distractor.mesh, d_vertices, d_faces, object_rgba
        )
    try:
        model = spec.compile()
    except ValueError as e:
        raise ConfigError(f"MuJoCo could not compile the scene: {e}") from None
    return _index_scene(model, scene, half_extents, len(distractors))


def _checked_mesh(mesh: MeshLike, what: str) -> tuple[F64, I64]:
    vertices = np.asarray(mesh.vertices_m, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) < 4 or len(faces) < 1:
        raise ConfigError(
            f"{what} mesh needs >= 4 vertices (V, 3) and >= 1 face, got {vertices.shape} "
            f"vertices and {faces.shape} faces"
        )
    return vertices, faces


def _set_visual_options(
    spec: mujoco.MjSpec, intrinsics: CameraIntrinsics, scene: SceneConfig, render: RenderConfig
) -> None:
    """Offscreen buffer, MSAA, shadows, clipping in metres, headlight as ambient light only."""
    spec.stat.extent = 1.0
    spec.stat.center = [0.0, 0.0, 1.0]
    vis = spec.visual
    vis.global_.offwidth = intrinsics.width_px
    vis.global_.offheight = intrinsics.height_px
    vis.quality.offsamples = render.msaa_samples
    # MuJoCo allocates the shadow map in every rendering context: a 4096x4096 depth texture
    # costs ~0.04 s per context on llvmpipe, so a scene without shadows gets none
    vis.quality.shadowsize = 4096 if render.shadows else 0
    vis.map.znear = render.znear_m
    vis.map.zfar = render.zfar_m
    vis.map.shadowclip = 4.0
    vis.map.haze = 0.0
    vis.headlight.active = 1
    vis.headlight.ambient = [scene.ambient] * 3
    vis.headlight.diffuse = [0.0] * 3
    vis.headlight.specular = [0.0] * 3


def _add_camera_rig(spec: mujoco.MjSpec, intrinsics: CameraIntrinsics) -> None:
    """The camera on its rig; the rig's frame is the OpenCV optical frame."""
    rig = spec.worldbody.add_body(name="camera_rig", mocap=True)
    cam = rig.add_camera(name="camera", quat=list(QUAT_CV_MJ))
    params = mujoco_camera_params(intrinsics)
    cam.resolution = list(params.resolution)
    cam.sensor_size = list(params.sensor_size_m)
    cam.focal_pixel = list(params.focal_pixel)
    cam.principal_pixel = list(params.principal_pixel)


def _add_textured_body(
    spec: mujoco.MjSpec,
    name: str,
    mesh: MeshLike,
    vertices: F64,
    faces: I64,
    rgba: tuple[float, float, float, float],
) -> mujoco.MjsGeom:
    """A mocap body ``name`` with one mesh geom ``name`` (assets ``<name>_tex``, ``_mat``,
    ``_mesh``); returns the geom."""
    body = spec.worldbody.add_body(name=name, mocap=True)
    uv = getattr(mesh, "uv", None)
    texture = getattr(mesh, "texture_rgb", None)
    if uv is not None and texture is not None:
        _add_texture(spec, f"{name}_tex", texture)
        material = _add_material(spec, f"{name}_mat", f"{name}_tex")
        texcoords = mujoco_texcoords_from_obj(np.asarray(uv))
    else:
        material = _add_material(spec, f"{name}_mat", None, rgba=rgba)
        texcoords = None
    _add_mesh(spec, f"{name}_mesh", vertices, faces, texcoords)
    return _visual_geom(
        body,
        name=name,
        type=mujoco.mjtGeom.mjGEOM_MESH,
        meshname=f"{name}_mesh",
        material=material,
    )


def _add_hand(spec: mujoco.MjSpec, config: HandConfig, half_extents_m: F64) -> None:
    """The proxy (capsules on a mocap body in the object frame) or the articulated hand."""
    if config.kind == "articulated":
        material = _add_material(
            spec,
            "hand_skin",
            None,
            rgba=(*config.skin_rgb, 1.0),
            specular=config.skin_specular,
            shininess=0.3,
        )
        add_articulated_hand(spec, config, material)
        return
    hand = spec.worldbody.add_body(name="hand", mocap=True)
    rgba = [*config.skin_rgb, 1.0]
    for capsule in hand_capsules(config, half_extents_m):
        _visual_geom(
            hand,
            name=f"hand_{capsule.name}",
            type=mujoco.mjtGeom.mjGEOM_CAPSULE,
            fromto=[*capsule.start_m, *capsule.end_m],
            size=[capsule.radius_m, 0.0, 0.0],
            rgba=rgba,
        )


def _add_wall_and_table(
    spec: mujoco.MjSpec,
    intrinsics: CameraIntrinsics,
    scene: SceneConfig,
    rng: np.random.Generator,
    texture_cache_dir: Path | None,
) -> None:
    """The static world: the background wall (drawn first: it uses ``rng`` first) and the table."""
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
        image = _scene_texture(
            scene.background.style, scene.background.texture_px, rng, texture_cache_dir
        )
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
        image = _scene_texture(t.style, t.texture_px, rng, texture_cache_dir)
        _quad(spec, "table", corners, texcoords, image)


def _add_lights(spec: mujoco.MjSpec, scene: SceneConfig) -> None:
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


def _index_scene(
    model: mujoco.MjModel, scene: SceneConfig, half_extents_m: F64, n_distractors: int
) -> BuiltScene:
    """The rigid bodies of the ground truth and the map from geoms to them.

    Bodies, in order: ``static`` (world), ``object``, then the hand (``hand`` for the proxy; for
    the articulated hand the palm ``hand`` and every segment ``hand_<digit>_<i>``), then
    ``distractor0`` ...
    """

    def mocap(name: str) -> int:
        return int(model.body_mocapid[model.body(name).id])

    hand_model = None
    mj_bodies = [0, model.body("object").id]
    names = list(BODY_NAMES[:2])
    if scene.hand.enabled:
        if scene.hand.kind == "articulated":
            hand_model = HandModel.from_model(model, scene.hand)
            mj_bodies.extend(hand_model.body_ids)
        else:
            mj_bodies.append(model.body("hand").id)
    for i in range(n_distractors):
        mj_bodies.append(model.body(f"distractor{i}").id)
    names = [
        "static" if b == 0 else mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or ""
        for b in mj_bodies
    ]
    index_of_mj_body = {b: i for i, b in enumerate(mj_bodies)}
    geom_body = np.array(
        [index_of_mj_body.get(int(model.geom_bodyid[g]), -1) for g in range(model.ngeom)],
        dtype=np.int8,
    )
    return BuiltScene(
        model=model,
        camera_id=int(model.camera("camera").id),
        camera_mocap=mocap("camera_rig"),
        object_mocap=mocap("object"),
        hand_mocap=mocap("hand") if scene.hand.enabled else None,
        object_geom_id=int(model.geom("object").id),
        geom_body=geom_body,
        object_half_extents_m=half_extents_m,
        body_names=tuple(names),
        body_ids=tuple(int(b) for b in mj_bodies),
        hand=hand_model,
        distractor_mocaps=tuple(mocap(f"distractor{i}") for i in range(n_distractors)),
        distractor_geom_ids=tuple(
            int(model.geom(f"distractor{i}").id) for i in range(n_distractors)
        ),
    )
