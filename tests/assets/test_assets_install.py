"""install_assets: from a folder, an archive file and URLs (a local HTTP server), with the
refusals that keep the cache safe: path traversal, links, special files, corrupt or truncated
archives, SHA-256 mismatches."""

from __future__ import annotations

import functools
import hashlib
import http.server
import io
import json
import shutil
import tarfile
import threading
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest

from roft_sim.assets import (
    AssetNotFoundError,
    DatasetFormatError,
    UnknownObjectError,
    default_cache_dir,
    install_assets,
    load_object,
    official_archive_url,
)
from roft_sim.assets.install import safe_extract
from roft_sim.errors import ConfigError

OBJ_A, OBJ_B = "005_tomato_soup_can", "009_gelatin_box"


def _write_object(folder: Path, *, texture: bool = True, marker: int = 0) -> None:
    """A tiny textured google_16k-like object (a tetrahedron) plus files that are not needed."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "textured.obj").write_text(
        "mtllib textured.mtl\n"
        "v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nv 0 0 0.05\n"
        "vt 0 0\nvt 1 0\nvt 0 1\nvt 1 1\n"
        "usemtl material_0\n"
        "f 1/1 3/3 2/2\nf 1/1 2/2 4/4\nf 1/1 4/4 3/3\nf 2/2 3/3 4/4\n"
    )
    (folder / "textured.mtl").write_text("newmtl material_0\nmap_Kd texture_map.png \n")
    if texture:
        cv2.imwrite(str(folder / "texture_map.png"), np.full((8, 8, 3), marker, dtype=np.uint8))
    (folder / "nontextured.ply").write_text("not needed\n")
    (folder / "kinbody.xml").write_text("<not needed/>\n")


def _tar_bytes(add) -> bytes:
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz") as tar:
        add(tar)
    return buffer.getvalue()


def _tar_of_tree(root: Path) -> bytes:
    return _tar_bytes(lambda tar: [tar.add(p, arcname=p.name) for p in sorted(root.iterdir())])


def _add_bytes(tar: tarfile.TarFile, name: str, data: bytes = b"x", **fields) -> None:
    info = tarfile.TarInfo(name)
    info.size = len(data)
    for key, value in fields.items():
        setattr(info, key, value)
    tar.addfile(info, io.BytesIO(data) if info.isfile() else None)


@pytest.fixture
def source_tree(tmp_path) -> Path:
    root = tmp_path / "source"
    _write_object(root / OBJ_A / "google_16k", marker=11)
    _write_object(root / OBJ_B, marker=22)
    return root


class _Handler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args) -> None:  # keep test output clean
        pass

    def do_GET(self) -> None:
        if self.path.endswith("/lying.tgz"):  # promises more bytes than it sends
            self.send_response(200)
            self.send_header("Content-Length", "100000")
            self.end_headers()
            self.wfile.write(b"\x1f\x8b" + b"\0" * 100)
            return
        super().do_GET()


@pytest.fixture
def http_root(tmp_path):
    """(folder, base URL): a local HTTP server on 127.0.0.1 serving the folder."""
    folder = tmp_path / "www"
    folder.mkdir()
    server = http.server.ThreadingHTTPServer(
        ("127.0.0.1", 0), functools.partial(_Handler, directory=str(folder))
    )
    thread = threading.Thread(target=server.serve_forever, args=(0.05,), daemon=True)
    thread.start()
    try:
        yield folder, f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=5)


def _installed(cache: Path) -> list[str]:
    root = cache / "ycb"
    return (
        sorted(p.name for p in root.iterdir() if not p.name.startswith("."))
        if root.exists()
        else []
    )


# ---------------------------------------------------------------------------------- folders


def test_install_from_a_folder_copies_only_what_is_needed(source_tree, tmp_path):
    cache = tmp_path / "cache"
    paths = install_assets(str(source_tree), cache, progress=False)
    assert paths == [cache / "ycb" / OBJ_A, cache / "ycb" / OBJ_B]
    assert _installed(cache) == [OBJ_A, OBJ_B]
    for path in paths:
        files = sorted(p.name for p in path.iterdir())
        assert files == ["install.json", "texture_map.png", "textured.mtl", "textured.obj"]
    record = json.loads((paths[0] / "install.json").read_text())
    assert record["source"] == str(source_tree.resolve()) and record["object"] == OBJ_A
    assert "CC BY 4.0" in record["licence"]
    # the installed texture is the one from the source
    assert cv2.imread(str(paths[1] / "texture_map.png"))[0, 0, 0] == 22


def test_reinstalling_replaces_the_object(source_tree, tmp_path):
    cache = tmp_path / "cache"
    install_assets(str(source_tree), cache, objects=[OBJ_B], progress=False)
    _write_object(source_tree / OBJ_B, marker=99)
    install_assets(str(source_tree), cache, objects=[OBJ_B], progress=False)
    assert cv2.imread(str(cache / "ycb" / OBJ_B / "texture_map.png"))[0, 0, 0] == 99
    assert _installed(cache) == [OBJ_B]
    assert not [p for p in (cache / "ycb").iterdir() if p.name.startswith(".")]


def test_folder_errors_say_what_is_missing(source_tree, tmp_path):
    cache = tmp_path / "cache"
    with pytest.raises(AssetNotFoundError, match=r"holds no textured.obj for 003_cracker_box"):
        install_assets(str(source_tree), cache, objects=["003_cracker_box", OBJ_A])
    (source_tree / OBJ_B / "texture_map.png").unlink()
    with pytest.raises(DatasetFormatError, match=r"009_gelatin_box lacks texture_map.png"):
        install_assets(str(source_tree), cache)
    assert _installed(cache) == []  # validated before anything was installed
    with pytest.raises(UnknownObjectError, match=r"did you mean '009_gelatin_box'"):
        install_assets(str(source_tree), cache, objects=["009_gelatine_box"])
    with pytest.raises(AssetNotFoundError, match=r"'/nonexistent/ycb' does not exist"):
        install_assets("/nonexistent/ycb", cache)
    with pytest.raises(ConfigError, match=r"cannot be used with a folder"):
        install_assets(str(source_tree), cache, sha256="0" * 64)
    with pytest.raises(ConfigError, match=r"64 hexadecimal digits"):
        install_assets(str(source_tree), cache, sha256="abc")
    with pytest.raises(ConfigError, match=r"unsupported URL scheme"):
        install_assets("ftp://example.org/ycb.tgz", cache)


# ---------------------------------------------------------------------------------- archives


@pytest.mark.parametrize("fmt", ["tgz", "zip"])
def test_install_from_an_archive_file(source_tree, tmp_path, fmt):
    archive = tmp_path / f"ycb.{fmt}"
    if fmt == "tgz":
        archive.write_bytes(_tar_of_tree(source_tree))
    else:
        with zipfile.ZipFile(archive, "w") as zf:
            for p in sorted(source_tree.rglob("*")):
                zf.write(p, p.relative_to(source_tree).as_posix())
    digest = hashlib.sha256(archive.read_bytes()).hexdigest()
    cache = tmp_path / "cache"
    install_assets(str(archive), cache, sha256=digest.upper(), progress=False)
    assert _installed(cache) == [OBJ_A, OBJ_B]
    record = json.loads((cache / "ycb" / OBJ_A / "install.json").read_text())
    assert record["archive_sha256"] == digest
    assert not list((cache / "downloads").iterdir())  # unpacked files are cleaned up


def _unsafe_archives() -> dict[str, bytes]:
    def tar(*members):
        return _tar_bytes(lambda t: [_add_bytes(t, *m[:2], **m[2]) for m in members])

    ok = ("005_tomato_soup_can/textured.obj", b"v 0 0 0\n", {})
    zip_buffer = io.BytesIO()
    with zipfile.ZipFile(zip_buffer, "w") as zf:
        zf.writestr("../../evil.txt", b"owned")
    return {
        "dotdot": tar(ok, ("005_tomato_soup_can/../../evil.txt", b"owned", {})),
        "absolute": tar(("/tmp/roft_sim_evil.txt", b"owned", {})),
        "symlink": tar(ok, ("link", b"", {"type": tarfile.SYMTYPE, "linkname": "/etc/passwd"})),
        "hardlink": tar(ok, ("hard", b"", {"type": tarfile.LNKTYPE, "linkname": "../x"})),
        "device": tar(ok, ("dev", b"", {"type": tarfile.CHRTYPE, "devmajor": 1, "devminor": 3})),
        "fifo": tar(ok, ("pipe", b"", {"type": tarfile.FIFOTYPE})),
        "zip-dotdot": zip_buffer.getvalue(),
    }


@pytest.mark.parametrize("kind", list(_unsafe_archives()))
def test_unsafe_archives_are_refused_whole(tmp_path, kind):
    archive = tmp_path / "bad.tgz"
    archive.write_bytes(_unsafe_archives()[kind])
    out = tmp_path / "deep" / "out"
    match = {
        "dotdot": r"unsafe path '005_tomato_soup_can/../../evil.txt'",
        "absolute": r"unsafe path '/tmp/roft_sim_evil.txt'",
        "symlink": r"holds a link 'link' -> '/etc/passwd'",
        "hardlink": r"holds a link 'hard'",
        "device": r"'dev', which is a device, FIFO or other special file",
        "fifo": r"'pipe', which is a device, FIFO or other special file",
        "zip-dotdot": r"unsafe path '../../evil.txt'",
    }[kind]
    with pytest.raises(DatasetFormatError, match=match):
        safe_extract(archive, out)
    assert not list(out.rglob("*"))  # nothing was extracted, not even the good member
    assert not (tmp_path / "evil.txt").exists() and not (tmp_path / "deep" / "evil.txt").exists()
    cache = tmp_path / "cache"
    with pytest.raises(DatasetFormatError):
        install_assets(str(archive), cache, progress=False)
    assert _installed(cache) == []


def test_corrupt_and_truncated_archives_are_refused(source_tree, tmp_path):
    good = _tar_of_tree(source_tree)
    cache = tmp_path / "cache"
    truncated = tmp_path / "truncated.tgz"
    truncated.write_bytes(good[: len(good) // 2])
    with pytest.raises(DatasetFormatError, match=r"truncated or corrupt"):
        install_assets(str(truncated), cache, progress=False)
    garbage = tmp_path / "garbage.tgz"
    garbage.write_bytes(np.random.default_rng(0).bytes(5000))
    with pytest.raises(DatasetFormatError, match=r"is not a tar or zip archive"):
        install_assets(str(garbage), cache, progress=False)
    assert _installed(cache) == []


def test_sha256_mismatch_installs_nothing(source_tree, tmp_path):
    archive = tmp_path / "ycb.tgz"
    archive.write_bytes(_tar_of_tree(source_tree))
    cache = tmp_path / "cache"
    with pytest.raises(
        DatasetFormatError, match=r"SHA-256 of .*ycb.tgz is [0-9a-f]{64}, expected 0{64}"
    ):
        install_assets(str(archive), cache, sha256="0" * 64, progress=False)
    assert _installed(cache) == []


# -------------------------------------------------------------------------------------- URLs


def test_install_from_an_archive_url(source_tree, tmp_path, http_root):
    folder, base = http_root
    data = _tar_of_tree(source_tree)
    (folder / "ycb.tgz").write_bytes(data)
    cache = tmp_path / "cache"
    digest = hashlib.sha256(data).hexdigest()
    paths = install_assets(f"{base}/ycb.tgz", cache, objects=[OBJ_B], sha256=digest, progress=True)
    assert paths == [cache / "ycb" / OBJ_B] and _installed(cache) == [OBJ_B]
    record = json.loads((paths[0] / "install.json").read_text())
    assert record["source"] == f"{base}/ycb.tgz" and record["archive_sha256"] == digest
    with pytest.raises(DatasetFormatError, match=r"SHA-256 of http://127.0.0.1:\d+/ycb.tgz is"):
        install_assets(f"{base}/ycb.tgz", tmp_path / "c2", sha256="f" * 64, progress=False)
    assert _installed(tmp_path / "c2") == []


def test_install_per_object_archives_like_the_official_layout(tmp_path, http_root):
    folder, base = http_root
    for name in (OBJ_A, OBJ_B):  # <name>_google_16k.tgz holding <name>/google_16k/...
        tree = tmp_path / f"tree-{name}"
        _write_object(tree / name / "google_16k")
        (folder / f"{name}_google_16k.tgz").write_bytes(_tar_of_tree(tree))
    assert official_archive_url(OBJ_A).endswith(f"/data/google/{OBJ_A}_google_16k.tgz")
    cache = tmp_path / "cache"
    install_assets(base + "/", cache, objects=[OBJ_A, OBJ_B], progress=False)
    assert _installed(cache) == [OBJ_A, OBJ_B]
    cache2 = tmp_path / "cache2"
    install_assets(base + "/{name}_google_16k.tgz", cache2, objects=[OBJ_B], progress=False)
    assert _installed(cache2) == [OBJ_B]
    with pytest.raises(ConfigError, match=r"--sha256 checks one archive, but this source needs 2"):
        install_assets(base, cache, objects=[OBJ_A, OBJ_B], sha256="0" * 64)


def test_url_failures_are_clear(tmp_path, http_root, source_tree):
    folder, base = http_root
    cache = tmp_path / "cache"
    with pytest.raises(AssetNotFoundError, match=r"HTTP 404"):
        install_assets(f"{base}/missing.tgz", cache, progress=False)
    with pytest.raises(DatasetFormatError, match=r"lying.tgz is truncated: received 102 of 100000"):
        install_assets(f"{base}/lying.tgz", cache, progress=False)
    good = _tar_of_tree(source_tree)
    (folder / "half.tgz").write_bytes(good[: len(good) // 3])
    with pytest.raises(DatasetFormatError, match=r"truncated or corrupt"):
        install_assets(f"{base}/half.tgz", cache, progress=False)
    (folder / "evil.tgz").write_bytes(_unsafe_archives()["dotdot"])
    with pytest.raises(DatasetFormatError, match=r"unsafe path"):
        install_assets(f"{base}/evil.tgz", cache, progress=False)
    with pytest.raises(AssetNotFoundError, match=r"cannot download http://127.0.0.1:9/"):
        install_assets("http://127.0.0.1:9/ycb.tgz", cache, progress=False)
    assert _installed(cache) == []
    assert not [p for p in (cache / "downloads").iterdir()]


def test_install_then_load_a_real_mesh_end_to_end(shared_ycb_dir, tmp_path, http_root):
    folder, base = http_root
    name = "005_tomato_soup_can"
    tree = tmp_path / "tree"
    (tree / name / "google_16k").mkdir(parents=True)
    for f in ("textured.obj", "textured.mtl", "texture_map.jpg"):
        shutil.copy(shared_ycb_dir / name / f, tree / name / "google_16k" / f)
    with tarfile.open(folder / f"{name}_google_16k.tgz", "w:gz", compresslevel=1) as tar:
        tar.add(tree / name, arcname=name)
    cache = tmp_path / "cache"
    install_assets(base, cache, objects=[name], progress=False)
    assets = load_object(name, cache_dir=cache, prefer="ycb", max_texture_px=64)
    assert assets.source == "ycb" and assets.source_path == cache / "ycb" / name / "textured.obj"
    lo, hi = assets.mesh.bounds_m
    np.testing.assert_allclose(0.5 * (lo + hi), 0.0, atol=1e-4)


def test_default_cache_dir_precedence():
    assert default_cache_dir({"ROFT_SIM_CACHE": "/c", "HOME": "/h"}) == Path("/c")
    assert default_cache_dir({"XDG_CACHE_HOME": "/x", "HOME": "/h"}) == Path("/x/roft_sim")
    assert default_cache_dir({"HOME": "/h"}) == Path("/h/.cache/roft_sim")
