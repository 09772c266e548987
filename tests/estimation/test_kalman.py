"""PositionVelocityKF: accuracy against differencing, NEES consistency, gating, gaps, smoothing."""

import math

import numpy as np
import pytest
from filterpy.common import Q_discrete_white_noise
from scipy.stats import chi2

from visloc.estimation import PositionVelocityKF

RATE = 30.0
POS_STD = 0.015  # m, marker-map position noise


def rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def smooth_trajectory(seconds=20.0, rate=RATE, seed=0, accel_std=1.0):
    """Analytic 2-D trajectory, sums of sinusoids (0.1-0.8 Hz): times (N,), position, velocity
    and acceleration (N, 2); each acceleration axis has standard deviation ``accel_std``."""
    rng = np.random.default_rng(seed)
    t = np.arange(round(seconds * rate)) / rate
    pos, vel, acc = (np.zeros((t.size, 2)) for _ in range(3))
    for axis in range(2):
        w = 2 * np.pi * rng.uniform(0.1, 0.8, 6)
        phase = rng.uniform(0, 2 * np.pi, 6)
        amp = rng.uniform(0.5, 1.0, 6) / w**2
        amp *= accel_std / math.sqrt(0.5 * np.sum((amp * w**2) ** 2))
        arg = np.outer(t, w) + phase
        pos[:, axis] = np.sin(arg) @ amp
        vel[:, axis] = np.cos(arg) @ (amp * w)
        acc[:, axis] = -np.sin(arg) @ (amp * w**2)
    return t, pos, vel, acc


def noisy_fixes(pos, seed, missing=0.1, std=POS_STD):
    """Position measurements with white noise; a fraction ``missing`` replaced by None (never the
    first two)."""
    rng = np.random.default_rng(seed)
    z = pos + rng.normal(0.0, std, pos.shape)
    drop = rng.random(len(pos)) < missing
    drop[:2] = False
    return [None if d else zi for zi, d in zip(z, drop)]


def run(t, fixes, *, kf=None, vel_meas=None, vel_std=0.05, accel=None, accel_std=None, **kw):
    """Run a filter over the samples; returns the filter and its (N, 2) positions, velocities."""
    kf = kf or PositionVelocityKF(2, accel_noise=kw.pop("accel_noise", 1.0),
                                  accel_noise_kind="density", **kw)
    p_est, v_est = np.zeros((len(t), 2)), np.zeros((len(t), 2))
    for k, tk in enumerate(t):
        kf.predict(tk, None if accel is None else accel[k], accel_std=accel_std)
        if fixes[k] is not None:
            kf.update_position(fixes[k], std=POS_STD)
        if vel_meas is not None:
            kf.update_velocity(vel_meas[k], std=vel_std)
        p_est[k], v_est[k] = kf.position, kf.velocity
    return kf, p_est, v_est


def differenced_velocity(t, fixes):
    """Backward difference of consecutive available fixes (held over gaps), (N, 2)."""
    v = np.zeros((len(t), 2))
    last_t, last_z, current = None, None, np.zeros(2)
    for k, (tk, z) in enumerate(zip(t, fixes)):
        if z is not None:
            if last_z is not None:
                current = (z - last_z) / (tk - last_t)
            last_t, last_z = tk, z
        v[k] = current
    return v


@pytest.fixture(scope="module")
def track():
    t, pos, vel, acc = smooth_trajectory()
    return t, pos, vel, acc, noisy_fixes(pos, seed=1)


SETTLE = 30  # samples (1 s) left out of the error statistics


def test_velocity_beats_differencing(track):
    t, pos, vel, _, fixes = track
    _, p_est, v_est = run(t, fixes)
    kf_rms = rms(v_est[SETTLE:] - vel[SETTLE:])
    diff_rms = rms(differenced_velocity(t, fixes)[SETTLE:] - vel[SETTLE:])
    assert kf_rms < 0.5 * diff_rms, f"KF velocity RMS {kf_rms:.4f} m/s, differencing {diff_rms:.4f}"
    assert rms(p_est[SETTLE:] - pos[SETTLE:]) < POS_STD


def simulate_model(kf_model, kind, rng, n_steps, accel_noise, r_cov):
    """Truth drawn from the filter's own model on jittered 30 Hz steps: times, states (n, dim_x)
    in the filter's order, and fixes (some missing)."""
    order = 2 if kf_model == "cv" else 3
    dts = rng.uniform(0.8, 1.2, n_steps) / RATE
    t = np.concatenate([[0.0], np.cumsum(dts[1:])])
    x = np.zeros((n_steps, 2 * order))
    x0 = np.zeros(2 * order)
    x0[1::order] = rng.normal(0.0, 0.5, 2)  # velocity ~ N(0, 0.5^2), as the filter's prior
    if order == 3:
        x0[2::order] = rng.normal(0.0, 0.5, 2)
    x[0] = x0
    helper = PositionVelocityKF(2, model=kf_model, accel_noise=accel_noise, accel_noise_kind=kind)
    white = rng.standard_normal((n_steps, 2 * order))
    for k in range(1, n_steps):
        F, Q = helper.transition(t[k] - t[k - 1])
        w, v = np.linalg.eigh(Q)  # Q = L L^T with L = V sqrt(W): process noise ~ N(0, Q)
        x[k] = F @ x[k - 1] + (v * np.sqrt(np.clip(w, 0.0, None))) @ white[k]
    pos = x[:, 0::order]
    z = pos + rng.multivariate_normal(np.zeros(2), r_cov, n_steps)
    drop = rng.random(n_steps) < 0.1
    drop[:2] = False
    return t, x, [None if d else zi for zi, d in zip(z, drop)]


@pytest.mark.parametrize(("model", "kind"), [("cv", "std"), ("cv", "density"), ("ca", "density")])
def test_nees_consistent(model, kind):
    n_runs, n_steps, accel_noise = 50, 150, 0.5
    r_cov = POS_STD**2 * np.array([[1.0, 0.3], [0.3, 1.0]])
    rng = np.random.default_rng(42)
    nees = np.zeros((n_runs, n_steps))
    dim_x = 0
    for i in range(n_runs):
        t, x, fixes = simulate_model(model, kind, rng, n_steps, accel_noise, r_cov)
        kf = PositionVelocityKF(2, model=model, accel_noise=accel_noise, accel_noise_kind=kind,
                                initial_std=0.5)
        dim_x = kf.dim_x
        for k in range(n_steps):
            kf.predict(t[k])
            if fixes[k] is not None:
                kf.update_position(fixes[k], r_cov)
            e = kf.x - x[k]
            nees[i, k] = e @ np.linalg.solve(kf.P, e)
    anees = nees.mean(axis=0)
    lo, hi = chi2.ppf([0.025, 0.975], dim_x * n_runs) / n_runs
    inside = np.mean((anees >= lo) & (anees <= hi))
    assert lo <= anees.mean() <= hi, f"average NEES {anees.mean():.3f}, bounds [{lo:.3f}, {hi:.3f}]"
    assert inside >= 0.9, f"ANEES inside [{lo:.3f}, {hi:.3f}] at only {inside:.0%} of the steps"


def test_outliers_rejected_and_track_unaffected(track):
    t, pos, _, _, fixes = track
    idx = [100, 180, 260, 340, 420]
    assert all(fixes[i] is not None for i in idx)
    rng = np.random.default_rng(5)
    bad = list(fixes)
    for i in idx:
        direction = rng.normal(size=2)
        bad[i] = fixes[i] + direction / np.linalg.norm(direction)  # 1 m off
    kf = PositionVelocityKF(2, accel_noise=1.0, accel_noise_kind="density")
    used = []
    for k, tk in enumerate(t):
        kf.predict(tk)
        if bad[k] is not None and not kf.update_position(bad[k], std=POS_STD):
            used.append(k)
    assert used == idx, f"rejected samples {used}, outliers at {idx}"
    assert kf.rejected["position"] == 5
    # the same as if those samples had been missing
    missing = [None if k in idx else z for k, z in enumerate(fixes)]
    _, p_ref, v_ref = run(t, missing)
    ref = PositionVelocityKF(2, accel_noise=1.0, accel_noise_kind="density")
    _, p_out, v_out = run(t, bad, kf=ref)
    np.testing.assert_allclose(p_out, p_ref, atol=1e-12)
    np.testing.assert_allclose(v_out, v_ref, atol=1e-12)
    assert rms(p_out[SETTLE:] - pos[SETTLE:]) < POS_STD
    # without the gate the outliers pull the track
    _, p_nogate, _ = run(t, bad, gate=None)
    assert np.max(np.linalg.norm(p_nogate - pos, axis=1)) > 0.1


def test_gap_grows_covariance_and_recovers(track):
    t, pos, vel, _, fixes = track
    gap = range(240, 270)  # 1 s without fixes
    fixes = [None if k in gap else z for k, z in enumerate(fixes)]
    kf = PositionVelocityKF(2, accel_noise=1.0, accel_noise_kind="density")
    traces, errors, v_err = [], [], []
    for k, tk in enumerate(t):
        kf.predict(tk)
        if fixes[k] is not None:
            accepted = kf.update_position(fixes[k], std=POS_STD)
            assert accepted or k != gap.stop, "first fix after the gap rejected"
        traces.append(np.trace(kf.P))
        errors.append(np.linalg.norm(kf.position - pos[k]))
        v_err.append(kf.velocity - vel[k])
    in_gap = np.array(traces[gap.start - 1:gap.stop])
    assert np.all(np.diff(in_gap) > 0), "P must grow while predicting only"
    assert in_gap[-1] > 20 * in_gap[0]
    after = slice(gap.stop + 30, gap.stop + 90)
    assert max(errors[after]) < 4 * POS_STD, f"not recovered: {max(errors[after]):.3f} m"
    v_after, v_before = rms(v_err[after]), rms(v_err[SETTLE:gap.start])
    assert v_after < 1.5 * v_before, f"velocity RMS {v_after:.3f} after, {v_before:.3f} before"
    assert kf.rejected["position"] == 0


def test_out_of_order_and_nan():
    kf = PositionVelocityKF(2, initial_position=(0.0, 0.0))
    kf.predict(1.0)
    with pytest.raises(ValueError, match=r"out-of-order timestamp: t=0\.5"):
        kf.predict(0.5)
    with pytest.raises(ValueError, match=r"out-of-order timestamp: t=0\.25"):
        kf.update_position((0.0, 0.0), std=0.01, t=0.25)
    kf.predict(1.0)  # same time: nothing happens
    x, P = kf.x, kf.P
    assert not kf.update_position((math.nan, 0.0), std=0.01)
    assert not kf.update_velocity((0.0, math.inf), std=0.01)
    assert not kf.update_position((0.0, 0.0), R=np.full((2, 2), math.nan))
    assert kf.skipped["position"] == 2 and kf.skipped["velocity"] == 1
    kf.predict(1.1, (math.nan, 0.0))
    assert kf.skipped["accel_input"] == 1
    assert np.all(np.isfinite(kf.x)) and np.all(np.isfinite(kf.P))
    np.testing.assert_array_equal(x, kf.history[0][1])
    np.testing.assert_array_equal(P, kf.history[0][2])
    assert len(kf.history) == 2


def test_flow_velocity_lowers_error(track):
    t, _, vel, _, fixes = track
    flow = vel + np.random.default_rng(3).normal(0.0, 0.05, vel.shape)
    _, _, v_pos = run(t, fixes)
    kf, _, v_flow = run(t, fixes, vel_meas=flow)
    e_pos, e_flow = rms(v_pos[SETTLE:] - vel[SETTLE:]), rms(v_flow[SETTLE:] - vel[SETTLE:])
    assert e_flow < 0.7 * e_pos, f"velocity RMS with flow {e_flow:.4f}, without {e_pos:.4f} m/s"
    assert kf.rejected["velocity"] <= 2


def test_rts_smoothing_improves(track):
    t, pos, vel, _, fixes = track
    kf, p_fwd, v_fwd = run(t, fixes)
    xs, Ps = kf.rts_smooth()
    assert xs.shape == (len(t), 4) and Ps.shape == (len(t), 4, 4)
    s = slice(SETTLE, None)
    for name, fwd, smooth, truth in [("position", p_fwd, xs[:, 0::2], pos),
                                     ("velocity", v_fwd, xs[:, 1::2], vel)]:
        e_fwd, e_smooth = rms(fwd[s] - truth[s]), rms(smooth[s] - truth[s])
        assert e_smooth < 0.8 * e_fwd, f"{name} RMS smoothed {e_smooth:.4f}, forward {e_fwd:.4f}"
    assert np.all(np.trace(Ps, axis1=1, axis2=2) <= np.trace(np.array(
        [p for _, _, p in kf.history]), axis1=1, axis2=2) + 1e-12)


def test_rts_matches_filterpy_without_inputs(track):
    t, _, _, _, fixes = track
    kf, _, _ = run(t[:200], fixes[:200])
    xs, Ps = kf.rts_smooth()
    hist = kf.history
    steps = [kf.transition(hist[max(k, 1)][0] - hist[max(k, 1) - 1][0]) for k in range(len(hist))]
    ref_x, ref_P, _, _ = kf.kf.rts_smoother(np.array([x for _, x, _ in hist]),
                                            np.array([p for _, _, p in hist]),
                                            Fs=[f for f, _ in steps], Qs=[q for _, q in steps])
    np.testing.assert_allclose(xs, ref_x, atol=1e-9)
    np.testing.assert_allclose(Ps, ref_P, atol=1e-12)


def test_accelerometer_input_lowers_velocity_error(track):
    t, _, vel, acc, fixes = track
    mid_acc = np.vstack([acc[:1], 0.5 * (acc[1:] + acc[:-1])])  # mean over each step
    meas = mid_acc + np.random.default_rng(4).normal(0.0, 0.05, acc.shape)
    _, _, v_plain = run(t, fixes)
    _, _, v_acc = run(t, fixes, accel=meas, accel_std=0.1)
    e_plain, e_acc = rms(v_plain[SETTLE:] - vel[SETTLE:]), rms(v_acc[SETTLE:] - vel[SETTLE:])
    assert e_acc < 0.5 * e_plain, f"velocity RMS with accel {e_acc:.4f}, without {e_plain:.4f}"


def test_persistent_jump_resets():
    t, pos, _, _ = smooth_trajectory(seconds=6.0, seed=2)
    fixes = noisy_fixes(pos, seed=3, missing=0.0)
    jumped = [z + (1.0, 0.0) if k >= 90 else z for k, z in enumerate(fixes)]
    kf, p_est, _ = run(t, jumped, reset_after=5)
    assert kf.resets == 1 and kf.rejected["position"] == 5
    assert np.max(np.abs(p_est[-30:] - pos[-30:] - (1.0, 0.0))) < 0.05
    kf, _, _ = run(t, jumped, reset_after=None)  # only the growing P opens the gate, much later
    assert kf.resets == 0 and kf.rejected["position"] > 30


def test_constant_acceleration_model_and_3d():
    kf = PositionVelocityKF(3, model="ca", accel_noise=0.1, accel_noise_kind="density",
                            initial_std=(1.0, 1.0, 2.0))
    assert kf.dim_x == 9
    a = np.array([0.5, -0.2, 0.1])
    rng = np.random.default_rng(0)
    for k in range(150):
        tk = k / RATE
        kf.update_position(0.5 * a * tk**2 + rng.normal(0, POS_STD, 3), std=POS_STD, t=tk)
        if k % 10 == 0:
            kf.update_acceleration(a + rng.normal(0, 0.05, 3), std=0.05)
    np.testing.assert_allclose(kf.acceleration, a, atol=0.05)
    np.testing.assert_allclose(kf.velocity, a * 149 / RATE, atol=0.05)
    F, Q = kf.transition(0.1)
    block = Q_discrete_white_noise(3, dt=0.1, var=0.1**2 * 0.1)  # jerk density: q^2 dt
    np.testing.assert_allclose(Q[3:6, 3:6], block)  # per-axis blocks: [p, v, a] of y
    assert np.count_nonzero(Q) == 27
    np.testing.assert_allclose(F[0, :3], [1.0, 0.1, 0.005])
    per_step = PositionVelocityKF(3, model="ca", accel_noise=0.1)  # default kind "std"
    _, Q = per_step.transition(0.1)
    np.testing.assert_allclose(Q, Q_discrete_white_noise(3, dt=0.1, var=0.01, block_size=3))
    _, Q = PositionVelocityKF(2, accel_noise=2.0, accel_noise_kind="density").transition(0.05)
    np.testing.assert_allclose(Q, Q_discrete_white_noise(2, dt=0.05, var=4.0 / 0.05, block_size=2))
    with pytest.raises(ValueError, match="accel"):
        kf.predict(10.0, accel=(0.0, 0.0, 0.0))
    with pytest.raises(AttributeError):
        _ = PositionVelocityKF(2).acceleration


def test_density_noise_is_rate_independent():
    one, many = (PositionVelocityKF(2, initial_position=(0.0, 0.0), accel_noise_kind="density")
                 for _ in range(2))
    one.predict(0.0)
    one.predict(1.0)
    for k in range(31):
        many.predict(k / 30)
    np.testing.assert_allclose(one.P[1, 1], many.P[1, 1])  # velocity: 1 + q^2 * 1 s
    assert 0.8 < one.P[0, 0] / many.P[0, 0] < 1.2


@pytest.mark.parametrize(("kwargs", "exc", "match"), [
    ({"dims": 4}, ValueError, "dims"),
    ({"dims": 2.0}, TypeError, "dims"),
    ({"model": "cj"}, ValueError, "model"),
    ({"accel_noise": -1.0}, ValueError, "accel_noise"),
    ({"accel_noise_kind": "psd"}, ValueError, "accel_noise_kind"),
    ({"gate": 1.5}, ValueError, "gate"),
    ({"reset_after": 0}, ValueError, "reset_after"),
    ({"initial_position": (0.0, 0.0, 0.0)}, ValueError, "initial_position"),
    ({"initial_velocity": (0.0, math.nan)}, ValueError, "initial_velocity"),
    ({"initial_std": (1.0, 2.0, 3.0)}, ValueError, "initial_std"),
])
def test_constructor_checks(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        PositionVelocityKF(**kwargs)


def test_measurement_checks():
    kf = PositionVelocityKF(2)
    with pytest.raises(ValueError, match="predict"):
        kf.update_position((0.0, 0.0), std=0.01)
    kf.predict(0.0)
    with pytest.raises(ValueError, match="z must have shape"):
        kf.update_position((0.0, 0.0, 0.0), std=0.01)
    with pytest.raises(ValueError, match="R must have shape"):
        kf.update_position((0.0, 0.0), np.eye(3))
    with pytest.raises(ValueError, match="R must be symmetric"):
        kf.update_position((0.0, 0.0), [[1.0, 0.5], [0.0, 1.0]])
    with pytest.raises(ValueError, match="R must be positive definite"):
        kf.update_position((0.0, 0.0), [[1.0, 0.0], [0.0, -1.0]])
    with pytest.raises(ValueError, match="exactly one of R and std"):
        kf.update_velocity((0.0, 0.0))
    with pytest.raises(ValueError, match="std must be > 0"):
        kf.update_velocity((0.0, 0.0), std=0.0)
    with pytest.raises(ValueError, match="accel must have shape"):
        kf.predict(1.0, accel=(1.0,))
    with pytest.raises(TypeError, match="t must be a real number"):
        kf.predict("1.0")
    with pytest.raises(ValueError, match="update_acceleration needs model='ca'"):
        kf.update_acceleration((0.0, 0.0), std=1.0)
    with pytest.raises(ValueError, match="no history"):
        PositionVelocityKF(2, keep_history=False).rts_smooth()


@pytest.mark.parametrize("kind", ["position", "velocity", "acceleration"])
def test_a_bad_measurement_leaves_the_clock_alone(kind):
    kf = PositionVelocityKF(2, model="ca", initial_position=(0.0, 0.0))
    kf.predict(1.0)
    update = getattr(kf, f"update_{kind}")
    x, P = kf.x, kf.P
    for args, kwargs, match in (
        (((0.0, 0.0, 0.0),), {"std": 0.01}, "z must have shape"),
        (((0.0, 0.0),), {"R": np.eye(3)}, "R must have shape"),
        (((0.0, 0.0),), {"std": -0.01}, "std must be > 0"),
        (((0.0, 0.0),), {}, "exactly one of R and std"),
    ):
        with pytest.raises(ValueError, match=match):
            update(*args, t=2.0, **kwargs)
        assert kf.t == 1.0
        np.testing.assert_array_equal(kf.x, x)
        np.testing.assert_array_equal(kf.P, P)
    assert len(kf.history) == 1
    assert update((0.0, 0.0), std=0.01, t=2.0) and kf.t == 2.0


def test_a_refused_predict_counts_no_dropped_input():
    # skipped["accel_input"] used to count inputs of calls that then raised
    kf = PositionVelocityKF(2, model="cv")
    kf.predict(0.0)
    with pytest.raises(ValueError, match="out-of-order"):
        kf.predict(-1.0, accel=[np.nan, 0.0])
    with pytest.raises(ValueError, match="accel_std"):
        kf.predict(1.0, accel=[np.nan, 0.0], accel_std=-1.0)
    assert kf.skipped["accel_input"] == 0 and kf.t == 0.0
    kf.predict(1.0, accel=[np.nan, 0.0])
    assert kf.skipped["accel_input"] == 1 and kf.t == 1.0


def test_a_step_beyond_the_models_range_is_refused_and_changes_nothing():
    # dt ** 4 overflowed (OverflowError); a denormal step made P NaN without a word
    kf = PositionVelocityKF(2, model="cv")
    kf.predict(0.0)
    with pytest.raises(ValueError, match="dt: a step of 1e"):
        kf.predict(1e100)
    assert kf.t == 0.0 and np.isfinite(kf.P).all()
    dense = PositionVelocityKF(2, model="cv", accel_noise_kind="density")
    dense.predict(0.0)
    with pytest.raises(ValueError, match="non-finite"):
        dense.predict(5e-324)
    assert np.isfinite(dense.P).all()
