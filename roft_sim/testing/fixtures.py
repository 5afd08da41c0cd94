"""Sequences for tests: the renderer-free analytic scene (memoised) and tiny rendered sequences.

- :func:`analytic_sequence`: the analytic textured box (exact depth, masks, flow, a ``gt`` pose
  set), memoised per arguments: property tests call it in every example for free.
- :func:`render_tiny_sequence`: a shipped CI scenario rendered with MuJoCo at a tiny resolution
  into a folder (Fast-YCB layout: rgb, depth, ground truth, a ``dope`` pose set, masks,
  ``gt`` and ``nvof_1_slow`` flow), then opened; generated once, reused when already there.

The pytest plugin (:mod:`roft_sim.testing.pytest_plugin`) serves both as session fixtures.
Nothing here imports hypothesis; MuJoCo only inside :func:`render_tiny_sequence`.
"""

from __future__ import annotations

import functools
from pathlib import Path

from roft_sim.datasets.base import InMemorySequence, Sequence
from roft_sim.errors import ConfigError
from roft_sim.testing.analytic_scene import (
    AnalyticMotion,
    analytic_box_sequence,
    default_intrinsics,
)

__all__ = ["analytic_sequence", "render_tiny_sequence", "RENDER_SCENARIOS"]

RENDER_SCENARIOS = ("cracker_box", "mustard_hand_moving_camera", "tomato_off_centre_blur")
"""The shipped CI scenarios (``scenarios/ci/<name>.toml``) :func:`render_tiny_sequence` takes."""


@functools.lru_cache(maxsize=64)
def analytic_sequence(
    *,
    n_frames: int = 24,
    width_px: int = 64,
    height_px: int = 48,
    motion: AnalyticMotion | None = None,
    fps: int = 30,
) -> InMemorySequence:
    """The analytic box sequence (:func:`~roft_sim.testing.analytic_scene.analytic_box_sequence`)
    at ``width_px`` x ``height_px``, memoised: the same arguments return the same object, so
    never modify it. Default: 24 frames of the default fast motion (peaks near 0.5 m/s, 4 rad/s)
    at 64x48, 30 fps."""
    return analytic_box_sequence(
        n_frames=n_frames,
        fps=fps,
        intrinsics=default_intrinsics(width_px, height_px),
        motion=motion,
    )


def render_tiny_sequence(
    out_dir: str | Path,
    *,
    scenario: str = "cracker_box",
    frames: int = 8,
    resolution: tuple[int, int] = (64, 48),
    seed: int | None = None,
    gl_backend: str | None = None,
) -> Sequence:
    """Renders a shipped CI scenario into ``out_dir`` (once) and opens the sequence.

    The caller chooses the OpenGL backend before MuJoCo is imported (e.g. with
    :func:`roft_sim.render.gl_backend.select_gl_backend`); the pytest plugin's fixture does, and
    skips when none works.

    Args:
        out_dir: dataset root to write to. A finished sequence of this scenario already there
            is reused as it is (whatever frames or resolution it has): give each setting its own
            folder.
        scenario: one of :data:`RENDER_SCENARIOS`.
        frames: frames to render.
        resolution: ``(width, height)`` [px]; the simulated segmenter needs the object to cover
            about 100 px, so keep at least 64x48.
        seed: overrides the scenario's seed (None keeps it).
        gl_backend: the backend in use, recorded in the metadata.

    Raises:
        ConfigError: unknown scenario.
        RenderBackendError: no offscreen OpenGL backend works.
    """
    if scenario not in RENDER_SCENARIOS:
        raise ConfigError(
            f"unknown CI scenario {scenario!r}; expected one of {', '.join(RENDER_SCENARIOS)}"
        )
    from roft_sim.generation import (
        GenerationOptions,
        ScenarioOverrides,
        generate_dataset,
        shipped_scenarios_dir,
    )
    from roft_sim.harness import open_sequences
    from roft_sim.scenario import load_scenario

    out = Path(out_dir)
    loaded = load_scenario(shipped_scenarios_dir() / "ci" / f"{scenario}.toml")
    overrides = ScenarioOverrides(frames=frames, resolution=resolution, seed=seed)
    summary = generate_dataset(  # resume: a finished sequence is kept, not rendered again
        [loaded],
        out,
        GenerationOptions(progress=False, gl_backend=gl_backend, resume=True),
        overrides=overrides,
    )
    (result,) = summary.sequences
    assert result.path is not None  # generate_dataset finalises every sequence it is given
    (source,) = open_sequences([result.path])
    return source.sequence
