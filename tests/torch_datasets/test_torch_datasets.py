"""roft_sim.torch: DataLoaders with 2 workers over SequenceDataset and GeneratorDataset give the
tensors the files hold."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="torch is not installed (pip install -e '.[torch]')")

from roft_sim.datasets import open_sequence, write_sequence  # noqa: E402
from roft_sim.generation import (  # noqa: E402
    GenerationOptions,
    ScenarioOverrides,
    generate_dataset,
    shipped_scenarios_dir,  # noqa: E402
)
from roft_sim.scenario import load_scenario  # noqa: E402
from roft_sim.testing.analytic_scene import analytic_box_sequence, default_intrinsics  # noqa: E402
from roft_sim.torch import GeneratorDataset, SequenceDataset, collate  # noqa: E402
from roft_sim.torch.datasets import scenario_seed  # noqa: E402

DataLoader = torch.utils.data.DataLoader


def _check_item(batch: dict, i: int, seq, k: int) -> None:
    np.testing.assert_array_equal(batch["rgb"][i].permute(1, 2, 0).numpy(), seq.rgb(k))
    np.testing.assert_array_equal(batch["depth"][i, 0].numpy(), seq.depth(k))
    np.testing.assert_array_equal(batch["mask"][i].numpy(), seq.mask(k, "gt"))
    gt = seq.ground_truth()
    # (the files hold axis-angle text: the pose read back is equal to rounding)
    np.testing.assert_allclose(batch["pose"][i].numpy(), gt.T_cam_obj[k], rtol=0, atol=1e-14)
    np.testing.assert_array_equal(batch["velocity"][i, :3].numpy(), gt.v_obj_mps[k])
    np.testing.assert_array_equal(batch["velocity"][i, 3:].numpy(), gt.w_radps[k])
    np.testing.assert_array_equal(batch["intrinsics"][i].numpy(), seq.intrinsics.K)
    flow = seq.flow(k, "gt")
    if flow is None:
        assert not batch["flow_valid"][i].any() and not batch["flow"][i].any()
    else:
        np.testing.assert_array_equal(batch["flow"][i].permute(1, 2, 0).numpy(), flow.flow_px)


def test_sequence_dataset_with_two_workers(tmp_path):
    """Two sequences of different sizes (so collate pads), one with a detector miss."""
    big = analytic_box_sequence(n_frames=4, intrinsics=default_intrinsics(64, 48), name="big")
    small = analytic_box_sequence(n_frames=3, intrinsics=default_intrinsics(48, 32), name="small")
    masks = [m.copy() for m in small.gt_masks]
    small = dataclasses.replace(
        small, detector_masks={"mrcnn": [masks[0], None, masks[2]]}, detector_pose_sets={}
    )
    big = dataclasses.replace(
        big, detector_masks={"mrcnn": list(big.gt_masks)}, detector_pose_sets={}
    )
    for seq in (big, small):
        write_sequence(seq, "fast-ycb", tmp_path)
    dataset = SequenceDataset(tmp_path, flow_set="gt")
    assert len(dataset) == 7
    loader = DataLoader(dataset, batch_size=7, num_workers=2, collate_fn=collate)
    (batch,) = list(loader)
    on_disk = {p: open_sequence(tmp_path / p) for p in ("big", "small")}
    assert batch["rgb"].shape == (7, 3, 48, 64) and batch["rgb"].dtype == torch.uint8
    assert batch["rgb_size"][-1].tolist() == [3, 32, 48]  # padded from 48x32
    for i in range(7):
        name, k = batch["sequence"][i], int(batch["k"][i])
        seq = on_disk[name]
        h, w = seq.intrinsics.height_px, seq.intrinsics.width_px
        cropped = {
            key: (value[:, :, :h, :w] if value.ndim == 4 else value[:, :h, :w])
            if key in ("rgb", "depth", "mask", "flow", "flow_valid")
            else value
            for key, value in batch.items()
        }
        _check_item(cropped, i, seq, k)
    assert batch["detector_mask_present"].tolist() == [True] * 5 + [False, True]
    assert not batch["detector_mask"][5].any()


@pytest.mark.render
@pytest.mark.slow  # two spawned workers render two scenarios (~20 s)
def test_generator_dataset_with_two_workers_matches_generate(tmp_path):
    ci = shipped_scenarios_dir() / "ci"
    small = ScenarioOverrides(frames=3, resolution=(64, 48))
    scenarios = [
        small.apply(load_scenario(ci / f"{n}.toml"))
        for n in ("cracker_box", "mustard_hand_moving_camera")
    ]
    dataset = GeneratorDataset(scenarios, seed=7, flow_set="gt")
    loader = DataLoader(
        dataset, batch_size=3, num_workers=2, collate_fn=collate, multiprocessing_context="spawn"
    )
    batches = list(loader)
    assert len(batches) == 2 and {b["sequence"][0] for b in batches} == {s.name for s in scenarios}
    # the same scenarios with the same seeds, written by roft-sim generate's library call
    seeded = [ScenarioOverrides(seed=scenario_seed(7, i)).apply(s) for i, s in enumerate(scenarios)]
    generate_dataset(seeded, tmp_path, GenerationOptions(progress=False))
    for batch in batches:
        seq = open_sequence(tmp_path / batch["sequence"][0])
        for i in range(3):
            _check_item(batch, i, seq, int(batch["k"][i]))
