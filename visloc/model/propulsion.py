"""Static propulsion model and mixer of the AR.Drone 2.0 (report section 2.1-2.2.2, eq. 4.6).

Motor ``i`` (1-4) turns its command ``pwm_i`` (percent, 0-100) into a thrust
``T_i = c_i (pwm_i + k)^2`` along the body's -z axis (up, the body frame being NED) and a
reaction torque ``(-1)^i d_i (pwm_i + k)^2`` about body z; both are zero for ``pwm_i <= 0``
(report eqs. 2.9-2.10, 2.15-2.18). The mixer ``Gamma`` (eq. 2.12) maps the squared terms
``pwm_bar_i = (pwm_i + k)^2`` to ``u = [T, tau_x, tau_y, tau_z]``.

Motor layout implied by the signs of eq. (2.12), body x forward, y right, z down, arm
distance ``d`` to each body axis: motor 1 front-left ``(+d, -d)``, motor 2 front-right
``(+d, +d)``, motor 3 rear-right ``(-d, +d)``, motor 4 rear-left ``(-d, -d)`` (clockwise seen
from above). Motors 1 and 3 give a negative reaction torque about body z (Figure 2.4).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from visloc._checks import all_finite
from visloc.model.params import ARDrone2Params, check_params
from visloc.types import FloatArray

YAW_SIGNS: FloatArray = np.array([-1.0, 1.0, -1.0, 1.0])
"""Sign ``(-1)^i`` of the reaction torque of motor ``i = 1..4`` about body z (report eq. 2.10)."""

MOTOR_LAYOUT: FloatArray = np.array([[1.0, -1.0], [1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0]])
"""Body ``(x, y)`` of motors 1-4 in units of the arm distance ``d`` (from the signs of eq. 2.12)."""


def _as_float_array(value: ArrayLike, name: str) -> FloatArray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name}: expected real numbers, got {type(value).__name__}") from exc
    if not all_finite(arr):
        raise ValueError(f"{name}: expected finite values, got {arr!r}")
    return arr


def _as_vector(value: ArrayLike, name: str, size: int) -> FloatArray:
    arr = _as_float_array(value, name)
    if arr.shape != (size,):
        raise ValueError(f"{name}: expected shape ({size},), got {arr.shape}")
    return arr


def pwm_bar_values(pwm: list[float], k: float) -> list[float]:
    """:func:`pwm_bar` on Python floats, without its argument checks (a simulated vehicle's
    every new command, where floats are several times faster than small arrays).

    Parameters
    ----------
    pwm : list of float
        Motor commands, percent.
    k : float
        Shared shift, percent.

    Returns
    -------
    list of float
        ``(pwm + k)^2`` where ``pwm > 0``, else 0, %^2 (report eqs. 2.17-2.18).
    """
    return [(v + k) * (v + k) if v > 0 else 0.0 for v in pwm]

def pwm_bar(pwm: ArrayLike, k: float) -> FloatArray:
    """Squared, shifted motor command ``(pwm + k)^2``, zero where ``pwm <= 0``.

    Parameters
    ----------
    pwm : array_like
        Motor command(s), percent.
    k : float
        Shared shift, percent (report Table 2.3: 25.19).

    Returns
    -------
    ndarray
        ``pwm_bar`` with the shape of ``pwm``, %^2 (report eqs. 2.9, 2.17-2.18).

    Raises
    ------
    TypeError
        ``pwm`` or ``k`` not real numbers.
    ValueError
        ``pwm`` or ``k`` not finite, or ``k`` not a scalar.
    """
    p = _as_float_array(pwm, "pwm")
    k_arr = _as_float_array(k, "k")
    if k_arr.ndim != 0:
        raise ValueError(f"k: expected a scalar shift in %, got shape {k_arr.shape}")
    k = float(k_arr)
    return np.where(p > 0, (p + k) ** 2, 0.0)  # report eqs. (2.17)-(2.18)


def thrust(pwm: ArrayLike, c: ArrayLike, k: float) -> FloatArray:
    """Static thrust of a motor, ``T = c (pwm + k)^2`` for ``pwm > 0``, else 0.

    Parameters
    ----------
    pwm : array_like
        Motor command(s), percent; the model holds for ``0 < pwm <= 100`` (report section 2.2.2).
    c : array_like
        Thrust coefficient(s), N/%^2, broadcast against ``pwm``.
    k : float
        Shared shift, percent.

    Returns
    -------
    ndarray
        Thrust, N (report eqs. 2.15, 2.17), of the broadcast shape of ``pwm`` and ``c``.

    Raises
    ------
    TypeError, ValueError
        As for :func:`pwm_bar`, and for ``c``.
    """
    c = _as_float_array(c, "c")
    return c * pwm_bar(pwm, k)  # report eq. (2.15)


def torque(pwm: ArrayLike, d: ArrayLike, k: float) -> FloatArray:
    """Magnitude of a motor's reaction torque, ``tau = d (pwm + k)^2`` for ``pwm > 0``, else 0.

    The sign about body z is ``(-1)^i`` for motor ``i`` (:data:`YAW_SIGNS`, report eq. 2.10).

    Parameters
    ----------
    pwm : array_like
        Motor command(s), percent.
    d : array_like
        Torque coefficient(s), N m/%^2, broadcast against ``pwm``.
    k : float
        Shared shift, percent.

    Returns
    -------
    ndarray
        Torque magnitude, N m (report eqs. 2.16, 2.18), of the broadcast shape of ``pwm`` and
        ``d``.

    Raises
    ------
    TypeError, ValueError
        As for :func:`pwm_bar`, and for ``d``.
    """
    d = _as_float_array(d, "d")
    return d * pwm_bar(pwm, k)  # report eq. (2.16)


def mixer_matrix(
    params: ARDrone2Params,
    *,
    c: ArrayLike | None = None,
    d: ArrayLike | None = None,
    arm: float | None = None,
) -> FloatArray:
    """The mixer ``Gamma`` (4, 4) with ``u = Gamma @ pwm_bar`` (report eqs. 2.11-2.12).

    Parameters
    ----------
    params : ARDrone2Params
        Vehicle parameters; supplies the defaults below.
    c : array_like (4,), optional
        Thrust coefficients of motors 1-4, N/%^2; default ``params.c_motors`` (all the mean).
    d : array_like (4,), optional
        Torque coefficients of motors 1-4, N m/%^2; default ``params.d_motors`` (all the mean).
    arm : float, optional
        Distance from a motor centre to the body x or y axis (not the diagonal), m; default
        ``params.arm``. The report prints no value, so one of the two must be given.

    Returns
    -------
    ndarray (4, 4)
        Rows map ``pwm_bar`` (%^2) to ``T`` (N), ``tau_x``, ``tau_y``, ``tau_z`` (N m).

    Raises
    ------
    ValueError
        If no arm distance is known or an argument has the wrong shape or sign, or is not
        finite.
    TypeError
        ``params`` is not an :class:`ARDrone2Params`, or ``c`` / ``d`` not real numbers.
    """
    check_params(params)
    c = params.c_motors if c is None else _as_vector(c, "c", 4)
    d = params.d_motors if d is None else _as_vector(d, "d", 4)
    if arm is None:
        arm = params.arm
    if arm is None:
        raise ValueError(
            "arm: the report does not print the arm distance d of eq. (2.12); pass arm= (m) or "
            "use dataclasses.replace(params, arm=...)"
        )
    if not (isinstance(arm, numbers.Real) and math.isfinite(arm) and arm > 0):
        raise ValueError(f"arm: expected a finite distance > 0 m, got {arm!r}")
    if np.any(c <= 0) or np.any(d <= 0):
        raise ValueError(f"c, d: expected positive coefficients, got c={c!r}, d={d!r}")
    x, y = MOTOR_LAYOUT[:, 0] * arm, MOTOR_LAYOUT[:, 1] * arm
    return np.vstack(
        [
            c,  # report eq. (2.12), row T:     [c1, c2, c3, c4]
            -y * c,  # row tau_x: [d c1, -d c2, -d c3, d c4]
            x * c,  # row tau_y: [d c1, d c2, -d c3, -d c4]
            YAW_SIGNS * d,  # row tau_z: [-d1, d2, -d3, d4]
        ]
    )


def inputs_from_pwm(
    pwm: ArrayLike, params: ARDrone2Params, *, gamma: ArrayLike | None = None
) -> FloatArray:
    """Total thrust and body torques ``u = Gamma pwm_bar`` (4,) from the four motor commands.

    Parameters
    ----------
    pwm : array_like (4,)
        Commands of motors 1-4, percent.
    params : ARDrone2Params
        Vehicle parameters (``k`` and, unless ``gamma`` is given, the mixer).
    gamma : array_like (4, 4), optional
        Mixer to use instead of ``mixer_matrix(params)``.

    Returns
    -------
    ndarray (4,)
        ``[T, tau_x, tau_y, tau_z]`` in N and N m (report eq. 2.11).

    Raises
    ------
    ValueError
        ``pwm`` not (4,) or not finite; ``gamma`` not (4, 4) or not finite; no ``gamma`` and
        no arm distance in ``params`` (:func:`mixer_matrix`).
    TypeError
        ``params`` is not an :class:`ARDrone2Params`; ``pwm`` or ``gamma`` not real numbers.
    """
    check_params(params)
    p = _as_vector(pwm, "pwm", 4)
    g = _mixer(params, gamma)
    return g @ pwm_bar(p, params.k)  # report eq. (2.11)


@dataclass(frozen=True, eq=False)
class PwmResult:
    """Motor commands that realise a requested ``u = [T, tau_x, tau_y, tau_z]``.

    Attributes
    ----------
    pwm : ndarray (4,)
        Commands of motors 1-4, percent, within ``[0, pwm_max]``.
    saturated : bool
        True when at least one command was clipped, i.e. ``u`` is not exactly reachable.
    reason : str
        Which motors were clipped and why ("" when not saturated).
    pwm_bar : ndarray (4,)
        The requested squared terms ``Gamma^-1 u``, %^2, before clipping.
    """

    pwm: FloatArray
    saturated: bool
    reason: str
    pwm_bar: FloatArray


def pwm_from_inputs(
    u: ArrayLike,
    params: ARDrone2Params,
    *,
    gamma: ArrayLike | None = None,
    pwm_max: float = 100.0,
) -> PwmResult:
    """Invert the mixer: ``pwm = sqrt(Gamma^-1 u) - k`` saturated to ``[0, pwm_max]`` (eq. 4.6).

    A motor's command is clipped to 0 when its requested squared term is negative (no real
    root: the torque asked for needs a negative thrust) or below ``k^2`` (less thrust than the
    motor gives at the smallest positive command; the model jumps to zero at ``pwm = 0``,
    eqs. 2.17-2.18), and to ``pwm_max`` above ``(pwm_max + k)^2``.

    Parameters
    ----------
    u : array_like (4,)
        ``[T, tau_x, tau_y, tau_z]``, N and N m.
    params : ARDrone2Params
        Vehicle parameters (``k`` and, unless ``gamma`` is given, the mixer).
    gamma : array_like (4, 4), optional
        Mixer to invert instead of ``mixer_matrix(params)``.
    pwm_max : float
        Upper command limit, percent (the model holds up to 100 %).

    Returns
    -------
    PwmResult
        ``pwm`` (4,) of motors 1-4, percent, in ``[0, pwm_max]``; ``saturated`` and
        ``reason`` for clipped motors; ``pwm_bar`` (4,) the requested ``Gamma^-1 u``, %^2.

    Raises
    ------
    ValueError
        ``u`` not (4,) or not finite; ``pwm_max`` not a finite number > 0; ``gamma`` not (4, 4),
        not finite or singular; no ``gamma`` and no arm distance in ``params``.
    TypeError
        ``params`` is not an :class:`ARDrone2Params`; ``u`` or ``gamma`` not real numbers.
    """
    check_params(params)
    u = _as_vector(u, "u", 4)
    if isinstance(pwm_max, bool) or not (isinstance(pwm_max, numbers.Real) and 0 < pwm_max < math.inf):
        raise ValueError(f"pwm_max: expected a finite value > 0 %, got {pwm_max!r}")
    g = _mixer(params, gamma)
    try:
        s = np.linalg.solve(g, u)  # Gamma^-1 u, report eq. (4.6)
    except np.linalg.LinAlgError as exc:
        raise ValueError("gamma: the mixer matrix is singular") from exc
    return pwm_from_bar(s, params.k, pwm_max=pwm_max)


def pwm_from_bar(bar: FloatArray, k: float, *, pwm_max: float = 100.0) -> PwmResult:
    """The commands ``pwm = sqrt(bar) - k`` of requested squared terms ``bar = Gamma^-1 u``,
    saturated as :func:`pwm_from_inputs` says (whose second half this is; a controller that
    keeps ``Gamma^-1`` calls it directly). Arguments are not checked.

    Parameters
    ----------
    bar : ndarray (4,) float64
        ``Gamma^-1 u`` of motors 1-4, %^2.
    k : float
        Shared shift, percent.
    pwm_max : float
        Upper command limit, percent.

    Returns
    -------
    PwmResult
        As :func:`pwm_from_inputs` (``pwm_bar`` is ``bar``).
    """
    values = bar.tolist()
    raw = [math.sqrt(max(v, 0.0)) - k for v in values]  # report eq. (4.6); a negative Gamma^-1 u gives -k
    if min(values) >= 0.0 and min(raw) >= 0.0 and max(raw) <= pwm_max:  # nothing clipped (the usual step)
        return PwmResult(pwm=np.array(raw), saturated=False, reason="", pwm_bar=bar)
    pwm = np.array([min(max(r, 0.0), pwm_max) for r in raw])
    reasons = []
    for i in range(4):
        if values[i] < 0:
            reasons.append(
                f"motor {i + 1}: Gamma^-1 u = {values[i]:.4g} %^2 < 0 (unreachable), set to 0"
            )
        elif raw[i] < 0:
            reasons.append(
                f"motor {i + 1}: thrust below the minimum at pwm > 0 ({values[i]:.4g} < k^2 = "
                f"{k * k:.4g} %^2), set to 0"
            )
        elif raw[i] > pwm_max:
            reasons.append(f"motor {i + 1}: pwm {raw[i]:.4g} % > {pwm_max:g} %, clipped")
    return PwmResult(pwm=pwm, saturated=bool(reasons), reason="; ".join(reasons), pwm_bar=bar)


def hover_pwm(params: ARDrone2Params, *, mass: float | None = None) -> float:
    """Command of each motor in hover: ``sqrt(m g / (4 c_mean)) - k``, percent.

    Parameters
    ----------
    params : ARDrone2Params
        Vehicle parameters (``g``, ``c_mean``, ``k``).
    mass : float, optional
        Mass to lift, kg; default ``params.mass``.

    Returns
    -------
    float
        Trim command, percent: each motor gives ``T0 / 4`` with ``T0 = m g`` (report
        section 4.1) through eq. (2.15) with the mean coefficient.

    Raises
    ------
    ValueError
        ``mass`` not a finite number > 0.
    TypeError
        ``params`` is not an :class:`ARDrone2Params`.
    """
    check_params(params)
    m = params.mass if mass is None else mass
    if isinstance(m, bool) or not isinstance(m, numbers.Real) or not (0 < m < math.inf):
        raise ValueError(f"mass: expected a finite mass > 0 kg, got {m!r}")
    t0 = m * params.g  # report section 4.1: T0 = m g
    return math.sqrt(t0 / (4.0 * params.c_mean)) - params.k  # report eq. (2.15) inverted


def _mixer(params: ARDrone2Params, gamma: ArrayLike | None) -> FloatArray:
    if gamma is None:
        return mixer_matrix(params)
    g = _as_float_array(gamma, "gamma")
    if g.shape != (4, 4):
        raise ValueError(f"gamma: expected shape (4, 4), got {g.shape}")
    return g
