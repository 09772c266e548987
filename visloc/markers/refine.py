"""Stage 8 of the marker pipeline: sub-pixel edge refinement on the grey image.

The binary contour only locates an edge to about half a pixel and depends on the threshold.
Here each side of a quadrilateral is re-fitted on the grey levels: along normals sampled
across the side, the edge position is found from the *area* of the intensity step,

    e = R + 1/2 - sum_s v(s),      v = (I - black) / (white - black),  s = -R .. R,

which is exact for an ideal step integrated over pixels and stays unbiased under any
symmetric blur once the window is centred on the edge (the refinement iterates to centre it).
Blur mixes *light*, so the step is measured in linear intensity: grey levels are read through
the camera's response (:mod:`visloc.markers.response`; sRGB by default, as cameras write
8-bit images), which removes a bias of a fraction of the blur width on every side.
A total-least-squares line through the edge points of each side, with outliers dropped, gives
the side; the corners are the intersections of consecutive sides. Quads are refined in
batches (one OpenCV remap per pass for all markers of a frame).

The same steps compiled (``visloc.markers._refine``, built with the package) run one quad
after another and interpolate the grey levels in double precision instead of through
``cv2.remap`` (whose coordinates are rounded to 1/32 px and values to whole grey levels);
without the compiled module the numpy version here runs.
"""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc._compiled import use_compiled
from visloc.markers.corners import _NEXT, fit_lines, quad_from_lines
from visloc.markers.response import response_lut

try:
    from visloc.markers import _refine
except ImportError:  # installed without a C compiler: the numpy version below
    _refine = None

#: Whether :func:`refine_quads` runs the compiled stage 8.
NATIVE_REFINE = _refine is not None

_END_GAP = 0.15  # fraction of each side left out at both ends (sample_edge_profiles)
#: widest profile half-width stage 8 accepts (px): the work grows with it, and no marker edge
#: is blurred over more
_MAX_RADIUS = 64
_LEVELS = np.arange(256, dtype=np.float64)
_BEND_MIN_SIDE = 40.0  # px: markers with shorter sides keep them straight (as _refine.c)
#: a quad is noisy, and stage 8b then reads only the central 2 noisy_bend_radius + 1 samples of each
#: profile, when the noise of its innermost or outermost samples (as _side_levels measures it) is
#: at least this fraction of its contrast (as _refine.c's NOISY): on camera-like 640 x 480 frames
#: 0.18-0.35 on dark ones (10th-90th percentile), under 0.05 on hard ones, 0 without noise
_NOISY = 0.1
_LEVEL_Z = 3.0  # standard errors for a side's own levels (_side_levels, as _refine.c)
#: passes beyond ``iterations`` go on only while every pass shrank a quad's largest corner
#: move by this factor (one that did not, or failed, is not taken): blur wider than the
#: profiles shrinks the moves by about 0.6-0.7 per pass; noise (dark frames) moves the sides
#: about as much each pass, and a side that walks along a shadow keeps moving (as _refine.c)
_SHRINK = 0.8

__all__ = ["NATIVE_REFINE", "bend_corners", "edge_contrast", "edge_offsets", "edge_points", "refine_quads",
           "sample_edge_profiles"]


def _to_light(gray: NDArray[np.uint8], response: str | float | NDArray) -> NDArray:
    """``gray`` in linear intensity through the response (float32; ``gray`` itself when linear)."""
    if isinstance(response, str) and response == "linear":
        return gray
    return cv2.LUT(gray, response_lut(response).astype(np.float32))


@lru_cache(maxsize=32)
def _profile_grid(count: int, end_gap: float, radius: int) -> tuple[NDArray[np.float32], NDArray[np.float64]]:
    """Coefficients of the profile samples (read-only, cached): ``(3, count * S)`` rows 1, t,
    s for the sample at fraction t along a side and offset s along its normal (S = 2 radius
    + 1), and ``(2, count)`` rows 1, t for the profile centres."""
    t = np.linspace(end_gap, 1 - end_gap, count)
    s = np.arange(-radius, radius + 1, dtype=np.float64)
    samples = np.stack([np.ones((count, len(s))), np.repeat(t[:, None], len(s), axis=1),
                        np.repeat(s[None, :], count, axis=0)]).reshape(3, -1).astype(np.float32)
    centres = np.stack([np.ones(count), t])
    samples.setflags(write=False)
    centres.setflags(write=False)
    return samples, centres


def _check_edge_inputs(gray: NDArray, q: NDArray) -> None:
    """Raise unless ``gray`` is a non-empty (H, W) image and every corner of ``q`` is finite
    (OpenCV's remap of an empty image, or an empty crop of it, reads memory it does not own)."""
    if not isinstance(gray, np.ndarray) or gray.ndim != 2 or not gray.size:
        raise ValueError(f"gray must be a non-empty (H, W) image, got shape {getattr(gray, 'shape', None)}")
    if not np.isfinite(q).all():
        raise ValueError("quads: every corner must be finite")


def sample_edge_profiles(
    gray: NDArray, quads: NDArray, radius: int, *, count: int = 24, end_gap: float = 0.15
) -> tuple[NDArray, NDArray, NDArray]:
    """Sample grey levels along normals across the four sides of each quad.

    Parameters
    ----------
    gray : ndarray (H, W) uint8 or float32
        Grey image (or linear intensity, as stage 8 samples it).
    quads : ndarray (K, 4, 2) or (4, 2)
        Corners ``(x, y)``, px (pixel centres at integer coordinates), clockwise in the
        image; side ``s`` runs from corner ``s`` to corner ``s + 1``.
    radius : int
        Samples at offsets ``-radius .. radius`` px along the outward normal, 1 px apart.
    count : int
        Profiles per side (M), evenly spaced.
    end_gap : float
        Fraction of each side left out at both ends (near corners profiles cross two edges).

    Returns
    -------
    base : ndarray (K, 4, M, 2) float64
        Profile centres ``(x, y)`` on each side, px.
    normals : ndarray (K, 4, 2) float64
        Outward unit normals of the sides (image axes, y down).
    profiles : ndarray (K, 4, M, 2 * radius + 1) float32
        Bilinearly interpolated values of ``gray`` (the image's edge pixels repeated beyond
        it), inside (dark) first.

    Raises
    ------
    ValueError
        If ``gray`` is not a non-empty (H, W) image or a corner is not finite.
    """
    q = np.asarray(quads, np.float64).reshape(-1, 4, 2)
    _check_edge_inputs(gray, q)
    k = len(q)
    d = q[:, _NEXT] - q
    u = d / np.maximum(np.hypot(d[..., 0], d[..., 1]), 1e-9)[..., None]
    normals = np.stack([u[..., 1], -u[..., 0]], axis=-1)  # clockwise quad, y down: outward
    samples, centres = _profile_grid(count, end_gap, radius)
    # every sample is corner + t * side + s * normal: one product per side gives all of them
    frame = np.stack([q, d, normals], axis=-1).reshape(k * 4, 2, 3)
    xy = frame.astype(np.float32) @ samples  # (K * 4, 2, count * S)
    width = 2 * radius + 1
    prof = cv2.remap(gray, xy[:, 0].reshape(-1, width), xy[:, 1].reshape(-1, width), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)
    base = np.swapaxes(frame[:, :, :2] @ centres, 1, 2).reshape(k, 4, count, 2)
    return base, normals, prof.astype(np.float32).reshape(k, 4, count, -1)


def edge_contrast(gray: NDArray, quads: NDArray, *, count: int = 32) -> NDArray[np.float64]:
    """How well each quad's sides sit on dark-to-bright edges: the mean grey level 1-2 px
    outside the sides less the mean 1-2 px inside, along ``count`` normals per side over
    the middle 80 % of each side (:func:`sample_edge_profiles` with radius 2).

    A side a few pixels off its edge has both of its sample rows on the same side of the
    edge along part of it, so the difference falls; the detector keeps, of two refinements
    of one marker, the one with the larger (stage 8's wide first refinement,
    :class:`~visloc.markers.DetectorParams` ``coarse_scale``).

    Parameters
    ----------
    gray : ndarray (H, W) uint8 or float32
        Grey image (dark markers on a bright surround).
    quads : ndarray (K, 4, 2) or (4, 2)
        Corners ``(x, y)``, px, clockwise in the image.
    count : int
        Normals per side (>= 1).

    Returns
    -------
    ndarray (K,) float64
        Outside minus inside, grey levels (negative where the sides are inside out).

    Raises
    ------
    ValueError
        If ``gray`` is not a non-empty (H, W) image, a corner is not finite or ``count`` < 1.
    """
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise ValueError(f"count must be an integer >= 1, got {count!r}")
    prof = sample_edge_profiles(gray, quads, 2, count=int(count), end_gap=0.1)[2]  # offsets -2 .. 2, inside first
    k = len(prof)
    return (prof[..., 3:].reshape(k, -1).mean(axis=1, dtype=np.float64)
            - prof[..., :2].reshape(k, -1).mean(axis=1, dtype=np.float64))


def edge_offsets(profiles: NDArray, black: NDArray | float, white: NDArray | float) -> NDArray[np.float64]:
    """Edge position along each profile from the area of the normalised step (module docstring).

    Parameters
    ----------
    profiles : ndarray (..., 2R + 1)
        Intensities sampled 1 px apart across an edge, inside (dark) first, centred on the
        assumed edge (:func:`sample_edge_profiles`), in linear intensity.
    black, white : float or ndarray
        Levels of the dark inside and the bright outside, in the units of ``profiles``;
        they broadcast against ``profiles.shape[:-1]``.

    Returns
    -------
    ndarray (...) float64
        The edge's offset from each profile's centre, px, positive outward.
    """
    radius = (profiles.shape[-1] - 1) // 2
    span = np.maximum(np.asarray(white) - np.asarray(black), 1e-6)
    v = np.clip((profiles - np.asarray(black)[..., None]) / span[..., None], 0.0, 1.0)
    return radius + 0.5 - v.sum(axis=-1)


def _step_offsets(prof: NDArray, r: NDArray, big: int, long_sides: NDArray,
                  force: bool = False) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """The edge on each profile (K, 4, M, 2 big + 1) of quads with profile half-widths ``r``
    (K,), from the area of the normalised step (module docstring), as offsets (K, 4, M) from
    the profile centres; which profiles crossed a clean step (occlusion or a neighbouring
    edge makes outliers); and each quad's black and white levels (K,): the medians (upper
    middle) of its innermost and outermost samples. The steps of quads with ``long_sides``
    (K,) are normalised by levels that follow the light along each side (:func:`_side_levels`):
    across a large quad the light varies (vignetting, shading), and one pair of levels for the
    whole quad moved the edges of 100 px squares under 25 % vignetting by about 0.1 px (the
    area of the step counts a level error once per sample); the others' by the quad's levels
    (a small quad's side has too few samples for its own). ``prof`` is normalised in place."""
    k, m = len(prof), prof.shape[2]
    kk = np.arange(k)
    half = 2 * m  # of the 4 m inner (outer) end samples of each quad
    p_in = prof[kk, :, :, big - r]  # (K, 4, M): copies, read before the normalisation
    p_out = prof[kk, :, :, big + r]
    lo = np.partition(p_in.reshape(k, -1), half, axis=1)[:, half]
    hi = np.partition(p_out.reshape(k, -1), half, axis=1)[:, half]
    lo_s = np.broadcast_to(lo[:, None, None], p_in.shape).copy()  # (K, 4, M): the quad's levels,
    hi_s = np.broadcast_to(hi[:, None, None], p_out.shape).copy()
    if long_sides.any():  # each side's own on the large quads
        lo_s[long_sides] = _side_levels(p_in[long_sides], lo[long_sides], force)
        hi_s[long_sides] = _side_levels(p_out[long_sides], hi[long_sides], force)
    prof -= lo_s[..., None]  # (I - black) / (white - black), clipped to [0, 1]
    prof /= np.maximum(hi_s - lo_s, 1e-6)[..., None]
    np.clip(prof, 0.0, 1.0, out=prof)
    inside = (np.abs(np.arange(-big, big + 1))[None, :] <= r[:, None]).astype(np.float32)[:, None, None, :]
    r3 = r[:, None, None].astype(np.float64)
    e = r3 + 0.5 - np.vecdot(prof, inside)
    good = ((p_out - p_in) > 0.5 * (hi_s - lo_s)) & (np.abs(e) < r3)
    return e, good, lo, hi


def _longest_sides(q: NDArray) -> NDArray:
    """Each quad's (K, 4, 2) longest side, px."""
    return np.sqrt(((q[:, _NEXT] - q) ** 2).sum(axis=-1)).max(axis=1)


def _noise(ends: NDArray) -> NDArray:
    """Each quad's noise (K,) in its end samples ``ends`` (K, 4, M): neighbouring profiles'
    samples differ by it (times sqrt 2), not by a smooth change of the light, so 1.4826 /
    sqrt 2 times the median (upper middle) of those differences (``_refine.c``'s noise_of)."""
    steps = np.abs(np.diff(ends, axis=-1)).reshape(len(ends), -1)
    half = steps.shape[1] // 2
    return 1.4826 / np.sqrt(2.0) * np.partition(steps, half, axis=1)[:, half]


def _side_levels(ends: NDArray, quad: NDArray, force: bool = False) -> NDArray:
    """Each side's level (black from the innermost samples, white from the outermost) at each
    of its M profiles (K, 4, M), from the end samples ``ends`` (K, 4, M) and the quad's level
    ``quad`` (K,): the line along the side through the medians (upper middle) of its first and
    second half, each at its half's middle, where their difference is significant (over
    :data:`_LEVEL_Z` standard errors of a difference of medians, from the quad's noise:
    the light varies along the side), else the side's median where it differs significantly
    from the quad's level, else the quad's level (as ``_refine.c``); with ``force`` the line
    always."""
    m = ends.shape[2]
    out = np.broadcast_to(quad[:, None, None], ends.shape).copy()
    h1, h2 = m // 2, m - m // 2
    if h1 < 2:
        return out
    sd = _noise(ends)  # (K,)
    m1 = np.partition(ends[..., :h1], h1 // 2, axis=-1)[..., h1 // 2]  # (K, 4)
    m2 = np.partition(ends[..., h1:], h2 // 2, axis=-1)[..., h2 // 2]
    side = np.partition(ends, m // 2, axis=-1)[..., m // 2]
    c1, c2 = 0.5 * (h1 - 1), h1 + 0.5 * (h2 - 1)
    sloped = (np.abs(m2 - m1) > _LEVEL_Z * 1.2533 * sd[:, None] * np.sqrt(2.0 / h1)) | force
    shifted = ~sloped & (np.abs(side - quad[:, None]) > _LEVEL_Z * 1.2533 * sd[:, None] / np.sqrt(m))
    line = m1[..., None] + (m2 - m1)[..., None] * ((np.arange(m) - c1) / (c2 - c1))
    out[sloped] = line[sloped]
    out[shifted] = side[shifted][:, None]
    return out


def refine_quads(
    gray: NDArray[np.uint8], quads: NDArray, *, radius: int | NDArray = 2, iterations: int = 2,
    max_iterations: int | None = None, tolerance: float = 0.05, count: int = 24,
    response: str | float | NDArray = "srgb", bend: bool = False, bend_radius: int | None = None,
    noisy_bend_radius: int | None = None, levels: str = "auto", native: bool | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Refine the corners of dark squares on a bright surround to sub-pixel accuracy.

    Parameters
    ----------
    gray : ndarray (H, W) uint8
        The grey image (not the binary one).
    quads : ndarray (K, 4, 2) or (4, 2)
        Initial corners ``(x, y)``, px (pixel centres at integer coordinates), clockwise in
        the image, within about ``radius`` px of the truth.
    radius : int or ndarray (K,) of int
        Half-width of the sampled profiles, px, for all quads or per quad. It should not
        exceed the marker's cell size (beyond it the interior bits start) nor its margin.
    iterations : int
        Passes; each re-centres the profiles on the previous pass's lines.
    max_iterations : int or None
        After ``iterations`` passes, more passes (up to this many in all) for the quads whose
        corners still moved more than ``tolerance``, while each pass shrinks their largest
        corner move by a fifth (blur wider than the profiles; :data:`_SHRINK`); a pass that
        did not is not taken. ``None``: exactly ``iterations``.
    tolerance : float
        Largest corner move (px) of a converged pass.
    count : int
        Profiles per side.
    response : {"srgb", "linear"}, float or ndarray (256,)
        How grey levels encode light (:func:`visloc.markers.response.response_lut`): the
        edges are measured in linear intensity. ``"srgb"`` suits camera images and most
        files, ``"linear"`` linear sensor data and linear renders.
    bend : bool
        Stage 8b (:func:`bend_corners`) on the refined quads with a side of 40 px or more.
    bend_radius : int or None
        Stage 8b's profile half-width at most, px (1-64; a quad's ``radius`` where smaller);
        None: ``radius``. The detector uses 3 (:class:`~visloc.markers.DetectorParams`).
    noisy_bend_radius : int or None
        Stage 8b's half-width on a noisy quad, px (1-64, where smaller than the above): one
        whose innermost or outermost samples' noise is a tenth of its contrast or more
        (:data:`_NOISY`; a narrower window sums less noise at the cost of a small bias).
        None: no narrowing. The detector uses 2.
    levels : {"auto", "side"}
        The black and white levels of a quad with a side of 40 px or more: ``"auto"`` each
        side's own where the light varies significantly along or across it, else the quad's;
        ``"side"`` each side's own always (large plain squares, as a ChArUco board's).
    native : bool or None
        Run the compiled version (``True``) or the numpy one (``False``); ``None``: the
        compiled one when it was built (:data:`NATIVE_REFINE`).

    Returns
    -------
    corners : ndarray (K, 4, 2) float64
        Refined corners ``(x, y)``, px, in the same order (the input where refinement failed).
    ok : ndarray (K,) bool
        False where a side had too little contrast (4 grey levels) or too few clean profiles.

    Raises
    ------
    ValueError
        If ``gray`` is not a (H, W) uint8 image, a radius is outside 1-64 px, a corner is not
        finite, ``count < 2``, ``iterations < 1``, ``max_iterations`` above 100 or
        ``tolerance < 0``, or ``response`` is not a valid response
        (:func:`~visloc.markers.response.response_lut`).
    RuntimeError
        If ``native=True`` and the compiled module was not built.
    """
    q0, r, lut, most, cap, narrow = _checked_args(gray, quads, radius, iterations, max_iterations, tolerance,
                                                  count, response, levels, bend_radius, noisy_bend_radius)
    if not len(q0):
        return q0.copy(), np.ones(0, bool)
    if use_compiled(native, _refine, "visloc.markers._refine"):
        return _refine_compiled(gray, q0, r, iterations, count, lut, bend, levels == "side", most, tolerance, cap,
                                narrow)
    q, ok_all = _refine_passes(_to_light(gray, response), q0, r, iterations, most, tolerance, count, lut,
                               levels == "side")
    if bend:
        _bend_long(gray, q, ok_all, r, cap, narrow, response, levels)
    return q, ok_all


def _bend_long(gray: NDArray[np.uint8], q: NDArray, ok: NDArray, r: NDArray, cap: int, narrow: int,
               response: str | float | NDArray, levels: str) -> None:
    """Stage 8b in place on the refined quads (K, 4, 2) that stood and have a side of 40 px
    or more (short sides bend by a small fraction of a pixel), as ``_refine.c`` does."""
    pick = ok & (_longest_sides(q) >= _BEND_MIN_SIDE)
    if pick.any():
        radius = _narrowed(gray, q[pick], np.minimum(r[pick], cap), narrow, response)
        q[pick] = bend_corners(gray, q[pick], radius=radius, response=response, levels=levels)


def _checked_args(gray: NDArray, quads: NDArray, radius: int | NDArray, iterations: int, max_iterations: int | None,
                  tolerance: float, count: int, response: str | float | NDArray, levels: str,
                  bend_radius: int | None, noisy_bend_radius: int | None) -> tuple:
    """:func:`refine_quads`' inputs checked (ValueError naming the first bad one): the quads
    (K, 4, 2) float64, the radii (K,), the response's table, the most passes, stage 8b's
    widest half-width and its noisy half-width (0: none). No quads: the options unchecked."""
    if gray.ndim != 2 or gray.dtype != np.uint8:
        raise ValueError(f"gray must be a (H, W) uint8 image, got {gray.shape} {gray.dtype}")
    lut = response_lut(response)
    q0 = np.asarray(quads, np.float64).reshape(-1, 4, 2)
    r = np.broadcast_to(np.asarray(radius, np.int64), (len(q0),))
    if not len(q0):
        return q0, r, lut, 0, 0, 0
    if (r < 1).any() or (r > _MAX_RADIUS).any():
        raise ValueError(f"radius must be 1 to {_MAX_RADIUS} px, got {radius}")
    if not np.isfinite(q0).all():
        raise ValueError("quads: every corner must be finite")
    if count < 2 or iterations < 1:
        raise ValueError(f"count must be >= 2 and iterations >= 1, got {count} and {iterations}")
    most = iterations if max_iterations is None else max(int(max_iterations), iterations)
    if most > 100 or not tolerance >= 0:
        raise ValueError(f"max_iterations must be at most 100 and tolerance >= 0, got {max_iterations} and {tolerance}")
    if levels not in ("auto", "side"):
        raise ValueError(f"levels must be 'auto' or 'side', got {levels!r}")
    cap = _optional_radius(bend_radius, "bend_radius") or _MAX_RADIUS
    return q0, r, lut, most, cap, _optional_radius(noisy_bend_radius, "noisy_bend_radius")


def _refine_compiled(gray: NDArray[np.uint8], q0: NDArray, r: NDArray, iterations: int, count: int, lut: NDArray,
                     bend: bool, side_levels: bool, most: int, tolerance: float, cap: int,
                     narrow: int) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """:func:`refine_quads` in ``_refine.c`` (stage 8, and 8b when ``bend``): corners and ok."""
    g = np.ascontiguousarray(gray)
    raw, raw_ok = _refine.refine_quads(g, g.shape[0], g.shape[1], np.ascontiguousarray(q0),
                                       np.ascontiguousarray(r, np.int64), int(iterations), int(count), _END_GAP,
                                       lut, bool(bend), side_levels, most, float(tolerance), cap, narrow)
    return np.frombuffer(raw, np.float64).reshape(-1, 4, 2).copy(), np.frombuffer(raw_ok, np.uint8).astype(bool)


def _refine_passes(light: NDArray, q0: NDArray, r: NDArray, iterations: int, most: int, tolerance: float,
                   count: int, lut: NDArray, side_levels: bool) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Stage 8's passes in numpy over quads (K, 4, 2) on the linear-light image: the corners
    (the input where a first pass failed) and whether each quad stands. Under blur wider
    than the profiles each pass moves a side part of the way (camera-like 640 x 480 renders
    with strong blur: about 0.3 px RMS after 2 passes, 0.2 after up to 6)."""
    q = q0.copy()
    k = len(q)
    ok_all = np.ones(k, bool)
    busy = np.arange(k)  # the quads still refined: not failed, not converged
    last_move = np.full(k, np.inf)
    converging = np.ones(k, bool)  # every pass so far shrank the quad's largest corner move
    for it in range(most):
        last = it >= iterations - 1
        before = q[busy]
        new, ok = _refine_pass(light, before, r[busy], count, lut, last, side_levels)
        move = np.abs(new - before).max(axis=(1, 2))
        shrank = move <= _SHRINK * last_move[busy]
        take = ok & ((it < iterations) | shrank)  # a later pass that did not shrink the move is not taken
        if it < iterations:  # the first passes must stand; a later one that fails is not taken
            ok_all[busy[~ok]] = False
        q[busy[take]] = new[take]
        converging[busy] &= shrank
        last_move[busy] = move
        busy = busy[take & ~(last & ((move <= tolerance) | ~converging[busy]))]  # failed: not taken, stop
        if not len(busy):
            break
    q[~ok_all] = q0[~ok_all]
    return q, ok_all


def _optional_radius(value: int | None, name: str) -> int:
    """``value`` as an int (0 for None), having checked it is None or a whole number of px in 1-64."""
    if value is None:
        return 0
    if isinstance(value, bool) or int(value) != value or not 1 <= value <= _MAX_RADIUS:
        raise ValueError(f"{name} must be None or 1 to {_MAX_RADIUS} px, got {value!r}")
    return int(value)


def _narrowed(gray: NDArray[np.uint8], q: NDArray, r: NDArray, narrow: int, response: str | float | NDArray,
              count: int = 40, end_gap: float = 0.08) -> NDArray:
    """Stage 8b's half-widths (K,) for quads (K, 4, 2) read at half-widths ``r``: ``narrow``
    where it is smaller and the quad is noisy (:data:`_NOISY`: the noise of its innermost or
    outermost samples, 1.4826 / sqrt 2 times the upper-middle median of neighbouring profiles'
    differences along each side, over its contrast, the difference of those samples'
    upper-middle medians), as ``_refine.c``'s bend_one."""
    out = np.array(r, np.int64)
    wider = np.flatnonzero(out > narrow) if narrow > 0 else np.zeros(0, np.int64)
    if not len(wider):
        return out
    light = _to_light(gray, response)
    mid = 2 * count
    for rv in np.unique(out[wider]).tolist():
        idx = wider[out[wider] == rv]
        k = len(idx)
        p = sample_edge_profiles(light, q[idx], rv, count=count, end_gap=end_gap)[2]  # (k, 4, count, 2 rv + 1)
        ends = (p[..., 0], p[..., -1])
        lo, hi = (np.partition(e.reshape(k, -1), mid, axis=1)[:, mid] for e in ends)
        noisy = np.maximum(_noise(ends[0]), _noise(ends[1])) >= _NOISY * (hi - lo)
        out[idx[noisy]] = narrow
    return out


def _refine_pass(light: NDArray, q: NDArray, r: NDArray, count: int, lut: NDArray, drop_outliers: bool,
                 side_levels: bool) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """One stage-8 pass over quads (K, 4, 2) on the linear-light image: the corners of the
    sides fitted to the edge points of profiles centred on the quads' sides, and whether each
    quad stands (contrast of 4 grey levels, 3 clean profiles per side, a move of at most
    2 r + 1 px). ``drop_outliers``: fit each side again without the first fit's outliers."""
    k = len(q)
    big = int(r.max())
    base, normals, prof = sample_edge_profiles(light, q, big, count=count, end_gap=_END_GAP)
    e, good, lo, hi = _step_offsets(prof, r, big, _longest_sides(q) >= _BEND_MIN_SIDE, side_levels)
    pts = (base + e[..., None] * normals[:, :, None, :]).reshape(k * 4, count, 2)
    w = good.reshape(k * 4, count).astype(np.float64)
    lines = fit_lines(pts, w)
    if drop_outliers:
        res = np.abs(pts[..., 0] * lines[:, 0:1] + pts[..., 1] * lines[:, 1:2] - lines[:, 2:3])
        rms = np.sqrt((w * res * res).sum(axis=1) / np.maximum(w.sum(axis=1), 1))
        w2 = w * (res < 2.5 * rms[:, None] + 0.05)
        lines = fit_lines(pts, np.where(w2.sum(axis=1, keepdims=True) >= 3, w2, w))
    lines = lines.reshape(k, 4, 3)
    flip = (lines[..., :2] * normals).sum(axis=-1) < 0
    lines[flip] *= -1
    new = quad_from_lines(lines)
    move = np.abs(new - q).max(axis=(1, 2))  # NaN where two sides came out parallel
    grey_span = np.interp(hi, lut, _LEVELS) - np.interp(lo, lut, _LEVELS)  # contrast in grey levels
    ok = (grey_span >= 4.0) & (w.reshape(k, 4, count).sum(axis=2) >= 3).all(axis=1)
    ok &= move <= 2.0 * r + 1  # False for NaN too
    return new, ok


def edge_points(
    gray: NDArray[np.uint8],
    quads: NDArray,
    *,
    radius: int | NDArray,
    count: int = 24,
    end_gap: float = _END_GAP,
    response: str | float | NDArray = "srgb",
    levels: str = "auto",
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """The edge along ``count`` normals across each side of refined quads, located as stage 8
    locates it (the area of the step in linear light, each side read by its own levels where
    they differ from its quad's: ``_side_levels``, as for the large quads of stage 8).

    Parameters
    ----------
    gray : ndarray (H, W) uint8
        The grey image.
    quads : ndarray (K, 4, 2) or (4, 2)
        Corners ``(x, y)``, px, clockwise (side ``s`` from corner ``s`` to ``s + 1``), K >= 1.
    radius : int or ndarray (K,) of int
        Profile half-width, px (as in :func:`refine_quads`).
    count : int
        Profiles per side (M), at fractions ``end_gap .. 1 - end_gap`` along it.
    end_gap : float
        Fraction of each side left out at both ends.
    response, levels
        As in :func:`refine_quads`.

    Returns
    -------
    points : ndarray (K, 4, M, 2) float64
        The edge points ``(x, y)``, px.
    normals : ndarray (K, 4, 2) float64
        The sides' outward unit normals.
    offsets : ndarray (K, 4, M) float64
        Each point's offset from the straight side along its normal, px.
    good : ndarray (K, 4, M) bool
        The profiles that crossed a clean step.

    Raises
    ------
    ValueError
        If ``gray`` is not a non-empty (H, W) image, a corner is not finite, or no quad
        reaches the image.
    """
    q = np.asarray(quads, np.float64).reshape(-1, 4, 2)
    _check_edge_inputs(gray, q)
    r = np.broadcast_to(np.asarray(radius, np.int64), (len(q),))
    big = int(r.max())
    # only the part of the image around the quads, in linear light (clipped as floats: no
    # integer overflow for corners far off)
    h, w_img = gray.shape
    x0, y0 = np.clip(np.floor(q.reshape(-1, 2).min(axis=0)) - big - 2, 0, [w_img, h]).astype(int)
    x1, y1 = np.clip(np.ceil(q.reshape(-1, 2).max(axis=0)) + big + 3, 0, [w_img, h]).astype(int)
    if x1 <= x0 or y1 <= y0:
        raise ValueError(f"quads: none reaches the {w_img} x {h} image")
    light = _to_light(gray[y0:y1, x0:x1], response)
    base, normals, prof = sample_edge_profiles(light, q - [x0, y0], big, count=count, end_gap=end_gap)
    e, good, _, _ = _step_offsets(prof, r, big, np.ones(len(prof), bool), levels == "side")  # offsets, px
    points = base + [x0, y0] + e[..., None] * normals[:, :, None, :]
    return points, normals, e, good


def bend_corners(
    gray: NDArray[np.uint8], quads: NDArray, *, radius: int | NDArray = 2, count: int = 40, end_gap: float = 0.08,
    response: str | float | NDArray = "srgb", levels: str = "auto",
) -> NDArray[np.float64]:
    """Stage 8b: corners where the marker's sides are curves, not lines.

    A camera's lens distortion bends a marker's straight sides; lines fitted to them meet
    off the true corners (0.4-0.5 px RMS at 640 x 480 with a webcam's barrel distortion).
    Along ``count`` normals across each side of the refined ``quads`` the edge is located as
    in :func:`refine_quads`; its offset from the straight side is fitted as a quadratic in
    the position along the side (weighted least squares, outliers of a first fit dropped;
    a side whose curvature is within 3 standard errors of 0 stays a line), and each corner
    is where the two neighbouring curves' tangents at their ends meet.

    Parameters
    ----------
    gray : ndarray (H, W) uint8
        The grey image.
    quads : ndarray (K, 4, 2) or (4, 2)
        Corners ``(x, y)``, px (pixel centres at integer coordinates), from
        :func:`refine_quads`, clockwise.
    radius : int or ndarray (K,) of int
        Profile half-width, px (as in :func:`refine_quads`).
    count : int
        Profiles per side.
    end_gap : float
        Fraction of each side left out at both ends.
    response : {"srgb", "linear"}, float or ndarray (256,)
        As in :func:`refine_quads`.
    levels : {"auto", "side"}
        As in :func:`refine_quads`.

    Returns
    -------
    ndarray (K, 4, 2) float64
        The corners ``(x, y)``, px; a quad whose curves do not meet near its corners keeps
        them.

    Raises
    ------
    ValueError
        If ``response`` is not a valid response (:func:`~visloc.markers.response.response_lut`),
        ``gray`` is not a non-empty (H, W) image or a corner is not finite.
    """
    q = np.asarray(quads, np.float64).reshape(-1, 4, 2)
    k = len(q)
    if k == 0:
        return q.copy()
    _check_edge_inputs(gray, q)
    h, w_img = gray.shape
    if not ((q[..., 0].max(axis=1) > -1.0) & (q[..., 0].min(axis=1) < w_img)
            & (q[..., 1].max(axis=1) > -1.0) & (q[..., 1].min(axis=1) < h)).any():
        return q.copy()  # no quad reaches the image: nothing to bend
    _, normals, e, good = edge_points(gray, q, radius=radius, count=count, end_gap=end_gap, response=response,
                                      levels=levels)
    r = np.broadcast_to(np.asarray(radius, np.int64), (k,))
    coef, w = _side_curves(e, good, end_gap)
    out = _tangent_corners(q, normals, coef)
    enough = (w.sum(axis=2) >= 6).all(axis=1)
    ok = enough & np.isfinite(out).all(axis=(1, 2)) & (np.abs(out - q).max(axis=(1, 2)) < 1.0 + r)
    return np.where(ok[:, None, None], out, q)


def _side_curves(e: NDArray, good: NDArray, end_gap: float) -> tuple[NDArray, NDArray]:
    """Quadratics ``c0 + c1 t + c2 t^2`` (K, 4, 3) fitted by weighted least squares to the
    edge offsets ``e`` (K, 4, M), px, at ``t`` in ``end_gap .. 1 - end_gap`` along each side,
    outliers of a first fit dropped; a side whose curvature is within 3 standard errors of 0
    a line (``c2 = 0``). Also the weights (K, 4, M) of the second fit."""
    k, _, count = e.shape
    w = good.astype(np.float64)
    t = np.linspace(end_gap, 1 - end_gap, count)
    basis = np.stack([np.ones(count), t, t * t], axis=-1)  # (M, 3)
    coef = np.zeros((k, 4, 3))
    for last in (False, True):  # fit, then refit without the first fit's outliers
        gram = np.einsum("ksm,mi,mj->ksij", w, basis, basis) + 1e-9 * np.eye(3)
        coef = np.linalg.solve(gram, np.einsum("ksm,mi,ksm->ksi", w, basis, e)[..., None])[..., 0]
        res = np.abs(e - coef @ basis.T)
        n_used = np.maximum(w.sum(axis=2), 4)
        rms = np.sqrt((w * res * res).sum(axis=2) / (n_used - 3))
        if not last:
            w = w * (res < 2.5 * rms[..., None] + 0.05)
    # a side stays straight unless its curvature stands out of the noise (3 standard errors):
    # a quadratic fitted to a straight, noisy edge only adds noise to the corners
    c_std = rms * np.sqrt(np.linalg.inv(gram)[..., 2, 2])
    straight = np.abs(coef[..., 2]) < 3.0 * c_std
    if straight.any():
        g2 = gram[..., :2, :2][straight]
        rhs = np.einsum("nm,mi,nm->ni", w[straight], basis[:, :2], e[straight])
        coef[straight] = np.concatenate([np.linalg.solve(g2, rhs[..., None])[..., 0],
                                         np.zeros((int(straight.sum()), 1))], axis=1)
    return coef, w


def _tangent_corners(q: NDArray, normals: NDArray, coef: NDArray) -> NDArray:
    """Each corner (K, 4, 2) of quads ``q`` where the tangents of its two sides' curves
    (``coef`` (K, 4, 3), offsets along the outward ``normals`` (K, 4, 2)) at their ends meet
    (the curves bend by a fraction of a pixel, so this is their meeting point to far below
    the noise); NaN where the tangents are parallel."""
    d = q[:, _NEXT] - q
    at_end = coef[..., 0] + coef[..., 1] + coef[..., 2]  # offset at t = 1, (K, 4)
    a = q[:, _NEXT] + at_end[..., None] * normals  # side s ends at corner s + 1 ...
    da = d + (coef[..., 1] + 2 * coef[..., 2])[..., None] * normals  # ... heading this way
    b = q + coef[..., 0, None] * normals  # side s starts at corner s ...
    db = d + coef[..., 1, None] * normals  # ... heading this way
    a, da = a[:, [3, 0, 1, 2]], da[:, [3, 0, 1, 2]]  # corner s: the end of side s - 1
    den = da[..., 0] * db[..., 1] - da[..., 1] * db[..., 0]
    den = np.where(np.abs(den) < 1e-9, np.nan, den)
    f = b - a
    u = (f[..., 0] * db[..., 1] - f[..., 1] * db[..., 0]) / den
    return a + u[..., None] * da
