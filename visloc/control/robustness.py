"""Robustness against the spread of the motor coefficients (report §4.3, eqs. 4.12-4.16).

Each motor's thrust and torque coefficients are ``c_i = c_mean + r_i c_std`` and
``d_i = d_mean + s_i d_std`` (eqs. 4.12-4.13). The controller inverts the *mean* mixer
``Gamma_bar`` (eq. 4.6) while the motors apply ``Gamma(r, s)``, so the input matrix of the
closed loop is ``B(delta) = B Gamma(r, s) Gamma_bar^-1``, affine in the eight ratios
(eq. 4.15). With ``-n <= r_i, s_i <= n`` the closed-loop matrices ``A - B(delta) K`` form a
polytope with 2^8 = 256 vertices.

Two tests:

* the report's vertex check (eq. 4.16): every vertex has ``max Re lambda < 0``. Necessary,
  **not sufficient**: a polytope of stable vertices may contain unstable matrices;
* a common quadratic Lyapunov function: ``P > 0`` with ``A_i^T P + P A_i < 0`` at every
  vertex (an LMI, solved with SCS, which comes with cvxpy: ``pip install visloc[lmi]``).
  Sufficient: it proves every matrix of the polytope stable (even time-varying ones).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from functools import partial

import numpy as np
from scipy.linalg import matrix_balance

from visloc.control._checks import check_params, check_real, resolve_arm
from visloc.control.design import ControllerGains, augmented_model, design_gains
from visloc.model.params import ARDRONE2, ARDrone2Params
from visloc.model.propulsion import mixer_matrix
from visloc.types import FloatArray

LYAPUNOV_STATUSES: tuple[str, ...] = ("feasible", "infeasible", "unavailable")
"""Outcomes of :func:`common_lyapunov`."""

TESTS: tuple[str, ...] = ("vertex", "lyapunov")
"""Tests :func:`largest_sigma` can bisect."""


@dataclass(frozen=True, eq=False)
class LyapunovResult:
    """Outcome of the common-Lyapunov LMI.

    Attributes
    ----------
    status : str
        ``"feasible"`` (a ``P`` was found and verified with numpy eigenvalues),
        ``"infeasible"`` (the solver proved no ``P`` exists, or its answer failed the
        verification) or ``"unavailable"`` (cvxpy is not installed).
    P : ndarray (n, n) or None
        The certificate when feasible.
    max_lmi_eig : float
        Largest eigenvalue of ``A_i^T P + P A_i`` over the vertices (< 0 when feasible); nan
        without a ``P``.
    message : str
        Solver status and notes.
    """

    status: str
    P: FloatArray | None
    max_lmi_eig: float
    message: str


@dataclass(frozen=True, eq=False)
class VertexResult:
    """Outcome of the 256-vertex check (report eq. 4.16) and, optionally, the LMI.

    Attributes
    ----------
    n_sigma : float
        Half-width of the box of the ratios ``r_i, s_i`` in standard deviations.
    vertices : int
        Number of vertices checked (256).
    vertex_stable : bool
        Every vertex has ``max Re lambda < 0`` (eq. 4.16).
    max_real_eig : float
        Largest real part of any vertex eigenvalue, 1/s.
    worst_vertex : tuple of 8 float
        ``(r_1..r_4, s_1..s_4)`` of the vertex with ``max_real_eig``.
    lyapunov : str or None
        :attr:`LyapunovResult.status`, or None when the LMI was not asked for.
    """

    n_sigma: float
    vertices: int
    vertex_stable: bool
    max_real_eig: float
    worst_vertex: tuple[float, ...]
    lyapunov: str | None = None


def max_sigma(params: ARDrone2Params = ARDRONE2) -> float:
    """Largest ``n`` for which every perturbed coefficient stays positive (eqs. 4.12-4.13).

    Parameters
    ----------
    params : ARDrone2Params
        Vehicle parameters (``c_mean, c_std, d_mean, d_std``).

    Returns
    -------
    float
        ``min(c_mean / c_std, d_mean / d_std)``, in standard deviations (a ratio with a zero
        standard deviation counts as infinite; ``inf`` when both are zero).

    Raises
    ------
    TypeError
        ``params`` is not an :class:`ARDrone2Params`.
    """
    p = check_params(params)
    limits = [p.c_mean / p.c_std if p.c_std > 0 else math.inf,
              p.d_mean / p.d_std if p.d_std > 0 else math.inf]
    return min(limits)


def _check_sigma(n_sigma: float, params: ARDrone2Params) -> float:
    n = check_real(n_sigma, "n_sigma", nonneg=True)
    if n >= max_sigma(params):
        raise ValueError(
            f"n_sigma: expected < {max_sigma(params):.10g} (beyond it a motor coefficient of "
            f"eqs. 4.12-4.13 is <= 0), got {n!r}"
        )
    return n


def closed_loop_vertices(
    n_sigma: float,
    *,
    params: ARDrone2Params = ARDRONE2,
    gains: ControllerGains | None = None,
    arm: float | None = None,
    integral: bool = True,
    roll: float = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """Closed-loop matrices ``A - B(delta) K`` at the 256 vertices (report eqs. 4.14-4.16).

    Parameters
    ----------
    n_sigma : float
        ``n`` of ``-n <= r_i, s_i <= n``, standard deviations (>= 0, < :func:`max_sigma`).
    params : ARDrone2Params
        Vehicle parameters (means and standard deviations of ``c`` and ``d``).
    gains : ControllerGains, optional
        Default :func:`visloc.control.design_gains` of ``params``.
    arm : float, optional
        Arm distance of eq. (2.12), m (see :func:`visloc.control.resolve_arm`).
    integral : bool
        Include the four integral states (16 states) or not (12).
    roll : float
        The operating point, rad: 0 hover (the report's check), else the model linearised in
        a steady sideways acceleration at this roll (:func:`visloc.control.augmented_model`):
        a tracking loop flying a trajectory's tilt, its feed-forward holding the attitude and
        the feedback acting on the errors from it.

    Returns
    -------
    matrices : ndarray (256, n, n)
        ``A - B(delta) K`` of each vertex, ``n = 16`` with ``integral`` else 12; states in the
        order of :data:`visloc.control.PILOT_STATE_NAMES` then
        :data:`visloc.control.INTEGRAL_STATE_NAMES`.
    ratios : ndarray (256, 8)
        ``(r_1..r_4, s_1..s_4)`` of each vertex, standard deviations (each ``+- n_sigma``).

    Raises
    ------
    ValueError
        ``n_sigma`` negative, not finite or not below :func:`max_sigma`; ``arm`` not > 0.
    TypeError
        ``params`` is not an :class:`ARDrone2Params`, ``gains`` not a
        :class:`ControllerGains`, ``n_sigma`` or ``arm`` not a real number.
    """
    p = check_params(params)
    n = _check_sigma(n_sigma, p)
    d_arm = resolve_arm(p, arm)
    g = design_gains(p) if gains is None else gains
    if not isinstance(g, ControllerGains):
        raise TypeError(f"gains: expected ControllerGains, got {type(g).__name__}")
    a, b = augmented_model(p, roll=check_real(roll, "roll"))
    k = g.K(integral=True)
    size = 16 if integral else 12
    a, b, k = a[:size, :size], b[:size], k[:, :size]
    gamma_bar_inv = np.linalg.inv(mixer_matrix(p, arm=d_arm))  # report eq. (4.6)
    ratios = n * np.array(list(itertools.product((-1.0, 1.0), repeat=8)))
    out = np.empty((len(ratios), size, size))
    for i, rs in enumerate(ratios):
        c = p.c_mean + rs[:4] * p.c_std  # report eq. (4.12)
        d = p.d_mean + rs[4:] * p.d_std  # report eq. (4.13)
        b_delta = b @ mixer_matrix(p, c=c, d=d, arm=d_arm) @ gamma_bar_inv  # eq. (4.15)
        out[i] = a - b_delta @ k  # report eq. (4.16)
    return out, ratios


def vertex_stability(matrices: FloatArray) -> tuple[bool, float, int]:
    """Largest real part of the eigenvalues of a stack of matrices (report eq. 4.16).

    Parameters
    ----------
    matrices : array_like (N, n, n)
        N >= 1 state matrices of ``x' = A x`` (e.g. :func:`closed_loop_vertices`).

    Returns
    -------
    stable : bool
        Every matrix has all eigenvalues in the open left half-plane.
    max_real_eig : float
        Largest real part over all matrices, 1/s.
    worst : int
        Index of the matrix that has it.

    Raises
    ------
    TypeError
        ``matrices`` are not real numbers.
    ValueError
        ``matrices`` not (N, n, n) with N >= 1, or not finite.
    """
    m = _as_stack(matrices)
    per = np.array([np.max(np.linalg.eigvals(a).real) for a in m])
    worst = int(np.argmax(per))
    return bool(per[worst] < 0.0), float(per[worst]), worst


def common_lyapunov(matrices: FloatArray, *, solver: str | None = None) -> LyapunovResult:
    """Search one ``P > 0`` with ``A_i^T P + P A_i < 0`` for every matrix (an LMI, cvxpy).

    The strict inequalities are posed as ``P >= I`` and ``A_i^T P + P A_i <= -I`` (the same
    problem up to scaling ``P``); a solution is accepted only after numpy confirms both with
    eigenvalues. The LMI is solved on the vertices balanced by one diagonal similarity
    ``D^-1 A_i D`` (:func:`scipy.linalg.matrix_balance` of their mean): a strict certificate
    ``P'`` there is ``P = D^-1 P' D^-1`` here, and the first-order solver needs about a third
    of the iterations on the better-scaled entries.

    Parameters
    ----------
    matrices : array_like (N, n, n)
        The polytope's vertices (e.g. :func:`closed_loop_vertices`), N >= 1.
    solver : str, optional
        cvxpy solver name (the LMI is then posed and compiled by cvxpy). By default SCS
        (first order, at most 1000 iterations: 1.5-2 s for the 256 vertices of the 16-state
        loop here) on the problem data built here, which is what cvxpy hands SCS, without
        cvxpy's compile (about 1 s less); then Clarabel through cvxpy (interior point,
        about 10 s) when SCS stops without a conclusion (near the feasibility boundary).

    Returns
    -------
    LyapunovResult
        ``"feasible"`` with the certificate ``P`` (n, n), ``"infeasible"``, or
        ``"unavailable"`` without cvxpy (no exception then).

    Raises
    ------
    TypeError, ValueError
        As for :func:`vertex_stability`.
    """
    m = _as_stack(matrices)
    try:
        import cvxpy as cp
    except ImportError:
        return LyapunovResult("unavailable", None, math.nan,
                              "cvxpy is not installed (pip install visloc[lmi])")
    scale = matrix_balance(m.mean(axis=0), permute=False, separate=True)[1][0]  # D = diag(scale)
    balanced = m * (scale[None, None, :] / scale[None, :, None])  # D^-1 A_i D
    installed = cp.installed_solvers()
    if solver is not None:
        attempts = [(solver, partial(_lmi_cvxpy, cp, balanced, solver))]
    else:  # the default: SCS on the LMI's data built here, then Clarabel posed by cvxpy
        attempts = [(name, solve) for name, solve in (("SCS", partial(_lmi_scs, balanced, max_iters=1000)),
                                                       ("CLARABEL", partial(_lmi_cvxpy, cp, balanced, "CLARABEL")))
                    if name in installed] or [(None, partial(_lmi_cvxpy, cp, balanced, None))]
    notes, p_prime = [], None
    for name, solve in attempts:
        status, p_prime = solve()
        notes.append(f"{name}: {status}")
        if status in ("optimal", "optimal_inaccurate", "infeasible"):
            break
    message = "; ".join(notes)
    if p_prime is None or status not in ("optimal", "optimal_inaccurate"):
        return LyapunovResult("infeasible", None, math.nan, message)
    p_val = 0.5 * (p_prime + p_prime.T) / np.outer(scale, scale)  # D^-1 P' D^-1
    worst = max(float(np.max(np.linalg.eigvalsh(a.T @ p_val + p_val @ a))) for a in m)
    if np.min(np.linalg.eigvalsh(p_val)) <= 0.0 or worst >= 0.0:
        return LyapunovResult("infeasible", None, worst,
                              message + "; the P returned fails the eigenvalue check")
    return LyapunovResult("feasible", p_val, worst, message)


def _lmi_cvxpy(cp, balanced: FloatArray, solver: str | None) -> tuple[str, FloatArray | None]:
    """:func:`common_lyapunov`'s LMI on ``balanced`` (N, n, n) posed in cvxpy and solved with
    ``solver``: (cvxpy's status, or "failed (...)", and ``P'`` when it has a value)."""
    size = balanced.shape[1]
    p_var = cp.Variable((size, size), symmetric=True)
    eye = np.eye(size)
    constraints = [p_var >> eye]
    # one live array per vertex: cvxpy keys large constants by id(array), and views made and
    # dropped in the loop reuse one id, which left it comparing all 256 pairwise
    transposed = list(balanced.transpose(0, 2, 1))
    for a_t in transposed:
        lhs = a_t @ p_var
        constraints.append(lhs + lhs.T << -eye)  # A_i^T P + P A_i <= -I
    problem = cp.Problem(cp.Minimize(0), constraints)  # a feasibility problem
    try:
        problem.solve(solver=solver)
    except cp.error.SolverError as exc:
        return f"failed ({exc})", None
    return problem.status, p_var.value


def _lmi_scs_data(balanced: FloatArray) -> tuple[object, FloatArray, FloatArray]:
    """SCS's data of :func:`common_lyapunov`'s LMI on ``balanced`` (N, n, n).

    SCS's form is ``A x + s = b`` with ``s`` in N + 1 semidefinite cones, each a symmetric
    matrix given as its lower triangle column by column with the off-diagonal entries times
    sqrt(2) (``svec``). The unknown is ``x = svec(P')``; the cones hold ``P' - I``
    (``A = -1``, ``b = -svec(I)``) and ``-(A_i^T P' + P' A_i) - I`` (``A = svec(L_i(smat(.)))``,
    ``b = -svec(I)``).

    Returns ``A`` (scipy CSC, (N + 1) m x m with m = n (n + 1) / 2), ``b`` ((N + 1) m,) and the
    basis (n, n, m): ``basis @ x`` is ``smat(x)``.
    """
    import scipy.sparse as sp

    n_vert, size = balanced.shape[:2]
    cols, rows = np.triu_indices(size)  # the lower triangle column by column: (rows[k], cols[k])
    weight = np.where(rows != cols, math.sqrt(2.0), 1.0)  # svec's factor on each entry
    n_var = len(rows)
    basis = np.zeros((size, size, n_var))  # smat(e_k)
    basis[rows, cols, np.arange(n_var)] = 1.0 / weight
    basis[cols, rows, np.arange(n_var)] = 1.0 / weight
    blocks = [-sp.identity(n_var, format="csr")]
    for chunk in np.array_split(balanced, max(1, n_vert // 32)):  # 32 vertices: ~9 MB at a time
        g = (chunk.transpose(0, 2, 1) @ basis.reshape(size, -1)).reshape(len(chunk), size, size, n_var)
        lyap = g + g.transpose(0, 2, 1, 3)  # A_i^T E_k + E_k A_i, (vertices, n, n, m)
        blocks.append(sp.csr_matrix((lyap[:, rows, cols, :] * weight[None, :, None]).reshape(-1, n_var)))
    b_vec = np.tile(-np.eye(size)[rows, cols], n_vert + 1)
    return sp.vstack(blocks, format="csc"), b_vec, basis


#: SCS's status codes as cvxpy names them (its SCS interface's map)
_SCS_STATUS = {1: "optimal", 2: "optimal_inaccurate", -2: "infeasible", -7: "infeasible_inaccurate",
               -1: "unbounded", -6: "unbounded_inaccurate"}


def _lmi_scs(balanced: FloatArray, *, max_iters: int) -> tuple[str, FloatArray | None]:
    """:func:`common_lyapunov`'s LMI on ``balanced`` (N, n, n) handed to SCS directly: the
    problem and tolerances (1e-5) cvxpy gives SCS, without cvxpy's compile (2.2-2.8 s against
    3.1-3.7 s through cvxpy for the 256-vertex problem here). Returns (status as cvxpy names it, ``P'`` or None)."""
    import scs

    a_mat, b_vec, basis = _lmi_scs_data(balanced)
    cones = {"s": [balanced.shape[1]] * (balanced.shape[0] + 1)}
    out = scs.solve({"A": a_mat, "b": b_vec, "c": np.zeros(a_mat.shape[1])}, cones, verbose=False,
                    eps_abs=1e-5, eps_rel=1e-5, max_iters=max_iters)  # as cvxpy calls it
    status = _SCS_STATUS.get(out["info"]["status_val"], f"failed ({out['info']['status']})")
    if status not in ("optimal", "optimal_inaccurate"):
        return status, None
    return status, basis @ out["x"]


def vertex_check(
    n_sigma: float,
    *,
    params: ARDrone2Params = ARDRONE2,
    gains: ControllerGains | None = None,
    arm: float | None = None,
    integral: bool = True,
    lyapunov: bool = False,
    roll: float = 0.0,
) -> VertexResult:
    """The report's 2^8 = 256-vertex stability check at ``+- n_sigma`` (eq. 4.16).

    Parameters
    ----------
    n_sigma : float
        Box half-width in standard deviations of ``c`` and ``d`` (>= 0).
    params, gains, arm, integral, roll
        As for :func:`closed_loop_vertices`.
    lyapunov : bool
        Also run :func:`common_lyapunov` on the vertices.

    Returns
    -------
    VertexResult
        Vertex count, stability, largest real eigenvalue part (1/s), the worst vertex and,
        with ``lyapunov``, the LMI's status.

    Raises
    ------
    TypeError, ValueError
        As for :func:`closed_loop_vertices`.
    """
    mats, ratios = closed_loop_vertices(n_sigma, params=params, gains=gains, arm=arm,
                                        integral=integral, roll=roll)
    stable, worst_eig, worst = vertex_stability(mats)
    status = common_lyapunov(mats).status if lyapunov else None
    return VertexResult(n_sigma=float(n_sigma), vertices=len(mats), vertex_stable=stable,
                        max_real_eig=worst_eig, worst_vertex=tuple(ratios[worst].tolist()),
                        lyapunov=status)


def largest_sigma(
    *,
    test: str = "vertex",
    params: ARDrone2Params = ARDRONE2,
    gains: ControllerGains | None = None,
    arm: float | None = None,
    integral: bool = True,
    tol: float = 0.01,
) -> float:
    """Largest ``n`` (standard deviations) for which ``test`` passes, by bisection.

    Parameters
    ----------
    test : str
        ``"vertex"`` (eq. 4.16) or ``"lyapunov"`` (the common-Lyapunov LMI; needs cvxpy).
    params, gains, arm, integral
        As for :func:`closed_loop_vertices`.
    tol : float
        Bisection tolerance in standard deviations (> 0).

    Returns
    -------
    float
        The bracket's lower end: 0 when the test fails even at ``n = 0``; just below
        :func:`max_sigma` when it passes up to the point where a coefficient reaches 0
        (``inf`` when ``params`` has no spread, ``c_std = d_std = 0``, and the test passes). The
        Lyapunov test is monotone in ``n`` (the polytopes are nested); the vertex check need
        not be, so its answer is the edge bisection found, not a proof for every smaller n.

    Raises
    ------
    ValueError
        If ``test`` is unknown, or ``"lyapunov"`` without cvxpy installed; ``tol`` not finite
        and > 0; ``arm`` not > 0.
    TypeError
        ``tol`` not a real number; ``params`` or ``gains`` of the wrong type.

    Notes
    -----
    ``"vertex"`` takes a fraction of a second. ``"lyapunov"`` first bisects the vertex
    check (a common ``P`` needs stable vertices) and then solves one LMI per step, 2-15 s
    each: a few minutes at ``tol=0.01``.
    """
    if test not in TESTS:
        raise ValueError(f"test: expected one of {TESTS}, got {test!r}")
    step = check_real(tol, "tol", positive=True)
    if test == "lyapunov":
        try:
            import cvxpy  # noqa: F401
        except ImportError as exc:
            raise ValueError("test: 'lyapunov' needs cvxpy (pip install visloc[lmi])") from exc
    g = design_gains(params) if gains is None else gains

    def passes(n: float) -> bool:
        mats, _ = closed_loop_vertices(n, params=params, gains=g, arm=arm, integral=integral)
        if test == "vertex":
            return vertex_stability(mats)[0]
        return common_lyapunov(mats).status == "feasible"

    lo, hi = 0.0, max_sigma(params) * (1.0 - 1e-9)
    if math.isinf(hi):  # no spread in c or d: every n gives the nominal motors
        return math.inf if passes(lo) else 0.0
    if test == "lyapunov":  # a common P needs stable vertices: start below the vertex edge
        hi = min(hi, largest_sigma(test="vertex", params=params, gains=g, arm=arm,
                                   integral=integral, tol=step) + step)
    if not passes(lo):
        return 0.0
    if passes(hi):
        return hi
    while hi - lo > step:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if passes(mid) else (lo, mid)
    return lo


def robust_summary(n_sigma: float, *, params: ARDrone2Params = ARDRONE2,
                   arm: float | None = None, tilt_deg: float = 0.0) -> dict:
    """JSON-ready robustness figures for ``visloc robust --sigma N --json``.

    Parameters
    ----------
    n_sigma : float
        Box half-width in standard deviations (>= 0).
    params : ARDrone2Params
        Vehicle parameters.
    arm : float, optional
        Arm distance of eq. (2.12), m (see :func:`visloc.control.resolve_arm`).
    tilt_deg : float
        0: the report's check at hover. Else the tracking loop's: the vertices at hover and
        linearised in steady sideways accelerations at +- this roll (degrees, below 45; a
        trajectory's tilt, :func:`visloc.control.trajectory.model_limits`), 768 matrices,
        with one Lyapunov matrix common to all of them.

    Returns
    -------
    dict
        ``vertices`` (int), ``vertex_stable`` (bool), ``max_real_eig`` (float, 1/s),
        ``lyapunov`` (``"feasible"`` / ``"infeasible"`` / ``"unavailable"``), plus
        ``n_sigma``, ``tilt_deg``, ``arm_m`` and ``states`` (16: the 12 pilot-frame states
        and 4 integrals) for the record.

    Raises
    ------
    ValueError
        ``n_sigma`` negative, not finite or not below :func:`max_sigma`; ``arm`` not > 0.
    TypeError
        ``params`` is not an :class:`ARDrone2Params`; ``n_sigma`` or ``arm`` not a real number.
    """
    p = check_params(params)
    d_arm = resolve_arm(p, arm)
    tilt = check_real(tilt_deg, "tilt_deg", nonneg=True)
    if tilt >= 45.0:
        raise ValueError(f"tilt_deg must be below 45 degrees, got {tilt}")
    rolls = (0.0,) if tilt == 0.0 else (0.0, math.radians(tilt), -math.radians(tilt))
    mats = np.concatenate([closed_loop_vertices(n_sigma, params=p, arm=d_arm, roll=r)[0] for r in rolls])
    stable, worst_eig, _ = vertex_stability(mats)
    return {"n_sigma": float(n_sigma), "tilt_deg": tilt, "vertices": len(mats), "vertex_stable": stable,
            "max_real_eig": worst_eig, "lyapunov": common_lyapunov(mats).status, "arm_m": d_arm, "states": 16}


def _as_stack(matrices: FloatArray) -> FloatArray:
    try:
        m = np.asarray(matrices, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"matrices: expected real numbers, got {type(matrices).__name__}") from exc
    if m.ndim != 3 or m.shape[1] != m.shape[2] or m.shape[0] == 0 or m.shape[1] == 0:
        raise ValueError(f"matrices: expected shape (N, n, n) with N, n >= 1, got {m.shape}")
    if not np.all(np.isfinite(m)):
        raise ValueError("matrices: expected finite values")
    return m
