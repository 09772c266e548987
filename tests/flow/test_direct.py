"""The sub-pixel stage after the block-sum flow (visloc.flow.direct)."""

import numpy as np
import pytest

from visloc.flow import EgoMotion, block_flow, estimate_ground_velocity, global_motion
from visloc.flow.direct import refine_motion
from visloc.pose import Camera
from visloc.synth.flight import render_flight


@pytest.fixture(scope="module")
def flight():
    fl = render_flight(0.5, 60.0, size=(320, 240), seed=3, max_speed=1.5, height=(0.8, 2.0), max_yaw_rate=1.0,
                       noise_sigma=1.0, texture="gravel")
    return fl, Camera(fl.K, size=(320, 240))


def _errors(fl, cam, **kw):
    tr = fl.track
    errs = []
    for k in range(1, len(tr)):
        gv = estimate_ground_velocity(fl.frames[k - 1], fl.frames[k], cam, float(tr.position[k, 2]), 1 / 60, **kw)
        errs.append(np.linalg.norm(gv.v - tr.pair_v[k]) / max(np.linalg.norm(tr.pair_v[k]), 0.05))
    return np.array(errs)


def test_direct_alignment_is_more_accurate_than_the_block_sums(flight):
    fl, cam = flight
    plain, direct = _errors(fl, cam), _errors(fl, cam, direct=True)
    assert np.median(direct) < 0.5 * np.median(plain)
    assert np.percentile(direct, 90) < np.percentile(plain, 90)


def test_an_exposure_step_is_not_read_as_motion(flight):
    fl, _ = flight
    a, b = fl.frames[10], fl.frames[11]
    brighter = np.clip(b.astype(np.float64) * 1.2, 0, 255).astype(np.uint8)
    m0 = refine_motion(a, b, global_motion(block_flow(a, b)))
    m1 = refine_motion(a, brighter, global_motion(block_flow(a, brighter)))
    assert m0.method.endswith("+direct") and m1.method.endswith("+direct")
    assert np.abs(m1.translation - m0.translation).max() < 0.05  # px
    still = refine_motion(a, a, global_motion(block_flow(a, a)))
    assert np.abs(still.translation).max() < 0.01 and abs(still.scale - 1) < 1e-4


def test_a_start_it_cannot_improve_is_kept(flight):
    fl, _ = flight
    a = fl.frames[0]
    flat = np.full_like(a, 128)
    m = global_motion(block_flow(a, fl.frames[1]))
    assert refine_motion(a, flat, m) is m  # nothing to align to: the block-sum solution stands
    assert refine_motion(a[:20, :20], a[:20, :20], m) is m  # too small to refine
    with pytest.raises(ValueError, match="stride"):
        refine_motion(a, fl.frames[1], m, stride=0)


def test_the_numpy_steps_give_the_compiled_result(flight):
    pytest.importorskip("visloc.flow._direct", reason="the compiled stage was not built")
    fl, _ = flight
    for k in (5, 20):
        a, b = fl.frames[k], fl.frames[k + 1]
        m = global_motion(block_flow(a, b))
        c, p = refine_motion(a, b, m, native=True), refine_motion(a, b, m, native=False)
        assert c.method == p.method == m.method + "+direct"
        np.testing.assert_allclose(c.translation, p.translation, atol=1e-9)
        assert abs(c.rotation - p.rotation) < 1e-11 and abs(c.scale - p.scale) < 1e-11


def test_a_failed_refinement_lowers_the_quality_and_says_why(flight, monkeypatch):
    from visloc.flow import velocity

    fl, cam = flight
    a, b = fl.frames[5], fl.frames[6]
    good = estimate_ground_velocity(a, b, cam, 1.0, 1 / 60, direct=True)
    assert good.motion.method.endswith("+direct") and good.reason == ""
    monkeypatch.setattr(velocity, "refine_blurred", lambda *args: (None, float("inf")))  # as when it moved too far
    bad = estimate_ground_velocity(a, b, cam, 1.0, 1 / 60, direct=True)
    assert bad.reason == velocity.UNREFINED
    assert bad.quality == pytest.approx(velocity.UNREFINED_QUALITY * good.quality)


def test_a_prior_frees_the_stream_from_a_neighbouring_period():
    # bricks: at frame 120 of this flight the block sums lock onto the next period of the
    # pattern, about 8 px off, and the alignment from them cannot leave it; in a stream the
    # previous pair's motion steers the whole-image match and starts the alignment
    fl = render_flight(2.2, 60.0, size=(320, 240), seed=22, max_speed=2.0, height=(0.5, 2.5), max_yaw_rate=1.5,
                       noise_sigma=1.0, texture="brick")
    cam, tr = Camera(fl.K, size=(320, 240)), fl.track
    k = 120
    a, b = fl.frames[k - 1], fl.frames[k]
    alone = estimate_ground_velocity(a, b, cam, float(tr.position[k, 2]), 1 / 60, direct=True)
    assert np.linalg.norm(alone.v - tr.pair_v[k]) > 1.0  # the aliased solution
    for direct in (False, True):
        ego = EgoMotion(cam, options={"direct": direct})
        errs = []
        for j in range(95, 131):
            gv = ego.update(fl.frames[j], dt=1 / 60, height=float(tr.position[j, 2]))
            if gv is not None:
                errs.append(np.linalg.norm(gv.v - tr.pair_v[j]) / np.linalg.norm(tr.pair_v[j]))
                if j == k - 1:
                    before = gv.motion
        assert max(errs) < (0.05 if direct else 0.2)
    # the alignment alone, started from the aliased block sums and from the prior
    helped = refine_motion(a, b, global_motion(block_flow(a, b)), prior=before)
    assert helped.method == "similarity+direct+prior"
    assert np.abs(helped.translation - before.translation).max() < 1.0
    assert np.abs(alone.motion.translation - before.translation).max() > 3.0


def test_the_stream_tracks_between_block_sum_pairs(flight, monkeypatch):
    from visloc.flow import velocity

    monkeypatch.setattr(velocity, "TRACK_FRAMES", 10)
    fl, cam = flight
    tr = fl.track
    out = {}
    for track in (True, False):
        ego = EgoMotion(cam, options={"direct": True, "track": track})
        out[track] = [ego.update(f, dt=1 / 60, height=float(tr.position[j, 2]))
                      for j, f in enumerate(fl.frames)][1:]
    kinds = ["tracked" if gv.motion.method.endswith("+tracked") else "block" for gv in out[True]]
    assert kinds[0] == "block" and all(k == "block" for k in kinds[::10])  # re-anchored every 10th pair
    assert kinds.count("tracked") >= 0.8 * len(kinds)
    assert all(gv.motion.method.endswith("+direct") for gv in out[False])
    for gt, gf in zip(out[True], out[False], strict=True):  # the same velocities, to the noise of a pair
        assert np.linalg.norm(gt.v - gf.v) < 0.01 and 0.3 <= gt.quality <= 1


def test_tracking_falls_back_to_the_block_sums_on_a_jump(flight):
    fl, cam = flight
    ego = EgoMotion(cam, options={"direct": True}, height=1.0, fps=60)
    for f in fl.frames[:6]:
        ego.update(f)
    assert ego.update(fl.frames[6]).motion.method.endswith("+tracked")
    jump = np.roll(fl.frames[7], (25, -40), axis=(0, 1))  # 40 px left, 25 down: far from the prior
    gv = ego.update(jump)
    assert not gv.motion.method.endswith("+tracked") and ego.last_field is not None
    step = estimate_ground_velocity(fl.frames[6], fl.frames[7], cam, 1.0, 1 / 60, direct=True).motion
    np.testing.assert_allclose(gv.motion.translation, step.translation + (-40, 25), atol=1.0)


def test_the_grid_is_fine_in_slow_flight_and_coarse_at_flight_speed():
    from visloc.flow.direct import FAST_SHIFT, auto_stride
    from visloc.flow.motion import GlobalMotion

    def motion(tx, rotation=0.0):
        return GlobalMotion(np.array([tx, 0.0]), rotation, 1.0, None, 0.0, 10, "similarity")

    assert auto_stride((240, 320), motion(0.5)) == 2
    assert auto_stride((240, 320), motion(0.5, rotation=0.03)) == 2  # yaw moves the corners, not the centre
    assert auto_stride((240, 320), motion(FAST_SHIFT + 0.1)) == 4
    assert auto_stride((480, 640), motion(0.5)) == 4 and auto_stride((480, 640), motion(5.0)) == 8
    with pytest.raises(ValueError, match="stride"):
        refine_motion(np.zeros((64, 64), np.uint8), np.zeros((64, 64), np.uint8), motion(0.0), stride=0)


def test_a_moving_shadow_does_not_read_as_motion_with_shadows_on():
    # a band of 40 % less light drifting across the ground at 1 px per frame: the global gain
    # of the alignment cannot follow it, dividing each frame by its local mean can
    fl = render_flight(0.4, 60.0, size=(320, 240), seed=3, max_speed=1.5, height=(1.0, 1.5), max_yaw_rate=0.5,
                       noise_sigma=1.0, texture="grass")
    w = 320
    errors = {}
    for shadows in (False, True):
        ego = EgoMotion(Camera(fl.K, size=(320, 240)), options={"direct": True, "shadows": shadows})
        err = []
        for k, frame in enumerate(fl.frames):
            x = np.arange(w) - (60.0 + 1.0 * k)
            band = 0.5 * (np.tanh(x / 6.0) - np.tanh((x - w / 3.0) / 6.0))
            img = np.clip(frame * (1.0 - 0.4 * band[None, :]), 0, 255).astype(np.uint8)
            gv = ego.update(img, dt=1 / 60.0, height=float(fl.track.position[k, 2]))
            if gv is not None:
                v = fl.track.pair_v[k]
                err.append(np.linalg.norm(gv.v - v) / max(np.linalg.norm(v), 0.05))
        errors[shadows] = float(np.median(err))
    assert errors[True] < 0.6 * errors[False], errors
