"""Tests of the AprilGrid renderer: ground truth, Kalibr's layout, OpenCV reads it, arguments."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from visloc.pose.maps import GridMap
from visloc.synth import (
    CameraEffects,
    aprilgrid_tag_corners,
    default_camera,
    marker_object_points,
    random_board_scene,
    render_aprilgrid,
)
from visloc.types import Pose

FACING = np.diag([1.0, -1.0, -1.0])  # board x right, y up (image up), z towards the camera
K640 = default_camera((640, 480))


def _fronto(rows: int, cols: int, L: float, depth: float, ratio: float = 0.3) -> Pose:
    """Fronto-parallel board pose with the tags' block centred on the optical axis."""
    s = ratio * L
    width, height = cols * L + (cols - 1) * s, rows * L + (rows - 1) * s
    return Pose(FACING, np.array([-0.5 * width, -0.5 * height, depth]))


def test_ground_truth_is_cv2_projection_of_the_tag_corners():
    rows, cols, L = 3, 4, 0.05
    R = cv2.Rodrigues(np.array([0.35, -0.25, 0.1]))[0] @ FACING
    pose = Pose(R, np.array([-0.12, -0.05, 0.6]))
    camera = CameraEffects(k1=-0.12, k2=0.02)
    render = render_aprilgrid(K640, (640, 480), pose, rows=rows, cols=cols, tag_length=L,
                              first_id=7, camera=camera, rng=0)
    assert [m.id for m in render.markers] == list(range(7, 7 + rows * cols))
    assert all(m.visible for m in render.markers)
    np.testing.assert_array_equal(render.dist, camera.dist)
    board = aprilgrid_tag_corners(rows, cols, L)
    grid = GridMap(rows, cols, L, 0.3 * L, first_id=7)  # the same board frame as visloc's maps
    for m, corners in zip(render.markers, board, strict=True):
        np.testing.assert_allclose(grid.corners_of(m.id), corners, atol=1e-12)
        uv, _ = cv2.projectPoints(corners, pose.rvec, pose.t, K640, render.dist)
        np.testing.assert_allclose(m.corners, uv.reshape(4, 2), atol=1e-6)
        uv, _ = cv2.projectPoints(marker_object_points(L), m.pose.rvec, m.pose.t, K640,
                                  render.dist)
        np.testing.assert_allclose(m.corners, uv.reshape(4, 2), atol=1e-6)
        assert m.length == L


def test_corner_squares_touch_the_tags_at_their_corners():
    # 500 px/m at 1 m: tags 40 px, gaps and corner squares 12 px, every corner on a pixel centre
    K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
    pose = Pose(FACING, np.array([-0.2, -0.2, 1.0]))
    render = render_aprilgrid(K, (640, 480), pose, rows=4, cols=5, tag_length=0.08)
    img = render.image.astype(int)
    for m in render.markers:
        centre = m.corners.mean(axis=0)
        for corner in m.corners:
            x, y = (int(v) for v in np.rint(corner))
            np.testing.assert_allclose(corner, (x, y), atol=1e-9)
            ox, oy = (int(v) for v in np.sign(corner - centre))  # away from the tag
            # the pixel on the touching point: half black (tag, corner square), half white (gaps)
            assert img[y, x] in (127, 128)
            assert img[y + 6 * oy, x + 6 * ox] == 0  # corner square, diagonally outwards
            assert img[y - 2 * oy, x - 2 * ox] == 0  # the tag's border
            assert img[y + 6 * oy, x - 6 * ox] == 255  # gap
            assert img[y - 6 * oy, x + 6 * ox] == 255  # gap


def test_opencv_detects_a_clean_fronto_parallel_board():
    rows, cols = 4, 5
    render = render_aprilgrid(K640, (640, 480), _fronto(rows, cols, 0.05, 0.45), rows=rows,
                              cols=cols, tag_length=0.05)
    detector = cv2.aruco.ArucoDetector(
        cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    )
    corners, ids, _ = detector.detectMarkers(render.image)
    truth = {m.id: m.corners for m in render.markers}
    found = {} if ids is None else {int(i): c.reshape(4, 2) for i, c in zip(ids.ravel(), corners)}
    assert set(found) <= set(truth)
    assert len(found) >= 0.8 * rows * cols
    # OpenCV's unrefined corners sit ~2.3 px inside these tags (~0.8 px on isolated markers):
    # the touching corner squares cut its contours' corners; a wrong orientation is ~7 px off.
    for marker_id, c in found.items():
        assert np.abs(c - truth[marker_id]).max() < 3.0


def test_random_board_scene_fits_the_image_and_is_deterministic():
    a = random_board_scene(3, difficulty="hard")
    b = random_board_scene(np.random.default_rng(3), difficulty="hard")
    np.testing.assert_array_equal(a.image, b.image)
    assert a.params["difficulty"] == "hard" and "camera" in a.params
    p = a.params
    assert 3 <= p["rows"] <= 6 and 3 <= p["cols"] <= 6
    assert len(a.markers) == p["rows"] * p["cols"]
    assert all(m.visible for m in a.markers)
    sides = [np.linalg.norm(np.roll(m.corners, -1, axis=0) - m.corners, axis=1).min()
             for m in a.markers]
    assert min(sides) > 12.0
    clean = random_board_scene(4, camera=False, size=(320, 240))
    assert clean.image.shape == (240, 320) and "camera" not in clean.params


def test_a_board_seen_from_behind_is_not_drawn():
    pose = _fronto(2, 2, 0.05, 0.4)
    back = Pose(pose.R @ np.diag([-1.0, 1.0, -1.0]), pose.t)
    render = render_aprilgrid(K640, (640, 480), back, rows=2, cols=2, tag_length=0.05)
    assert np.all(render.image == 128)
    assert not any(m.visible for m in render.markers)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"rows": 0}, "rows"),
        ({"cols": -2}, "cols"),
        ({"tag_length": 0.0}, "tag_length"),
        ({"spacing_ratio": 0.0}, "spacing_ratio"),
        ({"first_id": 584}, "first_id"),
        ({"rows": 30, "cols": 30}, "rows \\* cols"),
        ({"blur_sigma": 1.0, "camera": CameraEffects()}, "blur_sigma"),
        ({"size": (4, 4)}, "size"),
    ],
)
def test_bad_arguments_raise_value_error_naming_them(kwargs, name):
    args = {"K": K640, "size": (640, 480), "pose": _fronto(2, 2, 0.05, 0.4), "rows": 2,
            "cols": 2, "tag_length": 0.05, **kwargs}
    with pytest.raises(ValueError, match=name):
        render_aprilgrid(args.pop("K"), args.pop("size"), args.pop("pose"), **args)


def test_bad_types_and_scene_arguments():
    with pytest.raises(TypeError, match="pose"):
        render_aprilgrid(K640, (640, 480), (np.eye(3), np.zeros(3)), rows=2, cols=2,
                         tag_length=0.05)
    with pytest.raises(ValueError, match="pose"):
        render_aprilgrid(K640, (640, 480), Pose(2.0 * np.eye(3), np.ones(3)), rows=2, cols=2,
                         tag_length=0.05)
    with pytest.raises(ValueError, match="difficulty"):
        random_board_scene(0, difficulty="small")
    with pytest.raises(ValueError, match="size"):
        random_board_scene(0, size=(120, 120))


def test_a_board_that_just_fits_is_placed():
    # this seed draws a board 2 half-extents + 8 px high: the centre's range used to be empty
    scene = random_board_scene(np.random.default_rng([9, 1, 8]), camera=False)
    assert all(m.visible for m in scene.markers)
