"""``roft-sim assets list|install`` in-process: environment variables, output, exit codes."""

from __future__ import annotations

import io
import json
import tarfile

import cv2
import numpy as np
import pytest

from roft_sim.cli import main

NAME = "009_gelatin_box"


def _write_object(folder) -> None:
    folder.mkdir(parents=True)
    (folder / "textured.obj").write_text(
        "mtllib textured.mtl\nv 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
        "f 1/1 2/2 3/3\n"
    )
    (folder / "textured.mtl").write_text("newmtl m\nmap_Kd texture_map.png\n")
    cv2.imwrite(str(folder / "texture_map.png"), np.zeros((4, 4, 3), dtype=np.uint8))


@pytest.fixture
def env(tmp_path, monkeypatch):
    monkeypatch.setenv("ROFT_SIM_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("ROFT_SIM_ASSETS", raising=False)
    return tmp_path


def test_list_shows_stand_ins_then_installed_meshes(env, capsys):
    assert main(["assets", "list", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["name"] for r in rows][:2] == ["003_cracker_box", "004_sugar_box"]
    assert all(r["real_mesh"] is None for r in rows)

    _write_object(env / "src" / NAME / "google_16k")
    assert main(["assets", "install", "--from", str(env / "src"), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert f"installed {NAME} -> {env / 'cache' / 'ycb' / NAME}" in out
    assert "CC BY 4.0" in out

    assert main(["assets", "list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    gelatin = next(line for line in lines if line.startswith(NAME))
    assert str(env / "cache" / "ycb" / NAME / "textured.obj") in gelatin
    assert "89.2 x  73.1 x  30.0" in gelatin
    cracker = next(line for line in lines if line.startswith("003_cracker_box"))
    assert "not installed (procedural stand-in)" in cracker
    assert f"searched: cache {env / 'cache'}" in lines[-1]


def test_list_reads_roft_sim_assets(env, capsys, monkeypatch):
    _write_object(env / "assets" / "003_cracker_box")
    monkeypatch.setenv("ROFT_SIM_ASSETS", str(env / "assets"))
    assert main(["assets", "list", "--json"]) == 0
    rows = {r["name"]: r for r in json.loads(capsys.readouterr().out)}
    assert rows["003_cracker_box"]["real_mesh"] == str(
        env / "assets" / "003_cracker_box" / "textured.obj"
    )


def test_list_of_a_missing_assets_folder_fails_like_generate(env, capsys, monkeypatch):
    """Review regression: list printed every object as a stand-in and exited 0."""
    assert main(["assets", "list", "--assets", str(env / "nowhere")]) == 2
    assert f"--assets {str(env / 'nowhere')!r} is not a folder" in capsys.readouterr().err
    monkeypatch.setenv("ROFT_SIM_ASSETS", str(env / "gone"))
    assert main(["assets", "list"]) == 2
    assert f"$ROFT_SIM_ASSETS {str(env / 'gone')!r} is not a folder" in capsys.readouterr().err


def test_install_errors_map_to_exit_codes(env, capsys):
    assert main(["assets", "install", "--from", str(env), "--objects", "009_jello"]) == 2
    assert "did you mean '009_gelatin_box'" in capsys.readouterr().err
    assert main(["assets", "install", "--from", str(env), "--sha256", "xyz"]) == 2
    assert "64 hexadecimal digits" in capsys.readouterr().err
    archive = env / "evil.tgz"
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz") as tar:
        info = tarfile.TarInfo("../escape.txt")
        info.size = 1
        tar.addfile(info, io.BytesIO(b"x"))
    archive.write_bytes(buffer.getvalue())
    assert main(["assets", "install", "--from", str(archive), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "roft-sim assets: error: archive" in err and "unsafe path '../escape.txt'" in err
    assert not (env / "escape.txt").exists() and not (env / "cache" / "escape.txt").exists()
    assert main(["assets", "install"]) == 2  # --from is required
