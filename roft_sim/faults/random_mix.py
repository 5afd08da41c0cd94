"""Random fault mixes: seeded fault files drawn from every fault kind, to judge a tracker on
mixes nobody tuned it on.

The shipped presets are eleven fixed points; a tracker whose defaults were chosen on them can
still fail on a mix between or beyond them (a mask outage while the object leaves the view, a
10 Hz pose stream with 40 % loss, ...). :func:`random_fault_mix` draws one fault file from a
fixed distribution (docs/faults.md, "Random mixes") around and beyond the presets' intensities;
the same seed gives the same file on every machine. ``roft-sim faults random --seed S`` prints
or writes one; ``benchmarks/bench_robustness.py --random-mixes N`` runs the stress benchmark's
trackers under N of them instead of the presets.

Every stream is drawn on its own:

- pose and mask networks: a rate (2-15 Hz) or a busy network (3-9 frames a run), one latency
  model (fixed 1-12 frames, uniform, log-normal with a tail to 15 frames, or the paper's 6),
  with given probabilities a Bernoulli and a bursty (Gilbert-Elliott) loss, a capture blackout
  of 10-40 frames, a clock skew, stale, duplicated and reordered deliveries; the pose stream's
  outliers (translation jumps up to 40 cm, half-turn flips, another object's pose), the mask
  stream's corruptions (shifts, erosion/dilation, blobs, empty masks, another frame's mask);
- the camera: dropped frames (single and bursts), depth holes and depth noise bursts;
- the flow: noise bursts (0.5-3 px), holes, reversed flow.

Image sizes are in pixels of the full image, as in the presets (which suit 640x480).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from roft_sim.config_files import toml_value

__all__ = ["random_fault_mix", "fault_mix_toml", "random_mix_name"]

_RATES_HZ = (2, 3, 5, 5, 6, 10, 15)
"""Network rates drawn from (5 Hz, the paper's, twice as likely)."""


def random_mix_name(seed: int) -> str:
    """The name of the mix of ``seed`` (``mix-<seed>``)."""
    return f"mix-{seed}"


def _p(rng: np.random.Generator, high: float) -> float:
    return round(float(rng.uniform(0.0, high)), 4)


def _timing(rng: np.random.Generator) -> list[dict[str, Any]]:
    """The sampling (rate or busy network) and one latency model of a detection stream."""
    faults: list[dict[str, Any]] = []
    if rng.random() < 0.15:
        low = int(rng.integers(3, 7))
        busy = {"kind": "uniform_delay", "min_frames": low, "max_frames": low + 3}
        faults.append({"kind": "busy", "processing": busy})
    else:
        faults.append({"kind": "rate", "rate_hz": int(rng.choice(_RATES_HZ))})
    model = int(rng.integers(0, 4))
    if model == 0:
        faults.append({"kind": "delay", "frames": int(rng.integers(1, 13))})
    elif model == 1:
        low = int(rng.integers(1, 8))
        high = low + int(rng.integers(1, 8))
        faults.append({"kind": "uniform_delay", "min_frames": low, "max_frames": high})
    elif model == 2:
        faults.append(
            {
                "kind": "lognormal_delay",
                "median_frames": round(float(rng.uniform(1.0, 8.0)), 3),
                "sigma": round(float(rng.uniform(0.2, 1.0)), 3),
                "max_frames": 15,
            }
        )
    else:
        faults.append({"kind": "delay", "frames": 6})
    if rng.random() < 0.2:
        faults.append(
            {
                "kind": "clock_skew",
                "offset_frames": round(float(rng.uniform(-0.5, 0.5)), 3),
                "noise_sd_frames": round(float(rng.uniform(0.0, 0.5)), 3),
            }
        )
    return faults


def _dropouts(
    rng: np.random.Generator,
    p_high: float,
    good_to_bad: tuple[float, float],
    bad_to_good: tuple[float, float],
) -> list[dict[str, Any]]:
    """(0.5) a Bernoulli loss with p below ``p_high``; (0.3) Gilbert-Elliott bursts with their
    transition probabilities drawn from the two ranges."""
    faults: list[dict[str, Any]] = []
    if rng.random() < 0.5:
        faults.append({"kind": "dropout", "p": _p(rng, p_high)})
    if rng.random() < 0.3:
        faults.append(
            {
                "kind": "burst_dropout",
                "p_good_to_bad": round(float(rng.uniform(*good_to_bad)), 4),
                "p_bad_to_good": round(float(rng.uniform(*bad_to_good)), 4),
            }
        )
    return faults


def _loss(rng: np.random.Generator) -> list[dict[str, Any]]:
    faults = _dropouts(rng, 0.4, (0.01, 0.1), (0.1, 0.5))
    if rng.random() < 0.2:
        start = int(rng.integers(10, 90))
        faults.append({"kind": "blackout", "windows": [[start, start + int(rng.integers(10, 41))]]})
    return faults


def _delivery(rng: np.random.Generator) -> list[dict[str, Any]]:
    faults: list[dict[str, Any]] = []
    if rng.random() < 0.2:
        faults.append({"kind": "stale", "p": _p(rng, 0.1)})
    if rng.random() < 0.2:
        faults.append({"kind": "duplicate", "p": _p(rng, 0.1), "max_after_frames": 3})
    if rng.random() < 0.3:
        faults.append({"kind": "reorder", "p": _p(rng, 0.2)})
    return faults


def _pose_content(rng: np.random.Generator) -> list[dict[str, Any]]:
    faults: list[dict[str, Any]] = []
    if rng.random() < 0.5:
        high = round(float(rng.uniform(0.1, 0.4)), 3)
        faults.append(
            {"kind": "translation_jump", "p": _p(rng, 0.12), "min_m": 0.05, "max_m": high}
        )
    if rng.random() < 0.5:
        faults.append({"kind": "rotation_flip", "p": _p(rng, 0.12)})
    if rng.random() < 0.3:
        faults.append({"kind": "wrong_object", "p": _p(rng, 0.05)})
    return faults


def _mask_content(rng: np.random.Generator) -> list[dict[str, Any]]:
    faults: list[dict[str, Any]] = []
    if rng.random() < 0.4:
        high = int(rng.integers(5, 26))
        faults.append({"kind": "mask_shift", "p": _p(rng, 0.2), "min_px": 2, "max_px": high})
    if rng.random() < 0.4:
        faults.append({"kind": "mask_morphology", "p": _p(rng, 0.2)})
    if rng.random() < 0.3:
        faults.append({"kind": "mask_blobs", "p": _p(rng, 0.2)})
    if rng.random() < 0.3:
        faults.append({"kind": "mask_empty", "p": _p(rng, 0.1)})
    if rng.random() < 0.2:
        faults.append({"kind": "mask_wrong_frame", "p": _p(rng, 0.1)})
    return faults


def _detection_stream(rng: np.random.Generator, stream: str) -> dict[str, Any]:
    content = _pose_content(rng) if stream == "pose" else _mask_content(rng)
    first = "undelayed" if rng.random() < 0.5 else "delayed"
    faults = _timing(rng) + _loss(rng) + content + _delivery(rng)
    return {"first_result": first, "faults": faults}


def _camera(rng: np.random.Generator) -> list[dict[str, Any]]:
    faults = _dropouts(rng, 0.12, (0.005, 0.03), (0.3, 0.7))
    if rng.random() < 0.4:
        faults.append({"kind": "depth_holes", "p": _p(rng, 0.2)})
    if rng.random() < 0.3:
        sd = round(float(rng.uniform(0.002, 0.02)), 4)
        faults.append({"kind": "depth_noise", "p": _p(rng, 0.05), "burst_frames": 5, "sd_m": sd})
    return faults


def _flow(rng: np.random.Generator) -> list[dict[str, Any]]:
    faults: list[dict[str, Any]] = []
    if rng.random() < 0.4:
        faults.append(
            {
                "kind": "flow_noise",
                "p": _p(rng, 0.1),
                "burst_frames": int(rng.integers(1, 8)),
                "sd_px": round(float(rng.uniform(0.5, 3.0)), 3),
            }
        )
    if rng.random() < 0.3:
        faults.append({"kind": "flow_holes", "p": _p(rng, 0.1)})
    if rng.random() < 0.15:
        faults.append({"kind": "flow_reversed", "p": _p(rng, 0.03)})
    return faults


def random_fault_mix(seed: int) -> dict[str, Any]:
    """The fault file of ``seed`` as a mapping (what ``load_toml`` would give for it): the
    name ``mix-<seed>``, a description and the ``[pose]``, ``[mask]``, ``[camera]`` and
    ``[flow]`` tables (module docstring). Deterministic in ``seed``.

    Raises:
        ValueError: ``seed`` < 0.
    """
    if seed < 0:
        raise ValueError(f"a mix seed must be >= 0, got {seed}")
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0x6D6978,)))
    mix = {
        "name": random_mix_name(seed),
        "description": f"random fault mix {seed} (roft_sim.faults.random_mix)",
        "pose": _detection_stream(rng, "pose"),
        "mask": _detection_stream(rng, "mask"),
        "camera": {"faults": _camera(rng)},
        "flow": {"faults": _flow(rng)},
    }
    return mix


def _inline(table: dict[str, Any]) -> str:
    items = [
        f"{key} = {_inline(value) if isinstance(value, dict) else toml_value(value)}"
        for key, value in table.items()
    ]
    return "{ " + ", ".join(items) + " }"


def fault_mix_toml(mix: dict[str, Any]) -> str:
    """TOML text of a fault mapping shaped like :func:`random_fault_mix`'s (a fault file that
    ``load_faults`` reads back to the same configuration)."""
    lines = [f"name = {toml_value(mix['name'])}", f"description = {toml_value(mix['description'])}"]
    for stream in ("pose", "mask", "camera", "flow"):
        table = mix.get(stream)
        if table is None:
            continue
        lines += ["", f"[{stream}]"]
        if "first_result" in table:
            lines.append(f"first_result = {toml_value(table['first_result'])}")
        faults = table.get("faults", [])
        if not faults:
            lines.append("faults = []")
            continue
        lines.append("faults = [")
        lines += [f"  {_inline(fault)}," for fault in faults]
        lines.append("]")
    return "\n".join(lines) + "\n"
