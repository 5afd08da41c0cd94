"""The paper run's side-by-side tables, Table IV's row order and the reference-config row."""

from __future__ import annotations

import numpy as np
import pytest

from roft_sim.harness import paper as paper_module
from roft_sim.harness.paper import (
    PAPER_ROWS,
    TABLE4_ORDER_ROWS,
    paper_rows,
    side_by_side_tables,
    table4_order,
    write_paper_tables,
)
from roft_sim.report.paper_reference import ALL, paper_tables


def _table4_as_results(transform=lambda key, metric, value: value) -> dict:
    paper = paper_tables()
    return {
        row.key: {ALL: {m: transform(row.key, m, v) for m, v in paper.table4[row.label].items()}}
        for row in PAPER_ROWS
    }


def test_the_paper_order_gives_tau_one():
    orders = table4_order(_table4_as_results(), paper_tables())
    assert [o.metric for o in orders] == ["add_auc_pct", "rmse_t_cm", "rmse_a_deg"]
    for order in orders:
        assert order.rows == 9 and order.kendall_tau == pytest.approx(1.0)
        assert order.paper_order == order.sim_order
    # best first: the GT rows lead on ADD-AUC, "w/o pose" is last
    assert orders[0].paper_order[0] == "roft_gt_mask_pose"
    assert orders[0].paper_order[-1] == "roft_no_pose"


def test_a_reversed_order_gives_tau_minus_one_and_missing_rows_shrink_the_count():
    reversed_auc = _table4_as_results(lambda k, m, v: -v if m == "add_auc_pct" else v)
    auc = table4_order(reversed_auc, paper_tables())[0]
    assert auc.kendall_tau == pytest.approx(-1.0)
    assert auc.sim_order == tuple(reversed(auc.paper_order))
    partial = {k: v for k, v in _table4_as_results().items() if k in TABLE4_ORDER_ROWS[:2]}
    assert table4_order(partial, paper_tables())[0].kendall_tau is None


def test_side_by_side_shows_paper_sim_and_difference_per_object():
    paper = paper_tables()
    entries = [*paper.objects, ALL]
    dope = paper.table1["DOPE"]
    results = {
        "detector": {e: {m: dope[m][e] + 1.0 for m in dope} for e in entries},
        "roft": {e: {"add_auc_pct": 70.0} for e in entries},
    }
    tables = side_by_side_tables(results, paper, entries)
    columns, rows = tables["ADD-AUC (%)"]
    keys = [c.key for c in columns]
    assert "roft_reference:sim" not in keys  # not run: left out
    assert keys[:4] == ["entry", "detector:paper", "detector:sim", "detector:diff"]
    for row in rows:
        assert row["detector:diff"] == pytest.approx(1.0)
        assert row["roft:diff"] == pytest.approx(
            70.0 - paper.table1["ROFT"]["add_auc_pct"][row["entry"]]
        )
    results["roft_reference"] = results["roft"]
    keys = [c.key for c in side_by_side_tables(results, paper, entries)["ADD-AUC (%)"][0]]
    assert "roft_reference:sim" in keys and keys.index("roft_reference:sim") < keys.index(
        "roft:sim"
    )


def test_tables_md_holds_the_side_by_side_and_the_order(tmp_path):
    path, _ = write_paper_tables(tmp_path, PAPER_ROWS, _table4_as_results())
    text = path.read_text()
    assert "## Side by side" in text and "Kendall tau" in text and "tau +1.000 over 9 rows" in text


def test_the_reference_row_is_a_paper_row_not_a_plugin_row(monkeypatch):
    assert "roft_reference" in [r.key for r in paper_rows(plugins=False)]
    registered = dict.fromkeys(["roft", "detector-hold", "detector-ideal", "roft-reference"])
    monkeypatch.setattr(paper_module, "discover_trackers", lambda: registered)
    keys = [r.key for r in paper_rows()]
    assert keys.count("roft_reference") == 1
    assert "plugin:roft-reference" not in keys


def test_the_reference_configuration_gets_its_own_order():
    default = _table4_as_results()
    reference = {
        "roft_reference" + key.removeprefix("roft"): value
        for key, value in _table4_as_results(lambda k, m, v: -v if m == "rmse_t_cm" else v).items()
        if key in TABLE4_ORDER_ROWS
    }
    results = default | reference
    ref_orders = table4_order(results, paper_tables(), configuration="roft_reference")
    assert [o.rows for o in ref_orders] == [9, 9, 9]
    assert ref_orders[0].kendall_tau == pytest.approx(1.0)
    assert ref_orders[1].kendall_tau == pytest.approx(-1.0)  # e_t reversed
    assert table4_order(results, paper_tables())[1].kendall_tau == pytest.approx(1.0)


@pytest.mark.parametrize("seed", range(6))
def test_kendall_tau_b_equals_scipys(seed):
    from scipy.stats import kendalltau

    from roft_sim.harness.paper import kendall_tau_b

    rng = np.random.default_rng(seed)
    x = rng.integers(0, 5, 9).astype(float)  # with ties
    y = rng.integers(0, 5, 9).astype(float)
    assert kendall_tau_b(list(x), list(y)) == pytest.approx(kendalltau(x, y).statistic)
    assert np.isnan(kendall_tau_b([1.0, 1.0, 1.0], [1.0, 2.0, 3.0]))
