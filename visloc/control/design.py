"""Gain design by loop shaping the report's lead/PD loops (report §4.2, eqs. 4.5-4.11).

The linear model at hover (:mod:`visloc.control.linear`) splits into six single-input loops:
roll, pitch and yaw are double integrators ``1 / (J s^2)`` driven by a torque (eq. 4.7), the
height is ``1 / (m s^2)`` driven by the thrust deviation, and x / y are the attitude-controlled
closed loops integrated twice (report Figure 4.3, "P2")::

    P_x(s) = g / (s^2 (Iyy s^2 + kd_theta s + kp_theta))   (x via pitch, udot_P = -g theta)
    P_y(s) = g / (s^2 (Ixx s^2 + kd_phi s + kp_phi))       (y via roll,  vdot_P =  g phi)

Each loop gets ``C(s) = kp + kd s + ki / s``: the lead filter of eq. (4.8) with its low-pass
pole left out, because "the low-pass filter is already embedded as part of the state
estimation" (report, after eq. 4.9). Then ``k2 = kp`` and ``k1 = kd`` of eq. (4.9) (and
``k4, k3`` / ``k6, k5`` of eqs. 4.10-4.11) are plain state-feedback gains, ``u = -K x``
(eq. 4.5), and ``ki`` multiplies the integrated error of x, y, z and yaw (§4.2.3).

The report prints no numbers for the loop shapes (Figures 4.2-4.3 are pictures), so the
specifications are ours (:class:`ControlSpecs`): a crossover frequency and phase margin per
loop, the position loops about five times slower than the attitude loops (the report: "the
bandwidth of the position controlled system is limited by the bandwidth of the attitude
controlled system"), integral corners a decade below crossover. :func:`design_loop` meets
them exactly at the crossover.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import solve_continuous_are

from visloc.control._checks import check_params, check_real
from visloc.control.linear import linearize_analytical, linearize_numerical
from visloc.model.params import ARDrone2Params
from visloc.types import FloatArray

LOOPS: tuple[str, ...] = ("roll", "pitch", "yaw", "height", "x", "y")
"""The six loops, in the order of :class:`ControllerGains`' fields."""

LOOP_ALIASES: dict[str, str] = {"attitude": "roll", "position": "x"}
"""``"attitude"`` is the roll loop of report Figure 4.2, ``"position"`` the x loop of Fig. 4.3."""

INTEGRAL_STATE_NAMES: tuple[str, ...] = ("int_x_P", "int_y_P", "int_z_P", "int_psi")
"""Integrated errors appended to the 12 pilot-frame states (m s, m s, m s, rad s; §4.2.3)."""


@dataclass(frozen=True)
class LoopSpec:
    """Loop-shaping specification of one loop.

    Attributes
    ----------
    crossover : float
        Gain crossover frequency of the open loop ``C P``, rad/s (> 0).
    phase_margin : float
        Phase margin at the crossover, degrees (0-90 exclusive).
    integral : float
        Integral corner as a fraction of the crossover, ``ki = kp * integral * crossover``;
        0 for no integral action (the report integrates only x, y, z and yaw, §4.2.3).
    """

    crossover: float
    phase_margin: float
    integral: float = 0.0

    def __post_init__(self) -> None:
        check_real(self.crossover, "crossover", positive=True)
        pm = check_real(self.phase_margin, "phase_margin")
        if not 0.0 < pm < 90.0:
            raise ValueError(f"phase_margin: expected 0 < PM < 90 degrees, got {pm!r}")
        ratio = check_real(self.integral, "integral", nonneg=True)
        if ratio >= 1.0:
            raise ValueError(f"integral: expected a corner below crossover (< 1), got {ratio!r}")


@dataclass(frozen=True, kw_only=True)
class ControlSpecs:
    """Specifications of all loops (our choice: the report prints none).

    Attributes
    ----------
    attitude : LoopSpec
        Roll and pitch (report Figure 4.2): 20 rad/s, 60 degrees.
    yaw : LoopSpec
        Heading: 3 rad/s, 60 degrees, integral corner at 0.1 x crossover.
    height : LoopSpec
        Thrust on z: 3 rad/s, 60 degrees, integral corner at 0.1 x crossover.
    position : LoopSpec
        x and y through the attitude loops (Figure 4.3): 3.5 rad/s, 50 degrees, integral
        corner at 0.05 x crossover.

    Notes
    -----
    The defaults were chosen with ``bench/sim.py``'s sweep on the non-linear simulation
    (:func:`visloc.sim.simulate`): a 1 m side step settles to 5 % in about 1.5 s with about
    3 % overshoot, and all 256 vertices stay stable at 2 sigma. The position integral corner
    sits a twentieth of the crossover down: a tenth leaves a slow tail on each step. The
    report's model has no motor lag; with a first-order lag (eq. 2.13) in the simulation the
    20 rad/s attitude loops still fly the side step up to a time constant of 0.07 s and
    crash at 0.08 s (``visloc sim sidestep --motor-lag``): slow motors need slower specs.
    """

    attitude: LoopSpec = field(default_factory=lambda: LoopSpec(20.0, 60.0))
    yaw: LoopSpec = field(default_factory=lambda: LoopSpec(3.0, 60.0, 0.1))
    height: LoopSpec = field(default_factory=lambda: LoopSpec(3.0, 60.0, 0.1))
    position: LoopSpec = field(default_factory=lambda: LoopSpec(3.5, 50.0, 0.05))

    def for_loop(self, loop: str) -> LoopSpec:
        """The specification of ``loop`` (one of :data:`LOOPS`).

        Parameters
        ----------
        loop : str
            A loop's name (:data:`LOOPS`) or one of its aliases (:data:`LOOP_ALIASES`).

        Returns
        -------
        LoopSpec
            :attr:`attitude` for roll and pitch, :attr:`position` for x and y, else :attr:`yaw`
            or :attr:`height`.

        Raises
        ------
        TypeError
            ``loop`` is not a str (:func:`loop_name`).
        ValueError
            ``loop`` is neither a loop nor an alias (:func:`loop_name`).
        """
        name = loop_name(loop)
        if name in ("roll", "pitch"):
            return self.attitude
        if name in ("x", "y"):
            return self.position
        return self.yaw if name == "yaw" else self.height


@dataclass(frozen=True)
class LoopGains:
    """PID gains of one loop, ``C(s) = kp + kd s + ki / s`` (report eqs. 4.8-4.11, §4.2.3).

    Attributes
    ----------
    kp, kd, ki : float
        Proportional, derivative and integral gains in the loop's units: N m/rad for the
        attitude loops, N/m for height, N m/m for position (per second for ``kd``, times
        seconds for ``ki``).
    """

    kp: float
    kd: float
    ki: float = 0.0


@dataclass(frozen=True, eq=False)
class ControllerGains:
    """Gains of the six loops and the specifications they were designed for."""

    roll: LoopGains
    pitch: LoopGains
    yaw: LoopGains
    height: LoopGains
    x: LoopGains
    y: LoopGains
    specs: ControlSpecs | None = None

    def loop(self, name: str) -> LoopGains:
        """The gains of ``name`` (one of :data:`LOOPS` or :data:`LOOP_ALIASES`).

        Parameters
        ----------
        name : str
            One of :data:`LOOPS` or an alias of :data:`LOOP_ALIASES` (``"attitude"``: roll,
            ``"position"``: x).

        Returns
        -------
        LoopGains
            That loop's field.

        Raises
        ------
        TypeError
            ``name`` is not a str (:func:`loop_name`).
        ValueError
            ``name`` is neither a loop nor an alias (:func:`loop_name`).
        """
        return getattr(self, loop_name(name))

    def K(self, *, integral: bool = True) -> FloatArray:
        """State-feedback matrix of ``u = -K x`` (report eq. 4.5).

        Parameters
        ----------
        integral : bool
            Include the columns of the integrated errors (:data:`INTEGRAL_STATE_NAMES`).

        Returns
        -------
        ndarray (4, 16) or (4, 12)
            Rows ``[T, tau_x, tau_y, tau_z]`` (deviation from hover); columns the pilot-frame
            states of :mod:`visloc.control.linear`, then the integrals.
        """
        k = np.zeros((4, 16))
        r, p, y, h = self.roll, self.pitch, self.yaw, self.height
        k[1, 6], k[1, 9] = r.kp, r.kd  # tau_x = -(k2 phi + k1 omega_x), eq. (4.9)
        k[2, 7], k[2, 10] = p.kp, p.kd  # tau_y = -(k2 theta + k1 omega_y), eq. (4.9)
        k[3, 8], k[3, 11], k[3, 15] = y.kp, y.kd, y.ki  # tau_z on heading, with integral
        k[0, 2], k[0, 5], k[0, 14] = -h.kp, -h.kd, -h.ki  # dT = +kp z: z is down (NED)
        gx, gy = self.x, self.y
        k[2, 0], k[2, 3], k[2, 12] = -gx.kp, -gx.kd, -gx.ki  # eq. (4.10): udot_P = -g theta
        k[1, 1], k[1, 4], k[1, 13] = gy.kp, gy.kd, gy.ki  # eq. (4.11): vdot_P = +g phi
        return k if integral else k[:, :12].copy()

    def to_dict(self) -> dict:
        """JSON-ready ``{loop: {"kp", "kd", "ki"}}``."""
        out = {}
        for name in LOOPS:
            g = self.loop(name)
            out[name] = {"kp": float(g.kp), "kd": float(g.kd), "ki": float(g.ki)}  # numpy scalars too
        return out


def loop_name(loop: str) -> str:
    """Canonical loop name.

    Parameters
    ----------
    loop : str
        One of :data:`LOOPS` or an alias of :data:`LOOP_ALIASES`.

    Returns
    -------
    str
        The name in :data:`LOOPS` (aliases resolved).

    Raises
    ------
    TypeError
        ``loop`` is not a str.
    ValueError
        ``loop`` is neither a loop nor an alias.
    """
    if not isinstance(loop, str):
        raise TypeError(f"loop: expected a str, got {type(loop).__name__}")
    name = LOOP_ALIASES.get(loop, loop)
    if name not in LOOPS:
        raise ValueError(f"loop: expected one of {LOOPS + tuple(LOOP_ALIASES)}, got {loop!r}")
    return name


def plant(loop: str, params: ARDrone2Params, *, gains: ControllerGains | None = None
          ) -> tuple[FloatArray, FloatArray]:
    """Numerator and denominator polynomials (highest power first) of a loop's plant.

    Parameters
    ----------
    loop : str
        One of :data:`LOOPS` (or ``"attitude"`` / ``"position"``).
    params : ARDrone2Params
        Vehicle parameters (mass, inertia, g).
    gains : ControllerGains, optional
        Needed for ``"x"`` and ``"y"``: the attitude gains close the inner loop (Fig. 4.3).

    Returns
    -------
    num : ndarray (1,)
        ``[1]``, or ``[g]`` (m/s^2) for x and y.
    den : ndarray (3,) or (5,)
        ``[J, 0, 0]`` (``Ixx``, ``Iyy``, ``Izz`` in kg m^2, or the mass in kg for height), or
        ``s^2 (I s^2 + kd s + kp)`` for x and y (pitch's ``Iyy`` and gains for x, roll's
        for y). ``P(s) = num(s) / den(s)`` with the loop's sign made positive, in rad/(N m)
        (roll, pitch, yaw), m/N (height) or m/(N m) (x, y).

    Raises
    ------
    ValueError
        Unknown ``loop``, or ``gains`` None for ``"x"`` or ``"y"``.
    TypeError
        ``loop`` is not a str or ``params`` not an :class:`ARDrone2Params`.
    """
    p = check_params(params)
    name = loop_name(loop)
    if name in ("x", "y"):
        if gains is None:
            raise ValueError(f"gains: the {name} plant needs the attitude gains, got None")
        inner, inertia = (gains.pitch, p.Iyy) if name == "x" else (gains.roll, p.Ixx)
        den = np.polymul([1.0, 0.0, 0.0], [inertia, inner.kd, inner.kp])  # report Fig. 4.3
        return np.array([p.g]), den
    scale = {"roll": p.Ixx, "pitch": p.Iyy, "yaw": p.Izz, "height": p.mass}[name]
    return np.array([1.0]), np.array([scale, 0.0, 0.0])  # report eq. (4.7): 1 / (J s^2)


def design_loop(num: FloatArray, den: FloatArray, spec: LoopSpec) -> LoopGains:
    """PID gains that put the crossover and phase margin of ``C P`` exactly at ``spec``.

    At ``w = spec.crossover`` the open loop must be ``1 * exp(j (PM - 180 deg))``, so
    ``C(jw) = exp(j (PM - 180 deg)) / P(jw)``; with ``C(jw) = kp + j (kd w - ki / w)`` and
    ``ki = kp * spec.integral * w`` this gives ``kp = Re C`` and ``kd = (Im C + kp
    spec.integral) / w`` (the lead filter of eq. 4.8 placed at the crossover, without its
    low-pass pole).

    Parameters
    ----------
    num, den : ndarray (n,), (m,)
        Plant polynomial coefficients, highest power first (see :func:`plant`).
    spec : LoopSpec
        Crossover (rad/s), phase margin (deg) and integral corner ratio.

    Returns
    -------
    LoopGains
        ``kp, kd, ki`` in the loop's units (see :class:`LoopGains`).

    Raises
    ------
    ValueError
        If a PID cannot meet the spec (more than 90 degrees of lead needed), the closed
        loop it gives is unstable, the plant's response or the gains at the crossover are out
        of floating-point range, or ``num``/``den`` are not finite polynomials (``den`` with a
        non-zero leading coefficient, ``num`` not all zero).
    TypeError
        ``spec`` is not a :class:`LoopSpec`; ``num`` or ``den`` not numbers.
    """
    if not isinstance(spec, LoopSpec):
        raise TypeError(f"spec: expected LoopSpec, got {type(spec).__name__}")
    num, den = _polynomial(num, "num"), _polynomial(den, "den")
    w = spec.crossover
    with np.errstate(all="ignore"):  # a response out of float range is refused just below
        pw = np.polyval(num, 1j * w) / np.polyval(den, 1j * w)
        c = np.exp(1j * np.deg2rad(spec.phase_margin - 180.0)) / pw
        kp = float(c.real)
        kd = float((c.imag + kp * spec.integral) / w)
        ki = kp * spec.integral * w
    if not (math.isfinite(kp) and math.isfinite(kd) and math.isfinite(ki)) or (kp > 0.0 and kd > 0.0 and not (
            np.all(np.isfinite(np.polymul(num, [kd, kp, ki]))))):
        raise ValueError(f"spec: the plant's response at the crossover {w:g} rad/s is out of floating-point range "
                         f"(gains kp = {kp:.4g}, kd = {kd:.4g}, ki = {ki:.4g}); choose a crossover nearer the plant's")
    if kp <= 0.0 or kd <= 0.0:
        raise ValueError(
            f"spec: {spec.phase_margin} deg at {w} rad/s needs more lead than a PD gives "
            f"(kp = {kp:.4g}, kd = {kd:.4g}); lower the crossover or the phase margin"
        )
    if ki > 0.0:  # 1 + C P = 0 with C = (kd s^2 + kp s + ki) / s
        char = np.polyadd(np.polymul(den, [1.0, 0.0]), np.polymul(num, [kd, kp, ki]))
    else:
        char = np.polyadd(den, np.polymul(num, [kd, kp]))
    if np.max(np.roots(char).real) >= 0.0:
        raise ValueError(f"spec: the loop designed for {spec} is unstable in closed loop")
    return LoopGains(kp=kp, kd=kd, ki=ki)


def _polynomial(coeffs: object, name: str) -> FloatArray:
    """``coeffs`` as a 1-D finite float polynomial (highest power first), or a TypeError /
    ValueError naming ``name``."""
    try:
        a = np.asarray(coeffs, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name}: expected polynomial coefficients, got {type(coeffs).__name__}") from exc
    if a.ndim != 1 or not a.size or not np.all(np.isfinite(a)) or not np.any(a) or (name == "den" and a[0] == 0):
        raise ValueError(f"{name}: expected finite coefficients, highest power first and not all zero"
                         + (" (the first non-zero)" if name == "den" else "") + f", got {a.tolist()!r}")
    return a


def design_gains(params: ARDrone2Params, *, specs: ControlSpecs | None = None) -> ControllerGains:
    """Design all six loops from ``specs`` (attitude first; position around it, Fig. 4.3).

    Parameters
    ----------
    params : ARDrone2Params
        Vehicle parameters (mass, inertia, g).
    specs : ControlSpecs, optional
        Default :class:`ControlSpecs` ().

    Returns
    -------
    ControllerGains
        The six loops' gains, with ``specs`` recorded.

    Raises
    ------
    TypeError
        ``params`` is not an :class:`ARDrone2Params` or ``specs`` not a :class:`ControlSpecs`.
    ValueError
        A loop's specification cannot be met (:func:`design_loop`).
    """
    p = check_params(params)
    s = ControlSpecs() if specs is None else specs
    if not isinstance(s, ControlSpecs):
        raise TypeError(f"specs: expected ControlSpecs, got {type(s).__name__}")
    inner = {n: design_loop(*plant(n, p), s.for_loop(n)) for n in ("roll", "pitch", "yaw", "height")}
    # the x / y plants only read the attitude gains: fill the outer loops with placeholders
    partial = ControllerGains(**inner, x=inner["pitch"], y=inner["roll"], specs=s)
    outer = {n: design_loop(*plant(n, p, gains=partial), s.for_loop(n)) for n in ("x", "y")}
    return ControllerGains(**inner, **outer, specs=s)


def augmented_model(params: ARDrone2Params, *, roll: float = 0.0) -> tuple[FloatArray, FloatArray]:
    """The pilot-frame linear model at hover with the integrated errors appended (§4.2.3).

    Parameters
    ----------
    params : ARDrone2Params
        Vehicle parameters (mass, inertia, g).
    roll : float
        0 (hover: :func:`visloc.control.linearize_analytical`), or the roll of a steady
        sideways acceleration to linearise at instead (rad,
        :func:`visloc.control.linearize_numerical`): the operating point of a tracking loop.

    Returns
    -------
    A : ndarray (16, 16)
        :func:`visloc.control.linearize_analytical`'s ``A`` for the 12 states of
        :data:`visloc.control.PILOT_STATE_NAMES`; the last four states integrate ``x_P, y_P,
        z_P`` and ``psi`` (:data:`INTEGRAL_STATE_NAMES`, m s and rad s).
    B : ndarray (16, 4)
        Input matrix for ``u = [T, tau_x, tau_y, tau_z]`` (deviation from hover, N and
        N m); zero rows for the integrals.

    Raises
    ------
    TypeError
        ``params`` is not an :class:`ARDrone2Params`.
    """
    a, b = linearize_analytical(params) if roll == 0.0 else linearize_numerical(params, roll=roll)
    aa = np.zeros((16, 16))
    aa[:12, :12] = a
    aa[12, 0] = aa[13, 1] = aa[14, 2] = aa[15, 8] = 1.0  # d/dt int e = e, report §4.2.3
    return aa, np.vstack([b, np.zeros((4, 4))])


def lqr_gains(
    params: ARDrone2Params,
    *,
    q: FloatArray | None = None,
    r: FloatArray | None = None,
    integral: bool = True,
) -> FloatArray:
    """LQR alternative to loop shaping (report §4.2 mentions it): ``K = R^-1 B^T X``.

    Parameters
    ----------
    params : ARDrone2Params
        Vehicle parameters.
    q : ndarray (n,) or (n, n), optional
        State weight; default Bryson's rule with 0.1 m, 0.5 m/s, 0.1 rad, 1 rad/s and 0.5
        (m or rad) s for the integrals.
    r : ndarray (4,) or (4, 4), optional
        Input weight; default Bryson's rule with 1 N and 0.05 N m.
    integral : bool
        Design on the 16-state augmented model (True) or on the 12 states.

    Returns
    -------
    ndarray (4, 16) or (4, 12)
        ``K`` of ``u = -K x``: rows ``[T, tau_x, tau_y, tau_z]`` (deviation from hover, N
        and N m), columns the states of :func:`augmented_model`.

    Raises
    ------
    ValueError
        ``q`` or ``r`` of the wrong shape or not finite, or weights for which the Riccati
        equation has no stabilising solution (e.g. a negative ``q`` or a singular ``r``).
    TypeError
        ``params`` is not an :class:`ARDrone2Params`.
    """
    a, b = augmented_model(params)
    n = 16 if integral else 12
    a, b = a[:n, :n], b[:n]
    scale = np.array([0.1] * 3 + [0.5] * 3 + [0.1] * 3 + [1.0] * 3 + [0.5] * 4)[:n]
    qm = np.diag(1.0 / scale**2) if q is None else np.asarray(q, dtype=float)
    rm = np.diag(1.0 / np.array([1.0, 0.05, 0.05, 0.05]) ** 2) if r is None else np.asarray(r, float)
    qm = np.diag(qm) if qm.ndim == 1 else qm
    rm = np.diag(rm) if rm.ndim == 1 else rm
    if qm.shape != (n, n):
        raise ValueError(f"q: expected shape ({n},) or ({n}, {n}), got {qm.shape}")
    if rm.shape != (4, 4):
        raise ValueError(f"r: expected shape (4,) or (4, 4), got {rm.shape}")
    if not (np.isfinite(qm).all() and np.isfinite(rm).all()):
        raise ValueError("q, r: expected finite weights")
    try:
        x = solve_continuous_are(a, b, qm, rm)
        return np.linalg.solve(rm, b.T @ x)
    except (np.linalg.LinAlgError, ValueError) as exc:  # scipy's and numpy's own words, named here
        raise ValueError(f"q, r: no LQR gains for these weights ({exc})") from None
