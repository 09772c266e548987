"""The bottom-camera flight renderer: geometry and signs, exact ground truth, files, bad args."""

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from visloc.synth import (
    Flight,
    FlightTrack,
    flight_trajectory,
    render_flight,
    render_ground_view,
    straight_track,
    write_flight,
)
from visloc.synth.flight import default_bottom_camera
from visloc.synth.textures import _photo_texture

SIZE = (320, 240)
K = default_bottom_camera(SIZE)
F = K[0, 0]
FPS = 30.0


def _smooth_grass():
    """Grass blurred by 4 texels: sub-pixel registration of it is free of interpolation bias."""
    b = cv2.GaussianBlur(_photo_texture("grass").astype(np.float32), (0, 0), 4)
    return np.clip((b - b.mean()) * 4 + 128, 0, 255)


def _pair(track, **kw):
    return [render_ground_view(K, SIZE, track.pose(k), **kw) for k in range(2)]


def _ecc_shift(a, b):
    """Translation (x, y) that carries the content of ``a`` onto ``b``."""
    warp = np.eye(2, 3, dtype=np.float32)
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-7)
    _, warp = cv2.findTransformECC(a.astype(np.float32), b.astype(np.float32), warp,
                                   cv2.MOTION_TRANSLATION, crit, None, 1)
    return warp[:, 2]


@pytest.mark.parametrize("axis", [0, 1])
def test_camera_translation_moves_the_content_the_other_way_by_f_dx_over_h(axis):
    h = 1.0
    v = [0.0, 0.0]
    v[axis] = 4.0 * h / F * FPS  # exactly 4 px between frames
    a, b = (img.astype(int) for img in _pair(straight_track(2 / FPS, FPS, velocity=tuple(v),
                                                            height=h, start=(0.37, 1.2))))
    # frame 1 at pixel p shows what frame 0 showed at p + 4 (along the axis of motion)
    if axis == 0:
        assert np.abs(b[:, :-4] - a[:, 4:]).max() <= 1
    else:
        assert np.abs(b[:-4] - a[4:]).max() <= 1
    for shift in (3.25, 0.37):  # sub-pixel: registration of a smooth texture
        v[axis] = shift * h / F * FPS
        track = straight_track(2 / FPS, FPS, velocity=tuple(v), height=h, start=(0.37, 0.2))
        measured = _ecc_shift(*_pair(track, texture=_smooth_grass()))
        expected = np.zeros(2)
        expected[axis] = -F * track.pair_v[1, axis] / FPS / h
        assert np.allclose(measured, expected, atol=0.01)


@pytest.mark.parametrize("yaw_rate", [1.5, -1.0])
def test_positive_yaw_rate_turns_the_content_the_other_way(yaw_rate):
    track = straight_track(2 / FPS, FPS, yaw_rate=yaw_rate, height=1.0, yaw=0.4, start=(0.3, 0.8))
    assert track.yaw_rate[0] == yaw_rate and np.isclose(track.pair_yaw_rate[1], yaw_rate)
    a, b = _pair(track)
    p = cv2.goodFeaturesToTrack(a, 400, 0.01, 7)
    q, status, _ = cv2.calcOpticalFlowPyrLK(a, b, p, None, winSize=(21, 21), maxLevel=2)
    ok = status.ravel() == 1
    m, _ = cv2.estimateAffinePartial2D(p[ok], q[ok], method=cv2.LMEDS)
    angle = np.arctan2(m[1, 0], m[0, 0])  # from image x towards image y
    assert angle == pytest.approx(-yaw_rate / FPS, rel=0.02)


def test_pixel_convention_and_seamless_mirror_tiling():
    # a linear ramp texture, so each pixel's grey level tells which ground point it shows
    v, u = np.mgrid[0:512, 0:512].astype(np.float64)
    texture = 0.3 * u + 0.2 * v
    mpt, h, c = 0.002, 0.5, np.array([0.45, 0.5, 0.5])
    R = straight_track(1.0, 1.0, height=h).pose(0)[0]
    assert np.allclose(R, np.diag([1.0, -1.0, -1.0]))
    img = render_ground_view(K, SIZE, (R, c), texture=texture, metres_per_texel=mpt)
    y, x = np.mgrid[0:240, 0:320]
    dx, dy = (x - K[0, 2]) * h / F, -(y - K[1, 2]) * h / F  # pixel (cx + f dx/h, cy - f dy/h)
    expected = 0.3 * (c[0] + dx) / mpt + 0.2 * (c[1] + dy) / mpt
    assert np.abs(img - expected).max() <= 0.52
    # across a tile edge (u = 511.5 texels) the ground mirrors: no seam, no jump
    c = np.array([511.5 * mpt, 0.5, h])
    img = render_ground_view(K, SIZE, (R, c), texture=0.4 * u, metres_per_texel=mpt,
                             supersample=1)
    m = np.mod((c[0] + dx) / mpt, 1024.0)
    expected = 0.4 * np.clip(511.5 - np.abs(m - 511.5), 0.0, 511.0)
    assert np.abs(img - expected).max() <= 0.52


def test_tilted_camera_sees_the_ground_where_its_rays_hit_it():
    track = flight_trajectory(5, 1.0, 10.0, roll_pitch=0.3)
    R, c = track.pose(3)
    assert abs(track.roll[3]) > 0.01 and abs(track.pitch[3]) > 0.01
    psi, phi, theta = track.yaw[3], track.roll[3], track.pitch[3]
    rz, rx, ry = (Rotation.from_euler(a, v).as_matrix() for a, v in
                  (("z", psi), ("x", phi), ("y", theta)))
    assert np.allclose(R, rz @ np.diag([1.0, -1.0, -1.0]) @ rx @ ry)  # documented convention
    v, u = np.mgrid[0:512, 0:512].astype(np.float64)
    img = render_ground_view(K, SIZE, (R, c), texture=0.3 * u + 0.2 * v, metres_per_texel=0.05)
    y, x = np.mgrid[100:140:4, 140:180:4]  # independent ray casting at a few pixel centres
    d = np.linalg.inv(K) @ np.stack([x.ravel(), y.ravel(), np.ones(x.size)]).astype(float)
    d = R @ d
    g = c[:2, None] - c[2] / d[2] * d[:2]
    gu, gv = np.clip(511.5 - np.abs(np.mod(g / 0.05, 1024.0) - 511.5), 0.0, 511.0)
    expected = 0.3 * gu + 0.2 * gv
    assert np.abs(img[y.ravel(), x.ravel()] - expected).max() <= 0.6


def test_high_flight_is_anti_aliased():
    checker = (np.indices((512, 512)).sum(axis=0) % 2 * 255).astype(np.uint8)  # 1-texel squares
    R = np.diag([1.0, -1.0, -1.0])
    high = render_ground_view(K, SIZE, (R, np.array([0.3, 0.2, 2.5])), texture=checker)
    assert abs(high.mean() - 127.5) < 2 and high.std() < 3
    low = render_ground_view(K, SIZE, (R, np.array([0.3, 0.2, 0.3])), texture=checker)
    assert low.std() > 25
    with pytest.raises(ValueError, match="misses the ground"):
        render_ground_view(K, SIZE, (np.diag([1.0, -1.0, -1.0]) @ Rotation.from_euler(
            "x", 1.3).as_matrix(), np.array([0.0, 0.0, 1.0])))


def test_ground_truth_is_exact():
    eps = 1e-5
    kw = {"roll_pitch": 0.3, "max_speed": 1.8}
    tr = flight_trajectory(4, 2.0, 10.0, **kw)
    lo, hi = (flight_trajectory(4, 2.0, 10.0, t0=s, **kw) for s in (-eps, eps))
    velocity = (hi.position - lo.position) / (2 * eps)
    R = tr.R_world_cam
    assert np.abs(tr.velocity - velocity).max() < 1e-6
    assert np.abs(tr.v_cam - np.einsum("nji,nj->ni", R, velocity)[:, :2]).max() < 1e-6
    rates = np.array([Rotation.from_matrix(a.T @ b).as_rotvec()
                      for a, b in zip(lo.R_world_cam, hi.R_world_cam, strict=True)]) / (2 * eps)
    assert np.abs(np.column_stack([tr.roll_rate, tr.pitch_rate, tr.yaw_rate]) - rates).max() < 1e-6
    step = np.einsum("nji,nj->ni", R[:-1], np.diff(tr.position, axis=0))[:, :2] * 10.0
    assert np.isnan(tr.pair_v[0]).all() and np.allclose(tr.pair_v[1:], step, atol=1e-12)
    psi = np.unwrap(tr.yaw)
    assert np.isnan(tr.pair_yaw_rate[0]) and np.allclose(tr.pair_yaw_rate[1:], -np.diff(psi) * 10)
    # a circle at constant v_cam and yaw rate
    circle = straight_track(3.0, 10.0, velocity=(0.8, -0.3), yaw_rate=0.7, height=1.5, yaw=2.0)
    assert np.allclose(circle.v_cam, [0.8, -0.3]) and np.allclose(circle.yaw_rate, 0.7)
    speed = np.linalg.norm(circle.velocity[:, :2], axis=1)
    assert np.allclose(speed, np.hypot(0.8, 0.3)) and np.allclose(circle.position[:, 2], 1.5)
    assert np.allclose(np.linalg.norm(np.diff(circle.position, axis=0), axis=1) * 10,
                       np.linalg.norm(circle.pair_v[1:], axis=1))


@pytest.mark.parametrize("seed", range(4))
def test_random_flights_keep_their_bounds(seed):
    tr = flight_trajectory(seed, 60.0, 50.0, max_speed=2.0, height=(0.5, 2.5), max_yaw_rate=1.5,
                           roll_pitch=0.2)
    speed = np.linalg.norm(tr.velocity, axis=1)
    assert speed.max() <= 2.0 and speed.mean() > 0.5
    assert tr.position[:, 2].min() >= 0.5 and tr.position[:, 2].max() <= 2.5
    assert np.abs(tr.yaw_rate).max() <= 1.5 and np.abs(tr.yaw_rate).max() > 0.5
    assert np.abs(tr.roll).max() <= 0.2 and np.abs(tr.pitch).max() <= 0.2
    assert np.all((tr.yaw >= -np.pi) & (tr.yaw < np.pi))
    level = flight_trajectory(seed, 1.0, 10.0, height=1.2)
    assert np.allclose(level.position[:, 2], 1.2) and not level.roll.any()


def test_renders_are_deterministic():
    a, b = (render_flight(0.2, FPS, seed=3) for _ in range(2))
    assert isinstance(a, Flight) and isinstance(a.track, FlightTrack)
    assert a.frames.shape == (6, 240, 320) and a.frames.dtype == np.uint8
    assert np.array_equal(a.frames, b.frames) and np.array_equal(a.track.position, b.track.position)
    assert not np.array_equal(a.frames, render_flight(0.2, FPS, seed=4).frames)
    track = straight_track(0.1, FPS, velocity=(0.5, 0.0))
    given = render_flight(0.1, FPS, size=(160, 120), track=track, noise_sigma=0.0)
    assert given.track is track and given.frames.shape == (3, 120, 160)
    assert np.allclose(given.K, [[160.03345, 0, 79.5], [0, 160.03345, 59.5], [0, 0, 1]])


@pytest.mark.parametrize("video", [False, True])
def test_write_flight(tmp_path, video):
    flight = render_flight(0.2, FPS, seed=2, max_speed=1.0)
    out = write_flight(tmp_path / "f", flight, video=video)
    if video:
        cap = cv2.VideoCapture(str(out / "flight.mp4"))
        n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        ok, img = cap.read()
        cap.release()
        assert ok and img.shape[:2] == (240, 320) and n == 6
    else:
        assert np.array_equal(cv2.imread(str(out / "frame_00005.png"), cv2.IMREAD_UNCHANGED),
                              flight.frames[5])
    header = (out / "ground_truth.csv").read_text().splitlines()[0]
    assert header == ("frame,t,x,y,height,yaw,roll,pitch,vx,vy,yaw_rate,roll_rate,pitch_rate,"
                      "pair_vx,pair_vy,pair_yaw_rate")
    gt = np.loadtxt(out / "ground_truth.csv", delimiter=",", skiprows=1)
    assert gt.shape == (6, 16) and np.isnan(gt[0, 13:]).all()
    assert np.allclose(gt[:, 8:10], flight.track.v_cam) and np.allclose(gt[1:, 13:15],
                                                                        flight.track.pair_v[1:])
    heights = np.loadtxt(out / "heights.csv", delimiter=",", skiprows=1)
    assert np.allclose(heights, gt[:, [0, 1, 4]])
    fs = cv2.FileStorage(str(out / "camera.yml"), cv2.FILE_STORAGE_READ)
    assert np.allclose(fs.getNode("camera_matrix").mat(), flight.K)
    assert int(fs.getNode("image_width").real()) == 320
    fs.release()


@pytest.mark.parametrize(("call", "name", "exc"), [
    (lambda: render_flight(0, FPS), "seconds", ValueError),
    (lambda: render_flight(1.0, -5), "fps", ValueError),
    (lambda: render_flight(1.0, FPS, noise_sigma=-1), "noise_sigma", ValueError),
    (lambda: render_flight(1.0, FPS, texture="snow"), "texture", ValueError),
    (lambda: render_flight(1.0, FPS, size=(4, 4)), "size", ValueError),
    (lambda: render_flight(1.0, FPS, size="big"), "size", TypeError),
    (lambda: render_flight(1.0, FPS, height=(2.0, 1.0)), "height", ValueError),
    (lambda: render_flight(1.0, FPS, track=straight_track(1.0, 10.0)), "track", ValueError),
    (lambda: flight_trajectory("x", 1.0, FPS), "rng_or_seed", TypeError),
    (lambda: flight_trajectory(1, 1.0, FPS, roll_pitch=1.0), "roll_pitch", ValueError),
    (lambda: straight_track(1.0, FPS, velocity=1.0), "velocity", TypeError),
    (lambda: render_ground_view(K, SIZE, (np.eye(3), np.zeros(3))), "pose_world_from_cam",
     ValueError),
    (lambda: render_ground_view(K, SIZE, (np.eye(3),)), "pose_world_from_cam", TypeError),
    (lambda: render_ground_view(K, SIZE, (np.diag([1.0, -1, -1]), [0, 0, 1.0]),
                                texture=np.zeros((4, 4, 3))), "texture", ValueError),
    (lambda: render_ground_view(K, SIZE, (np.diag([1.0, -1, -1]), [0, 0, 1.0]),
                                metres_per_texel=0), "metres_per_texel", ValueError),
    (lambda: write_flight("/tmp/x", "flight"), "flight", TypeError),
])
def test_bad_arguments_are_named(call, name, exc):
    with pytest.raises(exc, match=name):
        call()
