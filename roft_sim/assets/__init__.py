"""Object assets: the registry, real YCB meshes when installed, procedural stand-ins otherwise.

- :func:`list_objects` / :func:`get_object_info`: the registry (``assets/ycb/manifest.toml``):
  names, sizes in the aligned frame, shape class, colours, NVDU frame alignment.
- :func:`load_object`: an :class:`ObjectAssets` (textured mesh to render, :class:`ObjectModel`
  with model points for metrics) for a registry name or a mesh file; real meshes are moved into
  the NVDU-aligned frame (``p_nvdu = R p_orig + t``) once, here.
- :func:`install_assets`: copies or downloads YCB google_16k meshes into the user cache, safely.
- :func:`default_cache_dir`: where the cache lives (``$ROFT_SIM_CACHE`` or ``~/.cache/roft_sim``);
  called by the CLI only, the library never reads the environment.

See docs/assets.md.
"""

from roft_sim.assets.install import (
    OFFICIAL_YCB_BASE_URL,
    default_cache_dir,
    install_assets,
    official_archive_url,
)
from roft_sim.assets.meshes import TexturedMesh, model_point_seed, sample_surface_points
from roft_sim.assets.objects import (
    ObjectAssets,
    find_ycb_mesh,
    load_object,
    ycb_mesh_candidates,
)
from roft_sim.assets.registry import (
    FAST_YCB_OBJECTS,
    NvduAlignment,
    ObjectInfo,
    UnknownObjectError,
    get_object_info,
    list_objects,
    object_registry,
)
from roft_sim.errors import AssetNotFoundError, DatasetFormatError

__all__ = [
    "FAST_YCB_OBJECTS",
    "AssetNotFoundError",
    "DatasetFormatError",
    "NvduAlignment",
    "OFFICIAL_YCB_BASE_URL",
    "ObjectAssets",
    "ObjectInfo",
    "TexturedMesh",
    "UnknownObjectError",
    "default_cache_dir",
    "find_ycb_mesh",
    "get_object_info",
    "install_assets",
    "list_objects",
    "load_object",
    "model_point_seed",
    "object_registry",
    "official_archive_url",
    "sample_surface_points",
    "ycb_mesh_candidates",
]
