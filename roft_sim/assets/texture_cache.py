"""A disk cache for procedurally generated textures drawn from a shared random generator.

The scene's table and wall textures (:func:`roft_sim.scene.textures.procedural_texture`) take
about a second each to draw at their default size, and every generation worker builds the same
scene again. :func:`cached_texture` keeps each texture in ``<cache>/textures/`` and, since
the textures are drawn one after the other from ONE generator, also the generator's state after
the drawing: a cache hit restores that state, so whatever the generator draws next is exactly what
it would have drawn without the cache.

The key is everything that determines the image: the texture's name and parameters, the
generator's state before drawing, the bytes of the module that draws it (any change to the
drawing code is a miss), and the numpy and OpenCV versions (their random streams and drawing are
not bit-stable across versions). A damaged or partial entry is a miss (and is written again).

Images are stored as raw ``.npy`` files (:func:`save_cached_image`, :func:`load_cached_image`),
which read in a few milliseconds where decoding a PNG takes 30-200 ms (a 2048 px texture), for
about 1.4 times the size; the procedural objects' texture cache
(:mod:`roft_sim.assets.objects`) uses the same files. Entries written as PNG by earlier versions
are not read, and are deleted when the entry is written again.
"""

from __future__ import annotations

import hashlib
import io
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

__all__ = ["cached_texture", "texture_cache_key", "load_cached_image", "save_cached_image"]

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


def save_cached_image(path: Path, image: U8, *, legacy: Path | None = None) -> None:
    """Writes an (H, W, 3) uint8 image to ``path`` as a raw ``.npy`` file, atomically, then
    deletes ``legacy`` (the same entry in an earlier format), if given and present.

    Raises:
        OSError: the file cannot be written.
    """
    buffer = io.BytesIO()
    np.save(buffer, np.ascontiguousarray(image, dtype=np.uint8), allow_pickle=False)
    atomic_write_bytes(path, buffer.getvalue())
    if legacy is not None:
        legacy.unlink(missing_ok=True)


def load_cached_image(path: Path) -> U8 | None:
    """The (H, W, 3) uint8 image that :func:`save_cached_image` wrote to ``path``; None when the
    file is absent, or unreadable or not such an image (with a warning)."""
    try:
        with path.open("rb") as f:  # .npy only (np.load would also open zip or pickle files)
            image = np.lib.format.read_array(f, allow_pickle=False)
    except FileNotFoundError:
        return None
    except (OSError, ValueError, EOFError) as e:
        _log.warning("ignoring the unreadable cached texture %s (%s); drawing it again", path, e)
        return None
    if not (
        isinstance(image, np.ndarray)
        and image.dtype == np.uint8
        and image.ndim == 3
        and image.shape[2] == 3
    ):
        _log.warning(
            "ignoring the cached texture %s: not an (H, W, 3) uint8 image; drawing it again", path
        )
        return None
    return cast(U8, image)


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
    image_file = Path(cache_dir) / "textures" / f"{name}-{key}.npy"
    state_file = image_file.with_suffix(".rng.json")
    hit = _read_entry(image_file, state_file, rng)
    if hit is not None:
        return hit
    image = draw(rng)
    try:  # the image first: the state file's presence marks a complete entry
        save_cached_image(image_file, image, legacy=image_file.with_suffix(".png"))
        atomic_write_text(state_file, json.dumps(rng.bit_generator.state))
    except OSError as e:  # a read-only cache must not stop the simulation
        _log.warning("could not cache the texture %s: %s", image_file, e)
    return image


def _read_entry(image_file: Path, state_file: Path, rng: np.random.Generator) -> U8 | None:
    """The cached image, with ``rng`` set to the stored state; None on a missing or bad entry."""
    if not (state_file.is_file() and image_file.is_file()):
        return None
    try:
        state = json.loads(state_file.read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        _log.warning("ignoring the unreadable cached texture state %s: %s", state_file, e)
        return None
    if not isinstance(state, dict):
        _log.warning(
            "ignoring the unreadable cached texture state %s; drawing it again", state_file
        )
        return None
    if state.get("bit_generator") != rng.bit_generator.state["bit_generator"]:
        return None
    image = load_cached_image(image_file)
    if image is None:
        return None
    rng.bit_generator.state = state
    return image
