"""Installing real YCB meshes into the user cache: from a folder, an archive file or a URL.

The cache layout is ``<cache_dir>/ycb/<name>/`` holding ``textured.obj``, the material files it
names and their texture images (only those; the archives' other files are not kept), plus
``install.json`` saying where they came from.

Archives (``.tgz``, ``.tar.gz``, ``.tar``, ``.zip``) are verified before anything is written to
the cache: the SHA-256 when one is given; always, that the archive reads to the end and holds
``textured.obj`` with its material and texture for every object asked for. Extraction refuses the
whole archive if any member has an absolute path, a ``..`` component, a link (symbolic or hard),
or is a device, FIFO or other special file, or if the archive would unpack to more than
:data:`MAX_UNPACKED_BYTES`. Objects are installed atomically (a staging folder renamed into
place).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
import shutil
import stat
import tempfile
import zipfile
import zlib
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING

from roft_sim.assets.meshes import mtl_texture_path
from roft_sim.assets.objects import install_hint
from roft_sim.assets.registry import get_object_info, object_registry
from roft_sim.errors import AssetNotFoundError, ConfigError, DatasetFormatError, located

if TYPE_CHECKING:  # tarfile and the network modules are imported where they are used: every
    import tarfile  # importer of roft_sim.assets (generation, the CLI) would pay for them

__all__ = [
    "OFFICIAL_YCB_BASE_URL",
    "MAX_DOWNLOAD_BYTES",
    "MAX_UNPACKED_BYTES",
    "default_cache_dir",
    "install_assets",
    "official_archive_url",
    "safe_extract",
]

_log = logging.getLogger(__name__)

OFFICIAL_YCB_BASE_URL = "http://ycb-benchmarks.s3-website-us-east-1.amazonaws.com/data/google/"
"""Where the YCB project serves its per-object archives, ``<name>_google_16k.tgz`` (the URL used
by the YCB project's own download script, ``ycb_downloader.py``)."""

MAX_DOWNLOAD_BYTES = 2 * 1024**3
"""Downloads larger than this are refused (a google_16k archive is about 10-40 MB)."""

MAX_UNPACKED_BYTES = 4 * 1024**3
"""Archives that would unpack to more than this are refused (decompression bombs)."""

_MAX_MEMBERS = 20000
_ARCHIVE_SUFFIXES = (".tgz", ".tar.gz", ".tar.bz2", ".tar.xz", ".tar", ".zip")
_CHUNK = 1 << 20


def default_cache_dir(environ: Mapping[str, str]) -> Path:
    """The user cache: ``$ROFT_SIM_CACHE``, else ``$XDG_CACHE_HOME/roft_sim``, else
    ``~/.cache/roft_sim``. Called by the CLI (the library never reads the environment)."""
    if environ.get("ROFT_SIM_CACHE"):
        return Path(environ["ROFT_SIM_CACHE"]).expanduser()
    if environ.get("XDG_CACHE_HOME"):
        return Path(environ["XDG_CACHE_HOME"]).expanduser() / "roft_sim"
    home = environ.get("HOME")
    return (Path(home) if home else Path.home()) / ".cache" / "roft_sim"


def official_archive_url(name: str, base_url: str = OFFICIAL_YCB_BASE_URL) -> str:
    """URL of an object's google_16k archive, e.g. ``.../003_cracker_box_google_16k.tgz``."""
    return f"{base_url.rstrip('/')}/{name}_google_16k.tgz"


def _is_archive_name(name: str) -> bool:
    return name.lower().endswith(_ARCHIVE_SUFFIXES)


# ------------------------------------------------------------------------- safe extraction


def _check_member_name(archive: Path, name: str) -> None:
    path = PurePosixPath(name)
    bad = (
        name.startswith(("/", "\\"))
        or re.match(r"^[A-Za-z]:", name) is not None
        or "\\" in name
        or ".." in path.parts
        or "\x00" in name
    )
    if bad:
        raise DatasetFormatError(
            f"archive {located(archive)} holds the unsafe path {name!r} (absolute, '..', or a "
            "drive letter); refusing to extract anything from it. Get the archive from a "
            "trusted source"
        )


def _tar_members(archive: Path, tar: tarfile.TarFile) -> list[tarfile.TarInfo]:
    members: list[tarfile.TarInfo] = []
    total = 0
    for member in tar:  # reading every header also detects truncation early
        _check_member_name(archive, member.name)
        if member.issym() or member.islnk():
            raise DatasetFormatError(
                f"archive {located(archive)} holds a link {member.name!r} -> "
                f"{member.linkname!r}; links are refused (they can point outside the "
                "destination)"
            )
        if not (member.isfile() or member.isdir()):
            raise DatasetFormatError(
                f"archive {located(archive)} holds {member.name!r}, which is a device, FIFO or "
                "other special file; only regular files and folders are accepted"
            )
        total += member.size
        _check_unpacked_size(archive, len(members), total)
        members.append(member)
    return members


def _check_unpacked_size(archive: Path, members_before: int, total_bytes: int) -> None:
    """Refuses an archive once it lists ``_MAX_MEMBERS`` members or unpacks beyond
    ``MAX_UNPACKED_BYTES`` (a zip bomb), counting the member being added."""
    if members_before >= _MAX_MEMBERS or total_bytes > MAX_UNPACKED_BYTES:
        raise DatasetFormatError(
            f"archive {located(archive)} would unpack to more than {_MAX_MEMBERS} files or "
            f"{MAX_UNPACKED_BYTES} bytes; refusing it"
        )


def _zip_members(archive: Path, zf: zipfile.ZipFile) -> list[zipfile.ZipInfo]:
    members: list[zipfile.ZipInfo] = []
    total = 0
    for info in zf.infolist():
        _check_member_name(archive, info.filename)
        mode = info.external_attr >> 16
        if stat.S_ISLNK(mode) or (mode and not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))):
            raise DatasetFormatError(
                f"archive {located(archive)} holds {info.filename!r}, which is a link or a "
                "special file; only regular files and folders are accepted"
            )
        total += info.file_size
        _check_unpacked_size(archive, len(members), total)
        members.append(info)
    return members


def safe_extract(archive: Path, destination: Path) -> None:
    """Extracts a tar (any compression) or zip archive into ``destination``, refusing unsafe
    archives as a whole (see the module docstring) before writing anything.

    Raises:
        DatasetFormatError: unsafe member, unknown format, or a corrupt or truncated archive.
    """
    import tarfile

    destination.mkdir(parents=True, exist_ok=True)
    corrupt = (tarfile.TarError, zipfile.BadZipFile, EOFError, zlib.error, OSError)
    try:
        if zipfile.is_zipfile(archive):
            with zipfile.ZipFile(archive) as zf:
                members = _zip_members(archive, zf)
                bad = zf.testzip()  # CRC of every member
                if bad is not None:
                    raise zipfile.BadZipFile(f"CRC mismatch in {bad!r}")
                for info in members:
                    zf.extract(info, destination)
        elif tarfile.is_tarfile(archive):
            with tarfile.open(archive, "r:*") as tar:
                tar_members = _tar_members(archive, tar)
                if hasattr(tarfile, "data_filter"):  # Python >= 3.11.4: a second safety net
                    tar.extractall(destination, members=tar_members, filter="data")
                else:  # pragma: no cover - members were vetted above
                    tar.extractall(destination, members=tar_members)
        else:
            raise DatasetFormatError(
                f"{located(archive)} is not a tar or zip archive (truncated, corrupt or another "
                "format); expected e.g. <name>_google_16k.tgz"
            )
    except DatasetFormatError:
        raise
    except corrupt as e:
        raise DatasetFormatError(
            f"archive {located(archive)} cannot be read to the end ({type(e).__name__}: {e}); "
            "it is truncated or corrupt: download it again"
        ) from e


# ------------------------------------------------------------------------------- downloads


def _sha256_file(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for chunk in iter(lambda: f.read(_CHUNK), b""):
            digest.update(chunk)
    return digest.hexdigest()


def _download(url: str, target: Path, *, progress: bool, timeout_s: float = 60.0) -> str:
    """Streams ``url`` into ``target``; returns the SHA-256 of the bytes received."""
    import http.client
    import urllib.error
    import urllib.request

    digest = hashlib.sha256()
    request = urllib.request.Request(url, headers={"User-Agent": "roft-sim"})
    try:
        response = urllib.request.urlopen(request, timeout=timeout_s)  # noqa: S310 - http(s) only
    except urllib.error.HTTPError as e:
        raise AssetNotFoundError(
            f"download of {url} failed: HTTP {e.code} {e.reason}; check the URL and the object name"
        ) from None
    except (urllib.error.URLError, TimeoutError, OSError) as e:
        reason = getattr(e, "reason", e)
        raise AssetNotFoundError(
            f"cannot download {url}: {reason}. Without network access, download the archive "
            "elsewhere and run `roft-sim assets install --from FILE_OR_FOLDER`"
        ) from None
    with response:
        length = response.headers.get("Content-Length")
        total = int(length) if length and length.isdigit() else None
        if total is not None and total > MAX_DOWNLOAD_BYTES:
            raise DatasetFormatError(
                f"{url} is {total} bytes, more than the {MAX_DOWNLOAD_BYTES} accepted; is it the "
                "right archive?"
            )
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=total, unit="B", unit_scale=True, desc=url.rsplit("/", 1)[-1])
        received = 0
        try:
            with target.open("wb") as out:
                while chunk := response.read(_CHUNK):
                    received += len(chunk)
                    if received > MAX_DOWNLOAD_BYTES:
                        raise DatasetFormatError(
                            f"{url} sent more than {MAX_DOWNLOAD_BYTES} bytes; download stopped"
                        )
                    digest.update(chunk)
                    out.write(chunk)
                    if bar is not None:
                        bar.update(len(chunk))
        except (TimeoutError, OSError, http.client.HTTPException) as e:
            raise AssetNotFoundError(
                f"download of {url} broke off ({type(e).__name__}: {e}); try again"
            ) from None
        finally:
            if bar is not None:
                bar.close()
    if total is not None and received != total:
        raise DatasetFormatError(
            f"download of {url} is truncated: received {received} of {total} bytes; try again"
        )
    return digest.hexdigest()


# ------------------------------------------------------------------------------ installing


def _object_dir_in(root: Path, name: str) -> Path | None:
    """The folder holding ``textured.obj`` of ``name`` inside an unpacked source, if any."""
    patterns = (
        f"{name}/textured.obj",
        f"{name}/google_16k/textured.obj",
        f"*/{name}/textured.obj",
        f"*/{name}/google_16k/textured.obj",
    )
    for pattern in patterns:
        hits = sorted(root.glob(pattern))
        if hits:
            return hits[0].parent
    return None


def _files_to_copy(folder: Path, name: str, where: str) -> list[Path]:
    """textured.obj, its .mtl files and texture, all inside ``folder``; errors say what lacks."""
    obj = folder / "textured.obj"
    needed = [obj]
    with obj.open("r", encoding="utf-8", errors="replace") as f:
        mtls = [folder / line[6:].strip() for line in f if line.startswith("mtllib")]
    if not mtls:
        raise DatasetFormatError(
            f"{where}: {name}/textured.obj names no material library (mtllib); expected the "
            "textured google_16k mesh"
        )
    texture = mtl_texture_path(obj)
    for path in [*mtls, texture]:
        if path is None:
            raise DatasetFormatError(
                f"{where}: the material of {name} names no texture (map_Kd); expected "
                "texture_map.png beside textured.obj"
            )
        resolved = path.resolve()
        if not resolved.is_relative_to(folder.resolve()):
            raise DatasetFormatError(
                f"{where}: {name} refers to {str(path)!r}, outside its folder; refusing it"
            )
        if not path.is_file():
            raise DatasetFormatError(
                f"{where}: {name} lacks {path.relative_to(folder)} (named by its .obj/.mtl); the "
                "archive or folder is incomplete"
            )
        needed.append(path)
    return needed


def _install_object(
    folder: Path, name: str, cache_dir: Path, *, where: str, record: dict[str, object]
) -> Path:
    files = _files_to_copy(folder, name, where)
    root = cache_dir / "ycb"
    root.mkdir(parents=True, exist_ok=True)
    final = root / name
    staging = Path(tempfile.mkdtemp(prefix=f".staging-{name}-", dir=root))
    try:
        for path in files:
            target = staging / path.relative_to(folder)
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, target)
        (staging / "install.json").write_text(
            json.dumps(
                {
                    **record,
                    "object": name,
                    "files": sorted(str(p.relative_to(folder)) for p in files),
                    "installed_at": datetime.now(UTC).isoformat(timespec="seconds"),
                    "licence": "YCB Object and Model Set (ycbbenchmarks.com), CC BY 4.0",
                },
                indent=2,
            )
            + "\n"
        )
        if final.exists():
            old = Path(tempfile.mkdtemp(prefix=f".old-{name}-", dir=root))
            os.replace(final, old / name)
            os.replace(staging, final)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(staging, final)
    finally:
        if staging.exists():
            shutil.rmtree(staging, ignore_errors=True)
    _log.info("installed %s into %s", name, final)
    return final


def _install_from_tree(
    root: Path,
    cache_dir: Path,
    objects: Sequence[str] | None,
    *,
    where: str,
    record: dict[str, object],
    required: bool,
) -> list[Path]:
    registry = object_registry()
    names = list(objects) if objects is not None else list(registry)
    found = {name: _object_dir_in(root, name) for name in names}
    missing = [name for name, folder in found.items() if folder is None]
    if missing and (required or len(missing) == len(names)):
        raise AssetNotFoundError(
            f"{where} holds no textured.obj for {', '.join(missing)} (looked for <name>/"
            "textured.obj and <name>/google_16k/textured.obj); expected a folder of YCB "
            "google_16k objects"
        )
    # validate everything before installing anything
    for name, folder in found.items():
        if folder is not None:
            _files_to_copy(folder, name, where)
    return [
        _install_object(folder, name, cache_dir, where=where, record=record)
        for name, folder in found.items()
        if folder is not None
    ]


def _install_archive(
    archive: Path,
    cache_dir: Path,
    objects: Sequence[str] | None,
    *,
    sha256: str | None,
    actual_sha256: str | None,
    record: dict[str, object],
) -> list[Path]:
    actual = actual_sha256 or _sha256_file(archive)
    if sha256 is not None and actual != sha256.lower():
        raise DatasetFormatError(
            f"SHA-256 of {record.get('source', archive)} is {actual}, expected {sha256.lower()}; "
            "the file is corrupt or not the one you meant. Nothing was installed"
        )
    work = cache_dir / "downloads"
    work.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=".unpack-", dir=work) as unpack:
        safe_extract(archive, Path(unpack))
        return _install_from_tree(
            Path(unpack),
            cache_dir,
            objects,
            where=f"archive {record.get('source', archive)}",
            record={**record, "archive_sha256": actual},
            required=objects is not None,
        )


def _install_from_local(
    source: str, cache_dir: Path, objects: list[str] | None, sha256: str | None
) -> list[Path]:
    """:func:`install_assets` from a local folder or archive file."""
    path = Path(source).expanduser()
    if re.match(r"^[a-z][a-z0-9+.-]*://", source, flags=re.IGNORECASE):
        raise ConfigError(
            f"unsupported URL scheme in {source!r}; use http(s)://, a local folder or a "
            "local archive file"
        )
    if path.is_dir():
        if sha256 is not None:
            raise ConfigError("--sha256 checks an archive; it cannot be used with a folder")
        return _install_from_tree(
            path,
            cache_dir,
            objects,
            where=f"folder {located(path)}",
            record={"source": str(path.resolve())},
            required=objects is not None,
        )
    if path.is_file():
        return _install_archive(
            path,
            cache_dir,
            objects,
            sha256=sha256,
            actual_sha256=None,
            record={"source": str(path.resolve())},
        )
    raise AssetNotFoundError(
        f"{located(path)} does not exist; give a folder of YCB objects, an archive file, an "
        f"http(s) URL, or 'ycb' for the official download. {install_hint(['<name>'])}"
    )


def _install_from_urls(
    source: str,
    cache_dir: Path,
    objects: list[str] | None,
    sha256: str | None,
    progress: bool,
) -> list[Path]:
    """:func:`install_assets` from an archive URL, a base URL or a ``{name}`` URL template:
    every archive downloaded into ``<cache_dir>/downloads``, checked, installed, deleted."""
    downloads = cache_dir / "downloads"
    downloads.mkdir(parents=True, exist_ok=True)
    names = objects if objects is not None else list(object_registry())
    jobs: list[tuple[str, list[str] | None]]
    if "{name}" in source:
        jobs = [(source.replace("{name}", n), [n]) for n in names]
    elif _is_archive_name(source.split("?", 1)[0]):
        jobs = [(source, objects)]
    else:
        jobs = [(official_archive_url(n, source), [n]) for n in names]
    if sha256 is not None and len(jobs) != 1:
        raise ConfigError(
            f"--sha256 checks one archive, but this source needs {len(jobs)} downloads; "
            "install one object at a time (--objects NAME) to check each"
        )
    installed: list[Path] = []
    for url, names_in in jobs:
        fd, tmp = tempfile.mkstemp(prefix=".download-", suffix=".archive", dir=downloads)
        os.close(fd)
        try:
            actual = _download(url, Path(tmp), progress=progress)
            installed += _install_archive(
                Path(tmp),
                cache_dir,
                names_in,
                sha256=sha256,
                actual_sha256=actual,
                record={"source": url},
            )
        finally:
            Path(tmp).unlink(missing_ok=True)
    return installed


def install_assets(
    source: str,
    cache_dir: Path,
    *,
    objects: Sequence[str] | None = None,
    sha256: str | None = None,
    progress: bool = True,
) -> list[Path]:
    """Installs real YCB google_16k meshes into ``<cache_dir>/ycb/<name>/``.

    Args:
        source: one of
            - a folder holding ``<name>/textured.obj`` or ``<name>/google_16k/textured.obj``
              (with ``textured.mtl`` and the texture image) for some registry objects;
            - an archive file (``.tgz``, ``.tar.gz``, ``.tar``, ``.zip``) of such folders;
            - an ``http(s)://`` URL of such an archive;
            - an ``http(s)://`` base URL (not ending in an archive suffix) or a template with
              ``{name}``: one archive per object, ``<base>/<name>_google_16k.tgz``;
            - ``ycb``: the official YCB archives (:data:`OFFICIAL_YCB_BASE_URL`).
        cache_dir: the user cache (``roft_sim.assets.default_cache_dir`` in the CLI).
        objects: registry names to install; None = every registry object the source holds
            (for per-object URLs: the whole registry).
        sha256: expected SHA-256 (hex) of the ONE archive fetched (an archive file or URL, or a
            per-object URL with exactly one object).
        progress: show a download progress bar (tqdm, on stderr).

    Returns:
        The installed object folders, in order.

    Raises:
        UnknownObjectError: an entry of ``objects`` is not in the registry.
        ConfigError: bad ``sha256`` or a source of an unknown kind.
        AssetNotFoundError: missing source, unreachable URL, HTTP error, or objects that the
            source lacks.
        DatasetFormatError: SHA-256 mismatch, corrupt, truncated or unsafe archive, or an
            incomplete object folder. Nothing is installed from a source that fails these
            checks.
    """
    cache_dir = Path(cache_dir)
    if objects is not None:
        objects = list(dict.fromkeys(objects))
        for name in objects:
            get_object_info(name)  # raises UnknownObjectError with suggestions
    if sha256 is not None and not re.fullmatch(r"[0-9a-fA-F]{64}", sha256):
        raise ConfigError(f"--sha256 must be 64 hexadecimal digits, got {sha256!r}")
    source_str = str(source)
    is_url = re.match(r"^https?://", source_str, flags=re.IGNORECASE) is not None
    if source_str == "ycb":
        source_str, is_url = OFFICIAL_YCB_BASE_URL, True

    if not is_url:
        return _install_from_local(source_str, cache_dir, objects, sha256)
    return _install_from_urls(source_str, cache_dir, objects, sha256, progress)
