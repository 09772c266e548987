"""``visloc robust``: robust stability of the hover controller under propulsion uncertainty."""

from __future__ import annotations

import argparse
import json


def robust(args: argparse.Namespace) -> int:
    """``visloc robust --sigma N [--tilt DEG] [--json]``: check the closed loop at every vertex
    of the propulsion-coefficient box of half-width N standard deviations (report section 4.4,
    eqs. 4.12-4.13) and search for a common Lyapunov matrix; with ``--tilt``, the tracking
    loop's: the vertices also linearised at +-DEG roll; exit status 0 when every vertex is
    stable, 1 when one is not (2: a bad ``--sigma`` or ``--tilt``).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``visloc robust`` command line (:func:`visloc.cli.build_parser`).

    Returns
    -------
    int
        Exit status: 0 when every vertex is stable, 1 when one is not.
    """
    from visloc.control.robustness import max_sigma, robust_summary
    from visloc.errors import UsageError
    from visloc.model.params import ARDRONE2

    if not 0.0 <= args.tilt < 45.0:  # NaN too
        raise UsageError(f"--tilt must be from 0 to below 45 degrees, got {args.tilt:g}")
    if not 0.0 <= args.sigma < max_sigma(ARDRONE2):  # NaN too; named as the user typed it
        raise UsageError(f"--sigma must be from 0 to below {max_sigma(ARDRONE2):.10g} (beyond it a motor "
                         f"coefficient of eqs. 4.12-4.13 is <= 0), got {args.sigma:g}")
    s = robust_summary(args.sigma, tilt_deg=args.tilt)
    if args.json:
        print(json.dumps(s, indent=1))
    else:
        verdict = "stable at every vertex" if s["vertex_stable"] else "UNSTABLE at some vertex"
        where = f" at hover and +-{s['tilt_deg']:g} deg roll" if s["tilt_deg"] else ""
        print(f"propulsion box +-{s['n_sigma']:g} sigma (eqs. 4.12-4.13){where}: {s['vertices']} vertices, "
              f"closed loop ({s['states']} states) {verdict}")
        print(f"largest real part of a closed-loop eigenvalue: {s['max_real_eig']:.4g} 1/s")
        print(f"common Lyapunov matrix (quadratic stability over the polytope): {s['lyapunov']}")
        print(f"arm distance used: {s['arm_m']:.4g} m")
    return 0 if s["vertex_stable"] else 1
