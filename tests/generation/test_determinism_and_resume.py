"""Same scenario and seed -> byte-identical files (any format, any number of workers); an
interrupted run resumed gives the same bytes as an uninterrupted one; outputs are protected."""

from __future__ import annotations

import json
import shutil

import pytest
from generation_cases import run_generate, tiny_scenario, tree_hashes

from roft_sim.cli import main
from roft_sim.datasets.fast_ycb import PARTS_DIR_NAME
from roft_sim.errors import ConfigError
from roft_sim.generation import GenerationError, ScenarioOverrides

pytestmark = pytest.mark.render


@pytest.fixture(scope="module")
def scenario():
    return tiny_scenario("mustard_hand_moving_camera", frames=5)


@pytest.fixture(scope="module")
def reference(scenario, tmp_path_factory):
    """An uninterrupted one-process fast-ycb run: path -> file hashes."""
    out = tmp_path_factory.mktemp("reference")
    run_generate([scenario], out)
    return tree_hashes(out)


@pytest.mark.parametrize("fmt", ["fast-ycb", "bop", "hdf5"])
def test_same_scenario_and_seed_give_byte_identical_files(scenario, tmp_path, fmt):
    a, b = tmp_path / "a", tmp_path / "b"
    three = ScenarioOverrides(frames=3)
    run_generate([scenario], a, format=fmt, chunk_frames=1, overrides=three)
    run_generate([scenario], b, format=fmt, chunk_frames=3, overrides=three)
    hashes = tree_hashes(a)
    assert len(hashes) >= (1 if fmt == "hdf5" else 15)
    assert hashes == tree_hashes(b)


def test_another_seed_changes_noise_and_networks_but_not_ground_truth(scenario, tmp_path):
    run_generate([scenario], tmp_path / "a", overrides=ScenarioOverrides(frames=3))
    run_generate([scenario], tmp_path / "b", overrides=ScenarioOverrides(frames=3, seed=99))
    a, b = tree_hashes(tmp_path / "a"), tree_hashes(tmp_path / "b")
    name = scenario.name
    assert a[f"{name}/gt/poses.txt"] == b[f"{name}/gt/poses.txt"]
    assert (
        a[f"{name}/masks/gt/006_mustard_bottle_1.png"]
        == b[f"{name}/masks/gt/006_mustard_bottle_1.png"]
    )
    assert a[f"{name}/depth/1.float"] != b[f"{name}/depth/1.float"]  # RealSense-like noise
    assert a[f"{name}/dope/poses.txt"] != b[f"{name}/dope/poses.txt"]
    assert a[f"{name}/rgb/1.png"] != b[f"{name}/rgb/1.png"]  # textures follow the seed


@pytest.mark.slow  # two spawned workers start in ~10 s (imports, assets)
def test_two_worker_processes_give_the_same_bytes_as_one(scenario, reference, tmp_path):
    summary = run_generate([scenario], tmp_path, workers=2, chunk_frames=2)
    assert summary.workers == 2 and summary.finished
    assert tree_hashes(tmp_path) == reference


def test_a_stopped_run_resumes_to_the_same_bytes(scenario, reference, tmp_path):
    first = run_generate([scenario], tmp_path, stop_after_frames=3, chunk_frames=2)
    assert not first.finished and first.frames_generated == 3
    seq = tmp_path / scenario.name
    assert (seq / PARTS_DIR_NAME).is_dir() and not (seq / "metadata.json").exists()
    with pytest.raises(ConfigError, match="unfinished sequence; pass resume=True"):
        run_generate([scenario], tmp_path)
    second = run_generate([scenario], tmp_path, resume=True)
    assert second.finished and second.frames_generated == 2
    assert tree_hashes(tmp_path) == reference
    third = run_generate([scenario], tmp_path, resume=True)  # finished: nothing to do
    assert third.finished and third.frames_generated == 0
    assert tree_hashes(tmp_path) == reference


def test_a_crash_in_the_middle_of_a_frame_leaves_no_trace_after_resume(
    scenario, reference, tmp_path
):
    """A process killed while writing frame 3: its rgb written, its depth half written, a temp
    file left behind, no frame record. Resume regenerates frame 3 and the bytes match."""
    run_generate([scenario], tmp_path, stop_after_frames=4)
    seq = tmp_path / scenario.name
    (seq / PARTS_DIR_NAME / "frame_000003.json").unlink()
    (seq / "depth" / "3.float").write_bytes(b"\x00" * 7)  # truncated
    (seq / "rgb" / ".4.png.12345.tmp").write_bytes(b"half a png")
    summary = run_generate([scenario], tmp_path, resume=True)
    assert summary.frames_generated == 2  # frames 3 and 4
    assert tree_hashes(tmp_path) == reference


def test_resume_with_other_settings_is_refused(scenario, tmp_path):
    run_generate([scenario], tmp_path, stop_after_frames=2)
    with pytest.raises(ConfigError, match="different settings"):
        run_generate([scenario], tmp_path, resume=True, overrides=ScenarioOverrides(seed=5))
    with pytest.raises(ConfigError, match="different settings"):
        run_generate(
            [scenario],
            tmp_path,
            resume=True,
            format="fast-ycb",
            chunk_frames=1,
            overrides=ScenarioOverrides(frames=4),
        )
    # A finished sequence made from another seed is not silently kept either.
    run_generate([scenario], tmp_path, resume=True)
    with pytest.raises(ConfigError, match="finished sequence made with different settings"):
        run_generate([scenario], tmp_path, resume=True, overrides=ScenarioOverrides(seed=5))


def test_a_failing_worker_reports_the_frames_and_keeps_the_written_ones(
    scenario, tmp_path, monkeypatch
):
    """An exception while generating frame 3 stops the run with a GenerationError naming the
    unit's frames; the frames before stay, and resume generates only the rest."""
    from roft_sim.generation import sequence_generator

    real = sequence_generator.SequenceGenerator.dataset_frame

    def failing(self, current, previous, **kwargs):
        if current.k == 3:
            raise RuntimeError("simulated failure")
        return real(self, current, previous, **kwargs)

    monkeypatch.setattr(sequence_generator.SequenceGenerator, "dataset_frame", failing)
    with pytest.raises(GenerationError, match=r"frames 0-4 of .* RuntimeError: simulated fail"):
        run_generate([scenario], tmp_path, chunk_frames=5)
    seq = tmp_path / scenario.name
    done = sorted(p.name for p in (seq / PARTS_DIR_NAME).glob("frame_*.json"))
    assert done == ["frame_000000.json", "frame_000001.json", "frame_000002.json"]
    monkeypatch.setattr(sequence_generator.SequenceGenerator, "dataset_frame", real)
    assert run_generate([scenario], tmp_path, resume=True).frames_generated == 2


def test_cli_refuses_a_non_empty_output_without_overwrite(scenario, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("precious")
    path = tmp_path / "scenario.toml"
    shutil.copy(_ci_file(), path)
    code = main(["generate", str(path), "--out", str(out), "--frames", "2", "--no-progress"])
    assert code == 2
    err = capsys.readouterr().err
    assert "is not empty" in err and "--overwrite" in err
    assert (out / "keep.txt").read_text() == "precious"


def test_cli_generates_overwrites_and_resumes(tmp_path, capsys):
    out = tmp_path / "out"
    args = ["generate", str(_ci_file()), "--out", str(out), "--frames", "3",
            "--resolution", "96x72", "--no-progress", "--json"]  # fmt: skip
    assert main(args) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["finished"] and report["frames_generated"] == 3
    hashes = tree_hashes(out)
    assert main(args) == 2  # non-empty
    capsys.readouterr()
    assert main([*args, "--resume"]) == 0
    assert json.loads(capsys.readouterr().out)["frames_generated"] == 0
    assert main([*args, "--overwrite"]) == 0
    assert json.loads(capsys.readouterr().out)["frames_generated"] == 3
    assert tree_hashes(out) == hashes


def _ci_file():
    from roft_sim.generation import shipped_scenarios_dir

    return shipped_scenarios_dir() / "ci" / "cracker_box.toml"


def test_generation_error_is_a_runtime_error_for_the_cli():
    from roft_sim.errors import RoftSimError

    assert issubclass(GenerationError, RoftSimError)
    assert not issubclass(GenerationError, ConfigError)


@pytest.mark.slow
@pytest.mark.parametrize("sig", ["SIGKILL", "SIGINT"])
def test_a_killed_cli_run_with_two_workers_resumes_to_the_same_bytes(tmp_path, sig):
    """SIGKILL (a crash) or SIGINT (Ctrl-C: exit 130) to the whole process group of
    `roft-sim generate --workers 2` mid-run, then `--resume`: the dataset equals an
    uninterrupted one-process run byte for byte."""
    import os
    import signal
    import subprocess
    import sys
    import time

    frames = 16
    common = ["--frames", str(frames), "--resolution", "96x72", "--no-progress",
              "--chunk-frames", "2"]  # fmt: skip
    reference = tmp_path / "reference"
    assert main(["generate", str(_ci_file()), "--out", str(reference), *common]) == 0
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "roft_sim", "generate", str(_ci_file()), "--out", str(out),
           "--workers", "2", *common]  # fmt: skip
    # A shell's background job (`pytest ... &`) inherits SIGINT ignored, and Python then installs
    # no KeyboardInterrupt handler: the child ignored Ctrl-C and finished (exit 0). Ctrl-C is what
    # is tested, so the child starts with the default disposition.
    proc = subprocess.Popen(
        cmd,
        start_new_session=True,
        stderr=subprocess.DEVNULL,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    parts = out / "003_cracker_box" / PARTS_DIR_NAME  # generate names a folder by its object
    deadline = time.monotonic() + 240
    try:
        while len(list(parts.glob("frame_*.json"))) < 4:
            assert proc.poll() is None, "the run ended before it could be killed"
            assert time.monotonic() < deadline, "no progress within 240 s"
            time.sleep(0.05)
    finally:
        os.killpg(proc.pid, getattr(signal, sig))
        code = proc.wait(timeout=60)
    assert code == (130 if sig == "SIGINT" else -signal.SIGKILL)
    written = len(list(parts.glob("frame_*.json")))
    assert 4 <= written < frames
    assert main(["generate", str(_ci_file()), "--out", str(out), "--resume", *common]) == 0
    assert tree_hashes(out) == tree_hashes(reference)


def test_a_worker_that_loads_another_object_source_is_refused(tmp_path):
    """Review regression: a Ray node without the real mesh silently rendered the procedural
    stand-in into a dataset whose metadata and model say the real YCB mesh."""
    from roft_sim.generation.jobs import SequenceJob
    from roft_sim.generation.runner import GenerationOptions, _WorkerState

    scenario = tiny_scenario(frames=2)
    job = SequenceJob(
        index=0, scenario=scenario, sequence_name="seq", writer=None, missing_frames=(0, 1),
        object_source="ycb",  # what the driver found; this worker has no real mesh
    )  # fmt: skip
    state = _WorkerState([job], GenerationOptions(progress=False, cache_dir=tmp_path))
    with pytest.raises(ConfigError, match=r"loads as 'procedural', but the driver found 'ycb'"):
        state.generator(0)
    same = SequenceJob(
        index=0, scenario=scenario, sequence_name="seq", writer=None, missing_frames=(0, 1),
        object_source="procedural",
    )  # fmt: skip
    state = _WorkerState([same], GenerationOptions(progress=False, cache_dir=tmp_path))
    assert state.generator(0) is state.generator(0)
    state.close()


@pytest.mark.parametrize(("writer_threads", "pipelined"), [(0, False), (3, True), (1, False)])
def test_writer_threads_and_the_network_thread_do_not_change_the_bytes(
    scenario, reference, tmp_path, writer_threads, pipelined
):
    run_generate(
        [scenario], tmp_path, writer_threads=writer_threads, pipelined=pipelined, chunk_frames=2
    )
    assert tree_hashes(tmp_path) == reference


def test_cached_scene_textures_give_the_same_bytes_cold_and_warm(scenario, reference, tmp_path):
    cache = tmp_path / "cache"
    for run in ("cold", "warm"):
        run_generate([scenario], tmp_path / run, cache_dir=cache)
        assert tree_hashes(tmp_path / run) == reference, run
    assert len(list((cache / "textures").glob("*.npy"))) == 2  # the table and the wall


def test_png_compression_changes_the_bytes_not_the_images_and_a_resume_keeps_it(
    scenario, reference, tmp_path
):
    from roft_sim.datasets import open_sequence

    run_generate([scenario], tmp_path / "level3", png_compression=3)
    level3 = tree_hashes(tmp_path / "level3")
    name = scenario.name
    assert level3[f"{name}/rgb/1.png"] != reference[f"{name}/rgb/1.png"]
    assert level3[f"{name}/depth/1.float"] == reference[f"{name}/depth/1.float"]
    small = (tmp_path / "level3" / name / "rgb" / "1.png").stat().st_size
    run_generate([scenario], tmp_path / "level1")
    fast = (tmp_path / "level1" / name / "rgb" / "1.png").stat().st_size
    assert small < fast
    a, b = open_sequence(tmp_path / "level3" / name), open_sequence(tmp_path / "level1" / name)
    assert (a.rgb(1) == b.rgb(1)).all() and (a.mask(1, "gt") == b.mask(1, "gt")).all()
    run_generate([scenario], tmp_path / "part", stop_after_frames=2, png_compression=3)
    with pytest.raises(ConfigError, match="different settings"):
        run_generate([scenario], tmp_path / "part", resume=True)
    run_generate([scenario], tmp_path / "part", resume=True, png_compression=3)
    assert tree_hashes(tmp_path / "part") == level3


def test_pipelined_frames_compute_the_networks_off_the_rendering_thread(scenario, monkeypatch):
    import threading

    from roft_sim.generation import sequence_generator

    real = sequence_generator.SequenceGenerator.dataset_frame
    threads: dict[int, int] = {}

    def recording(self, current, previous, **kwargs):
        threads[current.k] = threading.get_ident()
        return real(self, current, previous, **kwargs)

    monkeypatch.setattr(sequence_generator.SequenceGenerator, "dataset_frame", recording)
    with sequence_generator.SequenceGenerator(scenario) as generator:
        piped = [f.k for f in generator.frames(1, 4)]
        assert piped == [1, 2, 3] and threading.get_ident() not in set(threads.values())
        threads.clear()
        plain = [f.k for f in generator.frames(1, 4, pipelined=False)]
        assert plain == [1, 2, 3] and set(threads.values()) == {threading.get_ident()}
