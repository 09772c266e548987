"""Closed-loop simulation of the AR.Drone 2.0 on visloc's own estimates (report chapter 4).

:class:`Vehicle` integrates the non-linear model (eqs. 2.1-2.8) by RK4 with per-motor
propulsion (eqs. 2.15-2.18) and saturation; :mod:`visloc.sim.sensors` gives an IMU, the
ultrasound and the bottom camera over a printed marker grid (:class:`BottomCamera`);
:mod:`visloc.sim.estimators` the true state or visloc's vision pipeline. :func:`simulate` runs
a :class:`Scenario` (:data:`SCENARIOS`: ``hover``, ``sidestep``, ``push``, ``hover-vision``, ...)
with :class:`visloc.control.Controller`, building every object itself, and returns a
:class:`SimResult` with a :class:`SimStatus`; :func:`fly` flies objects built by the caller
(vehicle, controller, estimator, :class:`VisionSensors`) through a scenario.
"""

from visloc.sim.estimators import TruthEstimator, VisionEstimator
from visloc.sim.loop import SIM_GRID, SimResult, SimStatus, VisionSensors, fly, simulate
from visloc.sim.metrics import linear_step_response, settling_time
from visloc.sim.scenarios import (
    SCENARIOS,
    Scenario,
    figure8_scenario,
    get_scenario,
    square_scenario,
    step_scenario,
)
from visloc.sim.sensors import BODY_TO_CAMERA, MAP_FROM_NED, BottomCamera, Imu, Ultrasound
from visloc.sim.vehicle import Vehicle, motor_coefficients

__all__ = [
    "BODY_TO_CAMERA",
    "MAP_FROM_NED",
    "SCENARIOS",
    "SIM_GRID",
    "BottomCamera",
    "Imu",
    "Scenario",
    "SimResult",
    "SimStatus",
    "TruthEstimator",
    "Ultrasound",
    "Vehicle",
    "VisionEstimator",
    "VisionSensors",
    "figure8_scenario",
    "fly",
    "get_scenario",
    "linear_step_response",
    "motor_coefficients",
    "settling_time",
    "simulate",
    "square_scenario",
    "step_scenario",
]
