"""AR.Drone 2.0 model: parameters, propulsion and mixer, fits, inertia, rigid-body dynamics.

Implements chapter 2 and Appendices A, D and E of the report (the seed document): the measured
parameters (:class:`ARDrone2Params`, :data:`ARDRONE2`), the static thrust/torque model and the
mixer ``Gamma`` with its inverse (eqs. 2.9-2.18, 4.6), the weighted least-squares propulsion fit
(App. E), the bifilar-pendulum inertia (eq. 2.14, App. D), the NED rigid-body equations with
Z-Y-X Euler angles (eqs. 2.1-2.8, A.1-A.16) and the gimbal-stand model (App. C, C.1-C.11).
SI units; motor commands ``pwm`` in percent.
"""

from visloc.model.fit import (
    REPORT_PWM_GRID,
    REPORT_WEIGHTS,
    PropulsionFit,
    fit_propulsion,
    mean_std,
)
from visloc.model.inertia import BifilarResult, bifilar_inertia, inertia_from_measurements
from visloc.model.params import ARDRONE2, ARDrone2Params
from visloc.model.propulsion import (
    MOTOR_LAYOUT,
    YAW_SIGNS,
    PwmResult,
    hover_pwm,
    inputs_from_pwm,
    mixer_matrix,
    pwm_bar,
    pwm_from_bar,
    pwm_from_inputs,
    thrust,
    torque,
)
from visloc.model.rigid_body import (
    STATE_NAMES,
    derivatives,
    euler_rate_matrix,
    motor_lag_derivative,
    rotation_matrix,
)
from visloc.model.stand import (
    STAND_STATE_NAMES,
    stand_derivatives,
    stand_gravity_torque,
    stand_inertia,
    stand_linear,
)

__all__ = [
    "ARDRONE2",
    "MOTOR_LAYOUT",
    "REPORT_PWM_GRID",
    "REPORT_WEIGHTS",
    "STAND_STATE_NAMES",
    "STATE_NAMES",
    "YAW_SIGNS",
    "ARDrone2Params",
    "BifilarResult",
    "PropulsionFit",
    "PwmResult",
    "bifilar_inertia",
    "derivatives",
    "euler_rate_matrix",
    "fit_propulsion",
    "hover_pwm",
    "inertia_from_measurements",
    "inputs_from_pwm",
    "mean_std",
    "mixer_matrix",
    "motor_lag_derivative",
    "pwm_bar",
    "pwm_from_bar",
    "pwm_from_inputs",
    "rotation_matrix",
    "stand_derivatives",
    "stand_gravity_torque",
    "stand_inertia",
    "stand_linear",
    "thrust",
    "torque",
]
