"""Tests of the synthetic marker renderer: exact geometry, ground truth, files, arguments."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from scipy.spatial import ConvexHull

from visloc.boards import CharucoBoard
from visloc.markers.dictionary import load_dictionary
from visloc.synth import (
    TEXTURES,
    default_camera,
    imu_stream,
    marker_object_points,
    polygon_coverage,
    random_board_scene,
    random_scene,
    render_dataset,
    render_markers,
    render_video,
    write_camera_yml,
)
from visloc.synth.calibration import calibration_views
from visloc.types import Pose

FACING = np.diag([1.0, -1.0, -1.0])  # marker x right, y up (image up), z towards the camera
K640 = default_camera((640, 480))


def _fronto(t: tuple[float, float, float], marker_id: int = 3, length: float = 0.2):
    return [(marker_id, Pose(FACING, np.array(t, float)), length)]


def _measure_edges(image: np.ndarray, corners: np.ndarray, n_cells: int) -> np.ndarray:
    """Edge positions [left x, right x, top y, bottom y] of an axis-aligned black square with
    a white quiet zone, from the identity: over a window spanning an edge, the sum of the
    normalised intensities is the white length (pixel j covers [j - 0.5, j + 0.5])."""
    img = image.astype(float) / 255.0
    left, right = corners[0, 0], corners[1, 0]
    top, bottom = corners[0, 1], corners[3, 1]
    half = 0.5 * (right - left) / n_cells
    row = int(np.rint(0.5 * (top + bottom)))
    col = int(np.rint(0.5 * (left + right)))

    def window(e: float) -> tuple[int, int]:
        return int(np.ceil(e - half)), int(np.floor(e + half))

    a, b = window(left)
    x_left = a - 0.5 + img[row, a : b + 1].sum()  # white on the left of the edge
    a, b = window(right)
    x_right = b + 0.5 - img[row, a : b + 1].sum()  # white on the right
    a, b = window(top)
    y_top = a - 0.5 + img[a : b + 1, col].sum()
    a, b = window(bottom)
    y_bottom = b + 0.5 - img[a : b + 1, col].sum()
    return np.array([x_left, x_right, y_top, y_bottom])


def _truth_edges(corners: np.ndarray) -> np.ndarray:
    return np.array([corners[0, 0], corners[1, 0], corners[0, 1], corners[3, 1]])


OFFSETS = [(0.0123, -0.0071, 1.0), (-0.0417, 0.0309, 0.93), (0.0, 0.0, 1.1), (0.1, 0.05, 1.27)]


@pytest.mark.parametrize("t", OFFSETS)
@pytest.mark.parametrize(
    "blur", [{}, {"blur_sigma": 1.5}, {"motion_blur": 6.0, "motion_angle": 0.3}]
)
def test_edges_sit_at_ground_truth(t, blur):
    render = render_markers(K640, (640, 480), _fronto(t), "DICT_4X4_50", **blur)
    corners = render.markers[0].corners
    # the corner positions are deliberately not on a pixel or half-pixel grid
    assert render.markers[0].visible
    err = _measure_edges(render.image, corners, 6) - _truth_edges(corners)
    assert np.all(np.abs(err) < 0.02), err


@pytest.mark.parametrize("t", OFFSETS[:2])
def test_supersampled_warp_agrees_within_its_sampling_step(t):
    s = 8
    render = render_markers(K640, (640, 480), _fronto(t), "DICT_4X4_50", supersample=s)
    corners = render.markers[0].corners
    err = _measure_edges(render.image, corners, 6) - _truth_edges(corners)
    assert np.all(np.abs(err) <= 0.5 / s + 0.01), err


def test_exact_and_supersampled_renders_agree():
    scene = random_scene(3, size=(320, 240), difficulty="easy", background="flat")
    placements = [(m.id, m.pose, m.length) for m in scene.markers]
    exact = render_markers(scene.K, (320, 240), placements, "DICT_4X4_50")
    warped = render_markers(scene.K, (320, 240), placements, "DICT_4X4_50", supersample=8)
    diff = exact.image.astype(float) - warped.image.astype(float)
    assert np.abs(diff).mean() < 0.5
    ink_exact = (255.0 - exact.image).sum()
    assert abs(diff.sum()) < 2e-3 * ink_exact


def test_polygon_coverage_is_exact():
    # an axis-aligned rectangle has known per-pixel coverage
    rect = np.array([[0.2, 1.1], [3.7, 1.1], [3.7, 2.4], [0.2, 2.4]])
    cov = polygon_coverage([rect], [1.0], (5, 6))
    xs = np.clip(np.minimum(np.arange(6) + 0.5, 3.7) - np.maximum(np.arange(6) - 0.5, 0.2), 0, 1)
    ys = np.clip(np.minimum(np.arange(5) + 0.5, 2.4) - np.maximum(np.arange(5) - 0.5, 1.1), 0, 1)
    np.testing.assert_allclose(cov, np.outer(ys, xs), atol=1e-12)
    # random convex polygons: values in [0, 1]; inside the grid, total = area
    rng = np.random.default_rng(0)
    for k in range(20):
        lo, hi = (-10, 40) if k % 2 else (0, 29)
        pts = rng.uniform(lo, hi, (8, 2))
        hull = pts[ConvexHull(pts).vertices]
        cov = polygon_coverage([hull], [1.0], (30, 30))
        assert cov.min() > -1e-9 and cov.max() < 1 + 1e-9
        if k % 2 == 0:
            q = np.roll(hull, -1, axis=0)
            area = 0.5 * abs(np.sum(hull[:, 0] * q[:, 1] - q[:, 0] * hull[:, 1]))
            assert cov.sum() == pytest.approx(area, abs=1e-9)


def test_coverages_of_many_grids_at_once_are_each_grids_own_to_the_bit():
    from visloc.synth.raster import edge_coverage, polygon_edges, window_coverages

    rng = np.random.default_rng(3)
    sets, shapes = [], []
    for k in range(7):  # convex polygons, holes, parts outside, some grids empty of edges
        shape = (int(rng.integers(1, 25)), int(rng.integers(1, 25)))
        polys, weights = [], []
        for _ in range(int(rng.integers(0, 4))):
            pts = rng.uniform(-6, 30, (7, 2))
            polys.append(pts[ConvexHull(pts).vertices])
            weights.append(float(rng.choice([1.0, -1.0, 0.5])))
        sets.append(polygon_edges(polys, weights))
        shapes.append(shape)
    window = np.concatenate([np.full(len(w), i) for i, (_, _, w) in enumerate(sets)])
    together = window_coverages(np.concatenate([a for a, _, _ in sets]), np.concatenate([b for _, b, _ in sets]),
                                np.concatenate([w for _, _, w in sets]), window, shapes)
    for (a, b, w), shape, cov in zip(sets, shapes, together, strict=True):
        assert cov.shape == shape
        assert np.array_equal(cov, edge_coverage(a, b, w, shape))  # the same bits, not just close
    with pytest.raises(ValueError, match="weights"):
        polygon_edges([np.eye(3)[:, :2]], [1.0, 2.0])
    with pytest.raises(ValueError, match="n, 2"):
        polygon_edges([np.ones((4, 3))], [1.0])


def test_corners_are_projections_of_the_pose():
    render = random_scene(np.random.default_rng(11), difficulty="hard", n_markers=4)
    assert len(render.markers) == 4
    for m in render.markers:
        obj = marker_object_points(m.length)
        proj, _ = cv2.projectPoints(obj, m.pose.rvec, m.pose.t, render.K, None)
        np.testing.assert_allclose(m.corners, proj.reshape(4, 2), atol=1e-9)
        assert m.visible


def test_seeded_scenes_are_deterministic():
    a = random_scene(np.random.default_rng(5), difficulty="hard")
    b = random_scene(np.random.default_rng(5), difficulty="hard")
    c = random_scene(np.random.default_rng(6), difficulty="hard")
    assert np.array_equal(a.image, b.image)
    assert a.params == b.params
    for ma, mb in zip(a.markers, b.markers, strict=True):
        assert ma.id == mb.id and np.array_equal(ma.corners, mb.corners)
    assert not np.array_equal(a.image, c.image)


def _sample_cells(image: np.ndarray, corners: np.ndarray, n: int) -> np.ndarray:
    """Mean-free bilinear samples at the centres of an (n + 2) x (n + 2) grid of cells: the
    quiet-zone ring, the border ring and the bits, through the corners' homography."""
    src = np.array([[0, 0], [n, 0], [n, n], [0, n]], np.float32)
    H = cv2.getPerspectiveTransform(src, corners.astype(np.float32))
    g = np.arange(-1, n + 1) + 0.5
    gx, gy = np.meshgrid(g, g)
    pts = cv2.perspectiveTransform(np.c_[gx.ravel(), gy.ravel()][None].astype(np.float64), H)[0]
    mx = pts[:, 0].reshape(gx.shape).astype(np.float32)
    my = pts[:, 1].reshape(gx.shape).astype(np.float32)
    return cv2.remap(image.astype(np.float32), mx, my, cv2.INTER_LINEAR)


@pytest.mark.parametrize("difficulty,seed", [("easy", 0), ("easy", 1), ("small", 2), ("hard", 4)])
def test_rendered_markers_decode_from_ground_truth_corners(difficulty, seed):
    dic = load_dictionary("DICT_4X4_50")
    render = random_scene(seed, difficulty=difficulty, background="flat")
    assert render.markers
    for m in render.markers:
        v = _sample_cells(render.image, m.corners, 6)  # 8 x 8: quiet zone, border, 4 x 4 bits
        quiet = np.r_[v[0], v[-1], v[1:-1, 0], v[1:-1, -1]]
        border = np.r_[v[1, 1:-1], v[-2, 1:-1], v[2:-2, 1], v[2:-2, -2]]
        thr = 0.5 * (np.median(quiet) + np.median(border))
        assert np.all(border < thr) and np.all(quiet > thr)
        np.testing.assert_array_equal((v[2:-2, 2:-2] > thr).astype(np.uint8), dic.bits[m.id])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_opencv_aruco_finds_the_same_markers_and_corners(seed):
    render = random_scene(seed, difficulty="easy")
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), params)
    corners, ids, _ = det.detectMarkers(render.image)
    assert ids is not None
    found = {int(i): c.reshape(4, 2) for i, c in zip(ids.ravel(), corners, strict=True)}
    assert set(found) == {m.id for m in render.markers}
    for m in render.markers:
        assert np.linalg.norm(found[m.id] - m.corners, axis=1).max() < 1.5


def test_back_facing_and_behind_markers_are_not_drawn():
    behind = (0, Pose(np.eye(3), np.array([0.0, 0.0, -1.0])), 0.2)  # faces +z, behind camera
    back = (1, Pose(np.eye(3), np.array([0.0, 0.0, 1.0])), 0.2)  # printed face away from camera
    render = render_markers(K640, (640, 480), [behind, back], "DICT_4X4_50")
    assert np.all(render.image == 128)
    assert not any(m.visible for m in render.markers)


def test_partly_visible_marker_is_drawn_but_not_visible():
    crossing = Pose(FACING, np.array([0.5, 0.0, 1.0]))  # straddles the right image border
    near_plane = Pose(FACING @ cv2.Rodrigues(np.array([1.3, 0.0, 0.0]))[0], np.array([0, 0, 0.05]))
    render = render_markers(K640, (640, 480), [(0, crossing, 0.3), (1, near_plane, 0.5)],
                            "DICT_4X4_50")
    assert not render.markers[0].visible and not render.markers[1].visible
    assert np.any(render.image[:, -1] != 128)


def test_scene_difficulties():
    for seed in range(6):
        hard = random_scene(seed, difficulty="hard").params
        assert (hard["blur_sigma"] >= 1 or hard["motion_blur"] >= 3 or hard["noise_sigma"] >= 4
                or hard["gain"] <= 0.5 or hard["gradient"] >= 0.3 or hard["jpeg_quality"])
        small = random_scene(seed, difficulty="small", size=(640, 480))
        for m in small.markers:
            side = np.linalg.norm(np.diff(np.r_[m.corners, m.corners[:1]], axis=0), axis=1)
            assert side.max() < 0.1 * 480 and side.min() > 0.02 * 480
    empty = random_scene(0, difficulty="empty")
    assert empty.markers == [] and empty.params["background"] in TEXTURES
    assert empty.image.std() > 10


def test_render_dataset_writes_readable_files(tmp_path):
    seen = []
    out = render_dataset(tmp_path / "ds", 2, seed=3, size=(160, 120), progress=seen.append)
    assert seen == [0, 1]
    gt = json.loads((out / "ground_truth.json").read_text())
    assert gt["dictionary"] == "DICT_4X4_50" and gt["size"] == [160, 120]
    assert gt["camera"]["dist"] == [-0.05, 0, 0, 0, 0] and gt["camera_like"]  # DATASET_LENS
    assert len(gt["frames"]) == 2
    for frame in gt["frames"]:
        img = cv2.imread(str(out / frame["file"]), cv2.IMREAD_UNCHANGED)
        assert img.shape == (120, 160) and img.dtype == np.uint8
        for m in frame["markers"]:
            assert set(m) >= {"id", "corners", "rvec", "tvec", "length"}
            proj, _ = cv2.projectPoints(marker_object_points(m["length"]), np.array(m["rvec"]),
                                        np.array(m["tvec"]), np.array(gt["camera"]["K"]),
                                        np.array(gt["camera"]["dist"]))
            np.testing.assert_allclose(proj.reshape(4, 2), m["corners"], atol=1e-6)
    fs = cv2.FileStorage(str(out / "camera.yml"), cv2.FILE_STORAGE_READ)
    np.testing.assert_allclose(fs.getNode("camera_matrix").mat(), gt["camera"]["K"])
    np.testing.assert_allclose(fs.getNode("distortion_coefficients").mat(), [gt["camera"]["dist"]])
    assert int(fs.getNode("image_width").real()) == 160
    fs.release()
    fs.release()
    linear = json.loads((render_dataset(tmp_path / "lin", 1, seed=3, size=(160, 120), camera=False)
                         / "ground_truth.json").read_text())
    assert linear["camera"]["dist"] == [0, 0, 0, 0, 0] and not linear["camera_like"]
    # frame i does not depend on n
    again = render_dataset(tmp_path / "ds1", 1, seed=3, size=(160, 120))
    assert np.array_equal(cv2.imread(str(again / "frame_0000.png"), cv2.IMREAD_UNCHANGED),
                          cv2.imread(str(out / "frame_0000.png"), cv2.IMREAD_UNCHANGED))


def test_render_video_writes_video_and_ground_truth(tmp_path):
    path = render_video(tmp_path / "fly.mp4", 6, size=(160, 120), n_markers=2)
    cap = cv2.VideoCapture(str(path))
    count = 0
    while cap.read()[0]:
        count += 1
    cap.release()
    assert count == 6
    gt = json.loads((tmp_path / "ground_truth.json").read_text())
    assert [f["file"] for f in gt["frames"]] == [f"fly.mp4#{i}" for i in range(6)]
    assert all(len(f["markers"]) == 2 for f in gt["frames"])


FLAT = np.full((480, 640), 128, np.uint8)


@pytest.mark.parametrize(
    "kwargs,exc,word",
    [
        ({"K": np.eye(2)}, ValueError, "K"),
        ({"K": "camera"}, TypeError, "K"),
        ({"size": (640,)}, TypeError, "size"),
        ({"size": (0, 480)}, ValueError, "size"),
        ({"placements": [(99, Pose(FACING, np.array([0, 0, 1.0])), 0.2)]}, ValueError, "id"),
        ({"placements": [(1, "pose", 0.2)]}, TypeError, "pose"),
        ({"placements": [(1, Pose(FACING, np.array([0, 0, 1.0])), -0.2)]}, ValueError, "length"),
        ({"placements": 5}, TypeError, "placements"),
        ({"dictionary": "DICT_NOPE"}, ValueError, "dictionary"),
        ({"supersample": 0}, ValueError, "supersample"),
        ({"supersample": 2.5}, TypeError, "supersample"),
        ({"margin_cells": -1.0}, ValueError, "margin_cells"),
        ({"blur_sigma": -0.1}, ValueError, "blur_sigma"),
        ({"noise_sigma": float("nan")}, ValueError, "noise_sigma"),
        ({"gain": 0.0}, ValueError, "gain"),
        ({"gradient": 1.0}, ValueError, "gradient"),
        ({"jpeg_quality": 0}, ValueError, "jpeg_quality"),
        ({"background": "marble"}, ValueError, "background"),
        ({"background": FLAT[:10]}, ValueError, "background"),
        ({"background": FLAT.astype(np.int32)}, TypeError, "background"),
        ({"rng": "seed"}, TypeError, "rng"),
    ],
)
def test_render_markers_rejects_bad_arguments(kwargs, exc, word):
    args = {"K": K640, "size": (640, 480), "placements": _fronto((0, 0, 1.0)),
            "dictionary": "DICT_4X4_50"} | kwargs
    with pytest.raises(exc, match=word):
        render_markers(args.pop("K"), args.pop("size"), args.pop("placements"),
                       args.pop("dictionary"), **args)


@pytest.mark.parametrize(
    "call,exc",
    [
        (lambda: random_scene(0, difficulty="impossible"), ValueError),
        (lambda: random_scene("seed"), TypeError),
        (lambda: random_scene(0, n_markers=-1), ValueError),
        (lambda: random_scene(0, difficulty="empty", n_markers=2), ValueError),
        (lambda: render_dataset("/nonexistent/never", 0), ValueError),
        (lambda: render_dataset("/nonexistent/never", 1, difficulty="x"), ValueError),
        (lambda: render_dataset("/nonexistent/never", 1, progress=3), TypeError),
        (lambda: render_video("/nonexistent/never.mp4", 1), ValueError),
        (lambda: default_camera((640, 480), hfov_deg=180), ValueError),
    ],
)
def test_scene_and_dataset_functions_reject_bad_arguments(call, exc):
    with pytest.raises(exc):
        call()


def test_an_interrupted_dataset_keeps_ground_truth_for_its_frames(tmp_path):
    import json

    def stop(i):
        if i == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        render_dataset(tmp_path / "ds", 10, seed=3, size=(160, 120), progress=stop)
    gt = json.loads((tmp_path / "ds" / "ground_truth.json").read_text())
    assert [f["file"] for f in gt["frames"]] == [f"frame_{i:04d}.png" for i in range(3)]
    assert (tmp_path / "ds" / "camera.yml").is_file()


@pytest.mark.parametrize("pose, word", [
    (Pose(FACING, np.array([0.0, 0.0, np.nan])), "finite"),
    (Pose(np.full((3, 3), np.inf), np.array([0.0, 0.0, 1.0])), "finite"),
    (Pose(2.0 * FACING, np.array([0.0, 0.0, 1.0])), "rotation"),
    (Pose(np.diag([1.0, 1.0, -1.0]), np.array([0.0, 0.0, 1.0])), "rotation"),  # a mirror
])
def test_a_placement_pose_that_is_not_a_finite_rotation_is_refused(pose, word):
    # a NaN pose used to render nothing, with NaN corners as the marker's truth
    with pytest.raises(ValueError, match=f"placements\\[0\\] pose.*{word}"):
        render_markers(K640, (640, 480), [(3, pose, 0.2)], "DICT_4X4_50")


@pytest.mark.parametrize("call, exc, word", [
    (lambda: random_scene(-1), ValueError, "rng.*>= 0"),
    (lambda: random_scene(True), TypeError, "rng"),
    (lambda: random_board_scene(-3), ValueError, "rng.*>= 0"),
    (lambda: render_markers(K640, (640, 480), [], "DICT_4X4_50", rng=-1), ValueError, "rng.*>= 0"),
    (lambda: render_markers(K640, (640, 480), [], "DICT_4X4_50", rng=2.5), TypeError, "rng"),
    (lambda: imu_stream(1.0, 100.0, seed=-1), ValueError, "seed"),
    (lambda: calibration_views(CharucoBoard(5, 5, 0.04, 0.03, "DICT_4X4_50"), 1, seed=-1), ValueError, "seed"),
])
def test_negative_or_fractional_seeds_are_refused_naming_the_argument(call, exc, word):
    # numpy's "expected non-negative integer" did not say which argument
    with pytest.raises(exc, match=word):
        call()


def test_write_camera_yml_round_trips_and_refuses_what_it_cannot_write(tmp_path):
    from visloc.pose import Camera

    dist = np.array([-0.1, 0.02, 0.0, 0.0, 0.001])
    cam = Camera.from_file(write_camera_yml(tmp_path / "cam.yml", K640, (640, 480), dist))
    np.testing.assert_array_equal(cam.K, K640)
    np.testing.assert_array_equal(np.ravel(cam.dist), dist)
    assert cam.size == (640, 480)
    for args, exc, word in [((tmp_path / "no" / "cam.yml", K640, (640, 480)), ValueError, "folder"),  # was cv2.error
                            ((tmp_path / "c.yml", np.eye(2), (640, 480)), ValueError, "K"),
                            ((tmp_path / "c.yml", K640, (640, 0)), ValueError, "size"),
                            ((tmp_path / "c.yml", K640, (640, 480), [0.1, np.nan, 0, 0]), ValueError, "dist"),
                            ((tmp_path / "c.yml", K640, (640, 480), [0.1]), ValueError, "dist")]:
        with pytest.raises(exc, match=word):
            write_camera_yml(*args)
    assert not (tmp_path / "c.yml").exists()
