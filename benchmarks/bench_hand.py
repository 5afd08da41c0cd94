"""What the hand costs and does: per-frame time of the hand kinds, the object's visible fraction
and the hand's clearance from the object, on this machine's OpenGL backend.

Parts (``--part``):

- ``pipeline``: ``roft-sim generate``'s frame pipeline (SequenceGenerator: render, ground truth,
  silhouette, flow sets, simulated networks) on the CI scenario ``mustard_hand_moving_camera``
  (4:3, ``--size``'s width) with no hand, the proxy and the articulated hand; interleaved rounds,
  best of rounds;
- ``render``: SceneRenderer.render_frame alone (rgb, depth, ids, finger posing) on the
  ``fast-ycb`` cracker box, same protocol;
- ``visibility``: the object's visible fraction with the articulated hand on the six ``fast-ycb``
  preset scenarios (first 120 frames, every 4th);
- ``clearance``: the deepest point of the object's surface (100 000 samples) inside any hand
  geom, over 3 seeds x 10 frames per object (negative = a gap: the hand never enters).

    python benchmarks/bench_hand.py --assets ../shared/ycb                  # every part
    python benchmarks/bench_hand.py --part pipeline --size 640x360
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from pathlib import Path

from roft_sim.render.gl_backend import require_gl_backend

BACKEND = require_gl_backend(os.environ)  # before anything imports mujoco

import numpy as np  # noqa: E402

from roft_sim.assets import FAST_YCB_OBJECTS, sample_surface_points  # noqa: E402
from roft_sim.generation import ScenarioOverrides, shipped_scenarios_dir  # noqa: E402
from roft_sim.generation.sequence_generator import SequenceGenerator  # noqa: E402
from roft_sim.render import SceneRenderer  # noqa: E402
from roft_sim.scenario import Scenario, load_scenario  # noqa: E402
from roft_sim.scene.config import HandConfig  # noqa: E402

OBJECTS = FAST_YCB_OBJECTS


def _with_hand(scenario: Scenario, hand: HandConfig) -> Scenario:
    return dataclasses.replace(scenario, scene=dataclasses.replace(scenario.scene, hand=hand))


def _kinds(proxy: HandConfig) -> dict[str, HandConfig]:
    return {
        "none": dataclasses.replace(proxy, enabled=False),
        "proxy": dataclasses.replace(proxy, enabled=True, kind="proxy"),
        "articulated": dataclasses.replace(proxy, enabled=True, kind="articulated"),
    }


def _report(best: dict[str, float]) -> None:
    for name, s in best.items():
        print(f"  {name}: {1000 * s:.1f} ms/frame")
    for name in ("proxy", "articulated"):
        print(f"  {name} vs none: {100 * (best[name] / best['none'] - 1):+.1f} %")


def bench_pipeline(size: tuple[int, int], assets: Path | None, rounds: int) -> None:
    base = load_scenario(shipped_scenarios_dir() / "ci" / "mustard_hand_moving_camera.toml")
    base = ScenarioOverrides(frames=8 * rounds + 8, resolution=size).apply(base)
    gens = {n: SequenceGenerator(_with_hand(base, h), assets_dir=assets) for n, h in
            _kinds(base.scene.hand).items()}  # fmt: skip
    best = {n: np.inf for n in gens}
    for r in range(rounds):
        for n, g in gens.items():
            start = 5 + 8 * r
            list(g.frames(start, start + 1))
            t0 = time.perf_counter()
            list(g.frames(start + 1, start + 8))
            best[n] = min(best[n], (time.perf_counter() - t0) / 7)
    for g in gens.values():
        g.close()
    print(f"pipeline, CI mustard scenario, {size[0]}x{size[1]}:")
    _report(best)


def bench_render(size: tuple[int, int], assets: Path | None, rounds: int) -> None:
    base = load_scenario(shipped_scenarios_dir() / "fast_ycb" / "003_cracker_box.toml")
    base = ScenarioOverrides(frames=20, resolution=size).apply(base)
    renderers = {n: SceneRenderer(_with_hand(base, h), assets_dir=assets) for n, h in
                 _kinds(HandConfig()).items()}  # fmt: skip
    best = {n: np.inf for n in renderers}
    for _ in range(rounds):
        for n, r in renderers.items():
            t0 = time.perf_counter()
            for k in range(5, 15):
                r.render_frame(k)
            best[n] = min(best[n], (time.perf_counter() - t0) / 10)
    for r in renderers.values():
        r.close()
    print(f"render only, fast-ycb cracker box, {size[0]}x{size[1]}:")
    _report(best)


def bench_visibility(size: tuple[int, int], assets: Path | None) -> None:
    print(f"visible fraction with the articulated hand, fast-ycb preset, {size[0]}x{size[1]}:")
    for obj in OBJECTS:
        s = load_scenario(shipped_scenarios_dir() / "fast_ycb" / f"{obj}.toml")
        s = _with_hand(
            ScenarioOverrides(frames=120, resolution=size).apply(s), HandConfig(enabled=True)
        )
        s = dataclasses.replace(s, networks=dataclasses.replace(s.networks, flow_sets=()))
        with SequenceGenerator(s, assets_dir=assets) as g:
            v = np.array(
                [next(iter(g.frames(k, k + 1))).gt_visible_fraction for k in range(0, 120, 4)]
            )
        print(
            f"  {obj}: mean {v.mean():.3f}, p10 {np.percentile(v, 10):.3f}, min {v.min():.3f}, "
            f"below half {100 * (v < 0.5).mean():.0f} %"
        )


def _deepest_m(renderer: SceneRenderer, points_obj: np.ndarray) -> float:
    """Deepest surface point inside a hand geom [m] (negative: the smallest clearance)."""
    m, d, hand = renderer.model, renderer._data, renderer.built.hand
    assert hand is not None
    body = m.body("object").id
    p = points_obj @ d.xmat[body].reshape(3, 3).T + d.xpos[body]
    signed = []
    for g in [hand.palm_geom, *(g for digit in hand.digit_geoms for g in digit)]:
        local = (p - d.geom_xpos[g]) @ d.geom_xmat[g].reshape(3, 3)
        size = m.geom_size[g]
        if m.geom_type[g] == 6:  # box
            q = np.abs(local) - size
            signed.append(np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0))
        else:  # capsule along local z
            z = np.clip(local[:, 2], -size[1], size[1])
            signed.append(np.linalg.norm(local - np.outer(z, [0, 0, 1]), axis=1) - size[0])
    return float(-np.min(signed))


def bench_clearance(assets: Path | None) -> None:
    print("hand vs object surface (100 000 points), 3 seeds x 10 frames, 160x90:")
    for obj in OBJECTS:
        s = load_scenario(shipped_scenarios_dir() / "fast_ycb" / f"{obj}.toml")
        s = _with_hand(
            ScenarioOverrides(frames=60, resolution=(160, 90)).apply(s), HandConfig(enabled=True)
        )
        worst = []
        for seed in range(3):
            with SceneRenderer(dataclasses.replace(s, seed=seed), assets_dir=assets) as r:
                mesh = r.object_assets.mesh
                points = sample_surface_points(mesh.vertices_m, mesh.faces, 100_000, seed=seed)
                for k in range(0, 60, 6):
                    r.render_frame(k)
                    worst.append(_deepest_m(r, points))
        print(f"  {obj}: deepest {1000 * max(worst):+.3f} mm (negative = clear of the object)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--part", choices=("pipeline", "render", "visibility", "clearance", "all"), default="all"
    )
    parser.add_argument("--size", default="640x360", help="WxH of the timing parts")
    parser.add_argument("--rounds", type=int, default=5, help="interleaved timing rounds")
    parser.add_argument("--assets", type=Path, help="folder of real YCB meshes")
    args = parser.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))
    assert len(size) == 2
    print(f"backend {BACKEND}")
    if args.part in ("pipeline", "all"):
        # The CI scenario's camera is 4:3: keep its pixels square.
        bench_pipeline((size[0], size[0] * 3 // 4), args.assets, args.rounds)
    if args.part in ("render", "all"):
        bench_render(size, args.assets, args.rounds)  # type: ignore[arg-type]
    if args.part in ("visibility", "all"):
        bench_visibility((320, 180), args.assets)
    if args.part in ("clearance", "all"):
        bench_clearance(args.assets)


if __name__ == "__main__":
    main()
