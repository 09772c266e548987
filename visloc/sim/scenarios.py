"""The closed-loop scenarios of ``visloc sim`` (report §4.4, Figures 4.5-4.6)."""

from __future__ import annotations

from dataclasses import KW_ONLY, dataclass

import numpy as np

from visloc.control._checks import as_array, check_real
from visloc.control.trajectory import (
    Figure8Trajectory,
    MinJerkTrajectory,
    TrajectoryLimits,
    model_limits,
)
from visloc.types import FloatArray

__all__ = ["SCENARIOS", "Scenario", "figure8_scenario", "get_scenario", "square_scenario", "step_scenario"]

HOVER_HEIGHT = 1.0
"""Height of every scenario's hover point above the floor, m (NED ``z = -1``)."""


@dataclass(frozen=True)
class Scenario:
    """One closed-loop experiment.

    Attributes
    ----------
    name : str
    description : str
    seconds : float
        Simulated duration, s.
    step : (float, ndarray (4,)) or None
        ``(time s, set point [x, y, z, psi])`` switched to at that time; the start set point
        is the hover point ``[0, 0, -HOVER_HEIGHT, 0]``.
    push : (float, float, ndarray (3,)) or None
        ``(start s, duration s, force N in A)``: a push on the CoG (report Figure 4.5).
    estimator : str
        ``"truth"`` or ``"vision"`` (:mod:`visloc.sim.estimators`).
    gust_std : float
        Standard deviation of a random horizontal force (N), low-passed at 1 Hz: air turbulence.
    band : float
        Settling band, m: 5 % of a step, or an absolute tolerance without one.
    trajectory : MinJerkTrajectory or None
        A smooth reference (:mod:`visloc.control.trajectory`): the set point follows its
        position and the controller gets its velocity and acceleration (feed-forward);
        ``step`` then names where it ends.

    Raises
    ------
    TypeError, ValueError
        ``step`` not ``(time, 4 finite numbers)`` or ``push`` not ``(start, duration, 3 finite
        numbers)``, with finite times (lists are taken: they are kept as float arrays);
        ``seconds``, ``gust_std`` or ``band`` not finite, or ``seconds`` or ``band`` not > 0
        or ``gust_std`` negative.
    """

    name: str
    description: str
    seconds: float
    _: KW_ONLY
    step: tuple[float, FloatArray] | None = None
    push: tuple[float, float, FloatArray] | None = None
    estimator: str = "truth"
    gust_std: float = 0.0
    band: float = 0.05
    trajectory: MinJerkTrajectory | Figure8Trajectory | None = None

    def __post_init__(self) -> None:
        check_real(self.seconds, "seconds", positive=True)
        check_real(self.gust_std, "gust_std", nonneg=True)
        check_real(self.band, "band", positive=True)
        if self.step is not None:
            if not isinstance(self.step, (tuple, list)) or len(self.step) != 2:
                raise ValueError(f"step: expected (time, [x, y, z, psi]), got {self.step!r}")
            step = (check_real(self.step[0], "step time"), as_array(self.step[1], "step set point", (4,)))
            object.__setattr__(self, "step", step)
        if self.push is not None:
            if not isinstance(self.push, (tuple, list)) or len(self.push) != 3:
                raise ValueError(f"push: expected (start, duration, [fx, fy, fz]), got {self.push!r}")
            push = (check_real(self.push[0], "push start"), check_real(self.push[1], "push duration", nonneg=True),
                    as_array(self.push[2], "push force", (3,)))
            object.__setattr__(self, "push", push)

    @property
    def start_setpoint(self) -> FloatArray:
        """``[x, y, z, psi]`` at t = 0."""
        return np.array([0.0, 0.0, -HOVER_HEIGHT, 0.0])

    def setpoint(self, t: float) -> FloatArray:
        """The set point at time ``t``.

        Parameters
        ----------
        t : float
            Time since the start, s.

        Returns
        -------
        ndarray (4,)
            ``[x, y, z, psi]``: position in A (NED, m, z down) and heading (rad): the
            trajectory's position when there is one, else the step's target from its time on,
            else :attr:`start_setpoint`.
        """
        if self.trajectory is not None:
            return np.r_[self.trajectory.sample(t)[0], self.start_setpoint[3]]
        if self.step is not None and t >= self.step[0]:
            return self.step[1]
        return self.start_setpoint

    def reference(self, t: float) -> tuple[FloatArray, FloatArray] | None:
        """The trajectory's velocity and acceleration at time ``t``.

        Parameters
        ----------
        t : float
            Simulated time, s (0 at the start).

        Returns
        -------
        (ndarray (3,), ndarray (3,)) or None
            Velocity (m/s) and acceleration (m/s^2) in A (NED), for the controller's feed-forward
            (:meth:`visloc.control.Controller.command`); None without a trajectory.
        """
        if self.trajectory is None:
            return None
        _, v, a, _ = self.trajectory.sample(t)
        return v, a

    def force(self, t: float) -> FloatArray | None:
        """The push on the centre of gravity at time ``t``.

        Parameters
        ----------
        t : float
            Seconds since the start.

        Returns
        -------
        ndarray (3,) or None
            The push's force, N, in A (NED), while ``push`` lasts (from its start, for its
            duration); None at other times and without a push.
        """
        if self.push is not None and self.push[0] <= t < self.push[0] + self.push[1]:
            return self.push[2]
        return None


SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        Scenario("hover", "hold 1 m above the floor for 10 s", 10.0),
        Scenario("sidestep", "a 1 m side step in y from hover at t = 1 s (report Figure 4.6)", 6.0,
                 step=(1.0, np.array([0.0, 1.0, -HOVER_HEIGHT, 0.0]))),
        Scenario("push", "a 4 N sideways push for 0.1 s at t = 1 s (report Figure 4.5)", 6.0,
                 push=(1.0, 0.1, np.array([0.0, 4.0, 0.0]))),
        Scenario("hover-vision", "30 s hover in light turbulence on visloc's marker-grid vision: "
                 "each bottom-camera frame goes through the marker tracker and the map localiser",
                 30.0, estimator="vision", gust_std=0.05),
    )
}
"""The scenarios by name."""


def step_scenario(distance: float, *, smooth: bool = True, start: float = 1.0, limits: TrajectoryLimits | None = None,
                  settle: float = 4.0) -> Scenario:
    """A side step of ``distance`` m in y from hover at ``start`` s: along a minimum-jerk
    trajectory within :func:`visloc.control.trajectory.model_limits` with feed-forward
    (``smooth``), or as the report's plain set-point step.

    Parameters
    ----------
    distance : float
        m (> 0, at most 100).
    smooth : bool
        Fly the trajectory (True) or jump the set point (False).
    start : float
        When the move starts, s.
    limits : TrajectoryLimits, optional
        Default :func:`visloc.control.trajectory.model_limits`.
    settle : float
        Seconds simulated after the trajectory's end (or after the step).

    Returns
    -------
    Scenario
        Named ``step``; its ``step`` is ``(end of the move, target)`` so that settling is
        measured from there, with a 5 % band.
    """
    d = float(distance)
    if not (0.0 < d <= 100.0):
        raise ValueError(f"distance must be in (0, 100] m, got {distance!r}")
    target = np.array([0.0, d, -HOVER_HEIGHT, 0.0])
    if not smooth:
        return Scenario("step", f"a {d:g} m set-point step in y at t = {start:g} s", start + settle,
                        step=(start, target), band=0.05 * d)
    traj = MinJerkTrajectory([[0.0, 0.0, -HOVER_HEIGHT], target[:3]], limits or model_limits(), start=start)
    return Scenario("step", f"a {d:g} m side step in y along a minimum-jerk trajectory ({traj.end - start:.2f} s) "
                            f"with feed-forward", traj.end + settle, step=(traj.end, target), band=0.05 * d,
                    trajectory=traj)


def square_scenario(side: float = 1.25, *, speed: float = 0.5, vision: bool = False, start: float = 1.0,
                    limits: TrajectoryLimits | None = None) -> Scenario:
    """Fly a square of ``side`` m around the hover point along minimum-jerk segments (resting
    at each corner) at up to ``speed`` m/s, then back to the hover point.

    Parameters
    ----------
    side : float
        m (> 0, at most 100; with ``vision`` the view must stay over the printed grid: up to about 1.3 m).
    speed : float
        Speed limit, m/s (> 0).
    vision : bool
        Fly on visloc's marker-grid vision (the bottom camera over :data:`visloc.sim.SIM_GRID`,
        light turbulence) instead of the true state.
    start : float
        When the square starts, s.
    limits : TrajectoryLimits, optional
        Default :func:`visloc.control.trajectory.model_limits` with ``speed``.

    Returns
    -------
    Scenario
        Named ``square``; 2 s after the return; ``position_rms_m`` is the tracking RMS.
    """
    s = float(side)
    if not (0.0 < s <= 100.0):
        raise ValueError(f"side must be in (0, 100] m, got {side!r}")
    h, z = 0.5 * s, -HOVER_HEIGHT
    corners = [[0.0, 0.0, z], [-h, -h, z], [h, -h, z], [h, h, z], [-h, h, z], [-h, -h, z], [0.0, 0.0, z]]
    traj = MinJerkTrajectory(corners, limits or model_limits(speed=speed), start=start)
    return _tracking("square", f"a {s:g} m square at up to {speed:g} m/s along minimum-jerk segments", traj, vision)


def figure8_scenario(width: float = 1.2, *, speed: float = 0.5, vision: bool = False, start: float = 1.0,
                     limits: TrajectoryLimits | None = None) -> Scenario:
    """Fly a figure eight ``width`` m wide (half as wide across) through the hover point, once,
    at up to ``speed`` m/s (:class:`visloc.control.trajectory.Figure8Trajectory`).

    Parameters
    ----------
    width : float
        m (> 0, at most 100; with ``vision`` up to about 1.3 m: the view stays over the printed grid).
    speed, vision, start, limits
        As :func:`square_scenario`.

    Returns
    -------
    Scenario
        Named ``figure8``; 2 s after the return; ``position_rms_m`` is the tracking RMS.
    """
    w = float(width)
    if not (0.0 < w <= 100.0):
        raise ValueError(f"width must be in (0, 100] m, got {width!r}")
    traj = Figure8Trajectory([0.0, 0.0, -HOVER_HEIGHT], w, limits or model_limits(speed=speed), start=start)
    return _tracking("figure8", f"a {w:g} m figure eight at up to {speed:g} m/s", traj, vision)


def _tracking(name: str, description: str, traj: MinJerkTrajectory | Figure8Trajectory, vision: bool) -> Scenario:
    """A scenario flying ``traj`` to its end and 2 s more, on the true state or (``vision``)
    on visloc's marker-grid vision with light turbulence."""
    return Scenario(name, description + (" on visloc's vision" if vision else ""), traj.end + 2.0,
                    estimator="vision" if vision else "truth", gust_std=0.05 if vision else 0.0, trajectory=traj)


def get_scenario(name: str) -> Scenario:
    """The scenario called ``name``.

    Parameters
    ----------
    name : str
        A key of :data:`SCENARIOS`.

    Returns
    -------
    Scenario
        The (frozen) entry of :data:`SCENARIOS`.

    Raises
    ------
    ValueError
        ``name`` is not a known scenario (the message lists the known ones).
    """
    if name not in SCENARIOS:
        raise ValueError(f"scenario: expected one of {sorted(SCENARIOS)}, got {name!r}")
    return SCENARIOS[name]
