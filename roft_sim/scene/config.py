"""Configuration of the MuJoCo scene and of the renderer (the ``[scene]`` and ``[render]`` tables
of a scenario file, and ``[camera.motion]``).

Every length is in metres in the WORLD frame, which is the OpenCV optical frame of the camera at
rest (x right, y down, z forward; docs/conventions.md): "below the camera" is +y, "in front" +z.
These dataclasses import nothing from MuJoCo, so scenario files load without a GL backend.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from roft_sim.errors import ConfigError
from roft_sim.sensors.depth_noise import DepthNoiseConfig, NoDepthNoise
from roft_sim.trajectories.build import TrajectoryConfig
from roft_sim.trajectories.bvh import BvhUnit
from roft_sim.trajectories.placement import GraspOffset

__all__ = [
    "TEXTURE_STYLES",
    "TableConfig",
    "BackgroundConfig",
    "LightConfig",
    "HAND_KINDS",
    "FingerConfig",
    "HandMotionConfig",
    "HandConfig",
    "DistractorConfig",
    "SceneConfig",
    "ImageFormationConfig",
    "RenderConfig",
    "CameraSwayConfig",
    "CameraFileMotionConfig",
    "CameraMotionConfig",
]

TextureStyle = Literal["wood", "stone", "fabric", "posters"]
TEXTURE_STYLES: tuple[str, ...] = ("wood", "stone", "fabric", "posters")
"""Procedural texture styles (see :mod:`roft_sim.scene.textures`)."""


def _check_positive(owner: str, **values: float) -> None:
    for name, value in values.items():
        if not (np.isfinite(value) and value > 0):
            raise ConfigError(f"{owner}.{name} must be a positive number, got {value}")


def _check_texture_px(owner: str, value: int) -> None:
    if not 16 <= value <= 4096:
        raise ConfigError(f"{owner}.texture_px must be 16 to 4096, got {value}")


def _check_choice(name: str, value: object, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ConfigError(f"{name} must be one of {', '.join(map(repr, choices))}, got {value!r}")


def _check_unit_interval(owner: str, **values: float) -> None:
    for name, value in values.items():
        if not (np.isfinite(value) and 0.0 <= value <= 1.0):
            raise ConfigError(f"{owner}.{name} must lie in [0, 1], got {value}")


@dataclass(frozen=True, slots=True, kw_only=True)
class TableConfig:
    """A horizontal, textured table top below the camera."""

    enabled: bool = True
    """Draw the table."""
    height_m: float = 0.35
    """Distance of the table top below the camera's optical centre (world +y) [m]."""
    near_m: float = 0.2
    """Nearest edge of the table along the optical axis (world z) [m]; the far edge meets the
    background wall (or ``near_m + 3`` m without one)."""
    width_m: float = 4.0
    """Extent across the view (world x) [m]."""
    style: TextureStyle = "wood"
    """Procedural texture style: ``wood``, ``stone``, ``fabric`` or ``posters``."""
    texture_period_m: float = 0.6
    """Size of one texture tile on the table [m] (the texture repeats seamlessly)."""
    texture_px: int = 1024
    """Side of the generated texture tile [px] (16 to 4096)."""

    def __post_init__(self) -> None:
        _check_positive(
            "table",
            height_m=self.height_m,
            width_m=self.width_m,
            texture_period_m=self.texture_period_m,
        )
        if not (np.isfinite(self.near_m) and self.near_m >= 0):
            raise ConfigError(f"table.near_m must be >= 0, got {self.near_m}")
        _check_texture_px("table", self.texture_px)


@dataclass(frozen=True, slots=True, kw_only=True)
class BackgroundConfig:
    """A textured wall facing the camera, large enough to fill the view."""

    enabled: bool = True
    """Draw the wall."""
    distance_m: float = 1.6
    """Distance of the wall along the optical axis (world z) [m]."""
    style: TextureStyle = "posters"
    """Procedural texture style: ``wood``, ``stone``, ``fabric`` or ``posters``."""
    texture_period_m: float = 0.8
    """Size of one texture tile on the wall [m]."""
    texture_px: int = 1024
    """Side of the generated texture tile [px] (16 to 4096)."""

    def __post_init__(self) -> None:
        _check_positive(
            "background", distance_m=self.distance_m, texture_period_m=self.texture_period_m
        )
        _check_texture_px("background", self.texture_px)


@dataclass(frozen=True, slots=True, kw_only=True)
class LightConfig:
    """One light; position and direction in the world frame (OpenCV: y down)."""

    kind: Literal["directional", "spot"] = "directional"
    """``directional`` (parallel rays along ``direction``) or ``spot`` (at ``position_m``)."""
    position_m: tuple[float, float, float] = (0.0, -1.0, 0.0)
    """Position [m] (spot lights; directional lights use it only for shadows)."""
    direction: tuple[float, float, float] = (0.0, 1.0, 1.0)
    """Direction the light points to (any length > 0)."""
    diffuse: float = 0.6
    """Diffuse intensity in [0, 1] (white light)."""
    specular: float = 0.1
    """Specular intensity in [0, 1]."""
    cast_shadow: bool = True
    """Casts shadows when ``[render] shadows = true``."""

    def __post_init__(self) -> None:
        _check_choice("light kind", self.kind, ("directional", "spot"))
        d = np.asarray(self.direction, dtype=np.float64)
        if not (np.isfinite(d).all() and np.linalg.norm(d) > 1e-9):
            raise ConfigError(f"light direction must be a non-zero vector, got {self.direction}")
        if not np.isfinite(np.asarray(self.position_m)).all():
            raise ConfigError(f"light position_m must be finite, got {self.position_m}")
        _check_unit_interval("light", diffuse=self.diffuse, specular=self.specular)


def _default_lights() -> tuple[LightConfig, ...]:
    return (
        LightConfig(position_m=(-1.0, -2.0, -0.5), direction=(0.35, 1.0, 0.6), diffuse=0.55),
        LightConfig(
            position_m=(1.5, -1.0, 0.0),
            direction=(-0.6, 0.5, 0.8),
            diffuse=0.25,
            specular=0.05,
            cast_shadow=False,
        ),
    )


HandKind = Literal["proxy", "articulated"]
HAND_KINDS: tuple[str, ...] = ("proxy", "articulated")
"""Hand models: ``proxy`` (rigid capsules fixed in the object frame) or ``articulated`` (a
jointed hand whose grasp is synthesised against the object mesh, :mod:`roft_sim.scene.hand`)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class FingerConfig:
    """One digit of the articulated hand: three phalanges on three flexion hinges.

    Lengths are joint-to-joint segment lengths [m]. For the four fingers the segments are the
    proximal, middle and distal phalanges (joints MCP, PIP, DIP); for the thumb they are the
    metacarpal, proximal and distal phalanges (joints CMC, MCP, IP).
    """

    name: str
    """Digit name (``index``, ``middle``, ``ring``, ``little``, ``thumb``); names the bodies."""
    lengths_m: tuple[float, float, float]
    """Segment lengths, proximal to distal [m]."""
    radius_m: float
    """Radius of the proximal segment [m]; the middle and distal ones are 0.93 and 0.86 of it."""
    flexion_limits_rad: tuple[float, float, float]
    """Largest active flexion of each joint, proximal to distal [rad] (the range starts at 0,
    the straight digit)."""

    def __post_init__(self) -> None:
        if not self.name or not self.name.isidentifier():
            raise ConfigError(f"hand finger name must be an identifier, got {self.name!r}")
        _check_positive(
            f"hand.{self.name}",
            radius_m=self.radius_m,
            **{f"lengths_m[{i}]": v for i, v in enumerate(self.lengths_m)},
        )
        limits = np.asarray(self.flexion_limits_rad, dtype=np.float64)
        if not (np.isfinite(limits).all() and (limits > 0).all() and (limits <= np.pi).all()):
            raise ConfigError(
                f"hand.{self.name}.flexion_limits_rad must lie in (0, pi], got "
                f"{self.flexion_limits_rad}"
            )


def _digit(name: str, lengths_mm: tuple[float, float, float], radius_mm: float,
           limits_deg: tuple[float, float, float]) -> FingerConfig:  # fmt: skip
    return FingerConfig(
        name=name,
        lengths_m=(lengths_mm[0] / 1000, lengths_mm[1] / 1000, lengths_mm[2] / 1000),
        radius_m=radius_mm / 1000,
        flexion_limits_rad=(
            float(np.radians(limits_deg[0])),
            float(np.radians(limits_deg[1])),
            float(np.radians(limits_deg[2])),
        ),
    )


def _default_fingers() -> tuple[FingerConfig, ...]:
    # Segment lengths: adult means rounded to the millimetre after Buryanov & Kotiuk,
    # "Proportions of hand segments", Int. J. Morphol. 28(3), 2010 (phalanx lengths) scaled to a
    # 19 cm hand (ANSUR II adult mean hand length). Flexion limits: active range of motion of
    # Hume et al., "Functional range of motion of the joints of the hand", J. Hand Surg. 15A,
    # 1990 (MCP 100, PIP 105, DIP 85 deg; thumb MCP 56, IP 73 deg; CMC flexion 50 deg).
    return (
        _digit("index", (43.0, 25.0, 19.0), 9.0, (100.0, 105.0, 85.0)),
        _digit("middle", (47.0, 29.0, 20.0), 9.3, (100.0, 105.0, 85.0)),
        _digit("ring", (44.0, 28.0, 19.0), 8.8, (100.0, 105.0, 85.0)),
        _digit("little", (35.0, 21.0, 18.0), 7.8, (100.0, 105.0, 85.0)),
    )


def _default_thumb() -> FingerConfig:
    return _digit("thumb", (40.0, 32.0, 27.0), 10.5, (50.0, 56.0, 73.0))


@dataclass(frozen=True, slots=True, kw_only=True)
class HandMotionConfig:
    """How the articulated hand's fingers move while it holds the object (seeded from the
    scenario's ``hand`` stream). Fingers only ever OPEN from the synthesised grasp (flexion
    decreases), and every frame is checked against the object: a finger whose planned opening
    would enter the object opens less (MuJoCo distance queries)."""

    flexion_jitter_rad: float = 0.07
    """Peak opening of the slow flexion changes of each digit [rad] (about 4 deg)."""
    jitter_frequency_hz: float = 0.4
    """Mean frequency of the slow flexion changes [Hz] (each digit draws its own in
    [0.5, 1.5] x this)."""
    regrip_rate_hz: float = 0.15
    """Mean rate of re-grips [1/s] (Poisson): one or more digits open and close again."""
    regrip_opening_rad: float = 0.45
    """Peak opening of a digit during a re-grip [rad] (about 26 deg)."""
    regrip_duration_s: float = 0.6
    """Duration of one re-grip [s] (raised-cosine opening and closing)."""

    def __post_init__(self) -> None:
        if not (np.isfinite(self.flexion_jitter_rad) and self.flexion_jitter_rad >= 0):
            raise ConfigError(
                f"hand.motion.flexion_jitter_rad must be >= 0, got {self.flexion_jitter_rad}"
            )
        if not (np.isfinite(self.regrip_rate_hz) and self.regrip_rate_hz >= 0):
            raise ConfigError(f"hand.motion.regrip_rate_hz must be >= 0, got {self.regrip_rate_hz}")
        if not (np.isfinite(self.regrip_opening_rad) and 0 <= self.regrip_opening_rad <= 1.5):
            raise ConfigError(
                f"hand.motion.regrip_opening_rad must lie in [0, 1.5], got "
                f"{self.regrip_opening_rad}"
            )
        _check_positive(
            "hand.motion",
            jitter_frequency_hz=self.jitter_frequency_hz,
            regrip_duration_s=self.regrip_duration_s,
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class HandConfig:
    """A hand that holds the object, of one of two kinds (``kind``).

    ``articulated`` (the default kind): a palm and five digits of three phalanges on flexion
    hinges, sized by ``palm_*_m``, ``fingers`` and ``thumb_digit``; per scenario a grasp is
    synthesised against the object mesh (:func:`roft_sim.scene.hand.synthesise_grasp`) and the
    fingers move during the sequence (``motion``).

    ``proxy``: rigid capsules that move with the object (the grasp does not change). The palm
    lies against the object face ``palm_side``; the fingers lie across the ``+wrap_axis`` face and
    the thumb across the ``-wrap_axis`` face, so the hand covers part of the object from most
    viewpoints. ``palm_side`` ... ``thumb`` apply to the proxy only.
    """

    enabled: bool = False
    """Add the hand."""
    kind: HandKind = "articulated"
    """``articulated`` (jointed hand with a synthesised grasp) or ``proxy`` (rigid capsules)."""
    palm_side: Literal["+x", "-x", "+y", "-y", "+z", "-z"] = "-x"
    """Object-frame face the palm rests against."""
    wrap_axis: Literal["x", "y", "z"] = "z"
    """Object-frame axis across whose faces the fingers (+) and the thumb (-) lie; must differ
    from the palm axis."""
    palm_radius_m: float = 0.02
    """Radius of the palm capsule [m]."""
    finger_radius_m: float = 0.009
    """Radius of each finger capsule [m]."""
    finger_length_m: float = 0.085
    """Length of each finger from the palm [m]."""
    finger_count: int = 4
    """Number of fingers besides the thumb (1 to 4)."""
    thumb: bool = True
    """Add a thumb on the opposite face."""
    skin_rgb: tuple[float, float, float] = (0.86, 0.66, 0.55)
    """Skin colour, RGB in [0, 1] (the hand is plain, untextured)."""
    palm_length_m: float = 0.1
    """Articulated: palm length, wrist crease to the knuckle (MCP) line [m] (about half of a
    19 cm adult hand)."""
    palm_width_m: float = 0.085
    """Articulated: palm breadth at the knuckles [m] (ANSUR II adult mean hand breadth, rounded)."""
    palm_thickness_m: float = 0.028
    """Articulated: palm thickness [m]."""
    fingers: tuple[FingerConfig, ...] = field(default_factory=_default_fingers)
    """Articulated: the fingers, from the thumb side (index) to the little finger."""
    thumb_digit: FingerConfig = field(default_factory=_default_thumb)
    """Articulated: the thumb (metacarpal, proximal and distal segments)."""
    skin_specular: float = 0.25
    """Articulated: specular reflection of the skin material in [0, 1] (skin is slightly
    glossy)."""
    contact_gap_m: float = 0.0003
    """Articulated: clearance at which a closing segment counts as touching the object [m]."""
    side: Literal["away_from_camera", "random"] = "away_from_camera"
    """Articulated: where the palm goes. ``away_from_camera``: on a side of the object that faces
    away from the camera over the sequence (as a person holds an object up to a camera: the
    fingers wrap round its edge); ``random``: any side whose extent fits the fingers' reach."""
    motion: HandMotionConfig = field(default_factory=HandMotionConfig)
    """Articulated: the fingers' motion during the sequence (``[scene.hand.motion]``)."""

    def __post_init__(self) -> None:
        _check_choice("hand.kind", self.kind, HAND_KINDS)
        _check_positive(
            "hand",
            palm_length_m=self.palm_length_m,
            palm_width_m=self.palm_width_m,
            palm_thickness_m=self.palm_thickness_m,
        )
        if not 1 <= len(self.fingers) <= 4:
            raise ConfigError(f"hand.fingers must list 1 to 4 fingers, got {len(self.fingers)}")
        names = [f.name for f in self.fingers] + [self.thumb_digit.name]
        if len(set(names)) != len(names):
            raise ConfigError(f"hand digit names must be unique, got {names}")
        if not (np.isfinite(self.contact_gap_m) and 0 < self.contact_gap_m <= 0.001):
            raise ConfigError(
                f"hand.contact_gap_m must lie in (0, 0.001] m, got {self.contact_gap_m}"
            )
        _check_unit_interval("hand", skin_specular=self.skin_specular)
        _check_choice("hand.side", self.side, ("away_from_camera", "random"))
        _check_choice("hand.palm_side", self.palm_side, ("+x", "-x", "+y", "-y", "+z", "-z"))
        _check_choice("hand.wrap_axis", self.wrap_axis, ("x", "y", "z"))
        _check_positive(
            "hand",
            palm_radius_m=self.palm_radius_m,
            finger_radius_m=self.finger_radius_m,
            finger_length_m=self.finger_length_m,
        )
        if not 1 <= self.finger_count <= 4:
            raise ConfigError(f"hand.finger_count must be 1 to 4, got {self.finger_count}")
        if self.palm_side[1] == self.wrap_axis:
            raise ConfigError(
                f"hand.wrap_axis ({self.wrap_axis!r}) must differ from the palm axis "
                f"(palm_side = {self.palm_side!r}); e.g. palm_side = '-x', wrap_axis = 'z'"
            )
        _check_unit_interval("hand", **{f"skin_rgb[{i}]": c for i, c in enumerate(self.skin_rgb)})


@dataclass(frozen=True, slots=True, kw_only=True)
class DistractorConfig:
    """A distractor object (``[[scene.distractors]]``): another mesh in the scene with its own
    ground truth (pose, segment id), either resting on the table or moved by its own
    trajectory."""

    name: str
    """Registry name or mesh file of the object (``roft_sim.assets.load_object``), e.g.
    ``005_tomato_soup_can``."""
    position_m: tuple[float, float] = (0.15, 0.7)
    """Resting: where it stands on the table, world (x, z) [m]."""
    yaw_rad: float = 0.0
    """Resting: rotation about the vertical (world y) [rad]; the object's +z points up."""
    trajectory: TrajectoryConfig | None = None
    """Its own motion (a ``[trajectory]``-like table, placed in view like the object's); absent =
    resting on the table (needs ``[scene.table] enabled``)."""

    def __post_init__(self) -> None:
        if not self.name:
            raise ConfigError("scene.distractors: name must be a registry name or mesh path")
        if not np.isfinite([*self.position_m, self.yaw_rad]).all():
            raise ConfigError(
                f"scene.distractors[{self.name!r}]: position_m and yaw_rad must be finite, got "
                f"{self.position_m}, {self.yaw_rad}"
            )


@dataclass(frozen=True, slots=True, kw_only=True)
class SceneConfig:
    """Everything in the scene besides the object and the camera."""

    table: TableConfig = field(default_factory=TableConfig)
    """The table top."""
    background: BackgroundConfig = field(default_factory=BackgroundConfig)
    """The wall behind the object."""
    lights: tuple[LightConfig, ...] = field(default_factory=_default_lights)
    """The lights (at most 8); the default is a key light from the upper left and a fill light."""
    ambient: float = 0.35
    """Ambient light intensity in [0, 1] (MuJoCo's headlight ambient; the headlight itself casts
    no diffuse light)."""
    hand: HandConfig = field(default_factory=HandConfig)
    """Optional hand occluder."""
    distractors: tuple[DistractorConfig, ...] = ()
    """Distractor objects (clutter), each with its own ground truth (at most 32)."""

    def __post_init__(self) -> None:
        if len(self.distractors) > 32:
            raise ConfigError(f"at most 32 distractors are supported, got {len(self.distractors)}")
        if any(d.trajectory is None for d in self.distractors) and not self.table.enabled:
            raise ConfigError(
                "a distractor without a trajectory rests on the table, but [scene.table] is "
                "disabled; enable the table or give the distractor a trajectory"
            )
        if len(self.lights) > 8:
            raise ConfigError(f"at most 8 lights are supported, got {len(self.lights)}")
        _check_unit_interval("scene", ambient=self.ambient)


@dataclass(frozen=True, slots=True, kw_only=True)
class ImageFormationConfig:
    """The colour camera's image formation (``[render.image_formation]``): exposure, gamma,
    Poisson-Gaussian sensor noise and a rolling shutter, applied to the rendered rgb
    (:mod:`roft_sim.render.image_formation`). Ground truth is unaffected.

    The defaults describe a RealSense-D415-like colour camera (an OmniVision OV2740-class
    1.4 um-pixel rolling-shutter CMOS at 30 fps): full well and read noise are typical values of
    that pixel class (EMVA 1288 data sheets of small-pixel CMOS sensors), not measurements of a
    D415; the readout time assumes the rows of a 1080p frame read out over about 80 % of the
    33 ms frame interval. Off by default: Fast-YCB's images are clean renders.
    """

    enabled: bool = False
    """Apply the model (off: the rendered image as is)."""
    exposure_gain: float = 1.0
    """Multiplies the linear irradiance (1 = as rendered; > 1 brighter, clipping at full well)."""
    gamma: float = 2.2
    """Encoding gamma: rendered values are linearised as ``(rgb / 255) ** gamma`` and encoded
    back with ``1 / gamma``."""
    full_well_e: float = 4500.0
    """Electrons of a white (saturated) pixel: sets the shot-noise level [e-]."""
    read_noise_e: float = 2.5
    """Standard deviation of the signal-independent (read) noise [e-]."""
    shot_noise: bool = True
    """Draw the signal as Poisson(electrons) (off: only the Gaussian read noise)."""
    rolling_shutter_readout_s: float = 0.026
    """Time from the first row's exposure to the last row's [s]; 0 = global shutter. Row r is
    exposed at ``t_k + (r / (H - 1) - 0.5) * readout``, so the middle row is at the frame time
    of the ground truth."""
    rolling_shutter_bands: int = 0
    """Renders per frame for the rolling shutter: the rows are split into this many bands, each
    rendered at its own mid-time (0 = one render per row: exact, slowest)."""

    def __post_init__(self) -> None:
        _check_positive(
            "render.image_formation",
            exposure_gain=self.exposure_gain,
            gamma=self.gamma,
            full_well_e=self.full_well_e,
        )
        if not (np.isfinite(self.read_noise_e) and self.read_noise_e >= 0):
            raise ConfigError(
                f"render.image_formation.read_noise_e must be >= 0, got {self.read_noise_e}"
            )
        readout = self.rolling_shutter_readout_s
        if not (np.isfinite(readout) and 0 <= readout <= 1.0):
            raise ConfigError(
                f"render.image_formation.rolling_shutter_readout_s must lie in [0, 1] s, got "
                f"{readout}"
            )
        if self.rolling_shutter_bands < 0:
            raise ConfigError(
                f"render.image_formation.rolling_shutter_bands must be >= 0 (0 = every row), got "
                f"{self.rolling_shutter_bands}"
            )

    @property
    def rolling_shutter(self) -> bool:
        """The model is on and rows are exposed in sequence."""
        return self.enabled and self.rolling_shutter_readout_s > 0


@dataclass(frozen=True, slots=True, kw_only=True)
class RenderConfig:
    """How images are rendered; ground truth is unaffected by every option here."""

    shadows: bool = False
    """Cast shadows (slower on CPU renderers)."""
    msaa_samples: int = 0
    """Multisample anti-aliasing samples of the colour image: 0 (off), 2, 4, 8 or 16. Depth
    and segmentation are never anti-aliased."""
    motion_blur_subframes: int = 1
    """Number of renders averaged into each rgb image (1 = no motion blur). Ground truth
    (pose, velocity, depth, mask, flow) stays at the frame time, the middle of the exposure."""
    exposure_fraction: float = 0.5
    """Exposure time as a fraction of the frame interval, in (0, 1] (motion blur only)."""
    znear_m: float = 0.05
    """Near clipping distance [m]; geometry closer than this is not drawn."""
    zfar_m: float = 20.0
    """Far clipping distance [m]."""
    depth_noise: DepthNoiseConfig = field(default_factory=NoDepthNoise)
    """Noise model of the SENSOR depth (``kind = "none" | "realsense" | "kinect_azure"``);
    ground-truth depth stays exact."""
    image_formation: ImageFormationConfig = field(default_factory=ImageFormationConfig)
    """Exposure, gamma, sensor noise and rolling shutter of the colour image (off by
    default)."""

    def __post_init__(self) -> None:
        if self.msaa_samples not in (0, 2, 4, 8, 16):
            raise ConfigError(
                f"render.msaa_samples must be one of 0, 2, 4, 8, 16, got {self.msaa_samples}"
            )
        if self.motion_blur_subframes < 1:
            raise ConfigError(
                f"render.motion_blur_subframes must be >= 1 (1 = no blur), got "
                f"{self.motion_blur_subframes}"
            )
        if not (np.isfinite(self.exposure_fraction) and 0 < self.exposure_fraction <= 1):
            raise ConfigError(
                f"render.exposure_fraction must lie in (0, 1], got {self.exposure_fraction}"
            )
        _check_positive("render", znear_m=self.znear_m, zfar_m=self.zfar_m)
        if self.image_formation.rolling_shutter and self.motion_blur_subframes > 1:
            raise ConfigError(
                "render.image_formation's rolling shutter and render.motion_blur_subframes > 1 "
                "cannot be combined (each row band is one instantaneous render); set "
                "motion_blur_subframes = 1 or rolling_shutter_readout_s = 0"
            )
        if self.zfar_m <= self.znear_m * 10:
            raise ConfigError(
                f"render.zfar_m ({self.zfar_m}) must exceed 10 x znear_m ({self.znear_m})"
            )


@dataclass(frozen=True, slots=True, kw_only=True)
class CameraSwayConfig:
    """Hand-held-like camera ego-motion: smooth sinusoidal sway about the rest pose.

    Each translation and rotation component ``i`` (x, y, z) follows
    ``a_i * sin(2 pi f t + phase_i)`` with phases ``(0, 2 pi / 3, 4 pi / 3)`` for translation and
    ``(pi / 2, pi / 2 + 2 pi / 3, pi / 2 + 4 pi / 3)`` for rotation (a rotation vector in the
    world frame), so the camera starts already moving and velocities are exact derivatives.
    """

    kind: Literal["sway"] = "sway"
    """Motion model (only ``sway`` so far)."""
    amplitude_m: tuple[float, float, float] = (0.03, 0.02, 0.02)
    """Translation amplitude per world axis [m]."""
    amplitude_rad: tuple[float, float, float] = (0.03, 0.04, 0.02)
    """Rotation-vector amplitude per world axis [rad]."""
    frequency_hz: float = 0.5
    """Sway frequency [Hz]."""

    def __post_init__(self) -> None:
        values = np.asarray(self.amplitude_m + self.amplitude_rad, dtype=np.float64)
        if not (np.isfinite(values).all() and (values >= 0).all()):
            raise ConfigError("camera.motion amplitudes must be finite and >= 0")
        if float(np.linalg.norm(self.amplitude_rad)) > 0.5:
            raise ConfigError(
                f"camera.motion.amplitude_rad {self.amplitude_rad} is too large (norm > 0.5 rad)"
            )
        _check_positive("camera.motion", frequency_hz=self.frequency_hz)


@dataclass(frozen=True, slots=True, kw_only=True)
class CameraFileMotionConfig:
    """Captured camera motion replayed from a file (``kind = "file"``): a TUM trajectory, a BVH
    joint (e.g. a head) or a trajectory CSV, cleaned like a captured object trajectory
    (drift removal, low-pass, window, speed) and anchored so that the camera starts at its rest
    pose: ``T_world_cam(t) = inv(T_ref_body(0) @ T_body_cam) @ T_ref_body(t) @ T_body_cam``,
    with ``t = 0`` the first kept sample. Velocities are exact derivatives of the spline
    (:mod:`roft_sim.scene.camera_motion`)."""

    kind: Literal["file"] = "file"
    """Tells camera motion models apart."""
    path: Path
    """The file (relative paths resolve against the scenario file's folder)."""
    format: Literal["tum", "bvh", "csv"]
    """``tum``, ``bvh`` or ``csv`` (the trajectory readers of :mod:`roft_sim.trajectories`)."""
    joint: str | None = None
    """BVH only, required: the joint carrying the camera, e.g. ``CC_Base_Head``."""
    relative_to: str | None = None
    """BVH only: follow ``joint`` relative to this joint."""
    bvh_unit: BvhUnit = "auto"
    """BVH only: length unit of the file."""
    lowpass_hz: float | None = None
    """Zero-phase low-pass cut-off [Hz] for position and rotation; None = no filtering."""
    window_s: tuple[float, float] | None = None
    """Keep only ``[start, end]`` [s] of the file; the motion then starts at 0."""
    speed_scale: float = 1.0
    """Play faster (> 1) or slower (< 1)."""
    remove_drift_window_s: float | None = None
    """Subtract a centred moving average of the position over this window [s] (keeps the camera
    near its rest pose on walking captures); None = keep."""
    camera_in_body: GraspOffset = field(default_factory=GraspOffset)
    """Placement of the camera on the tracked body: the pose ``T_body_cam`` of the camera's
    OpenCV optical frame in the body frame (default: the identity)."""

    def __post_init__(self) -> None:
        _check_choice("camera.motion.format", self.format, ("tum", "bvh", "csv"))
        if self.format == "bvh" and not self.joint:
            raise ConfigError("camera.motion format 'bvh' needs joint = e.g. 'CC_Base_Head'")
        if self.format != "bvh" and (self.joint or self.relative_to or self.bvh_unit != "auto"):
            raise ConfigError(
                f"camera.motion: joint, relative_to and bvh_unit apply to format 'bvh' only, "
                f"not {self.format!r}; remove them"
            )
        for name, value in (
            ("lowpass_hz", self.lowpass_hz),
            ("remove_drift_window_s", self.remove_drift_window_s),
        ):
            if value is not None:
                _check_positive("camera.motion", **{name: value})
        _check_positive("camera.motion", speed_scale=self.speed_scale)
        if self.window_s is not None:
            start, end = self.window_s
            if not (np.isfinite([start, end]).all() and 0 <= start < end):
                raise ConfigError(
                    f"camera.motion.window_s must be [start, end] with 0 <= start < end [s], "
                    f"got {self.window_s!r}"
                )


CameraMotionConfig = CameraSwayConfig | CameraFileMotionConfig
"""Camera ego-motion models, told apart by ``kind`` (``sway`` or ``file``)."""
