"""``MarkerDetector``: the report's staged square-marker detector (Appendix G, Figure G.1).

One frame's path: grey (1) -> blur (2) -> adaptive threshold (3) -> outer contours (4) ->
candidate filter (5) -> radial-peak corner split (6) -> line fits (7) -> bit sampling and
border check (9) -> dictionary match (10) -> sub-pixel edge refinement on the grey image (8)
-> duplicate merge. Edge refinement, the costliest step per candidate, runs after decoding so
that only real markers pay for it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc.markers.binarize import blur, default_window, threshold, to_gray
from visloc.markers.bits import CellSample, decode, read_bits, sample_cells
from visloc.markers.contours import CandidateFilter, filter_candidates, find_contours
from visloc.markers.corners import _NEXT, RadialSplit, fit_quad
from visloc.markers.dictionary import Dictionary, load_dictionary
from visloc.markers.refine import refine_quads
from visloc.types import MarkerDetection

__all__ = ["CandidateTrace", "DetectionTrace", "DetectorParams", "MarkerDetector"]


@dataclass(frozen=True)
class DetectorParams:
    """Parameters of :class:`MarkerDetector` (defaults chosen with ``bench/markers.py``).

    Attributes
    ----------
    decimate : float or None
        Stages 2-7 (the candidate search) run on the image shrunk by this factor; stages 8-10
        always use the full-resolution grey image. ``None``: shrink so the short side is
        ``search_height`` pixels (never enlarge).
    search_height : int
        See ``decimate``. At 320, markers of 3.5 % of the image height or more are found.
    blur_sigma : float
        Stage 2 Gaussian blur, px.
    window : int or None
        Stage 3 adaptive-threshold window (odd, px); ``None`` = 1/40 of the image's short side.
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
        Stage 8 profile half-width, px; ``None`` = 0.4 cell, clipped to [1, 3].
    refine_iterations : int
        Stage 8 passes.
    border_error_rate : float
        Stage 9: tolerated white border cells, as a fraction of the bit count (OpenCV: 0.35).
    error_correction_rate : float
        Stage 10: fraction of the dictionary's correction capacity used (OpenCV: 0.6).
    """

    decimate: float | None = None
    search_height: int = 320
    blur_sigma: float = 0.8
    window: int | None = None
    offset: float = 7.0
    candidates: CandidateFilter = field(default_factory=CandidateFilter)
    corner_sigma: float | None = None
    corner_padding: float = 0.1
    refine: bool = True
    refine_radius: int | None = None
    refine_iterations: int = 2
    border_error_rate: float = 0.35
    error_correction_rate: float = 0.6


@dataclass(frozen=True, eq=False)
class CandidateTrace:
    """What happened to one candidate contour (for ``--explain``).

    ``stage`` is where it stopped: ``"corners"``, ``"bits"``, ``"dictionary"``, ``"refine"``,
    ``"duplicate"`` or ``"accepted"``.
    """

    contour: NDArray[np.int32]
    split: RadialSplit | None
    line_corners: NDArray[np.float64] | None
    cells: CellSample | None
    bits: NDArray[np.uint8] | None
    detection: MarkerDetection | None
    stage: str


@dataclass(frozen=True, eq=False)
class DetectionTrace:
    """Every stage's intermediate result for one image (report Figure G.1, panels B-I)."""

    gray: NDArray[np.uint8]
    blurred: NDArray[np.uint8]
    binary: NDArray[np.uint8]
    contours: list[NDArray[np.int32]]
    candidates: list[CandidateTrace]
    detections: list[MarkerDetection]


class MarkerDetector:
    """Detect square fiducial markers of one dictionary.

    Parameters
    ----------
    dictionary : str or Dictionary
        An OpenCV predefined name (``"DICT_4X4_50"``, ``"DICT_APRILTAG_36h11"``, ...) or the
        path of an OpenCV dictionary YAML file.
    **params
        Fields of :class:`DetectorParams` (e.g. ``window=15``, ``refine=False``).

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
        self.params = replace(DetectorParams(), **params)  # type: ignore[arg-type]

    def __repr__(self) -> str:
        return f"MarkerDetector({self.dictionary.name!r}, {self.params})"

    def detect(self, image: NDArray[np.uint8]) -> list[MarkerDetection]:
        """Markers in ``image`` (uint8 grey or BGR), sorted by id."""
        return self._run(image, None)

    def trace(self, image: NDArray[np.uint8]) -> DetectionTrace:
        """Run :meth:`detect` keeping every stage's intermediate result."""
        log: dict = {"candidates": []}
        dets = self._run(image, log)
        return DetectionTrace(
            log["gray"], log["blurred"], log["binary"], log["contours"], log["candidates"], dets
        )

    def _decimation(self, shape: tuple[int, ...]) -> float:
        """Factor by which stages 2-7 shrink the image (1 = full resolution)."""
        d = self.params.decimate
        if d is None:
            return max(1.0, min(shape[:2]) / self.params.search_height)
        return float(d)

    def _run(self, image: NDArray[np.uint8], log: dict | None) -> list[MarkerDetection]:
        p = self.params
        gray = to_gray(image)  # stage 1
        f = self._decimation(gray.shape)
        work = gray
        if f > 1:
            size = (round(gray.shape[1] / f), round(gray.shape[0] / f))
            work = cv2.resize(gray, size, interpolation=cv2.INTER_AREA)
        scale = np.array([gray.shape[1] / work.shape[1], gray.shape[0] / work.shape[0]])
        blurred = blur(work, p.blur_sigma)  # stage 2
        window = p.window if p.window is not None else default_window(work.shape)
        binary = threshold(blurred, window=window, offset=p.offset)  # stage 3
        contours = find_contours(binary)  # stage 4
        cands = filter_candidates(contours, work.shape, p.candidates)  # stage 5
        if log is not None:
            log.update(gray=gray, blurred=blurred, binary=binary, contours=contours)
        quads, splits, kept = [], [], []
        for contour, approx in cands:  # stages 6-7, one contour at a time
            res = fit_quad(contour, sigma=p.corner_sigma, padding=p.corner_padding, hint=approx)
            if res is None:
                _note(log, contour, None, None, None, None, None, "corners")
                continue
            quads.append(res[0])
            splits.append(res[1])
            kept.append(contour)
        if not quads:
            return []
        quads_a = (np.array(quads) + 0.5) * scale - 0.5  # back to full-resolution pixel centres
        n_cells = self.dictionary.marker_size + 2
        # cheap, lenient look at the cells first: most texture candidates end here, before
        # they cost an edge refinement
        pre = read_bits(sample_cells(gray, quads_a, n_cells), 0.5)[0]
        if not pre.any():
            for i in range(len(quads_a)):
                _note(log, kept[i], splits[i], quads_a[i], None, None, None, "bits")
            return []
        if not pre.all():
            for i in np.flatnonzero(~pre):
                _note(log, kept[i], splits[i], quads_a[i], None, None, None, "bits")
            sel = np.flatnonzero(pre)
            quads_a = quads_a[sel]
            kept = [kept[i] for i in sel]
            splits = [splits[i] for i in sel]
        corners = quads_a
        refined_ok = np.ones(len(quads_a), bool)
        if p.refine:  # stage 8, batched
            side = np.sqrt(np.abs(_areas(quads_a)))
            radii = np.full(len(quads_a), p.refine_radius or 0)
            if not p.refine_radius:
                radii = np.clip(np.round(0.4 * side / n_cells), 1, 3).astype(int)
            corners, refined_ok = refine_quads(gray, quads_a, radius=radii, iterations=p.refine_iterations)
        cells = sample_cells(gray, corners, n_cells)  # stage 9, batched
        valid, bits, margin, contrast = read_bits(cells, p.border_error_rate)
        ids, shift, hamming, matched = decode(bits, self.dictionary, p.error_correction_rate)  # 10
        good = refined_ok & valid & matched
        found: list[tuple[MarkerDetection, float]] = []
        for i in range(len(quads_a)):
            if not good[i]:
                if log is not None:
                    stage = "refine" if not refined_ok[i] else "bits" if not valid[i] else "dictionary"
                    b = bits[i] if valid[i] else None
                    _note(log, kept[i], splits[i], quads_a[i], _cells_at(cells, i), b, None, stage)
                continue
            c = np.roll(corners[i], -int(shift[i]), axis=0)
            det = MarkerDetection(
                int(ids[i]), c, int(hamming[i]), float(margin[i]), int(shift[i]), float(contrast[i])
            )
            found.append((det, abs(_area(c))))
            _note(log, kept[i], splits[i], quads_a[i], _cells_at(cells, i), bits[i], det, "accepted")
        dets = _merge_duplicates(found)
        if log is not None and len(dets) < len(found):
            kept_ids = {id(d) for d in dets}
            for j, c in enumerate(log["candidates"]):
                if c.detection is not None and id(c.detection) not in kept_ids:
                    log["candidates"][j] = replace(c, stage="duplicate")
        return dets


def _cells_at(cells: CellSample, i: int) -> CellSample:
    return CellSample(cells.cells[i : i + 1], cells.ring[i : i + 1])


def _areas(q: NDArray) -> NDArray:
    x, y = q[..., 0], q[..., 1]
    return 0.5 * ((x * y[..., _NEXT]).sum(-1) - (x[..., _NEXT] * y).sum(-1))


def _note(log: dict | None, contour, split, quad, cells, bits, det, stage: str) -> None:
    if log is not None:
        log["candidates"].append(CandidateTrace(contour, split, quad, cells, bits, det, stage))


def _area(q: NDArray) -> float:
    return float(_areas(q))


def _merge_duplicates(found: list[tuple[MarkerDetection, float]]) -> list[MarkerDetection]:
    """Keep one detection per physical marker: of two with the same id whose centres are
    closer than half the smaller one's side, the larger (outer) one stays."""
    found = sorted(found, key=lambda fa: -fa[1])
    kept: list[tuple[MarkerDetection, float]] = []
    for det, area in found:
        c = det.center
        dup = any(
            k.id == det.id and np.hypot(*(k.center - c)) < 0.5 * np.sqrt(min(area, a))
            for k, a in kept
        )
        if not dup:
            kept.append((det, area))
    return sorted((d for d, _ in kept), key=lambda d: (d.id, d.corners[0, 1], d.corners[0, 0]))
