"""``visloc model``: the identified AR.Drone 2.0 model."""

from __future__ import annotations

import argparse

import numpy as np


def model_summary() -> dict:
    """The identified AR.Drone 2.0 parameters (report chapter 2), the hover trim per motor and
    the open-loop poles of the rigid-body model linearised at hover (numerical Jacobian)."""
    from visloc.model import ARDRONE2, hover_pwm
    from visloc.model.rigid_body import derivatives

    p = ARDRONE2
    u0 = np.array([p.mass * p.g, 0.0, 0.0, 0.0])  # T0 = m g (report section 4.1)
    x0 = np.zeros(12)
    h = 1e-6
    A = np.column_stack([(derivatives(x0 + h * e, u0, p) - derivatives(x0 - h * e, u0, p)) / (2 * h)
                         for e in np.eye(12)])
    poles = np.linalg.eigvals(A)
    trim = hover_pwm(p)
    return {
        "mass_kg": p.mass, "inertia_kg_m2": [p.Ixx, p.Iyy, p.Izz], "g": p.g,
        "thrust_coefficient_c_mean": p.c_mean, "thrust_coefficient_c_std": p.c_std,
        "torque_coefficient_d_mean": p.d_mean, "torque_coefficient_d_std": p.d_std, "pwm_shift_k": p.k,
        "hover_thrust_N": p.mass * p.g, "hover_pwm_percent": [trim] * 4,
        "open_loop_poles": [[float(v.real), float(v.imag)] for v in poles],
        "state_order": "x y z u v w phi theta psi p q r (NED)",
    }

def model(args: argparse.Namespace) -> int:
    """``visloc model``: print :func:`model_summary` as a table or JSON.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``visloc model`` command line (:func:`visloc.cli.build_parser`).

    Returns
    -------
    int
        Exit status: 0.
    """
    import json

    s = model_summary()
    if args.json:
        print(json.dumps(s, indent=1))
        return 0
    print(f"AR.Drone 2.0 (report chapter 2): mass {s['mass_kg']} kg, inertia "
          f"{s['inertia_kg_m2']} kg m^2, g {s['g']} m/s^2")
    print(f"propulsion (eqs. 2.15-2.16): c = {s['thrust_coefficient_c_mean']:.4e} +- "
          f"{s['thrust_coefficient_c_std']:.3e} N/%^2, d = {s['torque_coefficient_d_mean']:.4e} +- "
          f"{s['torque_coefficient_d_std']:.3e} N m/%^2, k = {s['pwm_shift_k']} %")
    print(f"hover: T0 = m g = {s['hover_thrust_N']:.4f} N, pwm per motor "
          f"{s['hover_pwm_percent'][0]:.2f} % (sqrt(m g / (4 c)) - k)")
    real = [p[0] for p in s["open_loop_poles"]]
    print(f"open-loop poles at hover: {len(real)}, largest real part {max(real):.3g} "
          "(a chain of integrators: the model needs feedback)")
    return 0
