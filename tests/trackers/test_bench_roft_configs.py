"""benchmarks/bench_roft.py: several ROFT configurations measured side by side in one run."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest

BENCH = Path(__file__).parents[2] / "benchmarks"


@pytest.fixture
def bench_roft(monkeypatch: pytest.MonkeyPatch) -> ModuleType:
    """The benchmark module (it pins the BLAS threads in the environment when imported: the
    variables are restored after the test)."""
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.syspath_prepend(str(BENCH))
    spec = importlib.util.spec_from_file_location("bench_roft", BENCH / "bench_roft.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "bench_roft", module)  # its dataclasses look it up
    spec.loader.exec_module(module)
    return module


def _trees(bench_roft: ModuleType, tmp_path: Path) -> list[Any]:
    """A baseline commit's tree and the working tree (labels only: nothing runs)."""
    return [bench_roft.Tree(label, tmp_path, tmp_path) for label in ("abc1234", "now")]


def test_each_tree_runs_under_each_configuration_with_its_own_label(
    bench_roft: ModuleType, tmp_path: Path
) -> None:
    variants = bench_roft.variants_of(_trees(bench_roft, tmp_path), ["default", "reference"])
    assert [(v.label, v.config) for v in variants] == [
        ("abc1234:default", "default"),
        ("now:default", "default"),
        ("abc1234:reference", "reference"),
        ("now:reference", "reference"),
    ]
    pairs = [(a.label, b.label) for a, b in bench_roft.comparisons(variants)]
    # the working tree against each baseline under the same configuration, then across
    # configurations against the first
    assert pairs == [
        ("now:default", "abc1234:default"),
        ("now:reference", "abc1234:reference"),
        ("now:reference", "now:default"),
    ]


def test_one_configuration_keeps_the_tree_labels(bench_roft: ModuleType, tmp_path: Path) -> None:
    variants = bench_roft.variants_of(_trees(bench_roft, tmp_path), ["default"])
    assert [v.label for v in variants] == ["abc1234", "now"]
    assert [(a.label, b.label) for a, b in bench_roft.comparisons(variants)] == [("now", "abc1234")]


def test_the_report_gives_the_median_ratio_of_the_configurations(
    bench_roft: ModuleType, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    variants = bench_roft.variants_of(
        [bench_roft.Tree("now", tmp_path, tmp_path)], ["default", "reference"]
    )
    n = 12
    has_pose = np.arange(n) % 6 == 0
    stages = np.full((n, len(bench_roft.STAGES)), np.nan)
    runs = {
        "now:default": [{"wall": np.full(n, 0.012), "has_pose": has_pose, "stages": stages}],
        "now:reference": [{"wall": np.full(n, 0.003), "has_pose": has_pose, "stages": stages}],
    }
    bench_roft.report("flow given", variants, runs)
    out = capsys.readouterr().out
    assert "now:reference / now:default: median step 0.250x" in out
    rows = [line.split() for line in out.splitlines() if line.strip().startswith("now:")]
    assert [(r[0], r[1]) for r in rows if r[1] == "all"] == [
        ("now:default", "all"),
        ("now:reference", "all"),
    ]
    assert [r for r in rows if r[0] == "now:reference" and r[1] == "all"][0][2] == "3.00"
