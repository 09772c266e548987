"""The sub-pixel stage after the block-sum flow (visloc.flow.direct)."""

import numpy as np
import pytest

from visloc.flow import block_flow, estimate_ground_velocity, global_motion
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
        gv = estimate_ground_velocity(fl.frames[k - 1], fl.frames[k], cam, float(tr.position[k - 1, 2]), 1 / 60, **kw)
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
