"""The object registry: names, sizes, shapes, colours and frame alignment of the known objects.

The registry is read from ``assets/ycb/manifest.toml``, installed as ``roft_sim/assets/ycb/``
(strictly: unknown keys and bad values are errors naming the key). Every geometric number is in
the object frame of the poses, which for YCB objects is the NVDU/DOPE-aligned frame of Fast-YCB
(bounding-box centre at the origin); :attr:`ObjectInfo.T_nvdu_orig` maps the original YCB mesh
frame into it.
"""

from __future__ import annotations

import difflib
import functools
import importlib.resources
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from roft_sim.config_files import dataclass_from_mapping
from roft_sim.errors import AssetNotFoundError, ConfigError
from roft_sim.geometry.so3 import as_rotation_matrix

F64 = NDArray[np.float64]

__all__ = [
    "NvduAlignment",
    "ObjectInfo",
    "UnknownObjectError",
    "get_object_info",
    "list_objects",
    "object_registry",
    "FAST_YCB_OBJECTS",
    "load_manifest",
    "MANIFEST_FORMAT_VERSION",
]

MANIFEST_FORMAT_VERSION = 1

FAST_YCB_OBJECTS: tuple[str, ...] = (
    "003_cracker_box",
    "004_sugar_box",
    "005_tomato_soup_can",
    "006_mustard_bottle",
    "009_gelatin_box",
    "010_potted_meat_can",
)
"""The six objects of Fast-YCB and of the ROFT paper's tables, in the paper's order (each is a
registry entry)."""
"""Version of ``manifest.toml`` this module reads."""

ShapeClass = Literal["box", "cylinder", "bottle"]

_PROFILE_SCALE_TOLERANCE = 0.03
"""A bottle profile may differ from ``dimensions_m`` by at most this fraction (it is rescaled)."""


class UnknownObjectError(AssetNotFoundError, ConfigError):
    """A name is neither a registry object nor an existing mesh file (a usage error)."""


Triple = tuple[float, float, float]


@dataclass(frozen=True, slots=True, kw_only=True)
class NvduAlignment:
    """Rigid transform from the original YCB mesh frame to the NVDU-aligned object frame."""

    R: tuple[Triple, Triple, Triple]
    """Rotation, rows of the 3x3 matrix ``R_nvdu_orig`` (orthonormal to 1e-5; projected onto
    SO(3) by :attr:`T_nvdu_orig`)."""
    t_m: Triple
    """Translation ``t_nvdu_orig`` [m]: ``p_nvdu = R p_orig + t``."""

    def __post_init__(self) -> None:
        try:
            as_rotation_matrix(self.R, atol=1e-5)
        except ValueError as e:
            raise ConfigError(f"R: {e}; give a rotation matrix (rows), e.g. 6 decimals") from None
        if not np.isfinite(self.t_m).all():
            raise ConfigError(f"t_m must be finite, got {self.t_m}")

    @property
    def T_nvdu_orig(self) -> F64:
        """(4, 4) pose of the original YCB frame in the aligned frame, R projected onto SO(3)."""
        u, _, vt = np.linalg.svd(np.asarray(self.R, dtype=np.float64))
        T = np.eye(4)
        T[:3, :3] = u @ vt
        T[:3, 3] = self.t_m
        return T


@dataclass(frozen=True, slots=True, kw_only=True)
class ObjectInfo:
    """One registry entry. Lengths in metres, in the aligned object frame."""

    name: str
    """Registry name, e.g. ``003_cracker_box``."""
    description: str
    """What the object is, for people."""
    shape: ShapeClass
    """Shape class of the procedural stand-in: ``box`` (axis-aligned cuboid), ``cylinder``
    (superelliptic prism along y) or ``bottle`` (lofted superelliptic sections along y)."""
    dimensions_m: Triple
    """Bounding-box extents ``(x, y, z)`` [m] in the aligned frame (centre at the origin)."""
    colors_rgb: tuple[tuple[int, int, int], ...]
    """Dominant surface colours, RGB 0-255, most frequent first (at least two)."""
    color_weights: tuple[float, ...]
    """Fraction of the surface covered by each colour (same length as ``colors_rgb``)."""
    section_exponent: float = 2.0
    """Cylinders: superellipse exponent of the cross-section (2 = ellipse, large = rectangle)."""
    profile: tuple[tuple[float, float, float, float], ...] = ()
    """Bottles: cross-sections ``(y_m, half_x_m, half_z_m, exponent)`` with increasing ``y``; the
    stand-in rescales them so that its bounding box is exactly ``dimensions_m``."""
    nvdu_alignment: NvduAlignment | None = None
    """Original YCB mesh frame -> aligned frame; None for objects that have no YCB mesh."""
    model_point_count: int = 2620
    """Number of model points sampled on the surface (YCB-Video's points.xyz has 2620)."""

    def __post_init__(self) -> None:
        where = f"object {self.name!r}"
        dims = np.asarray(self.dimensions_m, dtype=np.float64)
        if not (np.isfinite(dims).all() and (dims > 0).all() and (dims < 5.0).all()):
            raise ConfigError(
                f"{where}: dimensions_m must be three positive lengths in metres (< 5 m), "
                f"got {self.dimensions_m}"
            )
        if len(self.colors_rgb) < 2 or len(self.color_weights) != len(self.colors_rgb):
            raise ConfigError(
                f"{where}: need at least two colors_rgb and one color_weights entry per colour, "
                f"got {len(self.colors_rgb)} colours and {len(self.color_weights)} weights"
            )
        if any(not 0 <= c <= 255 for rgb in self.colors_rgb for c in rgb):
            raise ConfigError(f"{where}: colors_rgb values must lie in 0..255")
        if any(w < 0 for w in self.color_weights) or sum(self.color_weights) <= 0:
            raise ConfigError(f"{where}: color_weights must be >= 0 with a positive sum")
        if self.section_exponent < 1.0:
            raise ConfigError(
                f"{where}: section_exponent must be >= 1 (2 = ellipse), got {self.section_exponent}"
            )
        if self.model_point_count < 1:
            raise ConfigError(f"{where}: model_point_count must be >= 1")
        if self.shape == "bottle":
            self._check_profile(where, dims)
        elif self.profile:
            raise ConfigError(f"{where}: profile is only used with shape = 'bottle'; remove it")

    def _check_profile(self, where: str, dims: F64) -> None:
        p = np.asarray(self.profile, dtype=np.float64)
        if p.ndim != 2 or p.shape[0] < 2 or p.shape[1] != 4 or not np.isfinite(p).all():
            raise ConfigError(
                f"{where}: a bottle needs a profile of at least two [y_m, half_x_m, half_z_m, "
                f"exponent] rows, got shape {p.shape}"
            )
        if (np.diff(p[:, 0]) <= 0).any() or (p[:, 1:3] <= 0).any() or (p[:, 3] < 1).any():
            raise ConfigError(
                f"{where}: profile rows need increasing y, positive half widths and exponents >= 1"
            )
        # (x, y, z) extents spanned by the profile
        measured = np.array([2 * p[:, 1].max(), p[-1, 0] - p[0, 0], 2 * p[:, 2].max()])
        scale = dims / measured
        if np.abs(scale - 1).max() > _PROFILE_SCALE_TOLERANCE:
            raise ConfigError(
                f"{where}: the profile spans {np.round(measured, 4).tolist()} m but dimensions_m "
                f"is {list(self.dimensions_m)}; they must agree within "
                f"{_PROFILE_SCALE_TOLERANCE:.0%}"
            )

    @property
    def half_extents_m(self) -> F64:
        """(3,) half the bounding-box extents [m]."""
        return 0.5 * np.asarray(self.dimensions_m, dtype=np.float64)

    @property
    def palette_rgb(self) -> NDArray[np.uint8]:
        """(C, 3) uint8 colours, most frequent first."""
        return np.asarray(self.colors_rgb, dtype=np.uint8)


@dataclass(frozen=True, slots=True, kw_only=True)
class _Manifest:
    format_version: int
    object: tuple[ObjectInfo, ...]

    def __post_init__(self) -> None:
        if self.format_version != MANIFEST_FORMAT_VERSION:
            raise ConfigError(
                f"format_version {self.format_version} is not supported; this roft_sim reads "
                f"version {MANIFEST_FORMAT_VERSION}"
            )
        names = [o.name for o in self.object]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise ConfigError(f"objects listed twice: {', '.join(duplicates)}; keep one entry each")


def load_manifest(path: str | Path | None = None) -> tuple[ObjectInfo, ...]:
    """Reads and validates a registry manifest.

    Args:
        path: a manifest TOML file; None reads the one shipped with roft_sim.

    Returns:
        The entries in file order.

    Raises:
        ConfigError: not valid TOML, unknown keys, bad values or duplicate names (the message
            names the file and the key).
    """
    if path is None:
        resource = importlib.resources.files("roft_sim.assets.ycb") / "manifest.toml"
        text, where = resource.read_text(encoding="utf-8"), "assets/ycb/manifest.toml"
    else:
        path = Path(path)
        try:
            text, where = path.read_text(encoding="utf-8"), str(path)
        except FileNotFoundError:
            raise ConfigError(f"manifest {str(path)!r} does not exist; check the path") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{where!r} is not valid TOML: {e}") from None
    return dataclass_from_mapping(_Manifest, data, where=where).object


@functools.cache
def _builtin_registry() -> dict[str, ObjectInfo]:
    return {info.name: info for info in load_manifest()}


def object_registry() -> Mapping[str, ObjectInfo]:
    """The shipped registry as a read-only mapping ``name -> ObjectInfo`` (manifest order)."""
    return MappingProxyType(_builtin_registry())


def list_objects() -> list[ObjectInfo]:
    """All registry entries, in manifest order."""
    return list(_builtin_registry().values())


def get_object_info(name: str) -> ObjectInfo:
    """The registry entry called ``name``.

    Raises:
        TypeError: ``name`` is not a string (e.g. an :class:`ObjectInfo`, which is already the
            entry).
        UnknownObjectError: no such entry (the message lists the known names).
    """
    if not isinstance(name, str):
        raise TypeError(
            f"get_object_info takes an object's name (a str such as '003_cracker_box'), got "
            f"{type(name).__name__}; an ObjectInfo from list_objects() is already the entry"
        )
    registry = _builtin_registry()
    if name not in registry:
        close = difflib.get_close_matches(name, list(registry), n=1, cutoff=0.5)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise UnknownObjectError(
            f"{name!r} is not a registry object; {hint}known objects: {', '.join(registry)}"
        )
    return registry[name]
