"""Real photographs with geometric truth: marker corners against a ChArUco board's own geometry.

The other real-photo table (``bench/real_photos.py``) measures corners against references the
peers made, so it favours them. The two ChArUco photos of OpenCV's tutorial
(``datasets/real/choriginal.jpg`` and ``chocclusion_original.jpg``, Apache-2.0, see
``datasets/real/manifest.json``) carry a truth of their own: the board (OpenCV's tutorial board,
5 x 7 squares of 40 mm, 20 mm DICT_6X6_250 markers centred in the white squares: the sample's
``-w=5 -h=7 -sl=0.04 -ml=0.02 -d=10``) fixes where every marker corner lies relative to the
chessboard corners around it. The chessboard corners are X-junctions of two dark and two light
squares: they stay where they are under blur and under any grey-level response (the sRGB curve,
a camera's tone curve), unlike the edges of a marker on white.

Truth, per marker: the chessboard corners within ``--radius`` squares (Chebyshev, board plane)
of the marker's centre, as OpenCV's ``CharucoDetector.detectBoard`` finds them (``cornerSubPix``
on each X-junction), give a homography (least squares, 6 corners or more: a local fit absorbs
the lens distortion); the marker's four board corners through it are its truth. The truth's
own error is estimated two ways: each chessboard corner predicted from its neighbours the same
way (leave-one-out), and a second truth from visloc's saddle fit of the X-junctions
(``visloc.boards.detect_charuco(method="saddle")``), independent of any marker corner but its
start.

Methods on the grey image (``cv2.IMREAD_GRAYSCALE``): ``visloc`` (defaults), ``visloc_linear``
(``response="linear"``: edges in encoded grey levels, as the peers measure them), OpenCV's
``ArucoDetector`` with default parameters and each of its corner refinements (``SUBPIX``,
``CONTOUR``, ``APRILTAG``; the last shifted by -0.5 px to OpenCV's pixel-centre convention, which
brings it from 0.67 to 0.39 px median on ``choriginal.jpg``). AprilTag 3 reads no 6x6 ArUco
dictionary. Per method: the markers with a truth it found, the corner distance to the truth
(median, RMS, 90th percentile, px) and the mean radial offset (px, + = outward from the marker's
centre: a detector that finds the edges of black on white inside the black, as the intensity
midpoint of encoded grey levels does, has a negative one). Accuracy only: no timing, so a re-run
prints the same table.

Usage::

    python bench/real_truth.py [--radius 1.6] [--out bench/results]

Writes ``real_truth.json`` and ``real_truth.md``.
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import cv2
import numpy as np
from _results import fmt, write_results

from visloc.boards import CharucoBoard, detect_charuco
from visloc.markers import MarkerDetector

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT / "datasets/real"
IMAGES = ["choriginal.jpg", "chocclusion_original.jpg"]
#: OpenCV's tutorial board (samples/python/aruco_detect_board_charuco.py: -w=5 -h=7 -sl=0.04 -ml=0.02 -d=10)
BOARD = CharucoBoard(5, 7, 0.04, 0.02, "DICT_6X6_250")
SQUARE_M, DICTIONARY = BOARD.square_length, BOARD.dictionary
MIN_NEIGHBOURS = 6
OPENCV_REFINES = {"opencv": "CORNER_REFINE_NONE", "opencv_subpix": "CORNER_REFINE_SUBPIX",
                  "opencv_contour": "CORNER_REFINE_CONTOUR", "opencv_apriltag": "CORNER_REFINE_APRILTAG"}
METHODS = ["visloc", "visloc_linear", *OPENCV_REFINES]


def _local_homography(plane: np.ndarray, image: np.ndarray, centre: np.ndarray, radius: float,
                      skip: int | None = None) -> np.ndarray | None:
    """Least-squares homography board plane -> image from the corners (N, 2) within ``radius``
    squares of ``centre`` (board metres), leaving out index ``skip``; None below
    :data:`MIN_NEIGHBOURS` corners."""
    near = np.flatnonzero(np.abs(plane - centre).max(axis=1) < radius * SQUARE_M)
    near = near[near != skip] if skip is not None else near
    if len(near) < MIN_NEIGHBOURS:
        return None
    H, _ = cv2.findHomography(plane[near].astype(np.float64), image[near].astype(np.float64), 0)
    return H


def _through(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    return cv2.perspectiveTransform(np.asarray(pts, np.float64).reshape(-1, 1, 2), H).reshape(-1, 2)


def board_truth(chess_ids: np.ndarray, chess_px: np.ndarray, radius: float) -> tuple[dict, set, list[float]]:
    """Marker id -> truth corners (4, 2) in OpenCV's order from the chessboard corners found
    (ids (N,), pixels (N, 2)); the ids of the interior markers (all four corners of the
    marker's own square found: the truth is interpolated, not extrapolated towards the board's
    edge); and the leave-one-out errors (px) of the chessboard corners."""
    chess = BOARD.chessboard_corners[:, :2]
    plane = chess[chess_ids]
    truth, interior = {}, set()
    for mid, obj in zip(BOARD.marker_ids.tolist(), BOARD.marker_corners[:, :, :2], strict=True):
        centre = obj.mean(axis=0)
        H = _local_homography(plane, chess_px, centre, radius)
        if H is None:
            continue
        truth[mid] = _through(H, obj)
        own = np.flatnonzero(np.abs(chess - centre).max(axis=1) < 0.6 * SQUARE_M)  # the square's corners
        if len(own) == 4 and np.isin(own, chess_ids).all():
            interior.add(mid)
    loo = []
    for j in range(len(chess_ids)):
        H = _local_homography(plane, chess_px, plane[j], radius, skip=j)
        if H is not None:
            loo.append(float(np.linalg.norm(_through(H, plane[j]) - chess_px[j])))
    return truth, interior, loo


def opencv_chess(gray: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's ChArUco corners (ids (N,), pixels (N, 2))."""
    corners, ids, _, _ = cv2.aruco.CharucoDetector(BOARD.opencv).detectBoard(gray)
    if ids is None:
        return np.zeros(0, int), np.zeros((0, 2))
    return ids.ravel().astype(int), corners.reshape(-1, 2).astype(np.float64)


def visloc_chess(gray: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """visloc's saddle-fitted ChArUco corners (ids (N,), pixels (N, 2))."""
    found = detect_charuco(gray, BOARD, method="saddle")
    return np.asarray(found.ids, int).ravel(), np.asarray(found.corners, np.float64).reshape(-1, 2)


def detect(method: str, gray: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """(id, corners (4, 2), OpenCV order and pixel convention) of one method's markers."""
    if method.startswith("visloc"):
        det = MarkerDetector(DICTIONARY, response="linear" if method == "visloc_linear" else "srgb")
        return [(d.id, np.asarray(d.corners, np.float64)) for d in det.detect(gray)]
    p = cv2.aruco.DetectorParameters()
    p.cornerRefinementMethod = getattr(cv2.aruco, OPENCV_REFINES[method])
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, DICTIONARY))
    corners, ids, _ = cv2.aruco.ArucoDetector(d, p).detectMarkers(gray)
    shift = -0.5 if method == "opencv_apriltag" else 0.0  # AprilTag's +0.5 px convention
    return [] if ids is None else [(int(i), c.reshape(4, 2).astype(np.float64) + shift)
                                   for c, i in zip(corners, ids.ravel(), strict=True)]


def errors(dets: list[tuple[int, np.ndarray]], truth: dict) -> tuple[list[float], list[float], int]:
    """Per-corner distances and radial offsets (px, + outward) of the detections with a truth,
    and how many markers that is (an id found twice counts once: the nearer)."""
    dist, radial, seen = [], [], {}
    for mid, c in dets:
        if mid not in truth:
            continue
        d = np.linalg.norm(c - truth[mid], axis=1)
        if mid not in seen or d.mean() < seen[mid][0].mean():
            seen[mid] = (d, c)
    for mid, (d, c) in seen.items():
        t = truth[mid]
        u = (t - t.mean(axis=0)) / np.linalg.norm(t - t.mean(axis=0), axis=1, keepdims=True)
        dist += d.tolist()
        radial += ((c - t) * u).sum(axis=1).tolist()
    return dist, radial, len(seen)


def summary(dist: list[float], radial: list[float], found: int, of: int, dist2: list[float]) -> dict:
    d = np.asarray(dist)
    return {"found": found, "with_truth": of,
            "median_px": float(np.median(d)) if len(d) else None,
            "rms_px": float(np.sqrt(np.mean(d**2))) if len(d) else None,
            "p90_px": float(np.percentile(d, 90)) if len(d) else None,
            "radial_mean_px": float(np.mean(radial)) if radial else None,
            "median_px_saddle_truth": float(np.median(dist2)) if dist2 else None}


SCOPES = ("all", "interior")


def run(radius: float) -> dict:
    """Every method on every image against both truths, for all markers with a truth and for
    the interior ones."""
    images = []
    pooled = {(sc, m): ([], [], 0, 0, []) for sc in SCOPES for m in METHODS}
    for name in IMAGES:
        gray = cv2.imread(str(REAL / name), cv2.IMREAD_GRAYSCALE)
        if gray is None:
            raise FileNotFoundError(REAL / name)
        ids, px = opencv_chess(gray)
        truth, interior, loo = board_truth(ids, px, radius)
        ids2, px2 = visloc_chess(gray)
        truth2 = board_truth(ids2, px2, radius)[0]
        common = sorted(set(ids.tolist()) & set(ids2.tolist()))
        agree = [float(np.linalg.norm(px[ids == i][0] - px2[ids2 == i][0])) for i in common]
        row = {"image": name, "size": [gray.shape[1], gray.shape[0]], "chess_corners": len(ids),
               "markers_with_truth": len(truth), "interior_markers": sorted(interior),
               "loo_median_px": float(np.median(loo)), "loo_max_px": float(np.max(loo)),
               "saddle_agreement_median_px": float(np.median(agree)), "methods": {}}
        for m in METHODS:
            dets = detect(m, gray)
            row["methods"][m] = {}
            for sc in SCOPES:
                t = truth if sc == "all" else {k: v for k, v in truth.items() if k in interior}
                dist, radial, found = errors(dets, t)
                dist2 = errors(dets, {k: v for k, v in truth2.items() if k in t})[0]
                row["methods"][m][sc] = summary(dist, radial, found, len(t), dist2)
                acc = pooled[sc, m]
                pooled[sc, m] = (acc[0] + dist, acc[1] + radial, acc[2] + found, acc[3] + len(t), acc[4] + dist2)
        images.append(row)
    return {"radius_squares": radius, "images": images,
            "pooled": {sc: {m: summary(*pooled[sc, m]) for m in METHODS} for sc in SCOPES},
            "machine": {"python": platform.python_version(), "opencv": cv2.__version__, "numpy": np.__version__,
                        "platform": platform.platform()},
            "date": time.strftime("%Y-%m-%d %H:%M")}


def markdown(res: dict) -> str:
    """The tables the README shows."""
    lines = [(f"**Real photographs with geometric truth** (OpenCV's two ChArUco tutorial photos, 640x480; a "
             "marker's truth: its board corners through a homography fitted to the chessboard corners within "
             f"{res['radius_squares']:g} squares of its centre, as OpenCV's `CharucoDetector` finds them; "
             "interior: markers whose own square's four corners were found (interpolated truth); radial: "
             "mean offset along the marker's diagonals, + outward)"), "",
             ("| image | chessboard corners | markers with truth (interior) | truth leave-one-out median / max px "
             "| OpenCV vs visloc saddle chessboard corners, median px |"), "|---|---|---|---|---|"]
    for r in res["images"]:
        lines.append(f"| {r['image']} | {r['chess_corners']} | {r['markers_with_truth']} "
                     f"({len(r['interior_markers'])}) | {fmt(r['loo_median_px'], 2)} / {fmt(r['loo_max_px'], 2)} | "
                     f"{fmt(r['saddle_agreement_median_px'], 2)} |")
    lines += ["", ("| markers | method | found / with truth | corner median px | corner RMS px | corner p90 px "
              "| radial mean px | corner median px, saddle truth |"), "|---|---|---|---|---|---|---|---|"]
    for sc, rows in res["pooled"].items():
        for m, s in rows.items():
            lines.append(f"| {sc} | {m} | {s['found']}/{s['with_truth']} | {fmt(s['median_px'])} | "
                         f"{fmt(s['rms_px'])} | {fmt(s['p90_px'])} | {_signed(s['radial_mean_px'])} | "
                         f"{fmt(s['median_px_saddle_truth'])} |")
    return "\n".join(lines) + "\n"


def _signed(v: float | None) -> str:
    return "–" if v is None else f"{v:+.3f}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--radius", type=float, default=1.6,
                    help="chessboard corners within this many squares of a marker's centre fit its homography")
    ap.add_argument("--out", default=str(ROOT / "bench/results"))
    a = ap.parse_args(argv)
    if not 1.0 < a.radius <= 4.0:
        ap.error("--radius must be above 1 (the marker's own square) and at most 4 squares")
    res = run(a.radius)
    write_results(a.out, "real_truth", res, markdown(res))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
