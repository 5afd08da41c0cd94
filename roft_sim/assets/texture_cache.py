"""A disk cache for procedurally generated textures drawn from a shared random generator.

The scene's table and wall textures (:func:`roft_sim.scene.textures.procedural_texture`) take
about a second each to draw at their default size, and every generation worker builds the same
scene again. :func:`cached_texture` keeps each texture as a PNG in ``<cache>/textures/`` and, since
the textures are drawn one after the other from ONE generator, also the generator's state after
the drawing: a cache hit restores that state, so whatever the generator draws next is exactly what
it would have drawn without the cache.

The key is everything that determines the image: the texture's name and parameters, the
generator's state before drawing, the bytes of the module that draws it (any change to the
drawing code is a miss), and the numpy and OpenCV versions (their random streams and drawing are
not bit-stable across versions). A damaged or partial entry is a miss (and is written again).
"""

from __future__ import annotations

import hashlib
import json
import logging
from collections.abc import Callable, Mapping
from pathlib import Path
from types import ModuleType
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.atomic_files import atomic_write_bytes, atomic_write_text
from roft_sim.datasets.image_files import encode_png_rgb

__all__ = ["cached_texture", "texture_cache_key"]

U8 = NDArray[np.uint8]

_log = logging.getLogger(__name__)

_CODE_DIGESTS: dict[str, str] = {}
"""SHA-256 of each drawing module's source file, read once per process."""


def _code_digest(module: ModuleType) -> str:
    path = module.__file__
    if path is None:  # pragma: no cover - frozen modules have no file; never cache them
        raise ValueError(f"module {module.__name__} has no source file to key a cache on")
    if path not in _CODE_DIGESTS:
        _CODE_DIGESTS[path] = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    return _CODE_DIGESTS[path]


def texture_cache_key(
    name: str, params: Mapping[str, object], rng: np.random.Generator, code: ModuleType
) -> str:
    """Hex key of a texture: name, parameters, generator state, drawing code, library versions."""
    key = {
        "name": name,
        "params": dict(params),
        "rng_state": rng.bit_generator.state,
        "code": _code_digest(code),
        "numpy": np.__version__,
        "opencv": cv2.__version__,
    }
    return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:24]


def cached_texture(
    cache_dir: Path | None,
    name: str,
    params: Mapping[str, object],
    rng: np.random.Generator,
    draw: Callable[[np.random.Generator], U8],
    *,
    code: ModuleType,
) -> U8:
    """``draw(rng)``, read from the cache when an entry exists (and ``rng`` moved on as ``draw``
    would have moved it), else drawn and stored.

    Args:
        cache_dir: the asset cache folder; None = no cache (``draw(rng)`` is called).
        name: a readable name for the file (e.g. ``scene-wood-1024``).
        params: JSON-able parameters of ``draw`` besides the generator (style, size, ...).
        rng: the generator ``draw`` uses; its state is part of the key.
        draw: the drawing function, giving an (H, W, 3) uint8 RGB image.
        code: the module holding the drawing code; its source bytes are part of the key.

    Returns:
        (H, W, 3) uint8 RGB image, equal to ``draw(rng)``.
    """
    if cache_dir is None:
        return draw(rng)
    key = texture_cache_key(name, params, rng, code)
    png = Path(cache_dir) / "textures" / f"{name}-{key}.png"
    state_file = png.with_suffix(".rng.json")
    hit = _read_entry(png, state_file, rng)
    if hit is not None:
        return hit
    image = draw(rng)
    try:  # the image first: the state file's presence marks a complete entry
        atomic_write_bytes(png, encode_png_rgb(image))
        atomic_write_text(state_file, json.dumps(rng.bit_generator.state))
    except OSError as e:  # a read-only cache must not stop the simulation
        _log.warning("could not cache the texture %s: %s", png, e)
    return image


def _read_entry(png: Path, state_file: Path, rng: np.random.Generator) -> U8 | None:
    """The cached image, with ``rng`` set to the stored state; None on a missing or bad entry."""
    if not state_file.is_file():
        return None
    try:
        state = json.loads(state_file.read_text(encoding="utf-8"))
        image = cv2.imread(str(png), cv2.IMREAD_COLOR)
    except (OSError, ValueError) as e:
        _log.warning("ignoring the unreadable cached texture %s: %s", png, e)
        return None
    if image is None or not isinstance(state, dict):
        _log.warning("ignoring the unreadable cached texture %s; drawing it again", png)
        return None
    if state.get("bit_generator") != rng.bit_generator.state["bit_generator"]:
        return None
    rng.bit_generator.state = state
    # IMREAD_COLOR gives 8-bit BGR; cv2 types its results as any dtype
    return cast(U8, cv2.cvtColor(image, cv2.COLOR_BGR2RGB))
