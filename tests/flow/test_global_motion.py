import numpy as np
import pytest

from tests.flow.conftest import moved
from visloc.flow import block_flow, global_motion
from visloc.types import FlowField


def _synthetic_field(gamma, center, t=(0.0, 0.0), noise=0.0, seed=0):
    """A flow field of an exact rotation by gamma about center plus a translation."""
    ys, xs = np.mgrid[19.5:240:40, 19.5:320:40]
    p = np.stack([xs.ravel(), ys.ravel()], axis=1)
    c = np.asarray(center, float)
    cg, sg = np.cos(gamma), np.sin(gamma)
    r = p - c
    q = np.stack([cg * r[:, 0] - sg * r[:, 1], sg * r[:, 0] + cg * r[:, 1]], axis=1) + c + t
    v = q - p + np.random.default_rng(seed).normal(0, noise, p.shape)
    return FlowField(p, v, np.ones(len(p)), 40, (320, 240))


@pytest.mark.parametrize("method", ["cir", "similarity"])
@pytest.mark.parametrize("center", [(100.0, 80.0), (300.0, -50.0), (159.5, 119.5)])
def test_rotation_about_a_known_centre_is_recovered(method, center):
    # the report's rows-and-columns solver is a small-angle one; its second pass removes most
    # of the finite angle's error, not all
    tol_angle, tol_centre, tol_t = (2e-5, 0.1, 0.01) if method == "cir" else (1e-9, 1e-6, 1e-6)
    f = _synthetic_field(0.03, center)
    m = global_motion(f, method=method)
    assert m.rotation == pytest.approx(0.03, abs=tol_angle)
    assert np.allclose(m.center_of_rotation, center, atol=tol_centre)
    # translation at the image centre = displacement of the centre under the rotation
    c = np.array(center)
    r = np.array([159.5, 119.5]) - c
    expected = np.array([np.cos(0.03) * r[0] - np.sin(0.03) * r[1], np.sin(0.03) * r[0] + np.cos(0.03) * r[1]]) - r
    assert np.allclose(m.translation, expected, atol=tol_t)


@pytest.mark.parametrize("method", ["cir", "similarity"])
def test_pure_translation_puts_the_centre_at_infinity(method):
    f = _synthetic_field(0.0, (0.0, 0.0), t=(4.0, -2.5), noise=0.05)
    m = global_motion(f, method=method)
    assert m.center_of_rotation is None
    assert np.allclose(m.translation, (4.0, -2.5), atol=0.03)
    assert abs(m.rotation) < 1e-3 and np.isfinite(m.residual_rms)


def test_similarity_rejects_outliers():
    f = _synthetic_field(-0.02, (50.0, 200.0), t=(1.0, 2.0), noise=0.03)
    v = f.vectors.copy()
    v[:6] += 15.0  # six blocks matched something else
    m = global_motion(FlowField(f.centers, v, f.confidence, 40, (320, 240)))
    assert m.rotation == pytest.approx(-0.02, abs=5e-4)
    assert m.inliers <= len(v) - 6


@pytest.mark.parametrize("method", ["cir", "similarity"])
def test_real_image_rotation_and_shift(method):
    a, b = moved(5.0, -2.0, angle=0.02)
    m = global_motion(block_flow(a, b), method=method)
    assert m.rotation == pytest.approx(0.02, abs=1e-3)
    assert np.allclose(m.translation, (5.0, -2.0), atol=0.15)


def test_too_few_blocks_means_no_motion():
    f = _synthetic_field(0.0, (0, 0), t=(1.0, 1.0))
    f0 = FlowField(f.centers, f.vectors, np.zeros(len(f.vectors)), 40, (320, 240))
    m = global_motion(f0)
    assert m.inliers == 0 and np.allclose(m.translation, 0)


def test_bad_arguments():
    with pytest.raises(TypeError, match="field"):
        global_motion("flow")
    with pytest.raises(ValueError, match="method"):
        global_motion(_synthetic_field(0.0, (0, 0)), method="ransac")


def test_similarity_fit_needs_one_iteration():
    # iterations=0 used to end in an UnboundLocalError
    from visloc.flow.motion import similarity_fit

    a, b = moved(dx=2.0)
    field = block_flow(a, b)
    assert similarity_fit(field, iterations=1).inliers > 0
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="iterations"):
            similarity_fit(field, iterations=bad)
