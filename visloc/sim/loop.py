"""The closed loop: vehicle, sensors, estimator, controller in turn (report Figure 4.4).

:func:`simulate` integrates the non-linear model (:class:`visloc.sim.Vehicle`, RK4 at ``dt``)
with motor commands from :class:`visloc.control.Controller` at ``control_rate``; the
controller flies on the estimate of :mod:`visloc.sim.estimators` (the true state, or visloc's
marker-grid vision fused with the IMU and the ultrasound, the bottom camera ticking at
``camera_rate``). It
returns stacked arrays and an exit status with a readable reason (:class:`SimStatus`).
"""

from __future__ import annotations

import math
import numbers
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from enum import Enum

import numpy as np

from visloc.control._checks import check_params, check_real, resolve_arm
from visloc.control.controller import Controller
from visloc.control.design import ControllerGains, ControlSpecs
from visloc.model.params import ARDRONE2, ARDrone2Params
from visloc.model.propulsion import hover_pwm
from visloc.pose.maps import GridMap
from visloc.sim.estimators import TruthEstimator, VisionEstimator
from visloc.sim.metrics import run_metrics, step_metrics_linear
from visloc.sim.scenarios import Scenario, get_scenario
from visloc.sim.sensors import BottomCamera, Imu, Ultrasound
from visloc.sim.vehicle import Vehicle, motor_coefficients
from visloc.types import FloatArray

__all__ = ["SIM_GRID", "SimResult", "SimStatus", "VisionSensors", "fly", "simulate"]

SIM_GRID = {"rows": 10, "cols": 10, "marker_length": 0.10, "spacing": 0.05}
"""The floor grid of the vision scenarios (DICT_4X4_100), as ``visloc render localize``'s."""

CRASH_TILT = math.radians(80.0)
"""Roll or pitch beyond which the drone counts as crashed (it cannot recover)."""

ULTRASOUND_PERIOD = 0.04
"""Seconds between ultrasound readings in the vision scenarios (25 Hz)."""

VISION_TIMEOUT = 1.0
"""Seconds without a vision fix after which a vision run counts as diverged."""

WARMUP_SECONDS = 20.0
"""Default hover before t = 0 with spread motors (``simulate(warmup=...)``), s."""

FAR = 20.0
"""Distance from the set point (m) beyond which a run counts as diverged."""


class SimStatus(str, Enum):
    """How a run ended."""

    SETTLED = "settled"
    """Ran to the end and stayed in the settling band from ``settling_time_s`` on."""
    COMPLETED = "completed"
    """Ran to the end without settling into the band."""
    CRASHED = "crashed"
    """Hit the floor or tipped over."""
    DIVERGED = "diverged"
    """The state blew up, drifted away, or the estimator lost track."""
    INTERRUPTED = "interrupted"
    """Stopped by Ctrl-C (``KeyboardInterrupt``): the steps flown so far are kept."""


@dataclass(frozen=True, eq=False)
class SimResult:
    """A closed-loop run, sampled at the control rate.

    Attributes
    ----------
    scenario : str
    status : SimStatus
    reason : str
        Why the run ended as it did, in words.
    t : ndarray (N,)
        Times, s.
    state, estimate : ndarray (N, 12)
        True and estimated state (:data:`visloc.model.STATE_NAMES`).
    setpoint : ndarray (N, 4)
        ``[x, y, z, psi]``.
    pwm : ndarray (N, 4)
        Motor commands, percent.
    saturated : ndarray (N,) bool
        Whether the requested inputs were out of the motors' reach (eq. 4.6 clipped).
    metrics : dict
        ``settling_time_s``, ``overshoot_pct``, ``position_rms_m``, ``height_dip_m``,
        ``estimate_rms_m``, ``max_tilt_deg``, ``saturated_fraction``, ``realtime_factor``,
        and for vision runs ``camera_frames``, ``vision_fixes``, ``vision_misses``; for step
        scenarios that reached their step the linear model's ``linear_settling_time_s``,
        ``linear_overshoot_pct``, ``linear_height_dip_m``; ``None`` where they do not apply.
        ``settling_time_s`` is the time after the step or push (after t = 0 for a hover)
        from which the position error stays within the scenario's band (5 % of a step, else
        5 cm); ``overshoot_pct`` the travel beyond a step's target in % of the step;
        ``position_rms_m`` the RMS distance from the set point over the whole run;
        ``height_dip_m`` the largest height loss below the set point after the step or push;
        ``estimate_rms_m`` the RMS distance between estimated and true position;
        ``realtime_factor`` simulated seconds per wall-clock second.
    motors : dict
        The simulated motors' ``c`` and ``d`` (the controller uses the means).
    """

    scenario: str
    status: SimStatus
    reason: str
    t: FloatArray
    state: FloatArray
    estimate: FloatArray
    setpoint: FloatArray
    pwm: FloatArray
    saturated: np.ndarray
    metrics: dict = field(default_factory=dict)
    motors: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready summary (no arrays): the fields ``visloc sim --json`` prints."""
        out = {"scenario": self.scenario, "status": self.status.value, "reason": self.reason,
               "crashed": self.status is SimStatus.CRASHED, "seconds": float(self.t[-1]) if len(self.t) else 0.0}
        out.update(self.metrics)
        out["motors"] = self.motors
        return out


def _check_rate(value: float, name: str) -> float:
    return check_real(value, name, positive=True)


def simulate(
    scenario: str | Scenario, *, params: ARDrone2Params = ARDRONE2, sigma: float = 0.0, seed: int = 0,
    arm: float | None = None, specs: ControlSpecs | None = None, gains: ControllerGains | None = None,
    seconds: float | None = None, dt: float | None = None, control_rate: float = 200.0, camera_rate: float = 30.0,
    motor_lag: float = 0.0, progress: Callable[[float], None] | None = None, localizer: Callable | None = None,
    warmup: float | None = None, max_tilt: float = 0.3, redetect_every: int = 10,
) -> SimResult:
    """Fly ``scenario`` in closed loop on the non-linear model: build the vehicle (motors
    drawn at ``sigma``), the controller, the sensors and the estimator, hover ``warmup`` s,
    then :func:`fly` them.

    Parameters
    ----------
    scenario : str or Scenario
        A name from :data:`visloc.sim.SCENARIOS` or a :class:`Scenario`.
    params : ARDrone2Params
        The vehicle (its mean motor coefficients are what the controller knows).
    sigma : float
        Draw each motor's ``c_i, d_i`` at ``+- sigma`` standard deviations from the mean
        (signs from ``seed``; :func:`visloc.sim.motor_coefficients`); 0: nominal motors (>= 0).
    seed : int
        Seeds the motor signs, the sensor noise and the turbulence.
    arm : float, optional
        Arm distance of eq. (2.12), m (:func:`visloc.control.resolve_arm`).
    specs, gains : ControlSpecs, ControllerGains, optional
        Controller gains (default :func:`visloc.control.design_gains` of ``params`` and
        ``specs``, the loop specifications).
    seconds : float, optional
        Override the scenario's duration, s (> 0).
    dt : float, optional
        RK4 step of the vehicle, s (> 0; rounded to a whole number of steps per control
        period). Default: one step per control period without a motor lag (the inputs are
        held over the period), 1 ms with one (the lagged inputs change within the period).
    control_rate, camera_rate : float
        Controller / IMU rate and bottom-camera rate, Hz (> 0).
    motor_lag : float
        First-order motor time constant (report eq. 2.13), s; 0 as in the report's model.
    progress : callable, optional
        Called with the simulated time after each simulated second.
    localizer : callable, optional
        Vision front end of the ``"vision"`` estimator (:class:`VisionEstimator`'s).
    warmup : float, optional
        Seconds of hover on the true state before t = 0, not recorded (the report's take-off),
        for the integrators to absorb the motors' spread. Default :data:`WARMUP_SECONDS` when
        ``sigma > 0``, else 0.
    max_tilt : float
        Bound on the tilt the set-point part of the roll and pitch torques asks for, rad
        (report §4.4; :class:`visloc.control.Controller`); ``math.inf``: unbounded.
    redetect_every : int
        Above 1 the vision front end (:class:`VisionEstimator`) follows the markers from frame
        to frame and detects them in full only when that fails; 1: in full every frame.

    Returns
    -------
    SimResult
        Time, true and estimated state, set point, motor commands and saturation flags at
        ``control_rate``, the exit :class:`SimStatus`, its reason and the metrics.

    Raises
    ------
    TypeError
        ``scenario`` not a str or :class:`Scenario`, ``params`` not :class:`ARDrone2Params`,
        a number not a real number.
    ValueError
        Unknown scenario or estimator; ``seconds``, ``dt``, ``control_rate`` or ``camera_rate``
        not finite and > 0; ``sigma``, ``warmup`` or ``motor_lag`` negative; ``sigma`` so large
        a motor coefficient is not > 0; ``arm`` not > 0; ``redetect_every`` not an int >= 1.
    """
    sc, p = _scenario_and_vehicle(scenario, params, arm)
    duration, ctrl_dt, substeps, cam_dt = _checked_timing(sc, seconds, control_rate, motor_lag, dt, camera_rate,
                                                          redetect_every)
    rng = np.random.default_rng(seed)
    vehicle, controller = _warmed_up(sc, p, sigma, seed, motor_lag, gains, specs, max_tilt, warmup, ctrl_dt,
                                     substeps)
    sensors, estimator = _estimator(sc, rng, cam_dt, vehicle.state.copy(), p.g, localizer, redetect_every)
    result = fly(sc, vehicle, controller, estimator, sensors=sensors, seconds=duration, control_rate=control_rate,
                 substeps=substeps, rng=rng, progress=progress)
    result.motors["sigma"] = float(sigma)
    return result


def _scenario_and_vehicle(scenario: str | Scenario, params: ARDrone2Params,
                          arm: float | None) -> tuple[Scenario, ARDrone2Params]:
    """:func:`simulate`'s scenario (looked up by name) and vehicle parameters (with ``arm``)."""
    sc = get_scenario(scenario) if isinstance(scenario, str) else scenario
    if not isinstance(sc, Scenario):
        raise TypeError(f"scenario: expected a name or Scenario, got {type(scenario).__name__}")
    p = check_params(params)
    return sc, replace(p, arm=resolve_arm(p, arm))


def _warmed_up(sc: Scenario, p: ARDrone2Params, sigma: float, seed: int, motor_lag: float,
               gains: ControllerGains | None, specs: ControlSpecs | None, max_tilt: float, warmup: float | None,
               ctrl_dt: float, substeps: int) -> tuple[Vehicle, Controller]:
    """:func:`simulate`'s vehicle (motors drawn at ``sigma``, trimmed to hover at the
    scenario's start) and controller, after ``warmup`` s of hover on the true state."""
    c, d = motor_coefficients(p, sigma, seed=seed)
    vehicle = Vehicle(p, c=c, d=d, motor_lag=motor_lag, state=_at(sc.start_setpoint))
    vehicle.trim(np.full(4, hover_pwm(p)))
    controller = Controller(p, gains=gains, specs=specs, max_tilt=max_tilt)
    lead = (WARMUP_SECONDS if sigma > 0 else 0.0) if warmup is None else check_real(
        warmup, "warmup", nonneg=True)
    _hover(vehicle, controller, sc.start_setpoint, round(lead / ctrl_dt), ctrl_dt, substeps, ctrl_dt / substeps)
    return vehicle, controller


def _checked_timing(sc: Scenario, seconds: float | None, control_rate: float, motor_lag: float, dt: float | None,
                    camera_rate: float, redetect_every: int) -> tuple[float, float, int, float]:
    """:func:`simulate`'s timing checked: the duration (s), the control period (s), RK4 steps
    per control period and the camera period (s). With a motor lag the default step is 1 ms;
    without one a step per control period (the scenarios' states agree with 1 ms steps within
    1e-8 m and rad)."""
    duration = sc.seconds if seconds is None else check_real(seconds, "seconds", positive=True)
    ctrl_dt = 1.0 / _check_rate(control_rate, "control_rate")
    lag = check_real(motor_lag, "motor_lag", nonneg=True)
    h = _check_rate(dt, "dt") if dt is not None else (0.001 if lag > 0 else ctrl_dt)
    cam_dt = 1.0 / _check_rate(camera_rate, "camera_rate")
    if isinstance(redetect_every, bool) or not isinstance(redetect_every, numbers.Integral) or redetect_every < 1:
        raise ValueError(f"redetect_every must be an integer >= 1, got {redetect_every!r}")
    return duration, ctrl_dt, max(1, round(ctrl_dt / h)), cam_dt


def fly(scenario: Scenario, vehicle: Vehicle, controller: Controller, estimator: TruthEstimator | VisionEstimator,
        *, sensors: VisionSensors | None = None, seconds: float | None = None, control_rate: float = 200.0,
        substeps: int = 1, rng: np.random.Generator | None = None,
        progress: Callable[[float], None] | None = None) -> SimResult:
    """Fly a scenario with the objects given: the closed loop of :func:`simulate` without
    building anything (RotorPy's ``simulate(world, vehicle, controller, ...)`` pattern).

    Each control step: the scenario's force (and gusts), the sensors fed to the estimator
    (or the true state to a :class:`TruthEstimator`), the controller's motor commands on the
    estimate and the set point, ``substeps`` RK4 steps of the vehicle; the run stops early on
    the floor, tipped over, :data:`FAR` from the set point or when the vision is lost.

    Parameters
    ----------
    scenario : Scenario
        Set points, reference, forces, gusts and duration.
    vehicle : Vehicle
        The vehicle, in its start state (it is flown: its state changes).
    controller : Controller
        The controller (its integrators change).
    estimator : TruthEstimator or VisionEstimator
        What the controller flies on.
    sensors : VisionSensors, optional
        The vision scenario's sensors feeding ``estimator`` (None: ``estimator`` sees the
        true state).
    seconds : float, optional
        Duration, s (> 0; default the scenario's).
    control_rate : float
        Controller / IMU rate, Hz (> 0).
    substeps : int
        RK4 steps of the vehicle per control step (>= 1; 1 is :func:`simulate`'s default
        without a motor lag).
    rng : numpy.random.Generator, optional
        Source of the gusts (default ``default_rng(0)``).
    progress : callable, optional
        Called with the simulated time after each simulated second.

    Returns
    -------
    SimResult
        As :func:`simulate` (``motors`` holds the vehicle's ``c`` and ``d``).

    Raises
    ------
    TypeError
        A wrong type of scenario, vehicle, controller or sensors.
    ValueError
        ``seconds`` or ``control_rate`` not finite and > 0, ``substeps`` < 1.
    """
    _check_objects(scenario, vehicle, controller, sensors, substeps)
    sc, p = scenario, vehicle.params
    duration = sc.seconds if seconds is None else check_real(seconds, "seconds", positive=True)
    ctrl_dt = 1.0 / _check_rate(control_rate, "control_rate")
    turbulence = _Turbulence(sc.gust_std, ctrl_dt, rng if rng is not None else np.random.default_rng(0))
    wall = time.perf_counter()
    records, ended = _run(sc, vehicle, controller, estimator, sensors, turbulence, round(duration / ctrl_dt) + 1,
                          ctrl_dt, int(substeps), progress)
    wall = time.perf_counter() - wall
    metrics = run_metrics(sc, records[0], records[1], records[2], records[3], records[5], wall)
    if sensors is not None:
        metrics.update(camera_frames=sensors.frames, vision_fixes=estimator.fixes,  # type: ignore[union-attr]
                       vision_misses=estimator.misses)  # type: ignore[union-attr]
    if sc.step is not None and sc.trajectory is None and records[0][-1] > sc.step[0]:  # the linear model's answer
        # to the same set-point step (none when the run ended at or before the step)
        metrics.update(step_metrics_linear(controller.gains, p, sc, duration))
    status, reason = ended if ended is not None else _ran_out(sc, metrics, duration)
    motors = {"c": [float(v) for v in vehicle.c], "d": [float(v) for v in vehicle.d]}
    return SimResult(sc.name, status, reason, *records[:5], records[5], metrics, motors)


def _check_objects(scenario: Scenario, vehicle: Vehicle, controller: Controller, sensors: VisionSensors | None,
                   substeps: int) -> None:
    """TypeError or ValueError naming the first of :func:`fly`'s objects that is wrong."""
    if not isinstance(scenario, Scenario):
        raise TypeError(f"scenario: expected a Scenario, got {type(scenario).__name__}")
    if not isinstance(vehicle, Vehicle) or not isinstance(controller, Controller):
        raise TypeError(f"vehicle, controller: expected a Vehicle and a Controller, got "
                        f"{type(vehicle).__name__} and {type(controller).__name__}")
    if sensors is not None and not isinstance(sensors, VisionSensors):
        raise TypeError(f"sensors: expected VisionSensors or None, got {type(sensors).__name__}")
    if isinstance(substeps, bool) or int(substeps) != substeps or substeps < 1:
        raise ValueError(f"substeps must be an integer >= 1, got {substeps!r}")


def _run(sc: Scenario, vehicle: Vehicle, controller: Controller, estimator: TruthEstimator | VisionEstimator,
         sensors: VisionSensors | None, turbulence: _Turbulence, n: int, ctrl_dt: float, substeps: int,
         progress: Callable[[float], None] | None) -> tuple[tuple, tuple[SimStatus, str] | None]:
    """:func:`fly`'s loop over at most ``n`` control steps (report Figure 4.4). Returns the
    records of the steps flown (times, states, estimates, set points, pwm, saturation) and
    how the run ended early (None: it ran to the end)."""
    p = vehicle.params
    h = ctrl_dt / substeps
    t_out = np.arange(n) * ctrl_dt
    states, estimates = np.full((n, 12), np.nan), np.full((n, 12), np.nan)
    setpoints, pwms = np.full((n, 4), np.nan), np.full((n, 4), np.nan)
    saturated = np.zeros(n, bool)
    ended: tuple[SimStatus, str] | None = None
    k = 0
    done = 0  # steps whose records are complete
    try:
        for k in range(n):
            t = k * ctrl_dt
            s = vehicle.state
            force = turbulence.add(sc.force(t))
            if sensors is not None:
                ended = sensors.sense(t, vehicle, force, estimator, p.g)  # type: ignore[arg-type]
            else:
                estimator.observe(s)  # type: ignore[union-attr]
            sp = sc.setpoint(t)
            x_hat = estimator.state
            cmd = controller.pwm(x_hat, sp, ctrl_dt, reference=sc.reference(t))  # report eqs. (4.5)-(4.6)
            states[k], estimates[k], setpoints[k], pwms[k] = s, x_hat, sp, cmd.pwm
            saturated[k] = cmd.saturated
            done = k + 1
            ended = ended or _stopped(s, sp, t, p)
            if ended is not None or k == n - 1:
                break
            try:
                for _ in range(substeps):
                    vehicle.step(cmd.pwm, h, force)
            except FloatingPointError as exc:
                ended = SimStatus.DIVERGED, str(exc)
                break
            if progress is not None and int((k + 1) * ctrl_dt) != int(k * ctrl_dt):
                progress((k + 1) * ctrl_dt)
    except KeyboardInterrupt:  # Ctrl-C: keep the steps flown so far
        if done == 0:
            raise
        ended, k = (SimStatus.INTERRUPTED, f"interrupted at t = {done * ctrl_dt:.2f} s"), done - 1
    m = k + 1
    return (t_out[:m], states[:m], estimates[:m], setpoints[:m], pwms[:m], saturated[:m]), ended


def _estimator(sc: Scenario, rng: np.random.Generator, cam_dt: float, initial: FloatArray, g: float,
               localizer: Callable | None, redetect_every: int = 10
               ) -> tuple[VisionSensors | None, TruthEstimator | VisionEstimator]:
    """The scenario's sensors (None: the controller sees the true state) and estimator."""
    if sc.estimator == "vision":
        sensors = VisionSensors(rng, cam_dt)
        return sensors, VisionEstimator(sensors.camera, initial, g=g, localizer=localizer,
                                        redetect_every=redetect_every)
    if sc.estimator == "truth":
        return None, TruthEstimator()
    raise ValueError(f"scenario.estimator: expected 'truth' or 'vision', got {sc.estimator!r}")


class _Turbulence:
    """Horizontal gusts: white noise of ``std`` (N) through a 1 Hz first-order low-pass,
    drawn once per control step ``dt`` (none for ``std`` 0)."""

    def __init__(self, std: float, dt: float, rng: np.random.Generator) -> None:
        self.std, self.rng = std, rng
        self.a = math.exp(-2.0 * math.pi * 1.0 * dt)
        self.gust = np.zeros(3)

    def add(self, force: FloatArray | None) -> FloatArray | None:
        """``force`` (or None) with this step's gust added."""
        if self.std <= 0.0:
            return force
        # a g + sqrt(1 - a^2) std n on floats (the same floats as on the arrays), no vertical gust
        a, scale, (n0, n1, _) = self.a, math.sqrt(1 - self.a**2) * self.std, self.rng.normal(size=3).tolist()
        g0, g1, _ = self.gust.tolist()
        self.gust = np.array([a * g0 + scale * n0, a * g1 + scale * n1, 0.0])
        return self.gust if force is None else force + self.gust


def _at(setpoint: FloatArray) -> FloatArray:
    """A state (12,) at rest at a set point's position and yaw."""
    state = np.zeros(12)
    state[0:3], state[8] = setpoint[:3], setpoint[3]
    return state


def _hover(vehicle: Vehicle, controller: Controller, setpoint: FloatArray, steps: int, ctrl_dt: float,
           substeps: int, h: float) -> None:
    """Fly ``steps`` control steps at ``setpoint`` on the true state, ``substeps`` RK4 steps
    of ``h`` each, unrecorded (the warm-up: the integrators absorb the motors' spread)."""
    for _ in range(steps):
        cmd = controller.pwm(vehicle.state, setpoint, ctrl_dt)
        for _ in range(substeps):
            vehicle.step(cmd.pwm, h)


def _stopped(s: FloatArray, sp: FloatArray, t: float, p: ARDrone2Params) -> tuple[SimStatus, str] | None:
    """Why a run stops at time ``t`` with state ``s`` and set point ``sp``, or None: on the
    floor, tipped over, or drifted :data:`FAR` from the set point."""
    if s[2] > -p.cog_height:
        return SimStatus.CRASHED, f"hit the floor at t = {t:.2f} s"
    if max(abs(s[6]), abs(s[7])) > CRASH_TILT:
        return SimStatus.CRASHED, (f"tipped over at t = {t:.2f} s (roll {math.degrees(s[6]):.0f} deg, "
                                   f"pitch {math.degrees(s[7]):.0f} deg)")
    if math.dist(s[:3].tolist(), sp[:3].tolist()) > FAR:
        return SimStatus.DIVERGED, f"drifted {FAR:g} m from the set point at t = {t:.2f} s"
    return None


def _ran_out(sc: Scenario, metrics: dict, duration: float) -> tuple[SimStatus, str]:
    """How a run that flew its whole duration ended: settled into its band, or not."""
    settle = metrics["settling_time_s"]
    if settle is not None:
        return SimStatus.SETTLED, f"within {sc.band * 100:.0f} cm of the set point from {settle:.2f} s on"
    return SimStatus.COMPLETED, (f"ran {duration:g} s; ended {metrics['final_error_m'] * 100:.1f} cm from the set "
                                 f"point (band {sc.band * 100:.0f} cm)")


class VisionSensors:
    """The vision scenarios' sensors: the IMU at the control rate, the ultrasound at 25 Hz
    (report §3.2.1) and the bottom camera over the printed grid (:data:`SIM_GRID`) every
    ``cam_dt`` s.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the sensors' noise.
    cam_dt : float
        Seconds between camera frames (> 0).
    """

    def __init__(self, rng: np.random.Generator, cam_dt: float) -> None:
        self.imu = Imu(rng=rng)
        self.sonar = Ultrasound(rng=rng)
        self.camera = BottomCamera(GridMap(**SIM_GRID), "DICT_4X4_100", rng=rng)
        self.cam_dt = cam_dt
        self.next_frame = self.next_echo = 0.0
        self.frames = 0

    def sense(self, t: float, vehicle: Vehicle, force: FloatArray | None, estimator: VisionEstimator,
              g: float) -> tuple[SimStatus, str] | None:
        """Feed the estimator what the sensors read at time ``t``: an IMU sample every call,
        an ultrasound reading every :data:`ULTRASOUND_PERIOD` s, a camera frame every
        ``cam_dt`` s.

        Parameters
        ----------
        t : float
            Simulated time, s.
        vehicle : Vehicle
            The vehicle, at time ``t`` (its state and motor inputs are read, not changed).
        force : ndarray (3,) or None
            External force on the CoG now, N, in A (it shows in the accelerometer).
        estimator : VisionEstimator
            Receives the samples.
        g : float
            Gravity, m/s^2.

        Returns
        -------
        (SimStatus, str) or None
            Why the run must stop (the view left the printed floor, or no fix for
            :data:`VISION_TIMEOUT` s), or None.
        """
        s, R = vehicle.state, vehicle.rotation()
        gyro, accel = self.imu.sample(s, R, vehicle.acceleration(force), g)
        estimator.imu(t, gyro, accel)
        if t + 1e-9 >= self.next_echo:
            estimator.ultrasound(t, self.sonar.sample(s, R))
            self.next_echo += ULTRASOUND_PERIOD
        ended = None
        if t + 1e-9 >= self.next_frame:
            try:
                image = self.camera.capture(s, R)
            except ValueError as exc:  # the view left the printed floor
                ended = SimStatus.DIVERGED, f"vision lost at t = {t:.2f} s: {exc}"
            else:
                estimator.image(t, image, self.cam_dt)
                self.frames += 1
            self.next_frame += self.cam_dt
        if ended is None and t - estimator.last_fix_time > VISION_TIMEOUT:
            ended = SimStatus.DIVERGED, f"vision lost: no marker-map fix for {VISION_TIMEOUT:g} s at t = {t:.2f} s"
        return ended


