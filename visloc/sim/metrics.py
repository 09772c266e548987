"""Figures of a closed-loop run: settling, overshoot, height dip, RMS errors, and the same
step on the linear model (report §4.4: the height dip is a non-linear effect)."""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm

from visloc.control._checks import as_array, check_real
from visloc.control.design import ControllerGains, augmented_model
from visloc.model.params import ARDrone2Params
from visloc.sim.scenarios import Scenario
from visloc.types import FloatArray

__all__ = ["LINEAR_SECONDS", "linear_step_response", "run_metrics", "settling_time", "step_metrics_linear"]

LINEAR_SECONDS = 20.0
"""Shortest time the linear counterpart of a step is run for (its integrators never stop)."""

def settling_time(t: FloatArray, error: FloatArray, band: float, t0: float) -> float | None:
    """Time after ``t0`` (s) from which ``|error| <= band`` holds to the end; None if it never does.

    Parameters
    ----------
    t, error : ndarray (N,)
        Sample times (s) and the error at each.
    band : float
        Settling band, in the error's units.
    t0 : float
        When the step or disturbance happened, s.

    Returns
    -------
    float or None
        Settling time after ``t0``, s: 0 when the error never leaves the band after ``t0``;
        None when it is outside the band at the end or no sample is at or after ``t0``.
    """
    after = t >= t0
    outside = after & ~(np.abs(error) <= band)  # a NaN error is outside
    if not np.any(after) or not abs(error[-1]) <= band:
        return None
    if not np.any(outside):
        return 0.0
    last = int(np.flatnonzero(outside)[-1])
    return float(t[min(last + 1, len(t) - 1)] - t0)


def linear_step_response(gains: ControllerGains, params: ARDrone2Params, step: FloatArray,
                         seconds: float, *, dt: float = 0.005) -> tuple[FloatArray, FloatArray]:
    """Set-point step of the *linear* closed loop ``x' = (A - B K) x`` (report eqs. 4.4-4.5).

    Parameters
    ----------
    gains : ControllerGains
        The controller (``K`` with the integral states, :meth:`ControllerGains.K`).
    params : ARDrone2Params
        Vehicle parameters of the linear model (:func:`visloc.control.augmented_model`).
    step : array_like (4,)
        Set-point change ``[dx, dy, dz, dpsi]`` (m in the pilot-frame axes, rad): the error
        state starts at ``-step``.
    seconds : float
        Duration, s.
    dt : float
        Sample time, s.

    Returns
    -------
    t : ndarray (N,)
        Sample times ``0, dt, ...``, s; ``N = round(seconds / dt) + 1``.
    position : ndarray (N, 3)
        Position relative to the old set point, m, in the pilot-frame axes of the linear
        model (the A frame's NED axes at heading 0, as in every :data:`SCENARIOS` entry).

    Raises
    ------
    TypeError
        ``params`` is not an :class:`ARDrone2Params`, ``gains`` not :class:`ControllerGains`,
        or a number that is not real.
    ValueError
        ``step`` not 4 finite numbers; ``seconds`` not finite and >= 0; ``dt`` not finite
        and > 0.
    """
    if not isinstance(gains, ControllerGains):
        raise TypeError(f"gains: expected ControllerGains, got {type(gains).__name__}")
    step = as_array(step, "step", (4,))
    seconds = check_real(seconds, "seconds", nonneg=True)
    dt = check_real(dt, "dt", positive=True)
    a, b = augmented_model(params)
    a_cl = a - b @ gains.K(integral=True)  # report eq. (4.5): u = -K x
    x = np.zeros(16)
    x[0:3] = -step[:3]
    x[8] = -step[3]
    phi = expm(a_cl * dt)
    n = round(seconds / dt) + 1
    out = np.empty((n, 3))
    for i in range(n):
        out[i] = x[0:3] + step[:3]
        x = phi @ x
    return np.arange(n) * dt, out


def _event_time(sc: Scenario) -> float:
    if sc.step is not None:
        return sc.step[0]
    if sc.push is not None:
        return sc.push[0]
    return 0.0


def run_metrics(sc: Scenario, t: FloatArray, states: FloatArray, estimates: FloatArray,
                setpoints: FloatArray, saturated: np.ndarray, wall: float) -> dict:
    """The metrics of :class:`visloc.sim.SimResult` (see :func:`visloc.sim.simulate`'s notes).

    Parameters
    ----------
    sc : Scenario
        The scenario flown (its step or push time, start set point and settling band).
    t : ndarray (N,)
        Sample times, s.
    states, estimates : ndarray (N, 12)
        True and estimated state (:data:`visloc.model.STATE_NAMES`; A frame, NED).
    setpoints : ndarray (N, 4)
        ``[x, y, z, psi]`` at each sample, m (A frame, NED) and rad.
    saturated : ndarray (N,) bool
        Whether the motor commands were clipped at each sample.
    wall : float
        Wall-clock duration of the run, s.

    Returns
    -------
    dict
        ``settling_time_s`` (s, or None), ``overshoot_pct`` (% of the step; None without a
        step, up to it, or for a step that does not move the position), ``position_rms_m``,
        ``max_error_m`` (the largest distance from the set point or the moving reference), ``final_error_m``, ``height_dip_m``, ``estimate_rms_m``
        (m), ``max_tilt_deg`` (largest roll or pitch, degrees), ``saturated_fraction`` (0-1)
        and ``realtime_factor`` (simulated over wall-clock seconds; inf when ``wall`` is 0).
    """
    err = states[:, :3] - setpoints[:, :3]
    dist = np.linalg.norm(err, axis=1)
    t0 = _event_time(sc)
    after = t >= t0
    settle = settling_time(t, dist, sc.band, t0)
    overshoot = None
    size = 0.0 if sc.step is None else float(np.linalg.norm(sc.step[1][:3] - sc.start_setpoint[:3]))
    if size > 0.0 and (t > t0).any():  # None up to the step, and for a step of the heading alone
        start = sc.start_setpoint[:3]
        delta = sc.step[1][:3] - start
        travel = (states[after, :3] - start) @ (delta / size)
        overshoot = float(max(0.0, travel.max() - size) / size * 100.0)
    dip = float(np.max(err[after, 2])) if np.any(after) else 0.0  # NED: + is below
    tilt = np.degrees(np.max(np.abs(states[:, 6:8])))
    return {
        "settling_time_s": settle,
        "overshoot_pct": overshoot,
        "position_rms_m": float(np.sqrt(np.mean(dist**2))),
        "max_error_m": float(dist.max()),
        "final_error_m": float(dist[-1]),
        "height_dip_m": max(dip, 0.0),
        "estimate_rms_m": float(np.sqrt(np.mean(np.sum((estimates[:, :3] - states[:, :3]) ** 2, 1)))),
        "max_tilt_deg": float(tilt),
        "saturated_fraction": float(np.mean(saturated)),
        "realtime_factor": float(t[-1] / wall) if wall > 0 else math.inf,
    }


def step_metrics_linear(gains: ControllerGains, p: ARDrone2Params, sc: Scenario, seconds: float) -> dict:
    """The same step on the linear closed loop: no height dip there (report §4.4).

    Parameters
    ----------
    gains : ControllerGains
        The controller flown.
    p : ARDrone2Params
        Vehicle parameters of the linear model.
    sc : Scenario
        A scenario with a set-point step.
    seconds : float
        Duration of the non-linear run, s; the linear one runs from the step for
        ``max(seconds - step time, LINEAR_SECONDS)``.

    Returns
    -------
    dict
        ``linear_settling_time_s`` (s, or None), ``linear_overshoot_pct`` (% of the step; None
        for a step that does not move the position) and
        ``linear_height_dip_m`` (m).

    Raises
    ------
    ValueError
        ``sc`` has no set-point step.
    """
    if sc.step is None:
        raise ValueError(f"scenario {sc.name!r} has no set-point step to compare")
    delta = sc.step[1] - sc.start_setpoint
    t, pos = linear_step_response(gains, p, delta, max(seconds - sc.step[0], LINEAR_SECONDS))
    size = float(np.linalg.norm(delta[:3]))
    err = np.linalg.norm(pos - delta[:3], axis=1)
    overshoot = None
    if size > 0.0:  # a step of the heading alone has no travel to overshoot
        travel = pos @ (delta[:3] / size)
        overshoot = float(max(0.0, travel.max() - size) / size * 100.0)
    return {
        "linear_settling_time_s": settling_time(t, err, sc.band, 0.0),
        "linear_overshoot_pct": overshoot,
        "linear_height_dip_m": float(max(0.0, np.max(pos[:, 2] - delta[2]))),
    }
