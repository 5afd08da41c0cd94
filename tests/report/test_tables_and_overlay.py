"""Tables (text, Markdown, CSV, LaTeX), overlay silhouettes and videos, the paper's numbers."""

from __future__ import annotations

import csv
import io

import cv2
import numpy as np
import pytest

from roft_sim.errors import ConfigError
from roft_sim.geometry.se3 import transform_from_rt
from roft_sim.geometry.so3 import matrix_from_rotvec
from roft_sim.records import ObjectModel
from roft_sim.report.overlay import (
    ESTIMATE_COLOR,
    GT_COLOR,
    OverlayFrame,
    draw_overlay,
    silhouette_mask,
)
from roft_sim.report.paper_reference import ALL, paper_tables
from roft_sim.report.tables import (
    Column,
    csv_table,
    format_cell,
    latex_table,
    markdown_table,
    text_table,
)
from roft_sim.report.video import VideoWriter
from roft_sim.testing.analytic_scene import AnalyticBox, default_intrinsics, raycast_box

COLUMNS = [Column("name", "name", align="left"), Column("x", "x %", ".2f"), Column("n", "n", "d")]
ROWS = [{"name": "a_b", "x": 1.23456, "n": 3}, {"name": "c|d", "x": None, "n": 4}]


def test_format_cell():
    assert format_cell(1.23456, ".2f") == "1.23"
    assert format_cell(None) == "-" and format_cell(float("nan"), ".2f") == "-"
    assert format_cell(float("inf"), ".2f") == "inf"
    assert format_cell(7, "d") == "7" and format_cell(True) == "yes"


def test_markdown_table():
    md = markdown_table(COLUMNS, ROWS).splitlines()
    assert md == [
        "| name | x % | n |",
        "|:---|---:|---:|",
        "| a_b | 1.23 | 3 |",
        "| c\\|d | - | 4 |",
    ]


def test_text_table_aligns_columns():
    lines = text_table(COLUMNS, ROWS).splitlines()
    assert lines[0].split() == ["name", "x", "%", "n"]
    assert len({len(line) for line in lines[2:]}) == 1


def test_csv_table_keeps_full_precision_and_empty_missing_values():
    rows = list(csv.reader(io.StringIO(csv_table(COLUMNS, ROWS))))
    assert rows == [["name", "x", "n"], ["a_b", "1.23456", "3"], ["c|d", "", "4"]]


def test_latex_table_escapes_and_uses_booktabs():
    tex = latex_table(COLUMNS, ROWS, caption="50% of a_b", label="tab:x")
    assert r"\caption{50\% of a\_b}" in tex and r"\label{tab:x}" in tex
    assert r"a\_b & 1.23 & 3 \\" in tex and r"\toprule" in tex and r"\bottomrule" in tex
    assert r"\begin{tabular}{lrr}" in tex


# ------------------------------------------------------------------------------- overlay
def _box_pose() -> np.ndarray:
    return transform_from_rt(matrix_from_rotvec([0.4, -0.6, 0.3]), [0.01, -0.02, 0.45])


def test_silhouette_matches_an_exact_ray_cast():
    box = AnalyticBox()
    intr = default_intrinsics(160, 120)
    T = _box_pose()
    mask = silhouette_mask(box.object_model(), T, intr)
    depth, _, _ = raycast_box(box.half_extents_m, T, intr)
    truth = depth > 0
    iou = (mask & truth).sum() / (mask | truth).sum()
    assert iou > 0.95
    # every covered pixel centre is in, and the extra pixels lie on the outline (one pixel)
    eroded = cv2.erode(truth.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    dilated = cv2.dilate(truth.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    assert mask[eroded].all() and not mask[~dilated].any()


def test_silhouette_of_the_projected_centre_and_of_bad_poses():
    box = AnalyticBox()
    intr = default_intrinsics(160, 120)
    T = _box_pose()
    mask = silhouette_mask(box.object_model(), T, intr)
    u = intr.fx_px * T[0, 3] / T[2, 3] + intr.cx_px
    v = intr.fy_px * T[1, 3] / T[2, 3] + intr.cy_px
    assert mask[int(round(v)), int(round(u))]
    behind = T.copy()
    behind[2, 3] = -0.5
    assert not silhouette_mask(box.object_model(), behind, intr).any()
    assert not silhouette_mask(box.object_model(), np.full((4, 4), np.nan), intr).any()
    # a model without faces is drawn as its points
    points = ObjectModel(
        name="p",
        vertices_m=np.zeros((0, 3)),
        faces=np.zeros((0, 3), dtype=np.int64),
        model_points_m=np.zeros((1, 3)),
    )
    dots = silhouette_mask(points, T, intr)
    assert dots.sum() == 1 and dots[int(round(v)), int(round(u))]


def test_overlay_draws_the_outlines_where_the_masks_are():
    intr = default_intrinsics(160, 120)
    model = AnalyticBox().object_model()
    T = _box_pose()
    gt = silhouette_mask(model, T, intr)
    moved = T.copy()
    moved[0, 3] += 0.05
    est = silhouette_mask(model, moved, intr)
    rgb = np.full((120, 160, 3), 90, dtype=np.uint8)
    image = draw_overlay(OverlayFrame(rgb=rgb, gt_mask=gt, estimate_mask=est), legend=False)
    # (anti-aliased outline: mostly green pixels)
    green = (image[..., 1] > 150) & (image[..., 0] < 130) & (image[..., 2] < 130)
    assert GT_COLOR[1] > 150
    # the green outline hugs the ground-truth silhouette's border
    border = gt & ~cv2.erode(gt.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    near = cv2.dilate(border.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    assert green.sum() > 20 and not (green & ~near).any()
    # the estimate is tinted towards magenta inside, the image elsewhere is untouched
    inside = est & ~cv2.dilate(gt.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
    inside &= cv2.erode(est.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
    expected = np.round(0.65 * 90 + 0.35 * np.array(ESTIMATE_COLOR)).astype(int)
    np.testing.assert_allclose(
        image[inside].astype(int), np.broadcast_to(expected, (inside.sum(), 3)), atol=1
    )
    far = ~cv2.dilate((gt | est).astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
    far[:30] = False  # text area
    assert (image[far] == 90).all()


@pytest.mark.parametrize("suffix", [".mp4", ".avi", ".gif"])
def test_video_writer_writes_readable_frames(tmp_path, suffix):
    path = tmp_path / "new folder" / f"v{suffix}"
    with VideoWriter(path, fps=30) as video:
        for k in range(5):
            video.write(np.full((48, 64, 3), 40 * k, dtype=np.uint8))
    capture = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(frame)
    assert len(frames) == 5 and frames[0].shape == (48, 64, 3)
    assert abs(int(frames[4].mean()) - 160) < 8


def test_video_writer_errors(tmp_path):
    with pytest.raises(ConfigError, match=r"use one of \.mp4, \.avi, \.gif"):
        VideoWriter(tmp_path / "v.mkv", fps=30)
    with pytest.raises(ConfigError, match="fps must be > 0"):
        VideoWriter(tmp_path / "v.mp4", fps=0)
    video = VideoWriter(tmp_path / "v.mp4", fps=30)
    video.write(np.zeros((48, 64, 3), np.uint8))
    with pytest.raises(ValueError, match="differs from the first frame"):
        video.write(np.zeros((40, 64, 3), np.uint8))
    video.close()


# ------------------------------------------------------------------------------- paper numbers
def test_paper_numbers_are_consistent_across_tables():
    paper = paper_tables()
    assert len(paper.objects) == 6 and "RA-L" in paper.source
    t1, t4 = paper.table1, paper.table4
    # Table IV's ROFT and DOPE rows are Table I's ALL column
    for method in ("ROFT", "DOPE"):
        for metric in ("add_auc_pct", "rmse_t_cm", "rmse_a_deg"):
            assert t4[method][metric] == t1[method][metric][ALL]
    assert t1["ROFT"]["add_auc_pct"]["003_cracker_box"] == 78.50
    assert paper.table2["ROFT"]["rmse_v_cmps"][ALL] == 11.409
    assert paper.table2["ROFT w/o segm. sync."]["rmse_w_dps"][ALL] == 70.164
    assert len(t4) == 11 and t4["ROFT w/o pose"]["rmse_a_deg"] == 80.012
