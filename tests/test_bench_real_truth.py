"""``bench/real_truth.py``: marker corners on real photographs against a ChArUco board's geometry."""

import numpy as np
import pytest

from tests.conftest import load_bench

real_truth = load_bench("real_truth")


@pytest.fixture(scope="module")
def result():
    return real_truth.run(1.6)


def test_the_truth_is_consistent_with_itself_and_with_a_second_corner_finder(result):
    for row in result["images"]:
        # each chessboard corner predicted from its neighbours, and OpenCV's X-junctions against
        # visloc's saddle fit: both well under the peers' corner errors (0.7-1 px)
        assert row["loo_median_px"] < 0.35, row
        assert row["saddle_agreement_median_px"] < 0.25, row
        assert row["markers_with_truth"] >= 10 and len(row["interior_markers"]) >= 3


def test_the_truth_puts_a_synthetic_board_where_it_was_drawn():
    # a board drawn by OpenCV at a known scale: the truth of every marker equals its drawn corners
    board = real_truth.BOARD
    px_per_m = 2000.0
    image = board.opencv.generateImage((int(5 * 0.04 * px_per_m), int(7 * 0.04 * px_per_m)))
    ids, px = real_truth.opencv_chess(image)
    truth, interior, loo = real_truth.board_truth(ids, px, 1.6)
    assert len(truth) == 17 and np.median(loo) < 0.05
    assert len(interior) == 7  # the markers whose square has no side on the board's edge
    for mid, obj in zip(board.marker_ids.tolist(), board.marker_corners, strict=True):
        drawn = obj[:, :2] * px_per_m - 0.5  # board metres -> pixel centres (the image's corner at -0.5)
        np.testing.assert_allclose(truth[mid], drawn, atol=0.1)


def test_visloc_corners_are_nearer_the_truth_than_opencvs_on_the_real_photos(result):
    for scope, rows in result["pooled"].items():
        v = rows["visloc"]
        assert v["found"] == v["with_truth"], (scope, v)  # every marker with a truth found
        for peer in ("opencv", "opencv_subpix", "opencv_contour"):
            assert v["median_px"] < 0.6 * rows[peer]["median_px"], (scope, peer, v, rows[peer])
            assert abs(v["radial_mean_px"]) < abs(rows[peer]["radial_mean_px"]), (scope, peer)
        assert v["median_px"] < rows["opencv_apriltag"]["median_px"], (scope, v, rows["opencv_apriltag"])
        assert v["median_px_saddle_truth"] < rows["opencv_subpix"]["median_px_saddle_truth"]
    assert result["pooled"]["interior"]["visloc"]["median_px"] < 0.35
