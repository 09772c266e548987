"""Linear control of the AR.Drone 2.0 at hover (report chapter 4, Appendix B).

Linearisation (report §4.1, eqs. 4.1-4.4): the pilot frame (:func:`to_pilot`), the Jacobians
of the non-linear model (:func:`linearize_numerical`) and the written-out matrices
(:func:`linearize_analytical`), with the mixer as input map (:func:`mixer_input_matrix`,
:func:`pwm_input_matrix`).

Design (report §4.2, eqs. 4.5-4.11): six PID loops shaped to a crossover frequency and phase
margin each (:class:`ControlSpecs`, :func:`design_loop`, :func:`design_gains`), assembled into
``u = -K x`` (:meth:`ControllerGains.K`) on the 12 pilot-frame states plus the integrated
x, y, z and heading errors (§4.2.3); an LQR alternative (:func:`lqr_gains`); Bode data and
margins of each loop (:func:`bode`, :func:`loop_margins`, :func:`save_bode_png`; report
Figures 4.2-4.3).

Streaming controller (report Figure 4.4, §4.4): :class:`Controller` with ``command(state,
setpoint, dt) -> u`` and ``pwm(...)`` (eq. 4.6), gravity feed-forward and bounded position
torques.

Robustness (report §4.3, eqs. 4.12-4.16): the 256-vertex check (:func:`vertex_check`), the
sufficient common-Lyapunov LMI (:func:`common_lyapunov`, needs the optional ``cvxpy``:
``pip install visloc[lmi]``), :func:`largest_sigma` and :func:`robust_summary` for the CLI.

The report never gives the arm distance ``d`` of eq. (2.12); :func:`resolve_arm` documents
the 0.125 m default used when neither an ``arm=`` argument nor ``params.arm`` is set. The
gains do not depend on it, only the mixer and the robustness vertices do.
"""

from visloc.control._checks import DEFAULT_ARM, resolve_arm
from visloc.control.bode import PARTS, bode, frequency_response, loop_margins, save_bode_png
from visloc.control.controller import Controller, wrap_angle
from visloc.control.design import (
    INTEGRAL_STATE_NAMES,
    LOOP_ALIASES,
    LOOPS,
    ControllerGains,
    ControlSpecs,
    LoopGains,
    LoopSpec,
    augmented_model,
    design_gains,
    design_loop,
    lqr_gains,
    plant,
)
from visloc.control.linear import (
    INPUT_NAMES,
    PILOT_STATE_NAMES,
    from_pilot,
    hover_input,
    linearize_analytical,
    linearize_numerical,
    mixer_input_matrix,
    pwm_input_matrix,
    to_pilot,
    yaw_rotation,
)
from visloc.control.robustness import (
    LYAPUNOV_STATUSES,
    LyapunovResult,
    VertexResult,
    closed_loop_vertices,
    common_lyapunov,
    largest_sigma,
    max_sigma,
    robust_summary,
    vertex_check,
    vertex_stability,
)

__all__ = [
    "DEFAULT_ARM",
    "INPUT_NAMES",
    "INTEGRAL_STATE_NAMES",
    "LOOPS",
    "LOOP_ALIASES",
    "LYAPUNOV_STATUSES",
    "PARTS",
    "PILOT_STATE_NAMES",
    "ControlSpecs",
    "Controller",
    "ControllerGains",
    "LoopGains",
    "LoopSpec",
    "LyapunovResult",
    "VertexResult",
    "augmented_model",
    "bode",
    "closed_loop_vertices",
    "common_lyapunov",
    "design_gains",
    "design_loop",
    "frequency_response",
    "from_pilot",
    "hover_input",
    "largest_sigma",
    "linearize_analytical",
    "linearize_numerical",
    "loop_margins",
    "lqr_gains",
    "max_sigma",
    "mixer_input_matrix",
    "plant",
    "pwm_input_matrix",
    "resolve_arm",
    "robust_summary",
    "save_bode_png",
    "to_pilot",
    "vertex_check",
    "vertex_stability",
    "wrap_angle",
    "yaw_rotation",
]
