"""The compiled Levenberg-Marquardt takes the numpy version's steps."""

import numpy as np
import pytest

from visloc.pose.gauss_newton import NATIVE_LM, _project, levenberg_marquardt, reprojection_rms


def _problem(rng, planar):
    n = int(rng.integers(4, 60))
    X = np.c_[rng.uniform(-0.5, 0.5, (n, 2)), np.zeros(n) if planar else rng.uniform(-0.1, 0.1, n)].T.copy()
    truth = np.r_[rng.uniform(-0.3, 0.3, 2), rng.uniform(0.8, 2.5), rng.uniform(-0.5, 0.5, 3)]
    uv = _project(truth[None], X)[1][0]
    xy = uv + rng.normal(0, 0.5 / 500, uv.shape)
    starts = truth + rng.normal(0, 0.2, (int(rng.integers(1, 5)), 6))
    starts[:, 2] = np.abs(starts[:, 2]) + 0.3
    return X, xy, starts, truth


@pytest.mark.skipif(not NATIVE_LM, reason="compares the compiled solver with the numpy one")
def test_compiled_and_numpy_solvers_agree():
    rng = np.random.default_rng(0)
    f = np.array([[500.0], [500.0]])
    close = 0
    for case in range(120):
        X, xy, starts, truth = _problem(rng, planar=case % 2 == 0)
        if case % 7 == 0:
            starts[0, 2] = -1.0  # a start that puts the points behind the camera
        for max_iter in (0, 30):
            with np.errstate(invalid="ignore"):  # numpy's M of a start behind the camera
                want = levenberg_marquardt(starts, X, xy, f, max_iter=max_iter, native=False)
            got = levenberg_marquardt(starts, X, xy, f, max_iter=max_iter, native=True)
            finite = np.isfinite(want[1])
            assert (finite == np.isfinite(got[1])).all()
            np.testing.assert_allclose(got[0][finite], want[0][finite], rtol=0, atol=1e-9)
            np.testing.assert_allclose(got[1][finite], want[1][finite], rtol=1e-9)
            np.testing.assert_allclose(got[2][finite], want[2][finite], rtol=1e-9, atol=1e-9)
        best = got[0][np.argmin(got[1])]
        close += np.abs(best - truth).max() < 0.05
    assert close > 100  # and they do solve the problems


@pytest.mark.skipif(not NATIVE_LM, reason="the compiled solver's singular case")
def test_a_parameter_without_effect_takes_the_pseudo_inverse_step():
    # one point seen: rank-deficient normal equations; both versions must return finite steps
    X = np.array([[0.0], [0.0], [0.0]])
    xy = np.array([[0.01], [0.02]])
    f = np.array([[500.0], [500.0]])
    start = np.array([[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]])
    got = levenberg_marquardt(start, X, xy, f, max_iter=10, native=True)
    want = levenberg_marquardt(start, X, xy, f, max_iter=10, native=False)
    assert np.isfinite(got[0]).all() and got[1][0] < 1e-6
    np.testing.assert_allclose(got[1], want[1], atol=1e-9)


@pytest.mark.parametrize("native", [False, True] if NATIVE_LM else [False])
def test_arrays_of_the_wrong_shape_are_refused_before_the_solver(native):
    X = np.zeros((3, 4))
    xy = np.zeros((2, 4))
    f = np.array([[300.0], [300.0]])
    for args, word in (((np.zeros((1, 5)), X, xy, f, 5), "params"), ((np.zeros((1, 6)), X.T, xy, f, 5), "X must"),
                       ((np.zeros((1, 6)), X, xy[:, :3], f, 5), "X must"), ((np.zeros((1, 6)), X, xy, f, -1), "max_iter")):
        with pytest.raises(ValueError, match=word):
            levenberg_marquardt(*args[:4], max_iter=args[4], native=native)


@pytest.mark.parametrize("native", [False, True] if NATIVE_LM else [False])
def test_reprojection_rms_is_each_markers_rms_of_the_residuals(native):
    rng = np.random.default_rng(3)
    f = np.array([[500.0], [480.0]])
    for case in range(30):
        X, xy, starts, _ = _problem(rng, planar=case % 2 == 0)
        keep = len(X[0]) // 4 * 4
        X, xy = X[:, :keep].copy(), xy[:, :keep].copy()
        if case % 5 == 0:
            starts[0, 2] = -1.0  # behind the camera: inf
        got = reprojection_rms(starts, X, xy, f, native=native)
        assert got.shape == (len(starts), keep // 4)
        for s, p in enumerate(starts):
            q, uv = (a[0] for a in _project(p[None], X)[:2])
            z = q[2] + p[2]
            d = ((uv - xy) * f) ** 2
            want = np.sqrt(d.sum(axis=0).reshape(-1, 4).mean(axis=1))
            want[(z <= 1e-9).reshape(-1, 4).any(axis=1)] = np.inf
            np.testing.assert_allclose(got[s], want, rtol=1e-12)
        single = reprojection_rms(starts[-1], X, xy, f, native=native)
        np.testing.assert_array_equal(single, got[-1])


@pytest.mark.parametrize("native", [False, True] if NATIVE_LM else [False])
def test_reprojection_rms_refuses_runs_that_do_not_divide_the_points(native):
    X, xy, f = np.ones((3, 6)), np.zeros((2, 6)), np.array([[1.0], [1.0]])
    with pytest.raises(ValueError, match="group"):
        reprojection_rms(np.zeros(6), X, xy, f, native=native)
    with pytest.raises(ValueError, match="X must be"):
        reprojection_rms(np.zeros(6), X, xy[:, :4], f, group=2, native=native)
