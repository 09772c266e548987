"""Polytope robustness against the motor spread (report §4.3, eqs. 4.12-4.16)."""

import sys

import numpy as np
import pytest

from visloc.control import (
    augmented_model,
    closed_loop_vertices,
    common_lyapunov,
    design_gains,
    largest_sigma,
    max_sigma,
    vertex_check,
    vertex_stability,
)
from visloc.control.robustness import _lmi_scs_data
from visloc.model import ARDRONE2

P = ARDRONE2
# FIELD-NOTES: both vertices have the double eigenvalue -1, their midpoint has +0.5
A1 = np.array([[-1.0, 3.0], [0.0, -1.0]])
A2 = np.array([[-1.0, 0.0], [3.0, -1.0]])


def test_stable_vertices_do_not_make_a_stable_polytope():
    stable, worst, _ = vertex_stability(np.array([A1, A2]))
    assert stable and worst == pytest.approx(-1.0)
    mid_stable, mid_worst, _ = vertex_stability(((A1 + A2) / 2)[None])
    assert not mid_stable and mid_worst == pytest.approx(0.5)
    pytest.importorskip("cvxpy", exc_type=ImportError)
    assert common_lyapunov(np.array([A1, A2])).status == "infeasible"
    # a pair that does share one (the identity works for both): feasible and verified
    b1 = np.array([[-1.0, 1.0], [0.0, -1.0]])
    res = common_lyapunov(np.array([b1, b1.T]))
    assert res.status == "feasible" and res.max_lmi_eig < 0
    assert np.all(np.linalg.eigvalsh(res.P) > 0)


def test_the_lmi_data_handed_to_scs_is_the_lmi():
    # s = b - A x with x = svec(P) must hold P - I and -(A_i^T P + P A_i) - I, each as SCS
    # reads a cone: the lower triangle column by column, off-diagonal entries times sqrt(2)
    rng = np.random.default_rng(3)
    n = 4
    mats = rng.normal(size=(5, n, n))
    p = rng.normal(size=(n, n))
    p = p + p.T
    a_mat, b_vec, basis = _lmi_scs_data(mats)
    cols, rows = np.triu_indices(n)
    weight = np.where(rows != cols, np.sqrt(2.0), 1.0)
    x = p[rows, cols] * weight
    np.testing.assert_allclose(basis @ x, p, atol=1e-12)  # smat(svec(P)) = P
    s = (b_vec - a_mat @ x).reshape(len(mats) + 1, -1)
    wanted = [p - np.eye(n)] + [-(a.T @ p + p @ a) - np.eye(n) for a in mats]
    for got, w in zip(s, wanted):
        np.testing.assert_allclose(got, w[rows, cols] * weight, atol=1e-12)


def test_scs_on_the_data_built_here_agrees_with_scs_through_cvxpy():
    pytest.importorskip("cvxpy", exc_type=ImportError)
    rng = np.random.default_rng(8)
    base = rng.normal(size=(4, 4)) - 4.0 * np.eye(4)  # stable
    near = base + 0.3 * rng.normal(size=(12, 4, 4))  # stable vertices sharing a certificate
    far = np.array([A1, A2] * 3) + 0.05 * rng.normal(size=(6, 2, 2))  # stable vertices, none shared
    for mats, wanted in ((near, "feasible"), (far, "infeasible")):
        assert vertex_stability(mats)[0]
        direct, through = common_lyapunov(mats), common_lyapunov(mats, solver="SCS")
        assert direct.status == through.status == wanted, (direct.message, through.message)
        assert direct.message.startswith("SCS: ")
        if wanted == "feasible":
            for a in mats:
                assert np.max(np.linalg.eigvalsh(a.T @ direct.P + direct.P @ a)) < 0


def test_lyapunov_unavailable_without_cvxpy(monkeypatch):
    monkeypatch.setitem(sys.modules, "cvxpy", None)  # import cvxpy now raises ImportError
    res = common_lyapunov(np.array([A1, A2]))
    assert res.status == "unavailable" and res.P is None
    with pytest.raises(ValueError, match="test"):
        largest_sigma(test="lyapunov")


@pytest.fixture(scope="module")
def gains():
    return design_gains(P)


def test_vertices_of_the_polytope(gains):
    mats, ratios = closed_loop_vertices(2.0, gains=gains)
    assert mats.shape == (256, 16, 16) and ratios.shape == (256, 8)
    assert len({tuple(r) for r in ratios}) == 256 and np.all(np.abs(ratios) == 2.0)
    nominal, _ = closed_loop_vertices(0.0, gains=gains)
    np.testing.assert_allclose(nominal, nominal[0][None].repeat(256, axis=0))
    assert closed_loop_vertices(1.0, gains=gains, integral=False)[0].shape == (256, 12, 12)
    # the closed loop is affine in the ratios (eq. 4.15): the centre of two opposite vertices
    # is the nominal loop
    lo, hi = mats[0], mats[-1]
    np.testing.assert_allclose((lo + hi) / 2, nominal[0], atol=1e-12)


def test_designed_controller_passes_the_256_vertex_check_at_2_sigma(gains):
    r = vertex_check(2.0, gains=gains)
    assert r.vertices == 256 and r.vertex_stable
    a, b = augmented_model(P)
    nominal = np.max(np.linalg.eigvals(a - b @ gains.K()).real)
    assert nominal < 0 and abs(r.max_real_eig - nominal) < 1e-3  # the slow integral pole barely moves
    assert r.lyapunov is None


def test_lyapunov_certificate_at_2_sigma(gains):
    pytest.importorskip("cvxpy", exc_type=ImportError)
    mats, _ = closed_loop_vertices(2.0, gains=gains)
    res = common_lyapunov(mats)
    assert res.status == "feasible"
    for a in mats[::17]:
        assert np.max(np.linalg.eigvalsh(a.T @ res.P + res.P @ a)) < 0


def test_no_common_lyapunov_matrix_at_6_sigma_though_every_vertex_is_stable(gains):
    pytest.importorskip("cvxpy", exc_type=ImportError)
    r = vertex_check(6.0, gains=gains, lyapunov=True)
    assert r.vertex_stable and r.lyapunov == "infeasible"


def test_the_arm_distance_does_not_change_the_spectra(gains):
    # eq. (2.12)'s unknown d: a diagonal state scaling of the height and yaw chains maps one
    # arm's closed loop onto another's, so neither test depends on it
    a, _ = closed_loop_vertices(5.0, gains=gains, arm=0.10)
    b, _ = closed_loop_vertices(5.0, gains=gains, arm=0.18)
    assert np.max(np.abs(a - b)) > 1.0
    for i in (0, 77, 200, 255):  # same characteristic polynomial
        np.testing.assert_allclose(np.poly(a[i]), np.poly(b[i]), rtol=1e-9)


def test_vertex_check_fails_far_out_and_largest_sigma(gains):
    assert not vertex_check(8.0, gains=gains).vertex_stable
    n = largest_sigma(test="vertex", gains=gains, tol=0.02)
    assert 7.0 < n < 7.6
    assert vertex_check(n, gains=gains).vertex_stable
    assert not vertex_check(n + 0.02, gains=gains).vertex_stable
    assert max_sigma(P) == pytest.approx(P.d_mean / P.d_std)


def test_bad_arguments():
    with pytest.raises(ValueError, match="n_sigma"):
        vertex_check(-1.0)
    with pytest.raises(ValueError, match="n_sigma"):
        vertex_check(9.0)  # d_mean - 9 d_std < 0
    with pytest.raises(TypeError, match="n_sigma"):
        vertex_check("2")
    with pytest.raises(ValueError, match="test"):
        largest_sigma(test="eigen")
    with pytest.raises(ValueError, match="matrices"):
        vertex_stability(np.zeros((2, 3)))


def test_the_tracking_loop_at_a_trajectory_tilt(gains):
    # a trajectory holds a tilt (feed-forward) while the feedback acts on the errors from it:
    # the model linearised in a steady sideways acceleration at 15 degrees roll has thrust
    # pushing sideways as well as up (sin and cos of the roll over the mass), and every
    # vertex of the +-2 sigma box is still stable there
    import math

    from visloc.control import linearize_numerical

    phi = math.radians(15.0)
    _, b = linearize_numerical(ARDRONE2, roll=phi)
    assert b[4, 0] == pytest.approx(math.sin(phi) / ARDRONE2.mass, rel=1e-6)
    assert b[5, 0] == pytest.approx(-math.cos(phi) / ARDRONE2.mass, rel=1e-6)
    tilted, _ = closed_loop_vertices(2.0, gains=gains, roll=phi)
    hover, _ = closed_loop_vertices(2.0, gains=gains)
    assert not np.allclose(tilted, hover)  # another operating point
    assert vertex_stability(tilted)[0]
    with pytest.raises(ValueError, match="roll"):
        linearize_numerical(ARDRONE2, roll=1.3)


def test_motors_without_spread_are_robust_at_every_sigma():
    # max_sigma is inf: the bisection used to pass inf on to closed_loop_vertices
    import dataclasses
    import math

    exact = dataclasses.replace(P, c_std=0.0, d_std=0.0)
    assert max_sigma(exact) == math.inf and largest_sigma(params=exact) == math.inf
    with pytest.raises(ValueError, match="N, n >= 1"):
        vertex_stability(np.zeros((1, 0, 0)))
