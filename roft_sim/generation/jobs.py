"""Sequences of a generation run: scenario overrides, names, metadata and writers.

A :class:`SequenceJob` is everything a worker needs to generate frames of one sequence (the
resolved scenario and a picklable writer). :func:`prepare_jobs` builds them in the main process:
it applies the command-line overrides, names the sequences, loads each object once (for the
model written beside the data), and opens the writers (creating or resuming the outputs).
"""

from __future__ import annotations

import dataclasses
import logging
import re
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any, Literal

import numpy as np

from roft_sim.config_files import jsonable
from roft_sim.datasets import SequenceWriter, open_sequence, open_writer
from roft_sim.datasets.image_files import PNG_COMPRESSION
from roft_sim.datasets.metadata import dumps_json
from roft_sim.errors import ConfigError
from roft_sim.scenario import Scenario
from roft_sim.sensors.flow_sources import NVOF_GRID_PX

_log = logging.getLogger(__name__)

__all__ = [
    "ScenarioOverrides",
    "SequenceJob",
    "parse_resolution",
    "sequence_name_for",
    "sequence_names_for",
    "generation_metadata",
    "prepare_jobs",
]

_RESOLUTION = re.compile(r"^\s*(\d+)\s*[xX]\s*(\d+)\s*$")


def parse_resolution(text: str) -> tuple[int, int]:
    """``"640x480"`` -> ``(640, 480)`` (width, height) [px].

    Raises:
        ConfigError: not ``<width>x<height>`` with both at least 8.
    """
    m = _RESOLUTION.match(text)
    if not m or min(int(m.group(1)), int(m.group(2))) < 8:
        raise ConfigError(
            f"resolution {text!r}: expected WIDTHxHEIGHT with both >= 8 px, e.g. 640x480"
        )
    return int(m.group(1)), int(m.group(2))


@dataclass(frozen=True, slots=True, kw_only=True)
class ScenarioOverrides:
    """Command-line changes applied to every scenario of a run (recorded in the metadata)."""

    frames: int | None = None
    """Number of frames (replaces the scenario's ``frames``/``duration_s``)."""
    resolution: tuple[int, int] | None = None
    """(width, height) [px]; the intrinsics are scaled (``CameraIntrinsics.resized``), so the
    field of view and the motion in the image are kept."""
    seed: int | None = None
    """Scenario seed (textures, depth noise, networks; the trajectory keeps its own seed)."""

    def __post_init__(self) -> None:
        if self.frames is not None and self.frames < 1:
            raise ConfigError(f"--frames must be >= 1, got {self.frames}")
        if self.seed is not None and self.seed < 0:
            raise ConfigError(f"--seed must be >= 0, got {self.seed}")
        if self.resolution is not None and min(self.resolution) < 8:
            raise ConfigError(f"resolution must be at least 8x8 px, got {self.resolution}")

    def apply(self, scenario: Scenario) -> Scenario:
        """The scenario with the overrides applied (validated again)."""
        changes: dict[str, Any] = {}
        if self.resolution is not None:
            width, height = self.resolution
            k = scenario.intrinsics.resized(width, height)
            before = scenario.intrinsics.width_px / scenario.intrinsics.height_px
            if abs(width / height - before) > 1e-3 * before:
                _log.warning(
                    "%s: %dx%d changes the aspect ratio of the %dx%d camera; the field of view is "
                    "kept, so pixels are no longer square (fx %.1f, fy %.1f px); for square pixels "
                    "use %dx%d",
                    scenario.name, width, height, scenario.intrinsics.width_px,
                    scenario.intrinsics.height_px, k.fx_px, k.fy_px, width,
                    round(width / before),
                )  # fmt: skip
            changes["camera"] = dataclasses.replace(
                scenario.camera,
                width_px=k.width_px,
                height_px=k.height_px,
                fx_px=k.fx_px,
                fy_px=k.fy_px,
                cx_px=k.cx_px,
                cy_px=k.cy_px,
            )
        if self.frames is not None:
            changes.update(frames=self.frames, duration_s=None)
        if self.seed is not None:
            changes["seed"] = self.seed
        return dataclasses.replace(scenario, **changes) if changes else scenario


def object_name_of(scenario: Scenario) -> str:
    """The object's name in file names: the registry name, or the mesh file's stem."""
    obj = scenario.object
    return obj.name if obj.name is not None else Path(obj.mesh).stem  # type: ignore[arg-type]


def sequence_names_for(
    scenarios: Sequence[Scenario], naming: Literal["scenario", "object", "auto"]
) -> list[str]:
    """The sequence names of ``scenarios``; ``auto``: after the object when every scenario has
    its own (one object per sequence, as Fast-YCB: the fast-ycb loader's mask names
    ``<object>_<k>.png`` then match the folder), else after the scenario."""
    if naming == "auto":
        objects = [object_name_of(s) for s in scenarios]
        naming = "object" if len(set(objects)) == len(objects) else "scenario"
    return [sequence_name_for(s, naming) for s in scenarios]


def sequence_name_for(scenario: Scenario, naming: Literal["scenario", "object"]) -> str:
    """A sequence's folder/file name: the scenario's ``name`` or its object's name."""
    return scenario.name if naming == "scenario" else object_name_of(scenario)


@dataclass(frozen=True, slots=True, kw_only=True)
class SequenceJob:
    """One sequence of a run: what workers need (picklable)."""

    index: int
    """Position in the run."""
    scenario: Scenario
    """The scenario, overrides applied."""
    sequence_name: str
    """Output folder/file name."""
    writer: SequenceWriter
    """The open (created or resumed) writer; picklable, shared by the workers."""
    missing_frames: tuple[int, ...]
    """Frames the writer did not have when the run started."""
    object_source: str = ""
    """Where the driver found the object (``ycb`` real mesh or ``procedural`` stand-in; what
    the metadata and the written model say); every worker must render the same."""

    @property
    def n_frames(self) -> int:
        """Frames of the sequence."""
        return self.scenario.n_frames


def _version(name: str) -> str:
    try:
        return importlib_metadata.version(name)
    except importlib_metadata.PackageNotFoundError:
        return "not installed"


def generation_metadata(
    scenario: Scenario,
    *,
    object_source: str,
    overrides: ScenarioOverrides,
    preset: str | None,
    gl_backend: str | None,
) -> dict[str, Any]:
    """The user metadata of a generated sequence (the writer adds format, sets, conventions and
    package versions): the resolved scenario, the seed and how the data was made. Holds no
    time, host or path of the output, so the same inputs give byte-identical files."""
    return {
        "seed": scenario.seed,
        "scenario_name": scenario.name,
        "scenario": jsonable(scenario),
        "generator": {
            "tool": "roft-sim generate",
            "preset": preset,
            "overrides": jsonable(overrides),
            "object_source": object_source,
            "render": {
                "mujoco": _version("mujoco"),
                "scipy": _version("scipy"),
                "h5py": _version("h5py"),
                "gl_backend": gl_backend,
            },
            "depth": "sensor depth: the scenario's [render.depth_noise] model applied to the "
            "exact rendered z-depth (kind 'none' = exact)",
            "masks": "gt: visible mask; gt_full: the object's full silhouette (object rendered "
            "alone, united with the visible mask)",
            "flow_sets": {
                f.set_name: {"source": f.source, "encoding": f.encoding}
                for f in scenario.networks.flow_sets
            },
            "randomness": (
                "every stream is SeedSequence(seed, spawn_key=(crc32(subsystem), *index)): "
                "depth_noise per frame k, segmenter per frame k, pose_estimator once per "
                "sequence (its draws depend on the length only; frame k's detection on frame "
                "k's pose and visible fraction only), flow:<set> seeds frame_rng(seed, k-1, k); "
                "scene_textures once"
            ),
        },
    }


def _same_json(a: Any, b: Any) -> bool:
    return dumps_json({"v": a}) == dumps_json({"v": b})


def _check_finished_matches(path: Path, metadata: Mapping[str, Any]) -> None:
    """A finished sequence met on ``--resume`` must come from the same scenario and settings."""
    found = open_sequence(path).metadata()
    differ = [
        k for k in ("seed", "scenario", "generator") if not _same_json(found.get(k), metadata[k])
    ]
    if differ:
        raise ConfigError(
            f"cannot resume: {str(path)!r} is a finished sequence made with different settings "
            f"({', '.join(differ)} differ); use another --out, or --overwrite to start over"
        )


def _warn_about_grid_width(scenario: Scenario) -> None:
    """Warns when an ``nvof-like`` or ``nvof-model`` set's 4x4 grid does not divide the image
    width: our readers know the grid is 4 px, but the reference ROFT derives it as
    ``image_width / flow_cols`` in integer arithmetic (roft_reference.md section 8.4) and would
    sample the flow wrongly."""
    width = scenario.intrinsics.width_px
    grid_sets = [
        f.set_name
        for f in scenario.networks.flow_sets
        if f.source.startswith(("nvof-like", "nvof-model"))
    ]
    g = NVOF_GRID_PX
    if grid_sets and width % g:
        cols = -(-width // g)
        _log.warning(
            "%s: flow sets %s have %d grid columns for a width of %d px; the reference ROFT reads "
            "their grid as %d // %d = %d px instead of %d. Use a width that is a multiple of %d "
            "(e.g. %d) if the reference code will read this dataset",
            scenario.name, grid_sets, cols, width, width, cols, width // cols, g, g,
            width - width % g,
        )  # fmt: skip


def prepare_jobs(
    scenarios: Sequence[Scenario],
    out_dir: Path,
    *,
    fmt: str,
    sequence_names: Sequence[str],
    overrides: ScenarioOverrides,
    preset: str | None,
    resume: bool,
    assets_dir: Path | None,
    cache_dir: Path | None,
    gl_backend: str | None,
    prepare_output: Callable[[Path], Any] | None = None,
    shard_run: bool = False,
    png_compression: int = PNG_COMPRESSION,
) -> list[SequenceJob]:
    """Opens one writer per scenario (see the module doc). ``prepare_output(out_dir)`` is
    called after every check and before the first writer opens.

    With ``shard_run`` (one of several ``--shard`` jobs writing the same output at once) every
    writer is opened to resume (another shard may have created it a moment ago), and a sequence
    with every frame present is left alone: only a run without shards finalizes and checks
    finished sequences.

    Raises:
        ConfigError: duplicate sequence names, an output that exists without ``resume``, a
            resume with different settings, or an invalid scenario after the overrides.
    """
    from roft_sim.assets import load_object

    if len(set(sequence_names)) != len(sequence_names):
        dup = sorted({n for n in sequence_names if list(sequence_names).count(n) > 1})
        raise ConfigError(
            f"two scenarios would write the same sequence {dup}; give each scenario its own name"
        )
    loaded = []
    for scenario in scenarios:  # every check before any output is written
        assets = load_object(
            scenario.object.name_or_path, assets_dir=assets_dir, cache_dir=cache_dir
        )
        _check_trajectory_length(scenario, assets.mesh)
        _warn_about_grid_width(scenario)
        loaded.append(assets)
    if prepare_output is not None:
        prepare_output(out_dir)
    jobs = []
    for index, (scenario, name, assets) in enumerate(
        zip(scenarios, sequence_names, loaded, strict=True)
    ):
        metadata = generation_metadata(
            scenario,
            object_source=assets.source,
            overrides=overrides,
            preset=preset,
            gl_backend=gl_backend,
        )
        writer_args = {
            "sequence_name": name,
            "object_name": object_name_of(scenario),
            "intrinsics": scenario.intrinsics,
            "fps": scenario.fps,
            "n_frames": scenario.n_frames,
            "metadata": metadata,
            "object_model": assets.model,
            "flow_encodings": scenario.networks.flow_encodings,
            "png_compression": png_compression,
        }
        if fmt == "bop":  # scene folders 000001... in scenario order (a name map beside them)
            writer_args["bop_scene_id"] = index + 1
        if shard_run:
            writer = _open_shared_writer(fmt, out_dir, writer_args)
        else:
            writer = open_writer(fmt, out_dir, resume=resume, **writer_args)  # type: ignore[arg-type]
        missing = sorted(set(range(scenario.n_frames)) - writer.completed_frames())
        if not missing and resume and not shard_run:
            _check_finished_or_complete(writer, metadata)
        jobs.append(
            SequenceJob(
                index=index,
                scenario=scenario,
                sequence_name=name,
                writer=writer,
                missing_frames=tuple(missing),
                object_source=str(assets.source),
            )
        )
    return jobs


_SHARED_OPEN_TRIES = 4
"""Attempts to open a writer that other shards may be creating at the same moment."""


def _open_shared_writer(fmt: str, out_dir: Path, writer_args: dict[str, Any]) -> SequenceWriter:
    """Opens a writer to resume, retrying briefly: while another shard creates the same sequence
    folder, it can look like a foreign non-empty folder for an instant. A persistent problem
    (different settings, a foreign folder) is raised after the last try."""
    for attempt in range(_SHARED_OPEN_TRIES):
        try:
            return open_writer(fmt, out_dir, resume=True, **writer_args)  # type: ignore[arg-type]
        except ConfigError:
            if attempt == _SHARED_OPEN_TRIES - 1:
                raise
            time.sleep(0.25 * (attempt + 1))
    raise AssertionError("unreachable")


def _check_trajectory_length(scenario: Scenario, mesh: Any) -> None:
    """Fails before any output is written when the trajectory is shorter than the scenario
    (the same test :class:`~roft_sim.render.SceneRenderer` makes)."""
    from roft_sim.trajectories import build_trajectory

    radius = float(np.linalg.norm(np.asarray(mesh.vertices_m), axis=1).max())
    traj = build_trajectory(scenario.trajectory, scenario.intrinsics, object_radius_m=radius)
    last_s = float(traj.start_s) + (scenario.n_frames - 1) / scenario.fps
    if last_s > float(traj.end_s) + 1e-9:
        longest = int(np.floor((float(traj.end_s) - float(traj.start_s)) * scenario.fps + 1e-9)) + 1
        raise ConfigError(
            f"scenario {scenario.name!r} needs {scenario.n_frames} frames at {scenario.fps} fps "
            f"(until {last_s:.3f} s) but its trajectory ends at {float(traj.end_s):.3f} s; use "
            f"at most --frames {longest}, or lengthen the trajectory"
        )


def _check_finished_or_complete(writer: SequenceWriter, metadata: Mapping[str, Any]) -> None:
    """Every frame is present: finalize (a no-op when finished) and check the settings."""
    path = writer.finalize()
    _check_finished_matches(Path(path), metadata)
