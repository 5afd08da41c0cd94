"""``roft-sim assets list|install``: see which objects have real meshes, and install them.

- ``list``: every registry object with its shape, size in the aligned frame, and where its real
  mesh was found (``--assets DIR`` / ``$ROFT_SIM_ASSETS`` first, then the cache), or that the
  procedural stand-in is used; ``--json`` prints a JSON array instead.
- ``install --from DIR|ARCHIVE|URL|ycb [--objects ...] [--sha256 HEX]``: copies or downloads
  YCB google_16k meshes into the cache (``--cache DIR``, else ``$ROFT_SIM_CACHE``, else
  ``~/.cache/roft_sim``), verifying and extracting archives safely.

The YCB models are licensed CC BY 4.0 (YCB Object and Model Set, ycbbenchmarks.com).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any

from roft_sim.assets import (
    OFFICIAL_YCB_BASE_URL,
    default_cache_dir,
    find_ycb_mesh,
    install_assets,
    list_objects,
)
from roft_sim.errors import ConfigError

__all__ = ["register"]


def assets_dir_from_args(args: argparse.Namespace) -> Path | None:
    """The folder of real YCB meshes: ``--assets``, else ``$ROFT_SIM_ASSETS``, else None.

    The one place the verbs (assets list, generate, paper, preview) read it.

    Raises:
        ConfigError: the folder given does not exist or is not a folder (naming where it came
            from), so a typo is not silently replaced by the procedural stand-ins.
    """
    if args.assets is not None:
        path, given = Path(args.assets), "--assets"
    elif os.environ.get("ROFT_SIM_ASSETS"):
        path, given = Path(os.environ["ROFT_SIM_ASSETS"]).expanduser(), "$ROFT_SIM_ASSETS"
    else:
        return None
    if not path.is_dir():
        raise ConfigError(
            f"{given} {str(path)!r} is not a folder; give a folder of YCB objects "
            "(<name>/google_16k/textured.obj) or leave it out"
        )
    return path


def cache_dir_from_args(args: argparse.Namespace) -> Path:
    """The asset cache: ``--cache``, else ``$ROFT_SIM_CACHE``, else ``~/.cache/roft_sim``."""
    return args.cache if args.cache is not None else default_cache_dir(os.environ)


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds ``assets list`` and ``assets install``."""
    parser = subparsers.add_parser(
        "assets",
        help="list the object registry and install real YCB meshes",
        description=__doc__.split("\n\n")[0] if __doc__ else None,
    )
    verbs = parser.add_subparsers(dest="assets_verb", metavar="ACTION", required=True)

    listing = verbs.add_parser("list", help="registry objects and where their real meshes are")
    listing.add_argument(
        "--assets",
        type=Path,
        help="folder of YCB objects searched first (default $ROFT_SIM_ASSETS)",
    )
    listing.add_argument(
        "--cache", type=Path, help="user cache (default $ROFT_SIM_CACHE or ~/.cache/roft_sim)"
    )
    listing.add_argument("--json", action="store_true", help="print a JSON array")
    listing.set_defaults(func=_run_list)

    install = verbs.add_parser(
        "install",
        help="copy or download YCB google_16k meshes into the cache",
        description="Installs real YCB google_16k meshes into <cache>/ycb/<name>/. SOURCE is a "
        "folder of <name>/google_16k/textured.obj (or <name>/textured.obj), an archive file "
        "(.tgz/.tar.gz/.tar/.zip), an http(s) URL of an archive, a base URL or a template with "
        "{name} for per-object archives (<base>/<name>_google_16k.tgz), or 'ycb' for the "
        f"official archives at {OFFICIAL_YCB_BASE_URL}. The YCB models are licensed CC BY 4.0.",
    )
    install.add_argument(
        "--from", dest="source", required=True, metavar="SOURCE", help="DIR, ARCHIVE, URL or ycb"
    )
    install.add_argument(
        "--objects", nargs="+", metavar="NAME", help="registry names (default: all available)"
    )
    install.add_argument("--sha256", metavar="HEX", help="expected SHA-256 of the one archive")
    install.add_argument(
        "--cache", type=Path, help="user cache (default $ROFT_SIM_CACHE or ~/.cache/roft_sim)"
    )
    install.add_argument("--no-progress", action="store_true", help="no download progress bar")
    install.set_defaults(func=_run_install)


def _run_list(args: argparse.Namespace) -> int:
    assets_dir, cache_dir = assets_dir_from_args(args), cache_dir_from_args(args)
    rows: list[dict[str, Any]] = []
    for info in list_objects():
        path = find_ycb_mesh(info.name, assets_dir=assets_dir, cache_dir=cache_dir)
        rows.append(
            {
                "name": info.name,
                "description": info.description,
                "shape": info.shape,
                "dimensions_m": list(info.dimensions_m),
                "real_mesh": None if path is None else str(path),
            }
        )
    if args.json:
        json.dump(rows, sys.stdout, indent=2)
        print()
        return 0
    width = max(len(r["name"]) for r in rows)
    print(f"{'name':<{width}}  {'shape':<8}  {'size x*y*z [mm]':<23}  real mesh")
    for r in rows:
        size = " x ".join(f"{1000 * d:5.1f}" for d in r["dimensions_m"])
        where = r["real_mesh"] or "not installed (procedural stand-in)"
        print(f"{r['name']:<{width}}  {r['shape']:<8}  {size:<23}  {where}")
    looked = [f"--assets {assets_dir}"] if assets_dir is not None else []
    print(f"\nsearched: {', '.join([*looked, f'cache {cache_dir}'])}")
    return 0


def _run_install(args: argparse.Namespace) -> int:
    cache_dir = cache_dir_from_args(args)
    paths = install_assets(
        args.source,
        cache_dir,
        objects=args.objects,
        sha256=args.sha256,
        progress=not args.no_progress,
    )
    for path in paths:
        print(f"installed {path.name} -> {path}")
    print(
        f"{len(paths)} object(s) installed in {cache_dir / 'ycb'}. YCB models: CC BY 4.0, "
        "YCB Object and Model Set (ycbbenchmarks.com), B. Calli et al."
    )
    return 0
