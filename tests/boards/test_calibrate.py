"""``visloc calibrate``, ``visloc render board|calibration`` and ``visloc.boards.calibrate``."""

import json

import cv2
import numpy as np
import pytest

from visloc.boards import CharucoBoard, CharucoCorners, calibrate, detect_charuco
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


def test_calibrate_fisheye_json_is_strict(views, tmp_path, capsys):
    # the fisheye model has no standard deviations: they were printed as NaN (not JSON) and
    # written as .nan into the camera file
    _, board, out = views
    cam = tmp_path / "fisheye.yml"
    assert main(["calibrate", str(out), "--board", str(board), "--out", str(cam), "--json", "--quiet",
                 "--model", "fisheye"]) == 0

    def refuse(word):
        raise ValueError(f"not strict JSON: {word}")

    summary = json.loads(capsys.readouterr().out, parse_constant=refuse)
    assert summary["model"] == "fisheye" and summary["std_fx_fy_cx_cy_dist"] == [None] * 8
    assert "nan" not in cam.read_text().lower() and Camera.from_file(cam).model == "fisheye"


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
        calibrate(found, BOARD, (800, 600), model="omnidirectional")  # fisheye is a model now


def test_render_board_prints_to_scale(views, tmp_path):
    _, board, _ = views
    out = tmp_path / "sheet.png"
    assert main(["render", "board", str(board), str(out), "--dpi", "100"]) == 0
    img = cv2.imread(str(out), cv2.IMREAD_GRAYSCALE)
    px = round(0.03 / 0.0254 * 100)  # 118 px per 30 mm square at 100 dpi
    assert img.shape == (6 * px + 2 * (px // 2), 9 * px + 2 * (px // 2))
    assert len(detect_charuco(img, BOARD, response="linear")) == 8 * 5
    assert main(["render", "board", str(board), str(tmp_path / "sheet"), "--dpi", "100"]) == 2


def test_render_board_and_calibration_need_a_charuco_board_file(tmp_path, capsys):
    # a marker map (a board for calibrate, not one to draw) and an infinite square count used
    # to end in internal errors (AttributeError, OverflowError)
    from visloc.pose import GridMap

    GridMap(2, 2, 0.05, 0.01).to_file(tmp_path / "map.yml")
    (tmp_path / "inf.yml").write_text("%YAML:1.0\nboard_type: charuco\nsquares_x: .inf\nsquares_y: 5\n"
                                      "square_length: 0.04\nmarker_length: 0.03\n")
    for argv, message in ((["render", "board", "{d}/map.yml", "{d}/s.png"], "not a ChArUco board file"),
                          (["render", "calibration", "{d}/views", "--board", "{d}/map.yml", "--n", "3"],
                           "not a ChArUco board file"),
                          (["render", "board", "{d}/inf.yml", "{d}/s.png"], "must be integers, got inf")):
        assert main([a.format(d=tmp_path) for a in argv]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and message in err
    assert not (tmp_path / "views").exists() and not (tmp_path / "s.png").exists()


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


def _fisheye_views(board, K, D, size, n=12, seed=4):
    """Board corners seen through a fisheye lens (cv2.fisheye.projectPoints) at varied poses,
    with 0.05 px of noise: the views a wide-angle camera gives, without a renderer."""
    from visloc.boards import CharucoCorners

    rng = np.random.default_rng(seed)
    pts = board.chessboard_corners.astype(np.float64)
    centre = pts.mean(axis=0)
    views = []
    while len(views) < n:
        rvec = np.array([rng.uniform(-0.6, 0.6), rng.uniform(-0.6, 0.6), rng.uniform(-np.pi, np.pi)])
        R = cv2.Rodrigues(rvec)[0]
        # the board centre anywhere in a cone of 55 degrees, 0.12-0.3 m away
        direction = np.array([*rng.uniform(-1.4, 1.4, 2), 1.0])
        tvec = direction / np.linalg.norm(direction) * rng.uniform(0.12, 0.3) - R @ centre
        cam = pts @ R.T + tvec
        if (cam[:, 2] <= 0.02).any():
            continue
        px = cv2.fisheye.projectPoints(cam.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, D)[0].reshape(-1, 2)
        inside = (px[:, 0] >= 0) & (px[:, 0] < size[0]) & (px[:, 1] >= 0) & (px[:, 1] < size[1])
        if inside.sum() < 12:
            continue
        ids = np.flatnonzero(inside)
        views.append(CharucoCorners(ids.astype(np.int64), px[ids] + rng.normal(0, 0.05, (len(ids), 2))))
    return views


def _no_nan_in_the_commands_report(cal, capsys):
    """``visloc calibrate``'s JSON is strict JSON (null, not NaN) and its table says n/a."""
    import json

    from visloc.commands.calibrate import _print_summary, _summary
    from visloc.io import to_jsonable

    def refuse(word):
        raise ValueError(word)

    names = [f"v{i}" for i in range(max(cal.views) + 1)]
    report = json.loads(json.dumps(to_jsonable(_summary(cal, names))), parse_constant=refuse)
    assert report["std_fx_fy_cx_cy_dist"] == [None] * 8
    _print_summary(cal, names, [], "out.yml")
    err = capsys.readouterr().err
    assert "+- n/a" in err and "nan" not in err


def test_fisheye_model_recovers_a_wide_angle_camera(tmp_path, capsys):
    # a 190-degree-class lens: f = 250 px on 800 x 600, k1..k4 of a real fisheye
    board = CharucoBoard(9, 6, 0.03, 0.022, "DICT_5X5_100")
    K = np.array([[250.0, 0.0, 401.3], [0.0, 250.0, 297.8], [0.0, 0.0, 1.0]])
    D = np.array([0.021, -0.008, 0.0015, -0.0003])
    size = (800, 600)
    views = _fisheye_views(board, K, D, size)
    cal = calibrate(views, board, size, model="fisheye")
    assert cal.model == "fisheye" and cal.dist.shape == (4,) and np.isnan(cal.std).all()
    assert abs(cal.K[0, 0] - 250.0) < 0.5 and abs(cal.K[1, 1] - 250.0) < 0.5
    assert abs(cal.K[0, 2] - 401.3) < 0.5 and abs(cal.K[1, 2] - 297.8) < 0.5
    assert np.abs(cal.dist - D).max() < 0.01
    assert cal.rms < 0.1 and len(cal.per_view) == len(cal.views)
    # the pinhole models cannot follow the lens: their reprojection error is far larger
    assert calibrate(views, board, size, model="k1k2p1p2k3").rms > 5 * cal.rms
    # the camera file carries the model, and the camera projects as the lens does
    cam = Camera.from_file(cal.to_file(tmp_path / "fisheye.yml"))
    assert cam.model == "fisheye" and np.allclose(cam.dist, cal.dist)
    assert "nan" not in (tmp_path / "fisheye.yml").read_text().lower()  # no .nan deviations written
    _no_nan_in_the_commands_report(cal, capsys)
    p = np.array([[0.3, -0.2, 0.25], [-0.1, 0.05, 0.4]])
    expected = cv2.fisheye.projectPoints(p.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cal.K, cal.dist)[0]
    assert np.allclose(cam.project(p), expected.reshape(-1, 2))
    assert np.allclose(cam.normalize(cam.project(p)), p[:, :2] / p[:, 2:], atol=1e-9)


def test_corner_ids_off_the_board_are_named():
    n = len(BOARD.chessboard_corners)  # 40
    good = CharucoCorners(np.arange(10), np.random.default_rng(0).uniform(0, 600, (10, 2)))
    for bad, shown in ((np.arange(100, 110), r"\[100, 101, .*109\]"), (np.r_[-1, 1:10], r"\[-1\]"),
                       (np.arange(n - 5, n + 5), rf"\[{n}, .*{n + 4}\]")):
        views = [good, good, CharucoCorners(bad, good.corners), good]
        with pytest.raises(ValueError, match=rf"views\[2\]: corner ids {shown} are not .*\[0, {n}\)"):
            calibrate(views, BOARD, (800, 600))
    with pytest.raises(TypeError, match=r"views\[1\]: corner ids must be integers, got float64"):
        calibrate([good, CharucoCorners(np.arange(10.0), good.corners), good], BOARD, (800, 600))
