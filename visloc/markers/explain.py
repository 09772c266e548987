"""Pictures of every detector stage, so a user can see why a marker was missed.

The panels follow the report's Figure G.1: B binary image, C contours (grey: borders that
enclose no hole, which no marker's can; orange: the ones the candidate filter saw; thick:
candidates, coloured by the stage they stopped at), D radial distance profiles with their
peaks, E side groups, F fitted corners, G sampled bits, I detections.
Each candidate also gets a line in ``<stem>_candidates.json`` naming the stage it stopped at.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc.markers.detector import CandidateTrace, DetectionTrace

__all__ = ["explain_panels", "write_explain"]

_STAGE_COLOURS = {
    "corners": (128, 128, 128),
    "bits": (0, 140, 255),
    "dictionary": (0, 215, 255),
    "duplicate": (255, 128, 0),
    "accepted": (0, 200, 0),
}
_SIDE_COLOURS = [(0, 0, 255), (0, 200, 0), (255, 0, 0), (0, 200, 255)]


def _bgr(gray: NDArray[np.uint8]) -> NDArray[np.uint8]:
    return cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)


def _poly(img: NDArray, pts: NDArray, colour, closed: bool = True, thickness: int = 1) -> None:
    p = np.round(np.asarray(pts, np.float64) * 16).astype(np.int32).reshape(-1, 1, 2)
    cv2.polylines(img, [p], closed, colour, thickness, cv2.LINE_AA, shift=4)


def _full(contour: NDArray, scale: float) -> NDArray[np.float64]:
    """Contour points of a pass image in full-resolution pixel coordinates."""
    return (contour.astype(np.float64) + 0.5) * scale - 0.5


def _radial_plot(c: CandidateTrace, width: int = 320, height: int = 120) -> NDArray[np.uint8]:
    """Panel D for one candidate: distance to the centre (grey), smoothed (blue), peaks (red)."""
    img = np.full((height, width, 3), 255, np.uint8)
    s = c.split
    if s is None:
        cv2.putText(img, "no 4 peaks", (10, 60), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 200), 1)
        return img
    n = len(s.distance)
    lo, hi = float(s.distance.min()), float(s.distance.max()) + 1e-9
    x = np.linspace(5, width - 5, n)

    def y(v):
        return height - 10 - (v - lo) / (hi - lo) * (height - 20)

    _poly(img, np.stack([x, y(s.distance)], 1), (160, 160, 160), closed=False)
    _poly(img, np.stack([x, y(s.smoothed)], 1), (200, 80, 0), closed=False)
    for p in s.peaks:
        cv2.circle(img, (int(x[p]), int(y(s.smoothed[p]))), 4, (0, 0, 255), -1)
    return img


def _bits_tile(c: CandidateTrace, size: int = 96) -> NDArray[np.uint8]:
    """Panel G for one candidate: the cell means as a picture, ring included."""
    img = np.full((size, size, 3), 255, np.uint8)
    if c.cells is None:
        return img
    cells = c.cells.cells[0]
    n = cells.shape[0]
    tile = cv2.resize(np.clip(cells, 0, 255).astype(np.uint8), (size - 16, size - 16), interpolation=cv2.INTER_NEAREST)
    img[8:-8, 8:-8] = _bgr(tile)
    step = (size - 16) / n
    for k in range(n + 1):
        v = round(8 + k * step)
        cv2.line(img, (8, v), (size - 9, v), (0, 0, 255), 1)
        cv2.line(img, (v, 8), (v, size - 9), (0, 0, 255), 1)
    cv2.rectangle(img, (0, 0), (size - 1, size - 1), _STAGE_COLOURS[c.stage], 3)
    return img


def _tiles(tiles: list[NDArray[np.uint8]], per_row: int) -> NDArray[np.uint8]:
    if not tiles:
        return np.full((40, 320, 3), 255, np.uint8)
    h, w = tiles[0].shape[:2]
    rows = (len(tiles) + per_row - 1) // per_row
    out = np.full((rows * h, per_row * w, 3), 255, np.uint8)
    for i, t in enumerate(tiles):
        r, c = divmod(i, per_row)
        out[r * h : (r + 1) * h, c * w : (c + 1) * w] = t
    return out


def explain_panels(trace: DetectionTrace, *, max_candidates: int = 48) -> dict[str, NDArray[np.uint8]]:
    """Panels B-I of report Figure G.1 as BGR images.

    Parameters
    ----------
    trace : DetectionTrace
        One image's stages (:meth:`visloc.markers.MarkerDetector.trace`).
    max_candidates : int
        How many of the candidates (the first ones) the candidate panels show.

    Returns
    -------
    dict of str to ndarray (h, w, 3) uint8
        BGR panels keyed by file suffix: ``B_binary_pass<k>`` (each search pass's binary
        image, at the pass's scale), ``C_contours``, ``E_groups``, ``F_corners`` and
        ``I_detections`` (the size of ``trace.gray``), and the tile sheets ``D_radial``
        (radial profiles) and ``G_bits`` (sampled cells).
    """
    cands = trace.candidates[:max_candidates]
    panels: dict[str, NDArray[np.uint8]] = {}
    c_img = _bgr(trace.gray // 2 + 64)
    for k, ps in enumerate(trace.passes):
        panels[f"B_binary_pass{k}"] = _bgr(ps.binary)
        for contour, encloses in zip(ps.contours, ps.enclosing.tolist(), strict=True):
            # grey: encloses no hole (no marker can); orange: went on to the candidate filter
            _poly(c_img, _full(contour, ps.scale), (0, 160, 255) if encloses else (150, 150, 150))
    for c in cands:
        _poly(c_img, _full(c.contour, c.scale), _STAGE_COLOURS[c.stage], thickness=2)
    panels["C_contours"] = c_img

    panels["D_radial"] = _tiles([_radial_plot(c) for c in cands], per_row=3)

    e_img = _bgr(trace.gray)
    f_img = _bgr(trace.gray)
    for c in cands:
        if c.split is None:
            continue
        pts = _full(c.contour, c.scale)
        for k, g in enumerate(c.split.groups):
            for p in pts[g]:
                cv2.circle(e_img, (int(p[0]), int(p[1])), 1, _SIDE_COLOURS[k], -1)
        if c.line_corners is not None:
            _poly(f_img, c.line_corners, _STAGE_COLOURS[c.stage])
            for p in c.line_corners:
                cv2.drawMarker(f_img, (round(p[0]), round(p[1])), (0, 0, 255), cv2.MARKER_CROSS, 7)
    panels["E_groups"] = e_img
    panels["F_corners"] = f_img
    panels["G_bits"] = _tiles([_bits_tile(c) for c in cands if c.cells is not None], per_row=8)

    i_img = _bgr(trace.gray)
    for d in trace.detections:
        _poly(i_img, d.corners, (0, 200, 0), thickness=2)
        p0 = d.corners[0]
        cv2.circle(i_img, (round(p0[0]), round(p0[1])), 4, (0, 0, 255), -1)
        cx, cy = d.center
        cv2.putText(i_img, str(d.id), (int(cx) - 8, int(cy) + 5), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 0, 0), 2)
    panels["I_detections"] = i_img
    return panels


def write_explain(trace: DetectionTrace, outdir: str | Path, *, stem: str = "frame") -> list[Path]:
    """Write the panels of :func:`explain_panels` and a candidate list.

    Parameters
    ----------
    trace : DetectionTrace
        One image's stages (:meth:`visloc.markers.MarkerDetector.trace`).
    outdir : str or Path
        Output folder, created if missing; files already there are overwritten.
    stem : str
        Prefix of the file names.

    Returns
    -------
    list of Path
        The written files: ``<outdir>/<stem>_<panel>.png`` per panel, then
        ``<stem>_candidates.json``, listing every candidate's bounding box (``[x, y, w, h]``,
        full-resolution px), the stage it stopped at, and its id if decoded.

    Raises
    ------
    OSError
        If a panel cannot be written.
    """
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, img in explain_panels(trace).items():
        p = out / f"{stem}_{name}.png"
        if not cv2.imwrite(str(p), img):
            raise OSError(f"cannot write {p}")
        written.append(p)
    rows = []
    for c in trace.candidates:
        full = _full(c.contour, c.scale)
        lo, hi = full.min(axis=0), full.max(axis=0)
        row = {"bbox": [round(float(v), 1) for v in (*lo, *(hi - lo))], "pass_scale": c.scale, "stage": c.stage}
        if c.detection is not None:
            row["id"] = c.detection.id
        if c.bits is not None:
            row["bits"] = c.bits.astype(int).tolist()
        rows.append(row)
    summary = {
        "passes": [{"scale": ps.scale, "window": ps.window, "contours": len(ps.contours),
                    "enclosing_a_hole": int(ps.enclosing.sum())} for ps in trace.passes],
        "candidates": rows,
        "detections": [d.to_dict() for d in trace.detections],
    }
    p = out / f"{stem}_candidates.json"
    p.write_text(json.dumps(summary, indent=1))
    written.append(p)
    return written
