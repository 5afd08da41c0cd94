"""Random fault mixes (``roft_sim.faults.random_mix``, ``roft-sim faults random``): valid,
reproducible, written as fault files that read back to the same configuration, and covering
every fault kind they promise."""

from __future__ import annotations

import tomllib
from collections import Counter

import pytest

from roft_sim.cli import main
from roft_sim.faults import (
    fault_config_from_mapping,
    fault_mix_toml,
    fault_spec_name,
    load_faults,
    random_fault_mix,
)

SEEDS = range(200)


def test_every_mix_is_a_valid_fault_file_that_reads_back_the_same():
    for seed in SEEDS:
        mix = random_fault_mix(seed)
        config = fault_config_from_mapping(mix)
        assert config.name == f"mix-{seed}"
        assert fault_config_from_mapping(tomllib.loads(fault_mix_toml(mix))) == config


def test_mixes_are_reproducible_and_differ_between_seeds():
    assert random_fault_mix(17) == random_fault_mix(17)
    texts = {fault_mix_toml(random_fault_mix(s)).split("\n", 2)[2] for s in SEEDS}
    assert len(texts) == len(SEEDS)  # no two seeds draw the same faults
    with pytest.raises(ValueError, match="must be >= 0"):
        random_fault_mix(-1)


def test_mixes_cover_every_fault_kind_of_every_stream():
    kinds: dict[str, Counter[str]] = {s: Counter() for s in ("pose", "mask", "camera", "flow")}
    for seed in SEEDS:
        mix = random_fault_mix(seed)
        for stream, counter in kinds.items():
            counter.update(f["kind"] for f in mix[stream]["faults"])
    detection = {"rate", "busy", "delay", "uniform_delay", "lognormal_delay", "clock_skew"}
    detection |= {"dropout", "burst_dropout", "blackout", "stale", "duplicate", "reorder"}
    outliers = {"translation_jump", "rotation_flip", "wrong_object"}
    corruptions = {"mask_shift", "mask_morphology", "mask_blobs", "mask_empty", "mask_wrong_frame"}
    assert set(kinds["pose"]) == detection | outliers
    assert set(kinds["mask"]) == detection | corruptions
    assert set(kinds["camera"]) == {"dropout", "burst_dropout", "depth_holes", "depth_noise"}
    assert set(kinds["flow"]) == {"flow_noise", "flow_holes", "flow_reversed"}
    # every detection stream has exactly one sampling fault (a rate or a busy network)
    for seed in SEEDS:
        for stream in ("pose", "mask"):
            faults = random_fault_mix(seed)[stream]["faults"]
            assert sum(f["kind"] in ("rate", "busy") for f in faults) == 1


def test_cli_prints_or_writes_the_mix(tmp_path, capsys):
    assert main(["faults", "random", "--seed", "5"]) == 0
    printed = capsys.readouterr().out
    assert printed == fault_mix_toml(random_fault_mix(5))
    path = tmp_path / "mix.toml"
    assert main(["faults", "random", "--seed", "5", "--out", str(path)]) == 0
    assert path.read_text() == printed
    assert load_faults(path) == fault_config_from_mapping(random_fault_mix(5))
    assert "wrote" in capsys.readouterr().out


@pytest.mark.parametrize(
    "args, match",
    [(["--seed", "-1"], "--seed must be >= 0, got -1"), (["--out", "."], "is a folder")],
)
def test_cli_rejects_bad_arguments(args, match, capsys):
    assert main(["faults", "random", *args]) != 0
    assert match in capsys.readouterr().err


def test_reports_name_fault_files_by_their_stem():
    assert fault_spec_name("/tmp/out/mixes/mix-1000.toml") == "mix-1000"
    assert fault_spec_name("paper") == "paper"
    assert fault_spec_name("paper+extra.toml") == "paper+extra.toml"
