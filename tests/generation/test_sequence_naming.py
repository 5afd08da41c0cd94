"""`roft-sim generate` names sequence folders by object when each scenario has its own object
(as Fast-YCB: the fast-ycb loader's ``masks/<set>/<object>_<k>.png`` then match the folder),
keeps the scenario's name in metadata.json, and reads old scenario-named folders still."""

from __future__ import annotations

import json
import shutil

import pytest

from roft_sim.cli import main
from roft_sim.datasets import open_sequence
from roft_sim.generation import shipped_scenarios_dir
from roft_sim.generation.jobs import sequence_names_for
from roft_sim.scenario import load_scenario

CI = shipped_scenarios_dir() / "ci"


def test_auto_naming_uses_objects_only_when_they_are_unique():
    box, mustard = (
        load_scenario(CI / f"{n}.toml") for n in ("cracker_box", "mustard_hand_moving_camera")
    )
    assert sequence_names_for([box, mustard], "auto") == ["003_cracker_box", "006_mustard_bottle"]
    assert sequence_names_for([box, box], "auto") == [box.name, box.name]  # then the scenario
    assert sequence_names_for([box], "scenario") == [box.name]


@pytest.mark.render
def test_generate_names_the_folder_by_object_and_keeps_the_scenario(tmp_path, capsys):
    out = tmp_path / "out"
    args = ["generate", str(CI / "cracker_box.toml"), "--frames", "2", "--resolution", "64x48"]
    assert main([*args, "--out", str(out), "--no-progress"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["003_cracker_box"]
    folder = out / "003_cracker_box"
    meta = json.loads((folder / "metadata.json").read_text())
    scenario = load_scenario(CI / "cracker_box.toml")
    assert meta["scenario_name"] == scenario.name != "003_cracker_box"
    assert (folder / "masks" / "gt" / "003_cracker_box_1.png").is_file()
    # a folder named after the scenario (the old layout) still reads, object from metadata
    old = tmp_path / "old" / scenario.name
    shutil.copytree(folder, old)
    seq = open_sequence(old)
    assert seq.object_name == "003_cracker_box" and len(seq) == 2
