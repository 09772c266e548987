"""The marker renderer: exact ground truth, determinism, files on disk, bad arguments."""

import json

import cv2
import numpy as np
import pytest

from visloc.markers.bits import read_bits, sample_cells
from visloc.markers.dictionary import load_dictionary
from visloc.synth import (
    default_camera,
    marker_object_points,
    random_scene,
    render_dataset,
    render_markers,
    render_video,
)
from visloc.types import Pose

FACING = np.diag([1.0, -1.0, -1.0])  # marker upright, its face towards the camera


def test_fronto_parallel_edges_sit_where_the_ground_truth_says():
    K = default_camera((200, 160))
    scene = render_markers(K, (200, 160), [(3, Pose(FACING, np.array([0.013, -0.007, 0.9])), 0.2)],
                           "DICT_4X4_50", background="flat", margin_cells=2.0)
    img = scene.image.astype(np.float64)
    c = scene.markers[0].corners
    # a pixel-integrated step from white (255) to black (0) between columns: the sum of the
    # normalised darkness along a row equals the exact black extent, so the left edge x_l is
    # recovered as: x_l = (x0 - 0.5) + sum(white fraction) over columns x0..xm
    row = int(np.ceil(c[0, 1])) + 2  # inside the top border cell (a cell is 1/6 of the side)
    x0 = int(np.floor(c[0, 0])) - 4
    white = img[row, x0 : x0 + 8] / 255.0
    left_edge = (x0 - 0.5) + white.sum()
    assert abs(left_edge - c[0, 0]) < 0.02
    col = int(np.ceil(c[0, 0])) + 2
    y0 = int(np.floor(c[0, 1])) - 4
    top_edge = (y0 - 0.5) + (img[y0 : y0 + 8, col] / 255.0).sum()
    assert abs(top_edge - c[0, 1]) < 0.02


def test_ground_truth_corners_are_the_projected_marker_corners():
    scene = random_scene(5, size=(640, 480), difficulty="easy")
    for m in scene.markers:
        proj, _ = cv2.projectPoints(marker_object_points(m.length), m.pose.rvec, m.pose.t, scene.K, None)
        assert np.allclose(proj.reshape(4, 2), m.corners, atol=1e-9)


def test_renders_are_deterministic():
    a = random_scene(11, size=(320, 240), difficulty="hard")
    b = random_scene(11, size=(320, 240), difficulty="hard")
    assert np.array_equal(a.image, b.image) and a.params == b.params
    assert not np.array_equal(a.image, random_scene(12, size=(320, 240), difficulty="hard").image)


def test_corner_zero_is_the_marker_top_left_so_the_bits_read_back():
    d = load_dictionary("DICT_4X4_50")
    for seed in range(4):
        scene = random_scene(seed, size=(640, 480), difficulty="easy")
        for m in scene.markers:
            valid, bits, _, _ = read_bits(sample_cells(scene.image, m.corners, d.marker_size + 2))
            assert valid[0] and np.array_equal(bits[0], d.bits[m.id])


def test_opencv_agrees_on_ids_and_corner_order():
    scene = random_scene(7, size=(640, 480), difficulty="easy")
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50),
                                  cv2.aruco.DetectorParameters())
    corners, ids, _ = det.detectMarkers(scene.image)
    truth = {m.id: m.corners for m in scene.markers if m.visible}
    assert ids is not None and set(ids.ravel()) <= set(truth)
    for c, i in zip(corners, ids.ravel(), strict=True):
        assert np.abs(c.reshape(4, 2) - truth[int(i)]).max() < 1.5


def test_difficulties_and_empty_frames():
    small = random_scene(1, size=(640, 480), difficulty="small")
    sides = [np.sqrt(cv2.contourArea(m.corners.astype(np.float32))) for m in small.markers]
    assert all(10 < s < 45 for s in sides)
    empty = random_scene(1, size=(640, 480), difficulty="empty")
    assert empty.markers == [] and empty.image.std() > 5


def test_render_dataset_and_video_write_readable_files(tmp_path):
    out = render_dataset(tmp_path / "set", 3, seed=2, size=(160, 120))
    gt = json.loads((out / "ground_truth.json").read_text())
    assert len(gt["frames"]) == 3
    img = cv2.imread(str(out / gt["frames"][0]["file"]), cv2.IMREAD_GRAYSCALE)
    assert img.shape == (120, 160)
    fs = cv2.FileStorage(str(out / "camera.yml"), cv2.FILE_STORAGE_READ)
    assert np.allclose(fs.getNode("camera_matrix").mat(), gt["camera"]["K"])
    fs.release()
    video = render_video(tmp_path / "v.mp4", 5, size=(160, 120))
    cap = cv2.VideoCapture(str(video))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 5
    cap.release()
    assert len(json.loads((tmp_path / "ground_truth.json").read_text())["frames"]) == 5


@pytest.mark.parametrize(
    "kwargs, exc, word",
    [
        ({"size": (0, 10)}, ValueError, "size"),
        ({"placements": "x"}, TypeError, "placements"),
        ({"placements": [(1, "pose", 0.1)]}, TypeError, "pose"),
        ({"noise_sigma": -1.0}, ValueError, "noise_sigma"),
        ({"background": "lava"}, ValueError, "background"),
    ],
)
def test_bad_arguments_are_named(kwargs, exc, word):
    args = {"K": default_camera((64, 48)), "size": (64, 48), "placements": [], "dictionary": "DICT_4X4_50"}
    args.update(kwargs)
    with pytest.raises(exc, match=word):
        render_markers(**args)


def test_random_scene_rejects_unknown_difficulty():
    with pytest.raises(ValueError, match="difficulty"):
        random_scene(0, difficulty="impossible")
