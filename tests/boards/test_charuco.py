"""ChArUco boards: geometry against OpenCV's, board files, corners in renders and photos."""

from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from visloc.boards import CharucoBoard, detect_charuco, refine_saddles
from visloc.synth import default_camera
from visloc.synth.camera import CameraEffects
from visloc.synth.charuco import render_charuco
from visloc.types import Pose

REAL = Path(__file__).resolve().parents[2] / "datasets/real"
TUTORIAL = CharucoBoard(5, 7, 0.04, 0.02, "DICT_6X6_250")  # OpenCV's tutorial board (choriginal.jpg)
BOARD = CharucoBoard(7, 5, 0.04, 0.03, "DICT_5X5_100")


@pytest.mark.parametrize("board", [TUTORIAL, BOARD, CharucoBoard(6, 6, 0.03, 0.02, "DICT_4X4_50", first_id=3),
                                   CharucoBoard(6, 6, 0.03, 0.02, "DICT_4X4_50", legacy=True)])
def test_geometry_is_opencvs(board):
    cv_board = cv2.aruco.CharucoBoard((board.squares_x, board.squares_y), board.square_length,
                                      board.marker_length, cv2.aruco.getPredefinedDictionary(
                                          getattr(cv2.aruco, board.dictionary)),
                                      np.arange(board.first_id, board.first_id + board.n_markers))
    cv_board.setLegacyPattern(board.legacy)
    np.testing.assert_allclose(board.marker_corners, np.array(cv_board.getObjPoints()).reshape(-1, 4, 3), atol=1e-6)
    np.testing.assert_array_equal(board.marker_ids, cv_board.getIds().ravel())
    np.testing.assert_allclose(board.chessboard_corners, cv_board.getChessboardCorners(), atol=1e-6)
    quads, ids, _ = board.black_squares
    assert len(quads) == board.squares_x * board.squares_y - board.n_markers
    for q, corner_ids in zip(quads, ids, strict=True):  # each inner corner of a black square has its id
        for p, j in zip(q, corner_ids, strict=True):
            if j >= 0:
                np.testing.assert_allclose(board.chessboard_corners[j, :2], p, atol=1e-9)
    assert all(1 <= len(a) <= 2 for a in board.adjacent_markers)


def test_board_file_round_trip_and_bad_files(tmp_path):
    board = CharucoBoard(9, 6, 0.03, 0.022, "DICT_5X5_100", first_id=2, legacy=True)
    assert CharucoBoard.from_file(board.to_file(tmp_path / "b.yml")) == board
    bad = tmp_path / "bad.yml"
    bad.write_text("%YAML:1.0\n---\nboard_type: charuco\nsquares_x: 5\n")
    with pytest.raises(ValueError, match="squares_y"):
        CharucoBoard.from_file(bad)
    bad.write_text("%YAML:1.0\n---\nboard_type: aprilgrid\n")
    with pytest.raises(ValueError, match="board_type"):
        CharucoBoard.from_file(bad)
    with pytest.raises(ValueError, match="does not exist"):
        CharucoBoard.from_file(tmp_path / "none.yml")
    with pytest.raises(ValueError, match="marker_length"):
        CharucoBoard(5, 5, 0.02, 0.03)
    with pytest.raises(ValueError, match="first_id"):
        CharucoBoard(10, 10, 0.02, 0.01, "DICT_4X4_50", first_id=1)  # 50 markers from id 1: 51 ids needed
    with pytest.raises(ValueError, match="dictionary"):
        CharucoBoard(5, 5, 0.04, 0.02, "tutorial_dict.yml")


def _view(camera, seed):
    rng = np.random.default_rng(seed)
    R = Rotation.from_euler("xyz", rng.uniform(-0.5, 0.5, 3)).as_matrix()
    t = np.array([rng.uniform(-0.04, 0.04), rng.uniform(-0.03, 0.03), rng.uniform(0.35, 0.5)]) - R @ (0.14, 0.1, 0)
    return render_charuco(default_camera((640, 480)), (640, 480), Pose(R, t), BOARD, camera=camera, rng=seed)


@pytest.mark.parametrize("case", ["linear", "camera"])
def test_corners_on_renders_beat_opencv(case):
    camera = None if case == "linear" else CameraEffects(vignetting=0.0)
    ours, theirs, found, visible = [], [], 0, 0
    for seed in range(3):
        view = _view(camera, seed)
        got = detect_charuco(view.image, BOARD, response="linear" if camera is None else "srgb")
        assert set(got.ids.tolist()) <= set(np.flatnonzero(view.visible).tolist())
        ours.extend(np.linalg.norm(got.corners - view.corners[got.ids], axis=1))
        corners, ids, _, _ = cv2.aruco.CharucoDetector(BOARD.opencv).detectBoard(view.image)
        if ids is not None:
            theirs.extend(np.linalg.norm(corners.reshape(-1, 2) - view.corners[ids.ravel()], axis=1))
            found += len(ids)
        visible += int(view.visible.sum())
        assert len(got) >= (0 if ids is None else len(ids))
    rms = np.sqrt(np.mean(np.square(ours)))
    assert len(ours) >= 0.9 * visible
    assert rms < 0.5 * np.sqrt(np.mean(np.square(theirs)))


def test_each_corner_on_both_squares_lines_beats_the_squares_own_corners(monkeypatch):
    # camera-like views, the board whole and running off the image's right edge (squares cut
    # by it lend what they show): the board's lines fitted across both black squares at each
    # corner against the mean of the two squares' own corners
    from visloc.boards import charuco

    views = []
    for seed in range(3):
        for shift in (0.0, 0.12):
            rng = np.random.default_rng(seed)
            R = Rotation.from_euler("xyz", rng.uniform(-0.5, 0.5, 3)).as_matrix()
            t = np.array([rng.uniform(-0.04, 0.04) + shift, rng.uniform(-0.03, 0.03), rng.uniform(0.35, 0.5)])
            views.append(render_charuco(default_camera((640, 480)), (640, 480), Pose(R, t - R @ (0.14, 0.1, 0)),
                                        BOARD, camera=CameraEffects(), rng=seed))
    assert any(not v.visible.all() for v in views)

    def rms():
        errors = []
        for v in views:
            got = detect_charuco(v.image, BOARD)
            assert len(got) == int(v.visible.sum())
            errors.extend(np.linalg.norm(got.corners - v.corners[got.ids], axis=1))
        return float(np.sqrt(np.mean(np.square(errors))))

    joint = rms()
    monkeypatch.setattr(charuco, "_joint_corners", lambda *a, **k: (np.zeros(0, np.int64), np.zeros((0, 2))))
    assert joint < 0.7 * rms()  # 0.019 against 0.033 px here


@pytest.mark.parametrize("name", ["choriginal.jpg", "chocclusion_original.jpg"])
def test_tutorial_photos_match_opencvs_corners(name):
    img = cv2.imread(str(REAL / name), cv2.IMREAD_GRAYSCALE)
    got = detect_charuco(img, TUTORIAL)
    corners, ids, _, _ = cv2.aruco.CharucoDetector(TUTORIAL.opencv).detectBoard(img)
    theirs = {int(i): c.ravel() for i, c in zip(ids.ravel(), corners)}
    assert len(got) >= len(theirs)
    common = [k for k, i in enumerate(got.ids.tolist()) if i in theirs]
    assert len(common) == len(theirs)
    for k in common:
        assert np.linalg.norm(got.corners[k] - theirs[int(got.ids[k])]) < 1.0


def test_an_image_without_the_board_gives_no_corners():
    img = np.full((240, 320), 200, np.uint8)
    got = detect_charuco(img, TUTORIAL)
    assert len(got) == 0 and got.corners.shape == (0, 2)
    with pytest.raises(TypeError, match="CharucoBoard"):
        detect_charuco(img, "board.yml")
    with pytest.raises(ValueError, match="method"):
        detect_charuco(img, TUTORIAL, method="fast")


def test_saddle_fit_finds_a_sharp_x_corner():
    # each pixel the mean of 8 x 8 samples over its area: the corner at (20.3, 19.6) exactly
    yy, xx = (np.mgrid[0:328, 0:328] + 0.5) / 8.0 - 0.5
    c = (20.3, 19.6)
    fine = np.where((xx - c[0] > 0) ^ (yy - c[1] > 0), 200.0, 20.0)
    img = fine.reshape(41, 8, 41, 8).mean(axis=(1, 3))
    p, ok = refine_saddles(img, [[21.0, 19.0]], radius=5)
    assert ok[0] and np.abs(p[0] - c).max() < 0.1  # a quadratic is not the corner's shape: 0.07 px here
    ramp = np.add.outer(np.zeros(41), np.arange(41.0)) ** 2  # a valley along y: no saddle
    assert not refine_saddles(ramp, [[20.0, 20.0]], radius=5)[1][0]


@pytest.mark.parametrize("line, key", [("first_id: 2.7", "first_id"), ('first_id: "two"', "first_id"),
                                       ("legacy: 2", "legacy"), ("legacy: 0.5", "legacy")])
def test_a_board_file_with_a_fractional_or_text_id_or_flag_is_refused(tmp_path, line, key):
    # first_id 2.7 used to be read as 2 (a board two markers off), legacy 0.5 as True
    path = tmp_path / "b.yml"
    path.write_text("%YAML:1.0\n---\nboard_type: charuco\nsquares_x: 5\nsquares_y: 5\nsquare_length: 0.04\n"
                    f"marker_length: 0.03\ndictionary: DICT_4X4_50\n{line}\n")
    with pytest.raises(ValueError, match=key):
        CharucoBoard.from_file(path)
    path.write_text(path.read_text().replace(line, f"{key}: 1"))
    assert getattr(CharucoBoard.from_file(path), key) == 1
