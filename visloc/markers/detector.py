"""``MarkerDetector``: the report's staged square-marker detector (Appendix G, Figure G.1).

One frame's path:

1. grey; then, per search pass (an image scale and a threshold window; the passes after
   the first on a worker thread):
   2. Gaussian blur, 3. adaptive threshold, 4. outer contours of ink regions that enclose
   a hole, 5. candidate filter (4 and 5 in one compiled call);
   then, on the main thread once every pass is done: a cheap look at the cells of all passes'
   candidates (no black border, no contrast, or a white-bit count no marker has: dropped),
   and pass by pass, for the candidates no earlier pass proposed and fitted, 6. radial-peak
   corner split, 7. line fits -> candidate quads in full-resolution pixels;
8. sub-pixel edge refinement of all candidates on the full-resolution grey image (batched),
   8b. curved sides under lens distortion;
9. bit sampling with a per-marker threshold (each cell's bit the majority of its samples)
   and the black-border check (batched);
10. dictionary match in four orientations, corners rotated so corner 0 is the marker's own
    top-left; duplicates (one marker found twice) merged.

Several passes combine what one threshold window cannot do alone: a fine window at full
resolution closes the thin borders of small or oblique markers, a coarse window on a shrunk
image closes the borders of large, blurred ones, at a fraction of the cost. Stage 3b
(``erode``, off by default) runs stage 4 once more on the first pass's binary image with the
ink eroded, which separates markers whose border touches other ink at the corners (grid
boards). Stage 3c runs stage 3b (2 px) only when a found marker's corners touch other ink,
then stages 6-10 on what it adds: AprilGrid-style boards cost the second look, frames of
isolated markers a glance at their corners. In dark frames the pass on an image shrunk 4 times
thresholds with a lower offset.

White-on-black markers (``inverted=True``) are black-on-white markers of the inverted image;
stage 8 then reads the inverted grey levels through the matching response. ``"both"`` runs
the whole path twice, once per polarity.
"""

from __future__ import annotations

import math
import os
import statistics
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, fields, replace

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc._checks import marker_id
from visloc.markers.binarize import blur, default_window, threshold, to_gray
from visloc.markers.bits import (
    CellSample,
    cell_white_fractions,
    decode,
    read_bits,
    read_cells,
    sample_cells,
)
from visloc.markers.contours import CandidateFilter, find_candidates, outer_borders
from visloc.markers.corners import _NEXT, RadialSplit
from visloc.markers.corners_batch import fit_quads
from visloc.markers.dictionary import Dictionary, load_dictionary
from visloc.markers.refine import edge_contrast, refine_quads
from visloc.markers.response import response_lut
from visloc.types import MarkerDetection

_FOUR = np.arange(4)

__all__ = ["FAST_PASSES", "CandidateTrace", "DetectionTrace", "DetectorParams", "MarkerDetector", "PassTrace", "SearchPass"]


@dataclass(frozen=True, kw_only=True)
class SearchPass:
    """One candidate search (stages 2-7).

    Attributes
    ----------
    scale : float
        The image is shrunk by this factor (>= 1, times the base scale, see
        :class:`DetectorParams`) before blurring and thresholding.
    window : int or None
        Adaptive-threshold window in pixels of the shrunk image (odd, >= 3); ``None`` picks
        :func:`visloc.markers.binarize.default_window` of the shrunk image.
    offset : float or None
        Stage 3 threshold offset of this pass, grey levels; ``None``: the detector's ``offset``.
    """

    scale: float = 1.0
    window: int | None = None
    offset: float | None = None


#: Search passes trading recall on the smallest markers for speed: the fine pass on an image
#: shrunk 1.5 times, the coarse pass at 3 times (``MarkerDetector(d, passes=FAST_PASSES)``).
FAST_PASSES = (SearchPass(scale=1.5, window=9), SearchPass(scale=3.0, window=9))


@dataclass(frozen=True, kw_only=True)
class DetectorParams:
    """Parameters of :class:`MarkerDetector` (defaults chosen with ``bench/markers.py``).

    Attributes
    ----------
    passes : tuple of SearchPass
        Candidate searches, in order; a candidate an earlier pass proposed already is
        skipped. Their scales are relative to the base scale. The default's second pass, on
        the image shrunk 1.5 times with an 11 px window (16.5 px at full size), closes the
        borders that a 9 px window breaks on real photographs (soft, low-contrast prints, thin
        margins): 186 of 191 markers of the real photos against 183 with the half-size pass
        it replaced, at the same speed (the later passes run on the worker thread).
    dark_passes : tuple of SearchPass
        The searches of frames whose mean grey level is below ``dark_mean``. In a frame of
        mean grey below 30 the sRGB curve turns a little sensor noise into tens of grey levels
        on black, and the black border breaks up at the finer scales; the default's last
        passes, on the image shrunk 4 and 3 times, threshold with an offset of 4 instead of 7
        (on brighter frames that offset lets texture through as candidates, at a cost of about
        0.4 ms per 640 x 480 frame).
    dark_mean : float
        Mean grey level below which a frame is searched with ``dark_passes``.
    min_pass_size : int
        Search passes of ``passes`` (after the first) whose shrunk image would have a shorter
        side than this are skipped: on a 320 x 240 frame the pass on the image shrunk 4 times
        (60 px) found no marker of the bench's frames the others missed, and cost 0.4 ms.
        Dark frames keep every one of their ``dark_passes``.
    erode : int
        Stage 3b: stage 4 once more on the first pass's binary image with its ink eroded by a
        square this many pixels wide (0, the default: not). It cuts the thin necks where a
        marker's border touches other ink at its corners (grid boards such as AprilGrids,
        markers on patterned cards), so the marker's own outline closes again; stage 8
        restores the true edges. ``erode=2`` costs about 0.5 ms per 640 x 480 frame.
    board_retry : bool
        Stage 3c: when ``erode`` is 0 and a found marker's corners touch other ink (dark just
        outside at least two of its corners, light beyond its sides: a grid board such as an
        AprilGrid, where each tag touches the board's corner squares), stage 3b runs with a
        2 px square on the first pass's binary image, and stages 6-10 on the candidates it
        adds. Frames without such a marker pay only the look at the found markers' corners.
        Otherwise, in a frame of tightly packed small markers (two markers shorter than
        ``small_side`` whose margins together are under 0.3 of a marker), stage 3b runs
        within one marker side of the small markers that have another marker within three
        of their sides: on a tag sheet seen from afar a neighbour whose margin is a pixel or
        two merges with the dark around it (on a real photo of 25 tags, one more found).
        Marker grids printed with gaps of half a marker or more do not pay for the look.
    small_side : float
        Stage 3c's bound (full-resolution px, square root of the area) below which a found
        marker in a group has the eroded search run around it; 0: never.
    base_height : int
        Images whose short side exceeds this are searched at the base scale
        ``short side / base_height`` (stages 8-10 always use full resolution).
    blur_sigma : float
        Stage 2 Gaussian blur, px of the searched image.
    offset : float
        Stage 3 threshold offset, grey levels.
    candidates : CandidateFilter
        Stage 5 bounds.
    corner_sigma : float or None
        Stage 6 smoothing of the radial profile, contour points (``None``: N / 100).
    corner_padding : float
        Stage 6 fraction of each side left out next to the corners.
    refine : bool
        Stage 8 on/off.
    refine_radius : int or None
        Stage 8 profile half-width, px; ``None`` = 0.4 cell, clipped to [1, refine_max_radius].
    refine_max_radius : int
        Largest automatic profile half-width, px (wider profiles follow stronger blur).
    refine_profiles : int
        Stage 8 profiles across each side (more average more noise away).
    refine_iterations : int
        Stage 8 passes.
    refine_max_iterations : int
        Stage 8 passes at most: after ``refine_iterations``, quads whose corners still moved
        more than ``refine_tolerance`` px go on (strong blur, wider than the profiles, lets
        each pass move a side only part of the way).
    refine_tolerance : float
        Largest corner move (px) of a converged stage 8 pass.
    coarse_scale : float or None
        Candidates from search passes this coarse or coarser (full-resolution px per pass
        pixel) are refined a second way too: ``coarse_iterations`` passes with profiles 0.4
        cell wide (stage 8's own width without its ``refine_max_radius`` cap) from the
        stage-7 quad, then stage 8; the refinement whose sides sit on the stronger edges
        (:func:`visloc.markers.refine.edge_contrast`) is kept. A coarse pass's contour on a
        noisy dark frame can put a side several pixels off at one end, beyond stage 8's
        reach (camera-like dark 1280 x 720 renders of three seeds,
        ``bench/refine_window.py``: 7 of 133 found markers had a corner 3-30 px off without
        it). Only quads whose 0.4-cell width exceeds their stage-8 radius (cells of 14 px or
        more) pay for it. None: stage 8 alone.
    coarse_iterations : int
        Passes of the wide refinement: a stage-7 quad can be more than a cell off at one end,
        and each pass moves a side at most 0.4 cell (10, 12 and 16 did equally well on dark
        renders of four seeds, the markers bench's included, and 10 costs least; 4 and 8 left
        corners 8-15 px off there).
    bend : bool
        Stage 8b on/off: the corners where the sides, fitted as quadratic curves in stage 8's
        last pass, meet (lens distortion bends straight sides; a side stays a line unless its
        curvature is significant). On camera-like 640 x 480 renders with barrel distortion
        (k1 = -0.15, no noise) the corner RMS falls from 0.35 to 0.03 px.
    bend_radius : int
        Stage 8b's profile half-width at most, px (1-50; the quad's own radius where smaller).
        It starts from refined sides, so a narrow window suffices; the samples farther out
        only add noise, and clipped to the black-white span they move the edges outward
        where the white side is the noisier (dark frames). ``python bench/refine_window.py``
        compares widths on camera-like frames.
    noisy_bend_radius : int or None
        Stage 8b's half-width on a noisy marker (noise a tenth of the contrast or more: dark
        frames; :func:`visloc.markers.refine.refine_quads`), px (1-50), where smaller than the
        above; None: no narrowing. Without noise a narrow window's loss of a blurred edge's
        tails (a bias) is all there is; with much noise the noise it leaves out wins.
    border_bits : int
        Width of the markers' black border in cells, 1 to 3 (OpenCV's ``markerBorderBits``).
    inverted : bool or "both"
        ``False``: black markers on white; ``True``: white markers on black only (OpenCV's
        ``detectInvertedMarker`` finds both; that is ``"both"`` here, at twice the cost).
    response : {"srgb", "linear"} or float
        Stage 8: how the image's grey levels encode light
        (:func:`visloc.markers.response.response_lut`). The default ``"srgb"`` is what cameras
        and most image files use; ``"linear"`` is for linear sensor data and linear renders
        (:func:`visloc.synth.render_markers` without a camera model). Edges are measured in
        linear light, so the wrong choice biases corners by a fraction of the blur width.
    border_error_rate : float
        Stage 9: tolerated white border cells, as a fraction of the bit count (OpenCV: 0.35).
    min_quiet_zone : float
        Stage 9: least fraction of the cells of the ring around the border that must be white
        (the marker's quiet zone; lenient, as markers on boards touch other ink at their
        corners). On 19 real photos every marker's ring is at least 86 % white; the false
        detections of dark photos with bright specks have none.
    cell_margin : float
        Stage 10's check of a decoded marker reads each cell's area without this fraction of
        the cell on every side (OpenCV's ``perspectiveRemoveIgnoredMarginPerCell``, 0.13).
    bit_threshold : float or None
        With a value, that check also counts a cell as an error when more than this share of
        its read area is wrong (OpenCV's ``validBitIdThreshold``, default 0.49 there), and
        the border and the code tolerate ``border_error_rate`` and ``error_correction_rate``
        of such cells. ``None`` (the default): the bits are the majority reads of stage 9
        alone (the area read only gives the confidence): on small markers in real photos
        (about a pixel per cell) the two reads differ on a cell or two, and a marker both
        OpenCV and stage 9 read cleanly was lost to the area check.
    confidence : bool
        Whether stage 10 reads the area of every accepted marker's cells for its
        ``confidence`` (OpenCV's definition, :class:`~visloc.types.MarkerDetection`): a second
        sampling of each marker (in the simulator, 0.21 of the tracker's 1.14 ms per frame).
        ``False`` leaves ``confidence`` NaN, for a caller that uses only the ids and corners
        (the simulator's vision estimator); with a ``bit_threshold`` the area is read all the
        same.
    error_correction_rate : float
        Stage 10: fraction of the dictionary's correction capacity used (OpenCV: 0.6).
    native : bool or None
        Run the compiled stages (4-9: ``True``; a ``RuntimeError`` when they were not built),
        their Python versions (``False``: the same detections, stage 8's corners within about
        0.01 px, slower), or the compiled ones where they were built (``None``, the default).
    """

    passes: tuple[SearchPass, ...] = (SearchPass(scale=1.0, window=9), SearchPass(scale=1.5, window=11),
                                      SearchPass(scale=4.0, window=9))
    dark_passes: tuple[SearchPass, ...] = (SearchPass(scale=1.0, window=9), SearchPass(scale=1.5, window=11),
                                           SearchPass(scale=4.0, window=9, offset=4.0),
                                           SearchPass(scale=3.0, window=9, offset=4.0))
    dark_mean: float = 50.0
    min_pass_size: int = 100
    erode: int = 0
    board_retry: bool = True
    small_side: float = 30.0
    base_height: int = 540
    blur_sigma: float = 0.6
    offset: float = 7.0
    candidates: CandidateFilter = field(default_factory=CandidateFilter)
    corner_sigma: float | None = None
    corner_padding: float = 0.1
    refine: bool = True
    refine_radius: int | None = None
    refine_iterations: int = 2
    refine_max_iterations: int = 6
    refine_tolerance: float = 0.05
    refine_max_radius: int = 5
    refine_profiles: int = 24
    coarse_scale: float | None = 3.0
    coarse_iterations: int = 10
    bend: bool = True
    bend_radius: int = 3
    noisy_bend_radius: int | None = 2
    response: str | float = "srgb"
    border_bits: int = 1
    inverted: bool | str = False
    border_error_rate: float = 0.35
    min_quiet_zone: float = 0.25
    cell_margin: float = 0.13
    bit_threshold: float | None = None
    confidence: bool = True
    error_correction_rate: float = 0.6
    native: bool | None = None


@dataclass(frozen=True, eq=False)
class CandidateTrace:
    """What happened to one candidate contour (for ``--explain``).

    ``contour`` is in the pixels of its pass's image (``scale``); ``line_corners`` in
    full-resolution pixels. ``stage`` is where it stopped: ``"corners"``, ``"bits"``,
    ``"dictionary"``, ``"duplicate"`` or ``"accepted"``.
    """

    contour: NDArray[np.int32]
    scale: float
    split: RadialSplit | None
    line_corners: NDArray[np.float64] | None
    cells: CellSample | None
    bits: NDArray[np.uint8] | None
    detection: MarkerDetection | None
    stage: str


@dataclass(frozen=True, eq=False)
class PassTrace:
    """Stages 2-4 of one search pass: every outer border of the binary image (``contours``,
    in the pass image's pixels) and whether it encloses a hole (``enclosing``; only those
    go on to stage 5)."""

    scale: float
    window: int
    blurred: NDArray[np.uint8]
    binary: NDArray[np.uint8]
    contours: list[NDArray[np.int32]]
    enclosing: NDArray[np.bool_]


@dataclass(frozen=True, eq=False)
class DetectionTrace:
    """Every stage's intermediate result for one image (report Figure G.1, panels B-I)."""

    gray: NDArray[np.uint8]
    passes: list[PassTrace]
    candidates: list[CandidateTrace]
    detections: list[MarkerDetection]

    @property
    def binary(self) -> NDArray[np.uint8]:
        """The first pass's binary image."""
        return self.passes[0].binary


@dataclass(frozen=True, eq=False)
class _PassImage:
    """Stages 2-5 of one search pass: the pass image's shape and scale to full resolution,
    its threshold window and candidate bounds, the blurred and binary images, and the
    candidates (outer borders that enclose a hole and pass stage 5, each with its polygon),
    and the polygons' corners in full-resolution pixels (K, 4, 2)."""

    shape: tuple[int, ...]
    scale: NDArray[np.float64]
    window: int
    candidates: CandidateFilter
    blurred: NDArray[np.uint8]
    binary: NDArray[np.uint8]
    found: list[tuple[NDArray[np.int32], NDArray[np.int32]]]
    approx: NDArray[np.float64]


_POOL: tuple[int, ThreadPoolExecutor] | None = None
#: Largest image (pixels) whose later search passes run on the worker thread: measured with
#: bench/markers.py frames, the thread cuts median and p99 time at 320 x 240 and 640 x 480
#: (1.96 -> 1.68 ms) and adds to the p99 at 1280 x 720 (11.9 -> 15.9 ms).
_THREAD_MAX_PIXELS = 500_000


def _pool() -> ThreadPoolExecutor:
    """One worker thread for the later search passes (a new one after a fork)."""
    global _POOL
    if _POOL is None or _POOL[0] != os.getpid():
        _POOL = (os.getpid(), ThreadPoolExecutor(max_workers=1, thread_name_prefix="visloc-search"))
    return _POOL[1]


@dataclass
class _Cands:
    """Candidates pooled from the search passes (parallel lists)."""

    quads: list[NDArray[np.float64]] = field(default_factory=list)
    contours: list[NDArray[np.int32]] = field(default_factory=list)
    scales: list[float] = field(default_factory=list)
    splits: list[RadialSplit | None] = field(default_factory=list)


class MarkerDetector:
    """Detect square fiducial markers of one dictionary.

    Parameters
    ----------
    dictionary : str or Dictionary
        An OpenCV predefined name (``"DICT_4X4_50"``, ``"DICT_APRILTAG_36h11"``, ...) or the
        path of an OpenCV dictionary YAML file.
    **params
        Fields of :class:`DetectorParams` (e.g. ``offset=5``, ``refine=False``);
        ``passes`` may be given as ``[(scale, window), ...]``.

    Raises
    ------
    TypeError
        An unknown parameter, ``candidates`` not a ``CandidateFilter``, or ``board_retry``,
        ``refine`` or ``bend`` not a bool.
    ValueError
        An unknown dictionary, or a parameter out of its range (every field of
        :class:`DetectorParams` is checked here, not at the first frame; the message names it).

    Examples
    --------
    >>> det = MarkerDetector("DICT_4X4_50")
    >>> markers = det.detect(image)          # doctest: +SKIP
    >>> markers[0].id, markers[0].corners    # doctest: +SKIP
    """

    def __init__(self, dictionary: str | Dictionary = "DICT_4X4_50", **params: object) -> None:
        self.dictionary = load_dictionary(dictionary)
        names = {f.name for f in fields(DetectorParams)}
        unknown = set(params) - names
        if unknown:
            raise TypeError(f"unknown detector parameter(s): {', '.join(sorted(unknown))}")
        for key in ("passes", "dark_passes"):
            if key in params:
                params[key] = tuple(_as_pass(p) for p in params[key])  # type: ignore[union-attr]
        self.params = replace(DetectorParams(), **params)  # type: ignore[arg-type]
        _check_params(self.params)
        self._filters: dict[tuple[float, float], CandidateFilter] = {}  # stage 5's bounds per pass (_search)
        # the lenient first look at a candidate's cells (before stage 6) allows this many white
        # bits: the dictionary's range widened by the correctable errors, and one more
        slack = int(self.dictionary.max_correction * self.params.error_correction_rate) + 1
        lo_white, hi_white = self.dictionary.white_range
        self._white_range = (lo_white - slack, hi_white + slack)
        lut = response_lut(self.params.response)  # a clear error now rather than at the first frame
        # the inverted image's grey level v holds the light 255 - lut[255 - v] of the original
        self._luts = {False: lut, True: 255.0 - lut[::-1]}
        bb = self.params.border_bits
        # each id's cells (1 = white) with its border, as seen at 0-3 quarter turns (decode's r)
        codes = np.pad(self.dictionary.bits, ((0, 0), (bb, bb), (bb, bb)))
        self._cells_seen = np.stack([np.rot90(codes, r, axes=(1, 2)) for r in range(4)], axis=1)
        # stage 3c's probe points (12, 4) x corners (4, 2): half a cell outside the corners,
        # inside them and outside the sides' midpoints, along the rays from the centre
        step = 1.0 / (self.dictionary.marker_size + 2 * bb)
        eye, centre = np.eye(4), np.full((4, 4), 0.25)
        mid = 0.5 * (eye + eye[_NEXT])
        self._board_probes = np.concatenate([eye + step * (eye - centre), eye - step * (eye - centre),
                                             mid + step * (mid - centre)])

    def __repr__(self) -> str:
        return f"MarkerDetector({self.dictionary.name!r}, {self.params})"

    def detect(self, image: NDArray[np.uint8]) -> list[MarkerDetection]:
        """Markers in ``image`` (uint8 grey or BGR), sorted by id.

        Runs stages 1-10 (module docstring) with this detector's :class:`DetectorParams`.

        Parameters
        ----------
        image : ndarray (H, W) or (H, W, 3) uint8
            The frame, grey or BGR (other forms as :func:`visloc.markers.binarize.to_gray`
            accepts them: (H, W, 1), BGRA, uint16, floating point).

        Returns
        -------
        list of MarkerDetection
            The markers found, sorted by id (then by corner 0's y and x), duplicates (one
            marker found twice) merged. Each has ``corners`` (4, 2), px in full-resolution
            image coordinates (pixel centres at integers), clockwise from the marker's own
            top-left. Empty when none is found.

        Raises
        ------
        TypeError, ValueError
            If ``image`` is not a usable image (:func:`visloc.images.check_image`: not a numpy
            array, an unsupported pixel type or shape, smaller than 2 x 2, NaN or infinite
            pixels).
        """
        return self._run(image, None)

    def confirm(self, image: NDArray[np.uint8], quads: NDArray, ids: NDArray, *,
                inverted: bool = False) -> list[MarkerDetection | None]:
        """Stages 8-10 alone, on quads where known markers are expected (a tracker's
        prediction from earlier frames, :class:`visloc.markers.MarkerTracker`).

        Each quad is refined on the grey image (stage 8 converges onto the marker's edges
        from within its profile half-width, about 0.4 cell), read and matched against the
        dictionary as a candidate of :meth:`detect` is (less the second read through the
        stage-7 corners: a prediction is no fit); it stands only if the refinement succeeded
        and the marker decodes to the expected id with its own top-left corner at the quad's
        corner 0.

        Parameters
        ----------
        image : ndarray (H, W) or (H, W, 3) uint8
            The frame (grey or BGR).
        quads : array_like (K, 4, 2)
            Expected corners, px, clockwise from each marker's own top-left corner.
        ids : array_like (K,) int
            The id expected at each quad.
        inverted : bool
            Whether the markers are white on black.

        Returns
        -------
        list of MarkerDetection or None
            Per quad, the detection (``rotation`` 0: no contour was followed) or None.

        Raises
        ------
        TypeError
            An id that is a bool or not a number.
        ValueError
            ``quads`` not (K, 4, 2) finite corners with K ``ids``; an id with a fraction; an
            image that is not uint8 grey or BGR (also with no quads).
        """
        q = np.asarray(quads, dtype=np.float64)
        want = np.asarray(ids).reshape(-1)
        if q.ndim != 3 or q.shape[1:] != (4, 2) or len(want) != len(q):
            raise ValueError(f"quads, ids: expected (K, 4, 2) corners and K ids, got shapes {q.shape} and {want.shape}")
        gray = to_gray(image)  # checked even without quads
        if not len(q):
            return []
        if not np.isfinite(q).all():
            raise ValueError("quads: corners must be finite")
        expected = [marker_id(k, "ids") for k in want.tolist()]  # 3.7 is no marker (int() made it 3)
        gray = cv2.bitwise_not(gray) if inverted else gray
        made = self._made(gray, q, bool(inverted), retry_fit=False)[2]
        return [d if d is not None and d.id == k and d.rotation == 0 and d.refined else None
                for d, k in zip(made, expected, strict=True)]

    def trace(self, image: NDArray[np.uint8]) -> DetectionTrace:
        """Run :meth:`detect` keeping every stage's intermediate result.

        Parameters
        ----------
        image : ndarray (H, W) or (H, W, 3) uint8
            As for :meth:`detect`.

        Returns
        -------
        DetectionTrace
            The grey image (stage 1, before any inversion for ``inverted=True``), every search
            pass (:class:`PassTrace`), every candidate with the stage where it stopped
            (:class:`CandidateTrace`) and the detections, as :meth:`detect` returns them. With
            ``inverted="both"`` the passes and candidates are those of the black-on-white
            search only; the detections are of both polarities.

        Raises
        ------
        TypeError, ValueError
            As for :meth:`detect`.
        """
        log: dict = {"candidates": [], "passes": []}
        dets = self._run(image, log)
        return DetectionTrace(log["gray"], log["passes"], log["candidates"], dets)

    def _work_image(self, gray: NDArray[np.uint8], f: float) -> tuple[NDArray[np.uint8], NDArray]:
        """The grey image shrunk by ``f`` and the (x, y) scale back to full resolution."""
        work = gray
        if f > 1:
            size = (max(2, round(gray.shape[1] / f)), max(2, round(gray.shape[0] / f)))
            # area averaging has a fast path for whole factors; otherwise bilinear (the blur
            # of stage 2 follows) costs a fifth of it
            whole = f == int(f) and gray.shape[1] % int(f) == 0 and gray.shape[0] % int(f) == 0
            work = cv2.resize(gray, size, interpolation=cv2.INTER_AREA if whole else cv2.INTER_LINEAR)
        return work, np.array([gray.shape[1] / work.shape[1], gray.shape[0] / work.shape[0]])

    def _search(self, gray: NDArray[np.uint8], sp: SearchPass, base: float) -> _PassImage:
        """Stages 2-5 of one search pass. Touches nothing shared, so the passes after the
        first run on a worker thread while the first goes on (the compiled stages 4 and 5 and
        OpenCV's filters release the GIL). The first look at the cells and stages 6-7 stay
        on the main thread (:meth:`_propose`): on the worker, their Python waits for the GIL
        (on 320 x 240 views of a 36-marker grid, 2.98 against 2.87 ms)."""
        p = self.params
        work, scale = self._work_image(gray, sp.scale * base)
        window = sp.window if sp.window is not None else default_window(work.shape)
        # a marker needs at least about 1 px per cell to be decoded: smaller ones are not looked at
        min_side = max(p.candidates.min_side, (self.dictionary.marker_size + 2 * p.border_bits) / scale.max())
        # the image-border margin is in full-resolution pixels whatever the pass's scale
        key = (min_side, p.candidates.border_distance / scale.max())
        candidates = self._filters.get(key)
        if candidates is None:  # one per pass and image size (a dataclass replace costs 4 us a frame)
            if len(self._filters) >= 64:
                self._filters.clear()
            candidates = self._filters[key] = replace(p.candidates, min_side=key[0], border_distance=key[1])
        blurred = blur(work, sigma=p.blur_sigma)  # stage 2
        binary = threshold(blurred, window=window, offset=p.offset if sp.offset is None else sp.offset,
                           native=p.native)  # stage 3
        # stage 4: a marker's frame encloses its white cells, so ink without a hole is no marker;
        # stage 5 on those borders
        found = find_candidates(binary, params=candidates, native=p.native)
        return _PassImage(work.shape, scale, window, candidates, blurred, binary, found, _polygons(found, scale))

    def _looks_right(self, gray: NDArray[np.uint8], approx: NDArray) -> NDArray[np.bool_]:
        """A cheap, lenient look at the cells of candidates (K, 4, 2) through their polygon
        corners: most texture candidates (and the black cells inside markers) end there,
        before they cost a corner fit and an edge refinement: no black border, no contrast, or
        too few or too many white bits for any marker of the dictionary."""
        bb = self.params.border_bits
        valid, bits = read_cells(gray, approx, self.dictionary.marker_size + 2 * bb, border_error_rate=0.5,
                                 border=bb, native=self.params.native)[1][:2]
        white = bits.reshape(len(bits), -1).sum(axis=1)
        return valid & (white >= self._white_range[0]) & (white <= self._white_range[1])

    def _area_check(self, gray: NDArray[np.uint8], corners: NDArray, thr: NDArray, ids: NDArray,
                    shift: NDArray) -> tuple[NDArray, NDArray[np.bool_]]:
        """OpenCV's cell read of decoded markers (K): each cell's share of wrong area (white
        where the code has black or the other way round) over its read area
        (:func:`visloc.markers.bits.cell_white_fractions`, ``cell_margin`` left out).

        Returns the confidence (K,), ``1 - wrong area / read area`` over all cells, border
        included (OpenCV's ``detectMarkersWithConfidence``), and whether the marker stands: a
        cell whose wrong share exceeds ``bit_threshold`` is an error, and the border and the
        code tolerate ``border_error_rate`` and ``error_correction_rate`` of them."""
        p = self.params
        bb = p.border_bits
        n = self.dictionary.marker_size + 2 * bb
        cell_px = statistics.median(np.sqrt(np.abs(_areas(corners))).tolist()) / n  # np.median's value, cheaper
        per_side = min(max(math.ceil(cell_px / 2), 4), 32)  # a sample per 2 px of cell, 4-32
        white = cell_white_fractions(gray, corners, n, thr, per_side=per_side, margin=p.cell_margin, native=p.native)
        expected = self._cells_seen[ids, (4 - shift) % 4]  # decode: observed = rot90(true, (4 - shift) % 4)
        wrong = np.where(expected == 1, 1.0 - white, white)
        confidence = 1.0 - wrong.reshape(len(wrong), -1).mean(axis=1)
        if p.bit_threshold is None:
            return confidence, np.ones(len(wrong), bool)
        bad = wrong > p.bit_threshold
        frame = np.ones((n, n), bool)
        frame[bb:-bb, bb:-bb] = False
        s = self.dictionary.marker_size
        clear = ((bad[:, frame].sum(axis=1) <= int(p.border_error_rate * s * s))
                 & (bad[:, ~frame].sum(axis=1) <= int(self.dictionary.max_correction * p.error_correction_rate)))
        return confidence, clear

    def _eroded(self, found: _PassImage, width: int, around: NDArray | None = None) -> _PassImage:
        """Stage 3b: stages 4-5 again on a pass's binary image with its ink eroded by a
        square ``width`` px wide; with ``around`` (K, 4, 2 full-resolution corners) only
        within one marker side of those markers' bounding boxes (only that part of the image
        is eroded and followed)."""
        kernel = np.ones((width, width), np.uint8)
        if around is None:
            binary = cv2.erode(found.binary, kernel)
            cands = find_candidates(binary, params=found.candidates, native=self.params.native)
            return replace(found, binary=binary, found=cands, approx=_polygons(cands, found.scale))
        h, w = found.binary.shape
        lo, hi = around.min(axis=1), around.max(axis=1)  # (K, 2)
        side = (hi - lo).max(axis=1, keepdims=True)
        lo = np.clip(np.floor((lo - side) / found.scale), 0, (w - 1, h - 1)).astype(int)
        hi = np.clip(np.ceil((hi + side) / found.scale), 0, (w - 1, h - 1)).astype(int)
        (x0, y0), (x1, y1) = lo.min(axis=0).tolist(), hi.max(axis=0).tolist()
        crop = cv2.erode(found.binary[y0:y1 + 1, x0:x1 + 1], kernel)
        mask = np.zeros_like(crop)
        for (a, b), (c, d) in zip((lo - (x0, y0)).tolist(), (hi - (x0, y0)).tolist(), strict=True):
            mask[b:d + 1, a:c + 1] = 255
        crop &= mask
        # the whole pass image's contour-length bounds on the crop (they scale with the image side)
        f = max(h, w) / max(crop.shape)
        bounds = replace(found.candidates, min_perimeter_rate=found.candidates.min_perimeter_rate * f,
                         max_perimeter_rate=found.candidates.max_perimeter_rate * f)
        origin = np.array([x0, y0], np.int32)
        cands = [(c + origin, q + origin) for c, q in find_candidates(crop, params=bounds, native=self.params.native)]
        binary = np.zeros_like(found.binary)
        binary[y0:y1 + 1, x0:x1 + 1] = crop
        return replace(found, binary=binary, found=cands, approx=_polygons(cands, found.scale))

    def _passes(self, gray: NDArray[np.uint8], passes: list[SearchPass], base: float,
                keep: list[_PassImage]) -> Iterator[_PassImage]:
        """Stages 2-5 of the search passes in order, then (``erode``) stage 3b on the first
        pass's binary image; the first pass is also appended to ``keep`` (for stage 3c). All
        passes but the first are computed on a worker thread meanwhile, up to
        :data:`_THREAD_MAX_PIXELS` (beyond, OpenCV's own threads already keep both cores of the
        bench machine busy and the hand-over only adds to the slowest frames)."""
        first_pass, *rest = passes
        threaded = gray.size <= _THREAD_MAX_PIXELS
        later = [_pool().submit(self._search, gray, sp, base) for sp in rest] if threaded else []
        try:
            first = self._search(gray, first_pass, base)
            keep.append(first)
            yield first
            for job in later:
                yield job.result()
            if not threaded:
                for sp in rest:
                    yield self._search(gray, sp, base)
            if self.params.erode:
                yield self._eroded(first, self.params.erode)
        finally:
            for job in later:
                job.cancel()

    @staticmethod
    def _log_pass(found: _PassImage, log: dict | None) -> None:
        """Every border of a pass's binary image, for the pictures of ``--explain``."""
        if log is not None:
            everything, holes = outer_borders(found.binary)
            log["passes"].append(PassTrace(float(found.scale[0]), found.window, found.blurred, found.binary,
                                           everything, holes))

    def _run(self, image: NDArray[np.uint8], log: dict | None) -> list[MarkerDetection]:
        gray = to_gray(image)  # stage 1
        if log is not None:
            log["gray"] = gray
        polarity = self.params.inverted
        if polarity == "both":  # the trace shows the black-on-white search
            dets = self._detect(gray, False, log) + self._detect(cv2.bitwise_not(gray), True, None)
            return sorted(dets, key=lambda d: (d.id, d.corners[0, 1], d.corners[0, 0]))
        return self._detect(cv2.bitwise_not(gray) if polarity else gray, bool(polarity), log)

    def _detect(self, gray: NDArray[np.uint8], inverted: bool, log: dict | None) -> list[MarkerDetection]:
        """Stages 2-10 on a grey image in which the markers are black on white."""
        p = self.params
        base = max(1.0, min(gray.shape[:2]) / p.base_height)
        if cv2.mean(gray)[0] < p.dark_mean:
            passes = list(p.dark_passes)
        else:  # a pass on an image shrunk below min_pass_size finds nothing the others miss
            short = min(gray.shape[:2]) / base
            passes = [sp for k, sp in enumerate(p.passes) if k == 0 or short / sp.scale >= p.min_pass_size]
        first: list[_PassImage] = []
        dets = self._find(gray, self._passes(gray, passes, base, first), inverted, log)
        if p.board_retry and not p.erode and first and dets:  # stage 3c
            found = np.array([d.corners for d in dets])
            board = self._on_board(gray, dets)
            small = _small_in_group(found, p.small_side)
            if board or small.any():  # a board: everywhere; else only around the small markers
                more = self._find(gray, iter([self._eroded(first[0], 2, None if board else found[small])]), inverted,
                                  log, taken=found)
                if more:
                    dets = _merge_duplicates([(d, abs(float(_areas(d.corners)))) for d in dets + more])
        return dets

    def _on_board(self, gray: NDArray[np.uint8], dets: list[MarkerDetection]) -> bool:
        """Whether a found marker's corners touch other ink (stage 3c's trigger): half a cell
        diagonally outside at least two of its corners the grey level is nearer its black
        border's (half a cell inside the corners) than the light's half a cell outside its
        sides' midpoints."""
        if not dets:
            return False
        pts = np.matmul(self._board_probes, np.array([d.corners for d in dets]))  # (K, 12, 2)
        h, w = gray.shape[:2]
        xy = np.minimum(np.maximum(np.rint(pts), 0), (w - 1, h - 1)).astype(np.intp)
        v = gray[xy[..., 1], xy[..., 0]].astype(np.float64)  # (K, 12)
        black, light = v[:, 4:8].sum(axis=1), v[:, 8:].sum(axis=1)  # 4 x their mean levels
        dark = (8 * v[:, :4] < (black + light)[:, None]).sum(axis=1)
        return bool(((light - black > 40) & (dark >= 2)).any())

    def _propose(self, gray: NDArray[np.uint8], group: list[_PassImage], taken: NDArray, cands: _Cands,
                 log: dict | None) -> NDArray:
        """Stages 6-7 for the candidates of a group of search passes, appended to ``cands``;
        returns ``taken`` (K, 4, 2), the polygons of the candidates fitted so far, with those
        fitted now.

        Pass by pass, a candidate that an earlier pass already proposed and fitted (or an
        earlier one of its own pass proposed) is passed over, the others are looked at
        (:meth:`_looks_right`), and those whose cells look right are fitted. The look is one
        call for the whole group, made for every candidate that neither ``taken`` nor an
        earlier one of its own pass repeats (each look depends on its own candidate only, so
        the candidates the rule keeps get the look they would get pass by pass; the copies of
        markers an earlier pass fitted get a look too, and are then passed over: a look costs
        less than a call); the fits stay pass by pass, so no marker is fitted twice."""
        p = self.params
        for search in group:
            self._log_pass(search, log)
        pass_of = np.repeat(np.arange(len(group)), [len(s.found) for s in group])
        if not len(pass_of):
            return taken
        contours = [c for s in group for c, _ in s.found]
        scale = np.array([s.scale for s in group])[pass_of][:, None, :]  # (K, 1, 2)
        approx = np.concatenate([s.approx for s in group])
        t = len(taken)
        same = _same(np.concatenate([taken, approx]))[t:]  # (K, t + K): rows the group's candidates
        group_same = same[:, t:]
        # repeats of taken or of an earlier candidate of the same pass: never looked at
        passed_over = same[:, :t].any(axis=1) | np.tril(group_same & (pass_of[:, None] == pass_of[None, :]),
                                                         -1).any(axis=1)
        maybe = np.flatnonzero(~passed_over)
        looks = np.zeros(len(approx), bool)
        if len(maybe):
            looks[maybe] = self._looks_right(gray, approx[maybe])
        done = np.zeros(len(approx), bool)  # this group's candidates fitted by the earlier passes
        for k in range(len(group)):
            fresh = np.flatnonzero((pass_of == k) & ~passed_over)
            if k and len(fresh) and done.any():  # repeats of a candidate an earlier pass fitted
                fresh = fresh[~group_same[np.ix_(fresh, np.flatnonzero(done))].any(axis=1)]
            if log is not None:
                for i in fresh[~looks[fresh]].tolist():
                    _note(log, contours[i], float(scale[i, 0, 0]), None, None, None, None, None, "bits")
            keep = fresh[looks[fresh]]
            if not len(keep):
                continue
            hints = (approx[keep] + 0.5) / scale[keep] - 0.5
            quads, fitted, splits = fit_quads([contours[i] for i in keep], hints=hints, sigma=p.corner_sigma,
                                              padding=p.corner_padding, splits=log is not None,
                                              native=p.native)  # 6-7
            full = (quads + 0.5) * scale[keep] - 0.5  # to full-resolution pixel centres
            for j, (i, ok) in enumerate(zip(keep.tolist(), fitted.tolist(), strict=True)):
                if not ok:
                    _note(log, contours[i], float(scale[i, 0, 0]), None, None, None, None, None, "corners")
                    continue
                cands.quads.append(full[j])
                cands.contours.append(contours[i])
                cands.scales.append(float(scale[i, 0, 0]))
                cands.splits.append(splits[j] if splits is not None else None)
            done[keep[fitted]] = True
        return np.concatenate([taken, approx[done]])

    def _find(self, gray: NDArray[np.uint8], searches: Iterator[_PassImage], inverted: bool,
              log: dict | None, taken: NDArray | None = None) -> list[MarkerDetection]:
        """Stages 6-10 on the candidates of the searches (stages 2-5), in order (6-7:
        :meth:`_propose`), passing over candidates that repeat a quad of ``taken`` (K, 4, 2)."""
        cands = _Cands()
        if taken is None:
            taken = np.zeros((0, 4, 2))  # the polygons of the candidates fitted so far
        # every pass's candidates at once, the later passes' waited for (their stages 2-5 ran on
        # the worker meanwhile): one batch costs fewer numpy calls than one per pass, and less
        # than proposing the first pass's candidates while the worker ends (3 % at 320 x 240)
        taken = self._propose(gray, list(searches), taken, cands, log)
        if not cands.quads:
            return []
        quads = np.array(cands.quads)
        coarse = None if self.params.coarse_scale is None else np.array(cands.scales) >= self.params.coarse_scale
        cells, reads, made, corners = self._made(gray, quads, inverted, coarse=coarse)
        areas = np.abs(_areas(corners)).tolist()
        valid, bits = reads[:2]
        found: list[tuple[MarkerDetection, float]] = []
        for i, det in enumerate(made):
            cell_i = CellSample(cells.cells[i : i + 1], cells.ring[i : i + 1]) if log is not None else None
            if det is None:
                if log is not None:
                    stage, b = ("bits", None) if not valid[i] else ("dictionary", bits[i])
                    _note(log, cands.contours[i], cands.scales[i], cands.splits[i], quads[i], cell_i, b, None, stage)
                continue
            found.append((det, areas[i]))
            _note(log, cands.contours[i], cands.scales[i], cands.splits[i], quads[i], cell_i, bits[i], det, "accepted")
        dets = _merge_duplicates(found)
        if log is not None and len(dets) < len(found):
            kept_ids = {id(d) for d in dets}
            for j, c in enumerate(log["candidates"]):
                if c.detection is not None and id(c.detection) not in kept_ids:
                    log["candidates"][j] = replace(c, stage="duplicate")
        return dets

    def _made(self, gray: NDArray[np.uint8], quads: NDArray, inverted: bool, *, retry_fit: bool = True,
              coarse: NDArray | None = None
              ) -> tuple[CellSample, list[NDArray], list[MarkerDetection | None], NDArray]:
        """Stages 8-10 (:meth:`_read`) on candidate quads (K, 4, 2), and what they make:
        ``(cells, reads, detections, corners)``, a :class:`MarkerDetection` per accepted
        candidate (corners from the marker's own top-left corner) and None per rejected one,
        with every candidate's corners in that order (K, 4, 2). ``retry_fit``, ``coarse``: as
        :meth:`_read`."""
        corners, refined, cells, reads, accept, confidence = self._read(gray, quads, inverted, retry_fit=retry_fit,
                                                                        coarse=coarse)
        ids, shift, hamming = reads[5:8]
        order = (_FOUR[None, :] + shift[:, None]) % 4  # all at once
        rolled = corners[np.arange(len(corners))[:, None], order]
        rows = zip(accept.tolist(), ids.tolist(), list(rolled), hamming.tolist(), reads[2].tolist(), shift.tolist(),
                   reads[3].tolist(), refined.tolist(), confidence.tolist(), strict=True)  # Python ints, floats, bools
        made = [_detection(mid, c, ham, mar, rot, con, ref, conf, inverted) if ok else None
                for ok, mid, c, ham, mar, rot, con, ref, conf in rows]
        return cells, reads, made, rolled

    def _read(self, gray: NDArray[np.uint8], quads: NDArray, inverted: bool, *, retry_fit: bool = True,
              coarse: NDArray | None = None) -> tuple:
        """Stages 8-10 on candidate quads (K, 4, 2) in full-resolution pixels: edge
        refinement, cell reads (a second read where the first does not decode) and the
        dictionary match. Returns ``(corners, refined, cells, reads, accept, confidence)``:
        ``reads`` is (valid, bits, margin, contrast, threshold, ids, shift, hamming, matched),
        ``accept`` (K,) the candidates that decode and pass OpenCV's cell-area check.
        ``retry_fit`` False: no second read through ``quads`` themselves (they are
        predictions, not stage-7 fits). ``coarse`` (K,) bool: the quads from coarse search
        passes (``coarse_scale``), refined a second way too (:meth:`_coarse_refit`)."""
        p = self.params
        bb = p.border_bits
        n_cells = self.dictionary.marker_size + 2 * bb
        corners, refined = quads, np.zeros(len(quads), bool)
        if p.refine:  # stage 8, batched
            width = np.round(0.4 * np.sqrt(np.abs(_areas(quads))) / n_cells)  # 0.4 cell, px
            radii = p.refine_radius or np.clip(width, 1, p.refine_max_radius).astype(int)
            corners, refined = self._stage8(gray, quads, radii, inverted)  # 8, 8b
            if coarse is not None:
                corners, refined = self._coarse_refit(gray, quads, corners, refined, radii, width, coarse, inverted)
        cells, (valid, bits, margin, contrast, thr) = read_cells(  # stage 9, batched
            gray, corners, n_cells, per_side=4, border_error_rate=p.border_error_rate, border=bb,
            min_quiet_zone=p.min_quiet_zone, native=p.native)
        valid, bits, margin, contrast, thr = (np.array(a) for a in (valid, bits, margin, contrast, thr))
        reads = [valid, bits, margin, contrast, thr,
                 *decode(bits, self.dictionary, error_correction_rate=p.error_correction_rate, native=p.native)]  # 10
        cells = self._second_reads(gray, quads, corners, refined, cells, reads, retry_fit=retry_fit)
        valid, thr, ids, shift, matched = reads[0], reads[4], reads[5], reads[6], reads[8]
        accept = valid & matched
        confidence = np.zeros(len(quads))
        if not p.confidence and p.bit_threshold is None:  # nobody reads the area
            confidence[accept] = np.nan
        elif accept.any():  # OpenCV's read of the accepted markers: cell areas, confidence, bit threshold
            acc = np.flatnonzero(accept)
            confidence[acc], clear = self._area_check(gray, corners[acc], thr[acc], ids[acc], shift[acc])
            accept[acc[~clear]] = False
        return corners, refined, cells, reads, accept, confidence

    def _stage8(self, gray: NDArray[np.uint8], quads: NDArray, radii: NDArray | int, inverted: bool
                ) -> tuple[NDArray, NDArray[np.bool_]]:
        """Stages 8 and 8b on quads (K, 4, 2) with profile half-widths ``radii``: the refined
        corners and whether each refinement stood (:func:`~visloc.markers.refine.refine_quads`)."""
        p = self.params
        return refine_quads(gray, quads, radius=radii, iterations=p.refine_iterations,
                            max_iterations=p.refine_max_iterations, tolerance=p.refine_tolerance,
                            count=p.refine_profiles, response=self._luts[inverted], bend=p.bend,
                            bend_radius=p.bend_radius, noisy_bend_radius=p.noisy_bend_radius, native=p.native)

    def _coarse_refit(self, gray: NDArray[np.uint8], quads: NDArray, corners: NDArray, refined: NDArray,
                      radii: NDArray | int, width: NDArray, coarse: NDArray, inverted: bool
                      ) -> tuple[NDArray, NDArray[np.bool_]]:
        """Stage 8 again from a wide first refinement for the coarse-pass quads (``coarse``
        (K,) bool) whose 0.4-cell width (``width`` (K,) px, rounded) exceeds their stage-8
        ``radii``: ``coarse_iterations`` passes at that width from the stage-7 ``quads``, then stages 8
        and 8b. Where that stands and its sides sit on stronger edges
        (:func:`~visloc.markers.refine.edge_contrast`) than the first refinement's
        ``corners`` (or that one failed), it replaces them; returns ``(corners, refined)``."""
        p = self.params
        radii = np.broadcast_to(radii, (len(quads),))
        wide = np.clip(width, 1, 50).astype(int)
        pick = np.flatnonzero(coarse & (wide > radii))
        if not len(pick):
            return corners, refined
        start, ok = refine_quads(gray, quads[pick], radius=wide[pick], iterations=p.coarse_iterations,
                                 count=p.refine_profiles, response=self._luts[inverted], native=p.native)
        again, ok2 = self._stage8(gray, start, radii[pick], inverted)
        ok &= ok2
        better = ok & (~refined[pick] | (edge_contrast(gray, again) > edge_contrast(gray, corners[pick])))
        corners, refined = corners.copy(), refined.copy()
        corners[pick[better]], refined[pick[better]] = again[better], True
        return corners, refined

    def _second_reads(self, gray: NDArray[np.uint8], quads: NDArray, corners: NDArray, refined: NDArray,
                      cells: CellSample, reads: list[NDArray], *, retry_fit: bool = True) -> CellSample:
        """Stages 9-10 again for the candidates the first read did not decode: with a
        threshold that follows the light across the marker (glare, shadow edges), then
        through the stage-7 corners ``quads`` (a marker of about a pixel per cell can read
        differently through either; a refinement that spoilt the read is not trusted: its
        ``corners`` and ``refined`` are put back). ``reads`` (valid, bits, margin, contrast,
        threshold, ids, shift, hamming, matched) are updated in place where a second read
        decodes; returns the cell samples, with those read through the stage-7 corners."""
        p = self.params
        bb = p.border_bits
        n_cells = self.dictionary.marker_size + 2 * bb
        for use_fit, shading in ((False, True), (True, False))[:2 if retry_fit else 1]:
            retry = np.flatnonzero(~(reads[0] & reads[8]) & (refined if use_fit else True))
            if not len(retry):
                continue
            again = sample_cells(gray, quads[retry], n_cells, per_side=4, native=p.native) if use_fit else _take(cells, retry)
            read = read_bits(again, border_error_rate=p.border_error_rate, border=bb, min_quiet_zone=p.min_quiet_zone,
                             shading=shading)
            dec = decode(read.bits, self.dictionary, error_correction_rate=p.error_correction_rate, native=p.native)
            pick = read.valid & dec[3]
            won = retry[pick]
            if not len(won):
                continue
            if use_fit:
                cells = CellSample(cells.cells.copy(), cells.ring.copy(), cells.samples.copy())
                cells.cells[won], cells.ring[won], cells.samples[won] = (again.cells[pick], again.ring[pick],
                                                                         again.samples[pick])
                corners[won], refined[won] = quads[won], False  # the read vouches for those corners
            for arr, new in zip(reads, (*read, *dec), strict=True):
                arr[won] = new[pick]
        return cells


def _check_params(p: DetectorParams) -> None:
    """Raise a ValueError naming the first field of ``p`` out of its range (a TypeError for
    ``candidates`` not a :class:`~visloc.markers.contours.CandidateFilter` and a switch that
    is not a bool): every field is checked when the detector is made, not at its first frame."""
    if not p.passes or not p.dark_passes:
        raise ValueError("passes, dark_passes: at least one search pass is needed")
    if not isinstance(p.candidates, CandidateFilter):
        raise TypeError(f"candidates: expected a CandidateFilter, got {type(p.candidates).__name__}")
    for key in ("board_retry", "refine", "bend", "confidence"):
        if not isinstance(getattr(p, key), (bool, np.bool_)):
            raise TypeError(f"{key} must be True or False, got {getattr(p, key)!r}")
    ints = {"erode": (0, 5), "refine_max_iterations": (1, 100), "refine_iterations": (1, p.refine_max_iterations),
            "refine_max_radius": (1, 50), "bend_radius": (1, 50), "refine_profiles": (2, 1000), "border_bits": (1, 3),
            "min_pass_size": (0, None), "base_height": (16, None),
            "coarse_iterations": (1, 100)}
    for key, (lo, hi) in ints.items():
        v = getattr(p, key)
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo or (hi is not None and v > hi):
            raise ValueError(f"{key} must be an integer from {lo}" + (f" to {hi}" if hi is not None else " up")
                             + f", got {v!r}")
    for key in ("refine_radius", "noisy_bend_radius"):
        v = getattr(p, key)
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 1 <= v <= 50):
            raise ValueError(f"{key} must be None or an integer from 1 to 50, got {v!r}")
    # real fields: (least, largest, whether the largest is allowed); None: no bound
    reals = {"refine_tolerance": (0.0, None, True), "small_side": (0.0, None, True), "dark_mean": (0.0, None, True),
             "blur_sigma": (0.0, 10.0, True), "offset": (-255.0, 255.0, True), "corner_padding": (0.0, 0.5, False),
             "border_error_rate": (0.0, 1.0, True), "min_quiet_zone": (0.0, 1.0, True),
             "cell_margin": (0.0, 0.5, False), "error_correction_rate": (0.0, 1.0, True),
             "corner_sigma": (0.0, None, True), "bit_threshold": (0.0, 1.0, True), "coarse_scale": (1.0, None, True)}
    for key, (lo, hi, closed) in reals.items():
        v = getattr(p, key)
        if v is None and key in ("corner_sigma", "bit_threshold", "coarse_scale"):
            continue
        ok = not isinstance(v, bool) and isinstance(v, (int, float, np.integer, np.floating)) and math.isfinite(v)
        if not ok or v < lo or (hi is not None and (v > hi or (v == hi and not closed))):
            top = "" if hi is None else (f" and <= {hi:g}" if closed else f" and < {hi:g}")
            raise ValueError(f"{key} must be a finite number >= {lo:g}{top}, got {v!r}")
    if p.corner_sigma is not None and p.corner_sigma <= 0:
        raise ValueError(f"corner_sigma must be None or > 0, got {p.corner_sigma!r}")
    if p.native is not None and not isinstance(p.native, bool):
        raise ValueError(f"native must be True, False or None, got {p.native!r}")
    if p.inverted not in (False, True, "both") or not isinstance(p.inverted, (bool, str)):
        raise ValueError(f"inverted must be False, True or 'both', got {p.inverted!r}")


def _as_pass(p: object) -> SearchPass:
    if isinstance(p, SearchPass):
        sp = p
    else:  # (scale[, window[, offset]])
        values = tuple(p)  # type: ignore[call-overload]
        if len(values) > 3:
            raise ValueError(f"passes: a pass is a SearchPass or (scale[, window[, offset]]), got {p!r}")
        sp = SearchPass(**{f.name: v for f, v in zip(fields(SearchPass), values, strict=False)})
    if not isinstance(sp.scale, (int, float, np.integer, np.floating)) or not 1 <= sp.scale < math.inf:
        raise ValueError(f"passes: scale must be >= 1, got {sp.scale}")
    if sp.window is not None and (sp.window < 3 or sp.window % 2 == 0):
        raise ValueError(f"passes: window must be an odd integer >= 3, got {sp.window}")
    if sp.offset is not None and not np.isfinite(sp.offset):
        raise ValueError(f"passes: offset must be a finite number, got {sp.offset}")
    return SearchPass(scale=float(sp.scale), window=None if sp.window is None else int(sp.window),
                      offset=None if sp.offset is None else float(sp.offset))


def _note(log: dict | None, contour, scale, split, quad, cells, bits, det, stage: str) -> None:
    if log is not None:
        log["candidates"].append(CandidateTrace(contour, scale, split, quad, cells, bits, det, stage))


_NEW = object.__new__


def _detection(mid: int, corners: NDArray, hamming: int, margin: float, rotation: int, contrast: float,
               refined: bool, confidence: float, inverted: bool) -> MarkerDetection:
    """``MarkerDetection(mid, corners, ...)`` with its fields set at once (a frozen
    dataclass's ``__init__`` sets each through ``object.__setattr__``: twice the time, for
    the many detections of a tracked video)."""
    d = _NEW(MarkerDetection)
    d.__dict__.update(id=mid, corners=corners, hamming=hamming, margin=margin, rotation=rotation, contrast=contrast,
                      refined=refined, confidence=confidence, inverted=inverted)
    return d


def _take(cells: CellSample, rows: NDArray) -> CellSample:
    """The candidates ``rows`` of a cell sample."""
    return CellSample(cells.cells[rows], cells.ring[rows], None if cells.samples is None else cells.samples[rows])


def _polygons(found: list[tuple[NDArray[np.int32], NDArray[np.int32]]], scale: NDArray) -> NDArray[np.float64]:
    """The polygon corners (K, 4, 2) of a pass's candidates (:func:`find_candidates`' pairs) in
    full-resolution pixels, clockwise, through the pass's (x, y) ``scale``."""
    k = len(found)
    if not k:
        return np.zeros((0, 4, 2))
    approx = _clockwise(np.array([q for _, q in found], np.float64).reshape(k, 4, 2))
    return (approx + 0.5) * scale - 0.5


def _clockwise(quads: NDArray) -> NDArray:
    """Quads (K, 4, 2) ordered clockwise in the image, each from its first corner
    (:func:`visloc.markers.corners.orient_clockwise` for all at once)."""
    ccw = _areas(quads) <= 0
    if ccw.any():
        quads[ccw] = quads[ccw][:, [0, 3, 2, 1]]
    return quads


def _areas(q: NDArray) -> NDArray:
    """Signed areas of quads (..., 4, 2); positive for clockwise quads in y-down images: half
    the cross product of the diagonals (the shoelace sum of a quadrilateral, in 6 operations)."""
    d1 = q[..., 0, :] - q[..., 2, :]
    d2 = q[..., 1, :] - q[..., 3, :]
    return 0.5 * (d1[..., 0] * d2[..., 1] - d2[..., 0] * d1[..., 1])


def _small_in_group(quads: NDArray, small_side: float, packed: float = 1.3) -> NDArray[np.bool_]:
    """(K,): the found markers (K, 4, 2) that stage 3c looks around in a frame of tightly
    packed small tags: small ones (side, the square root of the area, below ``small_side`` px)
    with another found marker within three of their sides (centre to centre), when at least
    two small ones stand closer than ``packed`` times their half extents along the line
    between their centres (the two margins together under 0.3 of a marker: a tag sheet seen
    from afar; a marker grid printed with gaps of half a marker stands at 1.5 in any view)."""
    none = np.zeros(len(quads), bool)
    side = np.sqrt(np.abs(_areas(quads)))
    small = side < small_side
    if small.sum() < 2:
        return none
    c = quads.mean(axis=1)
    diff = c[:, None, :] - c[None, :, :]  # (K, K, 2)
    dist = np.sqrt((diff**2).sum(axis=2))
    np.fill_diagonal(dist, np.inf)
    near = small[:, None] & small[None, :] & (dist < 3.0 * side[:, None])
    i, j = np.nonzero(np.triu(near, 1))
    if not len(i):
        return none
    u = diff[i, j] / dist[i, j, None]  # (P, 2) unit vectors between the pairs' centres

    def half_extent(k: NDArray) -> NDArray:
        p = (quads[k] * u[:, None, :]).sum(axis=2)  # (P, 4) corners along u
        return 0.5 * (p.max(axis=1) - p.min(axis=1))

    if not (dist[i, j] < packed * (half_extent(i) + half_extent(j))).any():
        return none
    return small & (dist < 3.0 * side[:, None]).any(axis=1)


def _same(quads: NDArray) -> NDArray[np.bool_]:
    """(K, K): whether quad i is the same marker as quad j (K, 4, 2): its centre lies within
    15 % of its side of quad j's centre, and its side is within 25 % of quad j's."""
    side = np.sqrt(np.abs(_areas(quads)))
    c = quads.mean(axis=1)
    d2 = ((c[:, None, :] - c[None, :, :]) ** 2).sum(axis=2)
    ratio = side[:, None] / np.maximum(side[None, :], 1e-9)
    return (d2 < (0.15 * side[:, None]) ** 2) & (ratio > 0.8) & (ratio < 1.25)


def _merge_duplicates(found: list[tuple[MarkerDetection, float]]) -> list[MarkerDetection]:
    """Keep one detection per physical marker: of two with the same id whose centres are
    closer than half the smaller one's side, the larger (outer) one stays."""
    if len({d.id for d, _ in found}) == len(found):  # the common case: every id once
        return sorted((d for d, _ in found), key=lambda d: (d.id, d.corners[0, 1], d.corners[0, 0]))
    found = sorted(found, key=lambda fa: -fa[1])
    kept: list[int] = []
    if found:
        ids = np.array([d.id for d, _ in found])
        area = np.array([a for _, a in found])
        c = np.array([d.corners for d, _ in found]).mean(axis=1)
        d2 = ((c[:, None, :] - c[None, :, :]) ** 2).sum(axis=2)
        dup = np.tril((ids[:, None] == ids[None, :]) & (d2 < 0.25 * np.minimum(area[:, None], area[None, :])), -1)
        if not dup.any():  # one id on several markers far apart: all stay
            kept = list(range(len(found)))
        else:
            for i in range(len(found)):
                if not kept or not dup[i, kept].any():
                    kept.append(i)
    dets = [found[i][0] for i in kept]
    return sorted(dets, key=lambda d: (d.id, d.corners[0, 1], d.corners[0, 0]))
