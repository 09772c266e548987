import numpy as np
import pytest

from tests.flow.conftest import moved
from visloc.flow import EgoMotion, estimate_ground_velocity, ground_velocity
from visloc.pose import Camera
from visloc.types import GlobalMotion

CAM = Camera(np.array([[320.0, 0, 159.5], [0, 320.0, 119.5], [0, 0, 1]]), size=(320, 240))
DT = 1 / 60


def _motion(t=(0.0, 0.0), rotation=0.0):
    return GlobalMotion(np.asarray(t, float), rotation, 1.0, None, 0.05, 40, "similarity")


def test_content_moving_left_means_camera_moving_right():
    # content at the principal point moves by -f D / h: D = 0.02 m to +x at h = 1 m -> -6.4 px
    gv = ground_velocity(_motion((-6.4, 0.0)), CAM, 1.0, DT)
    assert np.allclose(gv.v, (0.02 / DT, 0.0))
    gv = ground_velocity(_motion((0.0, 3.2)), CAM, 2.0, DT)
    assert np.allclose(gv.v, (0.0, -0.02 / DT))
    assert gv.quality > 0.5 and gv.reason == ""


def test_yaw_rate_is_opposite_to_the_content_rotation():
    gv = ground_velocity(_motion(rotation=0.01), CAM, 1.0, DT)
    assert gv.yaw_rate == pytest.approx(-0.01 / DT)
    assert np.allclose(gv.v, 0.0, atol=1e-12)  # a rotation about the centre does not translate


def test_the_displacement_is_turned_into_the_first_frame_axes():
    # camera moved D in frame-1 axes and turned by yaw: the content at the centre moved by
    # -f/h * R(yaw)^T D (seen in the second frame's axes)
    D, yaw, f, h = np.array([0.03, -0.01]), 0.05, 320.0, 1.5
    c, s = np.cos(yaw), np.sin(yaw)
    d2 = -f / h * np.array([c * D[0] + s * D[1], -s * D[0] + c * D[1]])
    gv = ground_velocity(_motion(d2, rotation=-yaw), CAM, h, DT)
    assert np.allclose(gv.v * DT, D, atol=1e-12)


def test_gyro_removes_the_flow_of_a_pure_roll():
    wx = 0.5  # rad/s about camera x: content at the centre moves by +f * wx * dt in y
    shift = (0.0, 320.0 * wx * DT)
    assert np.linalg.norm(ground_velocity(_motion(shift), CAM, 1.0, DT).v) > 0.4  # 0.5 m/s apparent
    gv = ground_velocity(_motion(shift), CAM, 1.0, DT, gyro=(wx, 0.0, 0.0))
    assert np.allclose(gv.v, 0.0, atol=1e-12)
    wy = -0.3  # about camera y: content moves by -f * wy * dt in x
    gv = ground_velocity(_motion((-320.0 * wy * DT, 0.0)), CAM, 1.0, DT, gyro=(0.0, wy, 0.0))
    assert np.allclose(gv.v, 0.0, atol=1e-12)


def test_real_frames_velocity():
    a, b = moved(-6.4, 3.2)  # camera moved +0.02 m in x and -0.01 m in y at 1 m height
    gv = estimate_ground_velocity(a, b, CAM, 1.0, DT)
    assert np.allclose(gv.v * DT, (0.02, -0.01), atol=0.0005)
    assert gv.quality > 0.5


def test_identical_and_noisy_frames_give_no_velocity():
    a, _ = moved()
    assert np.linalg.norm(estimate_ground_velocity(a, a, CAM, 1.0, DT).v) < 0.02
    rng = np.random.default_rng(3)
    noisy = [np.clip(a + rng.normal(0, 2.0, a.shape), 0, 255).astype(np.uint8) for _ in range(2)]
    assert np.linalg.norm(estimate_ground_velocity(*noisy, CAM, 1.0, DT).v) < 0.02


def test_uniform_frames_have_quality_zero_and_no_nan():
    flat = np.full((240, 320), 120, np.uint8)
    gv = estimate_ground_velocity(flat, flat, CAM, 1.0, DT)
    assert gv.quality == 0.0 and gv.reason and np.isfinite(gv.v).all() and gv.yaw_rate == 0.0


@pytest.mark.parametrize("height, dt, word", [(0.0, DT, "height"), (-1.0, DT, "height"), (1.0, 0.0, "dt"),
                                              (float("nan"), DT, "height"), (1.0, float("inf"), "dt")])
def test_bad_height_or_dt(height, dt, word):
    a, b = moved(1, 1)
    with pytest.raises(ValueError, match=word):
        estimate_ground_velocity(a, b, CAM, height, dt)


def test_bad_gyro_and_types():
    with pytest.raises(ValueError, match="gyro"):
        ground_velocity(_motion(), CAM, 1.0, DT, gyro=(1.0, 2.0))
    with pytest.raises(TypeError, match="camera"):
        ground_velocity(_motion(), "cam", 1.0, DT)


def test_ego_motion_integrates_a_track():
    ego = EgoMotion(CAM, height=1.0, fps=60.0)
    frames = [moved(-3.2 * k, 0.0)[1] for k in range(6)]  # the camera moves 0.01 m per frame along x
    assert ego.update(frames[0]) is None
    for f in frames[1:]:
        gv = ego.update(f)
        assert gv.quality > 0.5
    assert np.allclose(ego.position, (0.05, 0.0), atol=0.002)
    assert len(ego.track) == 6 and ego.track[-1][0] == pytest.approx(5 / 60)
    with pytest.raises(ValueError, match="size"):
        ego.update(np.zeros((100, 100), np.uint8))


@pytest.mark.parametrize("kw", [{"fps": 0}, {"fps": -30.0}, {"height": float("nan")}, {"height": 0.0}, {"fps": True}])
def test_egomotion_refuses_a_rate_or_height_it_cannot_use(kw):
    with pytest.raises(ValueError, match="must be a finite number > 0"):
        EgoMotion(CAM, **kw)


def test_tracking_works_with_a_camera_without_size():
    # the tracked path (direct=True) takes the image size from the frames, as the block sums do
    cam = Camera(np.array([[160.0, 0, 79.5], [0, 160.0, 59.5], [0, 0, 1]]))
    ego = EgoMotion(cam, height=1.0, fps=60.0, options={"direct": True})
    frames = [moved(-1.6 * k, 0.0, size=(160, 120))[1] for k in range(4)]  # 0.01 m per frame along x
    assert ego.update(frames[0]) is None
    out = [ego.update(f) for f in frames[1:]]
    assert any(gv.motion.method.endswith("+tracked") for gv in out)
    for gv in out:
        assert gv.quality > 0.3 and np.allclose(gv.v, (0.6, 0.0), atol=0.03)


def test_a_first_frame_too_small_is_refused_and_the_stream_stays_usable():
    # it used to become the stream's first frame: every later frame then failed on its size
    a, b = moved(dx=1.0)
    ego = EgoMotion(CAM, height=1.0, fps=60.0)
    with pytest.raises(ValueError, match="16 x 16"):
        ego.update(a[:10, :10])
    assert ego.frame_shape is None
    assert ego.update(a) is None and ego.update(b) is not None
