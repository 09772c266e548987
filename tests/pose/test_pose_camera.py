"""visloc.pose.camera: validation, FileStorage I/O, point mappings."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from visloc.pose import Camera
from visloc.types import Pose

ROOT = Path(__file__).resolve().parents[2]
CALIB = ROOT / "calib"
REAL_TUTORIAL = ROOT / "datasets" / "real" / "tutorial_camera_params.yml"

K = np.array([[600.0, 0.0, 319.5], [0.0, 610.0, 239.5], [0.0, 0.0, 1.0]])
# strong but invertible over a 640x480 image (barrel, tangential, k3)
STRONG = np.array([-0.3, 0.12, 0.002, -0.001, -0.02])


# ---------------------------------------------------------------------------- construction
def test_defaults_and_read_only() -> None:
    cam = Camera(K)
    assert cam.dist.shape == (5,) and not cam.dist.any()
    assert cam.size is None
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (600.0, 610.0, 319.5, 239.5)
    assert not cam.has_distortion
    with pytest.raises(ValueError):
        cam.K[0, 0] = 1.0  # read-only
    assert "fx=600" in repr(cam) and "size=None" in repr(cam)


@pytest.mark.parametrize("n", [4, 5, 8, 12, 14])
def test_accepts_opencv_distortion_sizes(n: int) -> None:
    cam = Camera(K, np.arange(1, n + 1) * 1e-3, (640, 480))
    assert cam.dist.shape == (n,) and cam.has_distortion
    assert cam.size == (640, 480)
    assert Camera(K, np.zeros((1, n))).dist.shape == (n,)  # OpenCV's row vector


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"K": np.eye(2)}, "shape"),
        ({"K": np.diag([-1.0, 1.0, 1.0])}, "positive focal"),
        ({"K": np.diag([1.0, 0.0, 1.0])}, "positive focal"),
        ({"K": [[1, 0, 0], [0, 1, 0], [0, 0, 2]]}, "last row"),
        ({"K": [[1, 0.5, 0], [0, 1, 0], [0, 0, 1]]}, "skew"),
        ({"K": [[np.nan, 0, 0], [0, 1, 0], [0, 0, 1]]}, "finite"),
        ({"K": K, "dist": np.zeros(3)}, "coefficients"),
        ({"K": K, "dist": [np.inf, 0, 0, 0]}, "finite"),
        ({"K": K, "size": (640,)}, "size"),
        ({"K": K, "size": (640, -1)}, "size"),
        ({"K": K, "size": (640.5, 480)}, "size"),
    ],
)
def test_rejects_bad_values(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        Camera(**kwargs)


def test_from_fov_puts_the_edge_ray_on_the_image_edge() -> None:
    cam = Camera.from_fov(640, 480, 90.0)
    assert cam.fx == pytest.approx(320.0) and cam.size == (640, 480)
    # a ray at half the field of view lands on the outer edge of the last pixel
    u = cam.project([[np.tan(np.radians(45.0)), 0.0, 1.0]])
    assert u[0, 0] == pytest.approx(640 - 0.5)
    d = Camera.from_fov(320, 240, dfov_deg=64.0)
    half = np.tan(np.radians(32.0))
    corner = d.normalize([[319.5, 239.5]])[0]
    assert np.hypot(*corner) == pytest.approx(half)
    with pytest.raises(ValueError):
        Camera.from_fov(640, 480)
    with pytest.raises(ValueError):
        Camera.from_fov(640, 480, 180.0)


def test_scaled_matches_a_resized_image() -> None:
    cam = Camera(K, STRONG, (640, 480))
    half = cam.scaled(320, 240)
    assert half.size == (320, 240) and np.array_equal(half.dist, cam.dist)
    pts = np.array([[0.1, -0.2, 1.0], [-0.3, 0.25, 2.0], [0.0, 0.0, 1.0]])
    # cv2.resize maps pixel centre x to (x + 0.5) * s - 0.5
    expected = (cam.project(pts) + 0.5) * 0.5 - 0.5
    np.testing.assert_allclose(half.project(pts), expected, atol=1e-9)
    with pytest.raises(ValueError, match="size"):
        Camera(K).scaled(320, 240)


# ---------------------------------------------------------------------------- files
def test_round_trip(tmp_path: Path) -> None:
    cam = Camera(K, STRONG, (640, 480))
    path = tmp_path / "cam.yml"
    cam.to_file(path)
    back = Camera.from_file(path)
    np.testing.assert_array_equal(back.K, cam.K)
    np.testing.assert_array_equal(back.dist, cam.dist)
    assert back.size == (640, 480)
    text = path.read_text()
    for key in ("camera_matrix", "distortion_coefficients", "image_width", "image_height"):
        assert key in text


def test_round_trip_without_size(tmp_path: Path) -> None:
    cam = Camera(K, np.arange(8) * 1e-3)
    cam.to_file(tmp_path / "cam.yaml")
    back = Camera.from_file(str(tmp_path / "cam.yaml"))
    assert back.size is None and back.dist.shape == (8,)
    np.testing.assert_array_equal(back.dist, cam.dist)


def test_calib_files() -> None:
    bottom = Camera.from_file(CALIB / "ardrone2_bottom_320x240.yml")
    assert bottom.size == (320, 240)
    # 64 deg diagonal field of view
    corner = bottom.normalize([[-0.5, -0.5]])[0]
    assert np.degrees(np.arctan(np.hypot(*corner))) * 2 == pytest.approx(64.0, abs=1e-3)
    front = Camera.from_file(CALIB / "ardrone2_front_640x360.yml")
    assert front.size == (640, 360)
    corner = front.normalize([[-0.5, -0.5]])[0]
    assert np.degrees(np.arctan(np.hypot(*corner))) * 2 == pytest.approx(92.0, abs=1e-3)
    tutorial = Camera.from_file(CALIB / "opencv_tutorial_camera.yml")
    assert tutorial.size is None
    assert tutorial.fx == pytest.approx(628.158)
    np.testing.assert_allclose(tutorial.dist[:2], [0.0995485, -0.206384])


def test_tutorial_file_matches_the_copy_beside_the_photographs() -> None:
    a = Camera.from_file(REAL_TUTORIAL)
    b = Camera.from_file(CALIB / "opencv_tutorial_camera.yml")
    np.testing.assert_array_equal(a.K, b.K)
    np.testing.assert_array_equal(a.dist, b.dist)


MATRIX = "camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ %s ]\n"


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("", "empty"),
        ("%YAML:1.0\ncamera_matrix: [1, 2\n", "not OpenCV FileStorage"),
        ("just some text {{{", "not OpenCV FileStorage"),
        ("%YAML:1.0\nfoo: 1\n", "no 'camera_matrix'"),
        ("%YAML:1.0\ncamera_matrix: 3\n", "not an opencv-matrix"),
        ("%YAML:1.0\n" + MATRIX % "1, 0, 0, 0, 1, 0, 0, 0, 2", "last row"),
        ("%YAML:1.0\n" + MATRIX % "1, 0, 0, 0, 1, 0, 0, 0, 1" + "image_width: abc\n", "integer"),
        ("%YAML:1.0\n" + MATRIX % "1, 0, 0, 0, 1, 0, 0, 0, 1" + "image_width: 3\n", "only one"),
    ],
)
def test_malformed_files(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "bad.yml"
    path.write_text(text)
    with pytest.raises(ValueError, match=match) as info:
        Camera.from_file(path)
    assert str(path) in str(info.value)


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "nope.yml"
    with pytest.raises(ValueError, match="does not exist") as info:
        Camera.from_file(path)
    assert str(path) in str(info.value)


# ---------------------------------------------------------------------------- mappings
def _grid(w: int = 640, h: int = 480, n: int = 9) -> np.ndarray:
    xs, ys = np.meshgrid(np.linspace(0, w - 1, n), np.linspace(0, h - 1, n))
    return np.column_stack([xs.ravel(), ys.ravel()])


@pytest.mark.parametrize(
    "dist", [STRONG, "tutorial", np.array([0.05, -0.1, 0.0, 0.0, 0.0, 0.02, 0.01, 0.0])]
)
def test_undistort_inverts_project_points(dist: np.ndarray | str) -> None:
    cam = (
        Camera.from_file(CALIB / "opencv_tutorial_camera.yml")
        if isinstance(dist, str)
        else Camera(K, dist)
    )
    ideal = _grid()
    normalized = (ideal - cam.K[:2, 2]) / [cam.fx, cam.fy]
    pts = np.column_stack([normalized, np.ones(len(ideal))])
    distorted, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), cam.K, cam.dist)
    distorted = distorted.reshape(-1, 2)
    assert np.abs(distorted - ideal).max() > 1.0  # the distortion is not negligible
    np.testing.assert_allclose(cam.undistort_points(distorted), ideal, atol=1e-3)
    np.testing.assert_allclose(cam.normalize(distorted), normalized, atol=1e-3 / cam.fx)
    np.testing.assert_allclose(cam.project(pts), distorted, atol=1e-9)


def test_zero_distortion_fast_paths() -> None:
    cam = Camera(K)
    p = _grid()
    np.testing.assert_array_equal(cam.undistort_points(p), p)
    np.testing.assert_allclose(cam.normalize(p), (p - [319.5, 239.5]) / [600.0, 610.0])
    pts = np.array([[0.1, 0.2, 2.0], [-1.0, 0.5, 4.0]])
    ref, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K, None)
    np.testing.assert_allclose(cam.project(pts), ref.reshape(-1, 2), atol=1e-9)


def test_project_object() -> None:
    cam = Camera(K, STRONG)
    R = cv2.Rodrigues(np.array([0.2, -0.1, 0.3]))[0]
    t = np.array([0.1, -0.05, 1.5])
    obj = np.array([[0.0, 0.0, 0.0], [0.1, 0.2, 0.0], [-0.1, 0.05, 0.1]])
    ref, _ = cv2.projectPoints(obj, cv2.Rodrigues(R)[0], t, K, STRONG)
    np.testing.assert_allclose(cam.project_object(obj, Pose(R, t)), ref.reshape(-1, 2), atol=1e-9)


def test_point_shapes() -> None:
    cam = Camera(K)
    assert cam.normalize([100.0, 200.0]).shape == (1, 2)
    with pytest.raises(ValueError, match="points"):
        cam.undistort_points(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="points_cam"):
        cam.project(np.zeros((3, 2)))


def test_fisheye_camera_checks_its_model_and_keeps_it():
    K = np.array([[250.0, 0.0, 319.5], [0.0, 250.0, 239.5], [0.0, 0.0, 1.0]])
    cam = Camera(K, None, (640, 480), model="fisheye")
    assert cam.dist.shape == (4,) and cam.has_distortion  # r = f theta is not the pinhole's r = f tan(theta)
    # an ideal equidistant lens: a ray 60 degrees off the axis lands f * pi / 3 from the centre
    px = cam.project(np.array([[np.sin(np.pi / 3), 0.0, np.cos(np.pi / 3)]]))
    assert np.allclose(px, [[319.5 + 250.0 * np.pi / 3, 239.5]])
    assert cam.scaled(320, 240).model == "fisheye" and "fisheye" in repr(cam)
    with pytest.raises(ValueError, match="4 distortion coefficients"):
        Camera(K, np.zeros(5), model="fisheye")
    with pytest.raises(ValueError, match="model must be one of"):
        Camera(K, model="orthographic")


def test_extra_nodes_are_checked_before_the_file_is_opened(tmp_path: Path) -> None:
    cam = Camera(np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]]), size=(640, 480))
    cam.to_file(tmp_path / "ok.yml", extra={"per_view_rms_px": [0.1, 0.2, 0.3], "views_used": 3, "note": "lab"})
    fs = cv2.FileStorage(str(tmp_path / "ok.yml"), cv2.FILE_STORAGE_READ)
    assert fs.getNode("per_view_rms_px").mat().ravel().tolist() == pytest.approx([0.1, 0.2, 0.3])
    assert fs.getNode("views_used").real() == 3 and fs.getNode("note").string() == "lab"
    fs.release()
    with pytest.raises(TypeError, match="per_view"):
        cam.to_file(tmp_path / "bad.yml", extra={"per_view": {"a": 1}})
    with pytest.raises(ValueError, match="node name"):
        cam.to_file(tmp_path / "bad.yml", extra={"2 views": 1.0})
    assert not (tmp_path / "bad.yml").exists()  # nothing half-written


def test_no_points_give_no_points_with_distortion_too():
    # OpenCV returns None for an empty point set: normalize / project used to fail on .reshape
    K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
    for cam in (Camera(K), Camera(K, dist=[-0.2, 0.05, 0.0, 0.0, 0.0]),
                Camera(K, dist=[0.01, 0.0, 0.0, 0.0], model="fisheye")):
        for out in (cam.normalize(np.zeros((0, 2))), cam.undistort_points(np.zeros((0, 2))),
                    cam.project(np.zeros((0, 3)))):
            assert out.shape == (0, 2)
