"""``visloc calibrate``, ``visloc render board|calibration`` and ``visloc.boards.calibrate``."""

import json

import cv2
import numpy as np
import pytest

from visloc.boards import CharucoBoard, calibrate, detect_charuco
from visloc.cli import main
from visloc.pose import Camera

BOARD = CharucoBoard(9, 6, 0.03, 0.022, "DICT_5X5_100")


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    root = tmp_path_factory.mktemp("calib")
    board = BOARD.to_file(root / "board.yml")
    out = root / "views"
    assert main(["render", "calibration", str(out), "--board", str(board), "--n", "10", "--size", "800x600",
                 "--seed", "3"]) == 0
    return root, board, out


def test_calibrate_recovers_the_rendered_camera(views, tmp_path, capsys):
    _, board, out = views
    cam, cover = tmp_path / "camera.yml", tmp_path / "coverage.png"
    assert main(["calibrate", str(out), "--board", str(board), "--out", str(cam), "--json", "--coverage",
                 str(cover)]) == 0
    assert cv2.imread(str(cover)).shape == (600, 800, 3)
    summary = json.loads(capsys.readouterr().out)
    got, truth = Camera.from_file(cam), Camera.from_file(out / "camera_truth.yml")
    np.testing.assert_allclose(got.K, truth.K, atol=2.0)  # px, of focal lengths near 600 px
    assert abs(got.dist[0] - truth.dist[0]) < 0.02
    assert summary["views"] == 10 and summary["rms_px"] < 0.3
    fs = cv2.FileStorage(str(cam), cv2.FILE_STORAGE_READ)
    assert fs.getNode("per_view_rms_px").mat().size == 10 and fs.getNode("reprojection_rms_px").real() < 0.3
    fs.release()


def test_calibrate_api_leaves_out_thin_views(views):
    _, _, out = views
    found = [detect_charuco(cv2.imread(str(p)), BOARD) for p in sorted(out.glob("view_*.png"))]
    thin = found[:3] + [found[3].__class__(found[3].ids[:4], found[3].corners[:4])] + found[4:]
    cal = calibrate(thin, BOARD, (800, 600), model="pinhole-k1k2")
    assert 3 not in cal.views and len(cal.per_view) == len(found) - 1
    assert len(cal.dist) == 5 and cal.dist[2] == cal.dist[3] == cal.dist[4] == 0
    with pytest.raises(ValueError, match="at least 3 views"):
        calibrate(found[:2], BOARD, (800, 600))
    with pytest.raises(ValueError, match="model"):
        calibrate(found, BOARD, (800, 600), model="fisheye")


def test_render_board_prints_to_scale(views, tmp_path):
    _, board, _ = views
    out = tmp_path / "sheet.png"
    assert main(["render", "board", str(board), str(out), "--dpi", "100"]) == 0
    img = cv2.imread(str(out), cv2.IMREAD_GRAYSCALE)
    px = round(0.03 / 0.0254 * 100)  # 118 px per 30 mm square at 100 dpi
    assert img.shape == (6 * px + 2 * (px // 2), 9 * px + 2 * (px // 2))
    assert len(detect_charuco(img, BOARD, response="linear")) == 8 * 5
    assert main(["render", "board", str(board), str(tmp_path / "sheet"), "--dpi", "100"]) == 2


def test_bad_inputs_are_one_line_errors(views, tmp_path, capsys):
    _root, board, out = views
    empty = tmp_path / "empty"
    empty.mkdir()
    cv2.imwrite(str(empty / "grey.png"), np.full((120, 160), 128, np.uint8))
    assert main(["calibrate", str(empty), "--board", str(board), "--out", str(tmp_path / "c.yml")]) == 2
    assert "at least 3 views" in capsys.readouterr().err
    bad = tmp_path / "bad.yml"
    bad.write_text("%YAML:1.0\n---\nboard_type: charuco\nsquares_x: 3\n")
    assert main(["calibrate", str(out), "--board", str(bad), "--out", str(tmp_path / "c.yml")]) == 2
    assert "squares_y" in capsys.readouterr().err
    assert main(["calibrate", str(out), "--board", str(board), "--out", str(out / "c.yml")]) == 2  # into an input


def test_a_printed_marker_grid_calibrates_the_camera(tmp_path):
    """visloc's own GridMap as the board (MarkerBoard): camera-like 800x600 views with lens
    distortion (marker_map_views), through visloc calibrate with the map file as --board."""
    from visloc.pose.maps import GridMap
    from visloc.synth.calibration import CALIBRATION_CAMERA, marker_map_views

    grid = GridMap(rows=5, cols=7, marker_length=0.04, spacing=0.01, dictionary="DICT_4X4_50")
    grid.to_file(tmp_path / "grid.yml")
    (tmp_path / "views").mkdir()
    views = marker_map_views(grid, "DICT_4X4_50", 12, size=(800, 600), seed=1)
    for k, view in enumerate(views):
        cv2.imwrite(str(tmp_path / "views" / f"v{k:02d}.png"), view.render.image)
    cam = tmp_path / "cam.yml"
    assert main(["calibrate", str(tmp_path / "views"), "--board", str(tmp_path / "grid.yml"), "--out", str(cam),
                 "--quiet"]) == 0
    got, K = Camera.from_file(cam), views[0].render.K
    assert np.abs(got.K[[0, 1, 0, 1], [0, 1, 2, 2]] - K[[0, 1, 0, 1], [0, 1, 2, 2]]).max() < 1.0  # px
    assert got.dist[0] == pytest.approx(CALIBRATION_CAMERA.k1, abs=0.01)
