"""Tests of the camera model: transfer curve, distortion, ground truth of camera-like renders."""

from __future__ import annotations

import hashlib
import json

import cv2
import numpy as np
import pytest

from visloc.synth import (
    DARK_EXPOSURE,
    CameraEffects,
    apply_camera,
    default_camera,
    distort_points,
    ideal_window,
    marker_object_points,
    project_points,
    random_scene,
    render_markers,
    srgb_decode,
    srgb_encode,
)
from visloc.types import Pose

FACING = np.diag([1.0, -1.0, -1.0])  # marker x right, y up (image up), z towards the camera
K640 = default_camera((640, 480))
K320 = default_camera((320, 240))
#: Lossless, noiseless, sharp camera: only the lens distortion (set per test) and sRGB.
CLEAN = CameraEffects(blur_sigma=0.0, full_well=None, read_noise=0.0, vignetting=0.0, k1=0.0,
                      jpeg_quality=None)


def _camera(**changes: object) -> CameraEffects:
    return CameraEffects(**(CLEAN.to_dict() | changes))


def test_srgb_round_trip_and_reference_values():
    v = np.linspace(0.0, 1.0, 2001)
    np.testing.assert_allclose(srgb_decode(srgb_encode(v)), v, atol=1e-12)
    np.testing.assert_allclose(srgb_encode(srgb_decode(v)), v, atol=1e-12)
    assert srgb_encode(0.0) == 0.0 and srgb_encode(1.0) == pytest.approx(1.0, abs=1e-12)
    assert srgb_encode(0.5) == pytest.approx(0.735357, abs=1e-6)
    assert srgb_encode(0.0031308) == pytest.approx(0.04045, abs=1e-6)  # the two pieces meet
    assert np.all(np.diff(srgb_encode(v)) > 0)
    assert srgb_encode(2.0) == pytest.approx(1.0) and srgb_decode(-1.0) == 0.0  # clipped


@pytest.mark.parametrize("k1, k2", [(-0.15, 0.0), (0.05, -0.02), (-0.1, 0.02)])
def test_distort_points_agrees_with_opencv(k1, k2):
    rng = np.random.default_rng(0)
    pts = np.c_[rng.uniform(-0.6, 0.6, (40, 2)), np.ones(40)] * rng.uniform(0.5, 3.0, (40, 1))
    ref, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K640, np.array([k1, k2, 0, 0, 0]))
    pinhole = pts[:, :2] / pts[:, 2:] * K640[0, 0] + K640[:2, 2]
    np.testing.assert_allclose(distort_points(pinhole, K640, k1, k2), ref.reshape(-1, 2),
                               atol=1e-9)
    np.testing.assert_array_equal(distort_points(pinhole, K640, 0.0, 0.0), pinhole)


def test_render_ground_truth_is_the_opencv_camera_projection():
    cam = _camera(k1=-0.12, k2=0.01)
    scene = random_scene(2, size=(320, 240), n_markers=3, camera=cam)
    plain = random_scene(2, size=(320, 240), n_markers=3)
    np.testing.assert_array_equal(scene.dist, [-0.12, 0.01, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(plain.dist, np.zeros(5))
    assert scene.params["camera"] == cam.to_dict()
    json.dumps(scene.params)
    for m, p in zip(scene.markers, plain.markers, strict=True):
        assert m.id == p.id and np.array_equal(m.pose.t, p.pose.t)  # same scene, other camera
        proj, _ = cv2.projectPoints(marker_object_points(m.length), m.pose.rvec, m.pose.t,
                                    scene.K, scene.dist)
        np.testing.assert_allclose(m.corners, proj.reshape(4, 2), atol=1e-9)
        assert m.visible


def _edge_errors(image: np.ndarray, truth: np.ndarray, cell: float, white: float) -> np.ndarray:
    """Signed errors of the measured black-square edges [left, right, top, bottom] at the
    true edge midpoints ``truth`` (4, 2). Across each edge, over a window of one cell, the
    sum of the linear-light intensities (normalised by the ``white`` level) is the white
    length; the measurement is interpolated between the two pixel rows (columns) around the
    midpoint."""
    light = srgb_decode(image / 255.0) / white
    errors = []
    for j, (x, y) in enumerate(truth):
        across_x = j < 2
        at, along = (x, y) if across_x else (y, x)
        a, b = int(np.ceil(at - cell / 2)), int(np.floor(at + cell / 2))
        r0 = int(np.floor(along))
        found = []
        for r in (r0, r0 + 1):
            white = (light[r, a : b + 1] if across_x else light[a : b + 1, r]).sum()
            found.append(a - 0.5 + white if j in (0, 2) else b + 0.5 - white)
        f = along - r0
        errors.append((1 - f) * found[0] + f * found[1] - at)
    return np.array(errors)


@pytest.mark.parametrize(
    "t, changes",
    [
        ((0.0123, -0.0071, 0.6), {"k1": -0.15}),
        ((0.12, 0.07, 0.75), {"k1": -0.15, "k2": 0.02}),
        ((-0.1, 0.08, 0.7), {"k1": 0.05}),
        ((0.1, -0.05, 0.7), {"k1": -0.08, "blur_sigma": 0.8, "exposure": 0.9}),
    ],
)
def test_distorted_edges_sit_at_ground_truth(t, changes):
    """A large marker, flat background, no noise: every edge midpoint of the dark square is
    where the distorted projection puts it, and far from the pinhole projection."""
    cam = _camera(**changes)
    length = 0.2
    pose = Pose(FACING, np.array(t, float))
    render = render_markers(K320, (320, 240), [(3, pose, length)], "DICT_4X4_50", camera=cam)
    marker = render.markers[0]
    assert marker.visible
    h = 0.5 * length
    mids = np.array([[-h, 0, 0], [h, 0, 0], [0, h, 0], [0, -h, 0]])  # left, right, top, bottom
    pinhole = project_points(K320, pose, mids)
    truth = distort_points(pinhole, K320, cam.k1, cam.k2)
    cell = (truth[1, 0] - truth[0, 0]) / 6
    err = _edge_errors(render.image, truth, cell, cam.exposure)
    assert np.all(np.abs(err) < 0.05), err
    moved = np.abs(_edge_errors(render.image, pinhole, cell, cam.exposure))
    assert moved.max() > 0.2, moved  # the check tells distorted from pinhole positions


def test_barrel_distortion_brings_in_what_the_pinhole_frame_misses():
    """A marker entirely right of the pinhole frame is pulled into view by barrel distortion
    and drawn there (the ideal image extends past the frame as far as the lens sees)."""
    z = 0.15 * K640[0, 0] / 12.0  # about 12 px wide
    x = (648.0 - K640[0, 2]) / K640[0, 0] * z + 0.075
    pose = Pose(FACING, np.array([x, 0.0, z]))
    placements = [(3, pose, 0.15)]
    assert np.all(project_points(K640, pose, marker_object_points(0.15))[:, 0] > 640)
    plain = render_markers(K640, (640, 480), placements, "DICT_4X4_50", camera=CLEAN)
    assert not plain.markers[0].visible
    assert ideal_window(K640, -0.15, 0.0, (640, 480))[2] > 20
    render = render_markers(K640, (640, 480), placements, "DICT_4X4_50", camera=_camera(k1=-0.15))
    m = render.markers[0]
    assert m.visible
    (x0, y0), (x1, y1) = np.floor(m.corners.min(axis=0)), np.ceil(m.corners.max(axis=0))
    patch = render.image[int(y0) : int(y1) + 1, int(x0) : int(x1) + 1]
    assert patch.min() < 40 and render.image[:, :600].min() > 120  # drawn there, not elsewhere


def test_points_beyond_the_fold_are_not_visible():
    # with k1 = -0.2 the radial map folds at r = 1.29: a marker at r = 2 would be "distorted"
    # to r = 0.4, inside the frame, but the lens never shows it there
    pose = Pose(FACING, np.array([4.0, 0.0, 2.0]))
    render = render_markers(K640, (640, 480), [(3, pose, 0.2)], "DICT_4X4_50",
                            camera=_camera(k1=-0.2))
    m = render.markers[0]
    assert np.all((m.corners > 0) & (m.corners < [640, 480]))
    assert not m.visible
    assert render.image.min() > 120


def test_vignetting_exposure_and_noise_levels():
    size = (200, 150)
    K = default_camera(size)
    flat = np.full((150, 200), 200.0)
    linear = {"srgb": False}
    img, params = apply_camera(flat, K, _camera(vignetting=0.3, **linear), rng=0)
    assert params["vignetting"] == 0.3
    assert img[75, 100] == 200 and abs(int(img[0, 0]) - 140) <= 1  # 70 % at the far corner
    img, _ = apply_camera(flat, K, _camera(exposure=0.5, **linear), rng=0)
    assert np.all(img == 100)
    img, _ = apply_camera(flat, K, _camera(read_noise=4.0, **linear), rng=1)
    assert img.std() == pytest.approx(4.0, rel=0.05)
    img, _ = apply_camera(flat, K, _camera(full_well=1000.0, **linear), rng=2)
    assert img.var() == pytest.approx(255 * 200 / 1000.0, rel=0.1)  # shot noise: var ~ signal
    a, _ = apply_camera(flat, K, CameraEffects(), rng=3)
    b, _ = apply_camera(flat, K, CameraEffects(), rng=3)
    np.testing.assert_array_equal(a, b)


def test_random_camera_scenes():
    for difficulty in ("easy", "hard", "small"):
        for seed in range(2):
            scene = random_scene(np.random.default_rng([seed, 1]), size=(160, 120),
                                 difficulty=difficulty, camera=True)
            cam = scene.params["camera"]
            assert cam["srgb"] and cam["full_well"] is not None
            assert -0.15 <= cam["k1"] <= 0.05 and all(m.visible for m in scene.markers)


def test_dark_scenes_are_dark():
    for seed in range(4):
        scene = random_scene(np.random.default_rng([seed, 2]), size=(160, 120),
                             difficulty="dark", camera=True)
        assert DARK_EXPOSURE[0] <= scene.params["camera"]["exposure"] <= DARK_EXPOSURE[1]
        assert scene.image.mean() < 30
        assert scene.markers and all(m.visible for m in scene.markers)
        plain = random_scene(np.random.default_rng([seed, 2]), size=(160, 120), difficulty="dark")
        assert plain.image.mean() < 30


def _digest(render) -> str:
    h = hashlib.sha256(render.image.tobytes())
    for m in render.markers:
        h.update(np.round(m.corners, 9).tobytes())
        h.update(bytes([m.visible]))
    h.update(json.dumps(render.params, sort_keys=True).encode())
    return h.hexdigest()[:16]


#: Digests (image, corners, visibility, params) computed with the renderer before the camera
#: model was added: scenes without a camera must stay bit-for-bit the same.
BEFORE_CAMERA = {
    "easy": ["957705cc93ccd2bc", "fb9ca23f7ef3163a", "c552012bec80e8f2"],
    "hard": ["046561923cf85f5b", "8b7afc2759829314", "3289aca1ae3a75de"],
    "small": ["b49e4d44fdbf496d", "d8c127701314b914", "5286c4bebf0a2a23"],
    "empty": ["bd23d8d413a89e15", "e8133afafb1b77c0", "565fcd2a662b114a"],
}


@pytest.mark.parametrize("difficulty", sorted(BEFORE_CAMERA))
def test_scenes_without_camera_are_unchanged(difficulty):
    got = [_digest(random_scene(np.random.default_rng([s, 7]), size=(160, 120),
                                difficulty=difficulty, camera=False)) for s in range(3)]
    assert got == BEFORE_CAMERA[difficulty]


@pytest.mark.parametrize(
    "field, value, exc",
    [
        ("blur_sigma", -1.0, ValueError),
        ("full_well", 0.0, ValueError),
        ("read_noise", -0.1, ValueError),
        ("vignetting", 1.0, ValueError),
        ("k1", float("nan"), ValueError),
        ("motion_blur", -2.0, ValueError),
        ("exposure", 0.0, ValueError),
        ("jpeg_quality", 0, ValueError),
        ("srgb", "yes", TypeError),
        ("k2", "0.1", TypeError),
    ],
)
def test_camera_effects_check_their_fields(field, value, exc):
    with pytest.raises(exc, match=f"CameraEffects.{field}"):
        CameraEffects(**{field: value})


def test_bad_arguments_name_the_argument():
    placements = [(3, Pose(FACING, np.array([0.0, 0.0, 1.0])), 0.2)]
    args = (K320, (320, 240), placements, "DICT_4X4_50")
    with pytest.raises(ValueError, match="blur_sigma=1.0"):
        render_markers(*args, camera=CameraEffects(), blur_sigma=1.0)
    with pytest.raises(ValueError, match="gain=0.5, jpeg_quality=80"):
        render_markers(*args, camera=CameraEffects(), gain=0.5, jpeg_quality=80)
    with pytest.raises(TypeError, match="camera"):
        render_markers(*args, camera={"k1": 0.1})
    with pytest.raises(TypeError, match="camera"):
        random_scene(1, size=(160, 120), camera="webcam")
    with pytest.raises(ValueError, match="k1, k2"):  # folds before the image corner
        render_markers(*args, camera=CameraEffects(k1=-0.6))
    with pytest.raises(ValueError, match="linear"):
        apply_camera(np.zeros((4, 5, 3)), K320, CameraEffects())
    with pytest.raises(ValueError, match="linear"):
        apply_camera(np.full((40, 50), -1.0), K320, CameraEffects())
    with pytest.raises(TypeError, match="effects"):
        apply_camera(np.zeros((40, 50)), K320, {"k1": 0.0})
    with pytest.raises(ValueError, match="K"):
        apply_camera(np.zeros((40, 50)), np.eye(2), CameraEffects())
    with pytest.raises(ValueError, match="points"):
        distort_points(np.zeros((3, 3)), K320, 0.1, 0.0)
    with pytest.raises(TypeError, match="k1"):
        distort_points(np.zeros((3, 2)), K320, None, 0.0)
