"""Bode data and margins of the designed loops (report Figures 4.2-4.3).

Each loop has the four curves of the report's figures: the plant ``P``, the controller ``C``,
the open loop ``CP`` and the closed loop ``CP / (1 + CP)``.
"""

from __future__ import annotations

from os import PathLike

import numpy as np
from numpy.typing import ArrayLike

from visloc.control._checks import check_params
from visloc.control.design import ControllerGains, design_gains, loop_name, plant
from visloc.model.params import ARDRONE2, ARDrone2Params
from visloc.types import FloatArray

PARTS: tuple[str, ...] = ("plant", "controller", "open", "closed")
"""Curves of :func:`bode`: ``P``, ``C``, ``CP`` and ``CP / (1 + CP)`` (report Figs. 4.2-4.3)."""

_LABELS = {"plant": "P", "controller": "C", "open": "CP", "closed": "CP/(1+CP)"}


def frequency_response(
    loop: str,
    w: FloatArray,
    *,
    part: str = "open",
    gains: ControllerGains | None = None,
    params: ARDrone2Params = ARDRONE2,
) -> FloatArray:
    """Complex frequency response of one curve of one loop at the frequencies ``w`` (rad/s).

    Parameters
    ----------
    loop : str
        ``"roll"``, ``"pitch"``, ``"yaw"``, ``"height"``, ``"x"``, ``"y"``, or the aliases
        ``"attitude"`` (roll, Fig. 4.2) and ``"position"`` (x, Fig. 4.3).
    w : array_like (N,)
        Frequencies, rad/s (finite, > 0, N >= 1).
    part : str
        One of :data:`PARTS`: ``"plant"`` ``P``, ``"controller"`` ``C``, ``"open"`` ``C P``
        (default) or ``"closed"`` ``C P / (1 + C P)``.
    gains : ControllerGains, optional
        Default :func:`visloc.control.design_gains` of ``params``.
    params : ARDrone2Params
        Vehicle parameters (mass, inertia, g).

    Returns
    -------
    ndarray (N,) complex
        ``H(j w)`` of the curve. ``P`` is in the loop's output per unit input (rad/(N m) for
        roll, pitch and yaw, m/N for height, m/(N m) for x and y), ``C`` in its inverse (see
        :class:`visloc.control.LoopGains`); ``C P`` and the closed loop are dimensionless.

    Raises
    ------
    ValueError
        Unknown ``loop`` or ``part``; ``w`` None, not 1-D, empty, not finite or not > 0.
    TypeError
        ``loop`` not a str, ``gains`` not a :class:`ControllerGains`, ``params`` not an
        :class:`ARDrone2Params`.
    """
    check_params(params)
    if part not in PARTS:
        raise ValueError(f"part: expected one of {PARTS}, got {part!r}")
    g = design_gains(params) if gains is None else gains
    if not isinstance(g, ControllerGains):
        raise TypeError(f"gains: expected ControllerGains, got {type(g).__name__}")
    name = loop_name(loop)
    if w is None:
        raise ValueError("w: expected a 1-D array of finite frequencies > 0 rad/s, got None")
    freqs = _frequencies(w, min_size=1)
    s = 1j * freqs
    num, den = plant(name, params, gains=g)
    k = g.loop(name)
    p = np.polyval(num, s) / np.polyval(den, s)
    c = k.kp + k.kd * s + k.ki / s  # eqs. (4.8)-(4.11) without the low-pass pole, §4.2.3
    return {"plant": p, "controller": c, "open": c * p, "closed": c * p / (1.0 + c * p)}[part]


def _frequencies(w: ArrayLike | None, min_size: int = 2) -> FloatArray:
    """``w`` checked as a 1-D array of at least ``min_size`` finite frequencies > 0 rad/s;
    ``None``: 600 points log-spaced over 0.01-1000 rad/s."""
    if w is None:
        return np.logspace(-2, 3, 600)
    arr = np.asarray(w, dtype=float)
    if arr.ndim != 1 or arr.size < min_size or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ValueError(
            f"w: expected a 1-D array of >= {min_size} finite frequencies > 0 rad/s, got shape {arr.shape}"
        )
    return arr


def bode(
    loop: str,
    *,
    part: str = "open",
    w: ArrayLike | None = None,
    gains: ControllerGains | None = None,
    params: ARDrone2Params = ARDRONE2,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Bode data of a loop (report Figure 4.2 for ``"attitude"``, 4.3 for ``"position"``).

    Parameters
    ----------
    loop : str
        See :func:`frequency_response`.
    part : str
        ``"plant"``, ``"controller"``, ``"open"`` (default) or ``"closed"``.
    w : array_like (N,), optional
        Frequencies, rad/s (finite, > 0, N >= 2); default 600 points log-spaced over
        0.01-1000 rad/s.
    gains, params : as :func:`frequency_response`

    Returns
    -------
    w : ndarray (N,)
        Frequencies, rad/s.
    mag_db : ndarray (N,)
        ``20 log10 |H(jw)|``, dB.
    phase_deg : ndarray (N,)
        Unwrapped phase, degrees, on the branch that starts in (-300, 60] (so a double
        integrator reads -180, not +180).

    Raises
    ------
    ValueError, TypeError
        As for :func:`frequency_response` (``w`` here needs at least 2 frequencies).
    """
    freqs = _frequencies(w)
    h = frequency_response(loop, freqs, part=part, gains=gains, params=params)
    phase = np.rad2deg(np.unwrap(np.angle(h)))
    phase -= 360.0 * np.ceil((phase[0] - 60.0) / 360.0)  # branch: first value in (-300, 60]
    return freqs, 20.0 * np.log10(np.abs(h)), phase


def loop_margins(
    loop: str,
    *,
    gains: ControllerGains | None = None,
    params: ARDrone2Params = ARDRONE2,
) -> tuple[float, float]:
    """Gain crossover (rad/s) and phase margin (deg) of the open loop ``C P``, measured.

    The crossover is the highest frequency where ``|C P| = 1``, refined by bisection on a
    dense log grid; the phase margin is ``180 + arg(C P)`` there, wrapped to (-180, 180].

    Parameters
    ----------
    loop, gains, params : as :func:`frequency_response`

    Returns
    -------
    crossover : float
        rad/s.
    phase_margin : float
        Degrees.

    Raises
    ------
    ValueError
        ``loop`` has no gain crossover between 1e-3 and 1e4 rad/s, or is unknown.
    TypeError
        As for :func:`frequency_response`.
    """
    w = np.logspace(-3, 4, 20000)
    mag = np.abs(frequency_response(loop, w, gains=gains, params=params))
    above = np.nonzero(mag >= 1.0)[0]
    if above.size == 0 or above[-1] == w.size - 1:
        raise ValueError(f"loop: {loop!r} has no gain crossover in 1e-3 to 1e4 rad/s")
    lo, hi = w[above[-1]], w[above[-1] + 1]
    for _ in range(60):
        mid = np.sqrt(lo * hi)
        m = abs(frequency_response(loop, np.array([mid]), gains=gains, params=params)[0])
        lo, hi = (mid, hi) if m >= 1.0 else (lo, mid)
    wc = float(np.sqrt(lo * hi))
    h = frequency_response(loop, np.array([wc]), gains=gains, params=params)[0]
    pm = (np.rad2deg(np.angle(h)) + 180.0 + 180.0) % 360.0 - 180.0
    return wc, float(pm)


def save_bode_png(
    path: str | PathLike[str],
    *,
    loops: tuple[str, ...] = ("attitude", "position"),
    gains: ControllerGains | None = None,
    params: ARDrone2Params = ARDRONE2,
) -> None:
    """Draw the Bode diagrams of ``loops`` (P, C, CP, CP/(1+CP)) into a PNG file.

    Matplotlib's Agg canvas is used directly (no pyplot, no global backend change).

    Parameters
    ----------
    path : str or PathLike
        Output file (``.png``).
    loops : tuple of str
        Loops to draw side by side (names as for :func:`frequency_response`); default the
        report's Figures 4.2 and 4.3.
    gains, params : as :func:`frequency_response`

    Returns
    -------
    None
        The figure is written to ``path``.

    Raises
    ------
    ImportError
        matplotlib is not installed.
    ValueError
        ``loops`` is a str or empty, names an unknown loop, or a loop has no gain crossover
        (:func:`loop_margins`).
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:
        raise ImportError("save_bode_png needs matplotlib: pip install visloc[plot]") from exc

    if isinstance(loops, str) or not loops:
        raise ValueError(f"loops: expected a non-empty tuple of loop names, got {loops!r}")
    g = design_gains(params) if gains is None else gains
    fig = Figure(figsize=(5.5 * len(loops), 6.5))
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, len(loops), squeeze=False, sharex="col")
    for col, loop in enumerate(loops):
        name = loop_name(loop)
        wc, pm = loop_margins(name, gains=g, params=params)
        for part in PARTS:
            w, mag, ph = bode(name, part=part, gains=g, params=params)
            axes[0, col].semilogx(w, mag, label=_LABELS[part])
            axes[1, col].semilogx(w, ph, label=_LABELS[part])
        axes[0, col].set_title(f"{loop} ({name}): crossover {wc:.2f} rad/s, PM {pm:.1f} deg")
        axes[0, col].axhline(0.0, color="grey", lw=0.5)
        axes[1, col].axhline(-180.0, color="grey", lw=0.5)
        axes[0, col].set_ylabel("magnitude (dB)")
        axes[1, col].set_ylabel("phase (deg)")
        axes[1, col].set_xlabel("frequency (rad/s)")
        axes[0, col].legend(fontsize="small")
        for ax in axes[:, col]:
            ax.grid(True, which="both", lw=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
