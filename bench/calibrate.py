"""Calibration benchmark: visloc's ChArUco corners and calibration against OpenCV's route.

Camera-like 1280x720 views of a ChArUco board (9 x 6 squares of 30 mm, 22 mm DICT_5X5_100
markers; ``visloc.synth.calibration.calibration_views``: optics blur, shot and read noise,
vignetting, radial distortion k1 = -0.12, k2 = 0.03, the sRGB curve, JPEG 92; tilts up to 45
degrees), three sets of 30 views (seeds 0-2). On the same images, interleaved:

- ``visloc``: ``visloc.boards.detect_charuco`` (visloc's markers, each black square's edges
  fitted by the marker detector's stage 8), then ``visloc.boards.calibrate``;
- ``opencv``: ``cv2.aruco.CharucoDetector`` with its defaults (its chessboard corners refined by
  ``cornerSubPix``), then ``cv2.calibrateCamera``;
- ``opencv_subpix``: the same with the markers' ``CORNER_REFINE_SUBPIX``.

Printed per method: chessboard corners found (of those visible) and their RMS and median error
against the truth; calibrating from views 0-19 of each set (OpenCV's five-coefficient model for
all): the errors of fx, fy, cx, cy (px) and the RMS reprojection error on views 20-29 (their
true corners, each view's pose solved with the calibrated camera by ``solvePnP``); and the time
to calibrate from all 30 views (detection plus solver): each view's detection and the solver
its fastest of three rounds (``--rounds``), the methods interleaved, every call starting when the host runs
at its normal speed (``_timing.Steady``).

A second table does the same for visloc's own marker grid as the board (a 5 x 9 ``GridMap`` of
4 cm DICT_4X4_50 markers, ``marker_map_views``: the same camera and poses, seen from above):
visloc's ``MarkerBoard`` corners against OpenCV's ``ArucoDetector`` corners (default and
SUBPIX) matched to the same map points, each calibrated from all 30 views by the same
``cv2.calibrateCamera``; errors of fx, fy, cx, cy and k1 against the truth; timed as the first.

A third table shows the corners under growing defocus (12 views per optics blur sigma of 0.8,
1.5, 2 and 2.5 px): visloc with its default edge fit and with ``method="saddle"``, and OpenCV's
``CharucoDetector`` (default, SUBPIX).

Usage: ``python bench/calibrate.py [--rounds N]`` (about a minute); writes ``bench/results/calibrate.json`` and ``calibrate.md``.
"""

from __future__ import annotations

import argparse
import platform
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
from _results import fmt, write_results
from _timing import steady, time_sections

from visloc.boards import (
    CharucoBoard,
    CharucoCorners,
    MarkerBoard,
    calibrate,
    detect_charuco,
    detect_marker_board,
)
from visloc.pose.maps import GridMap
from visloc.synth.calibration import CALIBRATION_CAMERA, calibration_views, marker_map_views

ROOT = Path(__file__).resolve().parents[1]
BOARD = CharucoBoard(9, 6, 0.03, 0.022, "DICT_5X5_100")
SIZE = (1280, 720)
N_VIEWS, N_CALIB = 30, 20


def methods() -> dict:
    def opencv(subpix: bool):
        dp = cv2.aruco.DetectorParameters()
        if subpix:
            dp.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        det = cv2.aruco.CharucoDetector(BOARD.opencv, cv2.aruco.CharucoParameters(), dp)

        def run(img):
            corners, ids, _, _ = det.detectBoard(img)
            if ids is None:
                return CharucoCorners(np.zeros(0, np.int64), np.zeros((0, 2)))
            return CharucoCorners(ids.ravel().astype(np.int64), corners.reshape(-1, 2).astype(np.float64))
        return run

    return {"visloc": lambda img: detect_charuco(img, BOARD), "opencv": opencv(False),
            "opencv_subpix": opencv(True)}


def _calibrate(name: str, views: list[CharucoCorners]):
    """(K, dist) from the views: visloc's calibrate for visloc, cv2.calibrateCamera for the peers."""
    if name == "visloc":
        cal = calibrate(views, BOARD, SIZE)
        return cal.K, cal.dist
    use = [v for v in views if len(v) >= 6]
    obj = [BOARD.chessboard_corners[v.ids].astype(np.float32) for v in use]
    img = [v.corners.astype(np.float32).reshape(-1, 1, 2) for v in use]
    _, K, dist, _, _ = cv2.calibrateCamera(obj, img, SIZE, None, None)
    return K, np.ravel(dist)


def _holdout_rms(K, dist, views) -> float:
    """RMS reprojection error of held-out views' true corners, each view's pose solved."""
    err = []
    for v in views:
        ids = np.flatnonzero(v.visible)
        obj, truth = BOARD.chessboard_corners[ids], v.corners[ids]
        ok, rvec, tvec = cv2.solvePnP(obj, truth, K, dist)
        if not ok:
            continue
        rvec, tvec = cv2.solvePnPRefineLM(obj, truth, K, dist, rvec, tvec)
        proj = cv2.projectPoints(obj, rvec, tvec, K, dist)[0].reshape(-1, 2)
        err.extend(np.linalg.norm(proj - truth, axis=1))
    return float(np.sqrt(np.mean(np.square(err))))


#: timing rounds by default: each view's detection and each calibration solve count their fastest
#: of these
ROUNDS = 3


def _detect_and_solve(run_: dict, images: list, solve, rounds: int) -> tuple[dict, dict, dict]:
    """Every method's detections on ``images``, what ``solve(method, detections)`` makes of them,
    and the seconds of both: the sum of each image's fastest detection of ``rounds`` plus the
    fastest solve of as many, the methods interleaved (``_timing.time_sections``)."""
    detect_s, found = time_sections([(images, run_)], rounds)[0]
    # each solve's output in a list: time_sections reads a tuple output, as (K, dist) is, as a
    # peer's (output, its own seconds)
    solves = {m: (lambda _, m=m: [solve(m, found[m])]) for m in run_}
    solve_s, solved = time_sections([([None], solves)], rounds)[0]
    seconds = {m: float(detect_s[m].sum() + solve_s[m][0]) for m in run_}
    return found, {m: out[0][0] for m, out in solved.items()}, seconds


def run(seeds: list[int], rounds: int = ROUNDS) -> dict:
    run_ = methods()
    stats = {m: {"found": 0, "visible": 0, "errors": [], "f_err": [], "c_err": [], "holdout_rms": [], "seconds": []}
             for m in run_}
    for seed in seeds:
        print(f"calibrate: view set {seed} ...", file=sys.stderr, flush=True)
        views = calibration_views(BOARD, N_VIEWS, size=SIZE, seed=seed)
        truth_K = views[0].render.K
        found, _, seconds = _detect_and_solve(run_, [v.image for v in views], _calibrate, rounds)
        for m in run_:
            s = stats[m]
            for view, f in zip(views, found[m], strict=True):
                s["visible"] += int(view.visible.sum())
                s["found"] += len(f)
                s["errors"].extend(np.linalg.norm(f.corners - view.corners[f.ids], axis=1).tolist())
            K, dist = _calibrate(m, found[m][:N_CALIB])
            s["f_err"].extend([abs(K[0, 0] - truth_K[0, 0]), abs(K[1, 1] - truth_K[1, 1])])
            s["c_err"].extend([abs(K[0, 2] - truth_K[0, 2]), abs(K[1, 2] - truth_K[1, 2])])
            s["holdout_rms"].append(_holdout_rms(K, dist, views[N_CALIB:]))
            s["seconds"].append(seconds[m])
    out = {}
    for m, s in stats.items():
        e = np.array(s["errors"])
        out[m] = {"found": s["found"], "visible": s["visible"], "corner_rms_px": float(np.sqrt(np.mean(e**2))),
                  "corner_median_px": float(np.median(e)), "f_err_px_mean": float(np.mean(s["f_err"])),
                  "c_err_px_mean": float(np.mean(s["c_err"])), "holdout_rms_px": float(np.mean(s["holdout_rms"])),
                  "seconds_30_views_median": float(np.median(s["seconds"]))}
    return out


GRID = GridMap(rows=5, cols=9, marker_length=0.04, spacing=0.01, dictionary="DICT_4X4_50")


def _grid_methods() -> dict:
    """The points of a marker grid in one image, per method: visloc's MarkerBoard detection, and
    OpenCV's ArucoDetector (default, SUBPIX) corners matched to the same map points."""
    board = MarkerBoard(GRID)

    def opencv(subpix: bool):
        dp = cv2.aruco.DetectorParameters()
        if subpix:
            dp.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), dp)

        def run(img):
            corners, ids, _ = det.detectMarkers(img)
            rows = [] if ids is None else [(board.row(int(i)), c.reshape(4, 2)) for c, i in zip(corners, ids.ravel())]
            rows = sorted((k, c) for k, c in rows if k is not None)
            if not rows:
                return CharucoCorners(np.zeros(0, np.int64), np.zeros((0, 2)))
            return CharucoCorners(np.concatenate([4 * k + np.arange(4) for k, _ in rows]).astype(np.int64),
                                  np.concatenate([c for _, c in rows]).astype(np.float64))
        return run

    return board, {"visloc": lambda img: detect_marker_board(img, board), "opencv": opencv(False),
                   "opencv_subpix": opencv(True)}


def run_grid(seeds: list[int], rounds: int = ROUNDS) -> dict:
    """visloc's marker-grid board against OpenCV's marker corners on the same views: corners
    against the truth, the focal length, principal point and k1 of a calibration from all views."""
    board, run_ = _grid_methods()
    stats = {m: {"found": 0, "visible": 0, "errors": [], "f_err": [], "c_err": [], "k1_err": [], "seconds": []}
             for m in run_}
    for seed in seeds:
        print(f"calibrate: marker-grid set {seed} ...", file=sys.stderr, flush=True)
        views = marker_map_views(GRID, "DICT_4X4_50", N_VIEWS, size=SIZE, seed=100 + seed)
        K_true = views[0].render.K
        found, cals, seconds = _detect_and_solve(run_, [v.render.image for v in views],
                                                 lambda _, corners: calibrate(corners, board, SIZE), rounds)
        markers = [sorted(v.render.markers, key=lambda t: board.row(t.id)) for v in views]
        for m in run_:
            s = stats[m]
            for tags, f in zip(markers, found[m], strict=True):
                truth = np.concatenate([t.corners for t in tags])
                seen = np.concatenate([np.full(4, t.visible) for t in tags])
                s["visible"] += int(seen.sum())
                s["found"] += len(f)
                s["errors"].extend(np.linalg.norm(f.corners - truth[f.ids], axis=1).tolist())
            cal = cals[m]
            s["seconds"].append(seconds[m])
            s["f_err"].extend([abs(cal.K[0, 0] - K_true[0, 0]), abs(cal.K[1, 1] - K_true[1, 1])])
            s["c_err"].extend([abs(cal.K[0, 2] - K_true[0, 2]), abs(cal.K[1, 2] - K_true[1, 2])])
            s["k1_err"].append(abs(cal.dist[0] - CALIBRATION_CAMERA.k1))
    return {m: {"found": s["found"], "visible": s["visible"],
                "corner_rms_px": float(np.sqrt(np.mean(np.square(s["errors"])))),
                "corner_median_px": float(np.median(s["errors"])), "f_err_px_mean": float(np.mean(s["f_err"])),
                "c_err_px_mean": float(np.mean(s["c_err"])), "k1_err_mean": float(np.mean(s["k1_err"])),
                "seconds_30_views_median": float(np.median(s["seconds"]))} for m, s in stats.items()}


#: optics blur (sigma, px) of the defocus table, and its views per blur
DEFOCUS_BLURS, DEFOCUS_VIEWS = (0.8, 1.5, 2.0, 2.5), 12


def run_defocus(seed: int = 5) -> dict:
    """Corner errors under growing defocus: ``DEFOCUS_VIEWS`` views per optics blur (the
    calibration camera otherwise), visloc's two refinements (``method="edges"``, the default,
    and ``"saddle"``) and OpenCV's ``CharucoDetector`` (default, SUBPIX)."""
    run_ = methods()
    run_["visloc_saddle"] = lambda img: detect_charuco(img, BOARD, method="saddle")
    out = {}
    for blur in DEFOCUS_BLURS:
        print(f"calibrate: defocus {blur} px ...", file=sys.stderr, flush=True)
        views = calibration_views(BOARD, DEFOCUS_VIEWS, size=SIZE, seed=seed,
                                  camera=replace(CALIBRATION_CAMERA, blur_sigma=blur))
        row = {}
        for m, run_m in run_.items():
            e, visible = [], 0
            for view in views:
                f = run_m(view.image)
                e.extend(np.linalg.norm(f.corners - view.corners[f.ids], axis=1).tolist())
                visible += int(view.visible.sum())
            e = np.array(e)
            row[m] = {"found": len(e), "visible": visible,
                      "corner_rms_px": float(np.sqrt(np.mean(e**2))) if len(e) else None,
                      "corner_median_px": float(np.median(e)) if len(e) else None,
                      "corner_max_px": float(e.max()) if len(e) else None}
        out[str(blur)] = row
    return out


def markdown(result: dict) -> str:
    res = result["methods"]
    lines = [(f"\n**ChArUco calibration**, {SIZE[0]}x{SIZE[1]} camera-like views of a 9 x 6 board, "
             f"{len(result['seeds'])} sets of {N_VIEWS} views (calibrated from {N_CALIB}, {N_VIEWS - N_CALIB} held out; "
             f"errors against the truth; seconds: each view's detection and the solve, the fastest of {result['rounds']} "
             "interleaved rounds, the median over the sets)\n"),
             ("| method | corners found / visible | corner RMS px | corner median px | fx, fy error px (mean) | "
             "cx, cy error px (mean) | held-out reprojection RMS px | s to calibrate from 30 views |"),
             "|---|---|---|---|---|---|---|---|"]
    for m, s in res.items():
        lines.append(f"| {m} | {s['found']}/{s['visible']} | {fmt(s['corner_rms_px'])} | {fmt(s['corner_median_px'])} | "
                     f"{fmt(s['f_err_px_mean'], 2)} | {fmt(s['c_err_px_mean'], 2)} | {fmt(s['holdout_rms_px'], 4)} | "
                     f"{fmt(s['seconds_30_views_median'], 2)} |")
    if "grid" in result:
        lines += [(f"\n**Marker-grid board** (visloc's `GridMap` printed, 5 x 9 DICT_4X4_50 markers of 4 cm; the "
                   f"same camera-like {SIZE[0]}x{SIZE[1]} views, {len(result['seeds'])} sets of {N_VIEWS}; each "
                   "method's marker corners into the same `cv2.calibrateCamera`; errors against the truth; timed as the "
                   "first table)\n"),
                  ("| method | corners found / of markers 2 px inside the image | corner RMS px | corner median px | "
                   "fx, fy error px (mean) | cx, cy error px (mean) | k1 error (mean) | s to detect + calibrate 30 views |"),
                  "|---|---|---|---|---|---|---|---|"]
        for m, s in result["grid"].items():
            lines.append(f"| {m} | {s['found']}/{s['visible']} | {fmt(s['corner_rms_px'])} | "
                         f"{fmt(s['corner_median_px'])} | {fmt(s['f_err_px_mean'], 2)} | {fmt(s['c_err_px_mean'], 2)} | "
                         f"{fmt(s['k1_err_mean'], 4)} | {fmt(s['seconds_30_views_median'], 2)} |")
    if "defocus" in result:
        lines += [(f"\n**ChArUco corners under defocus** ({DEFOCUS_VIEWS} camera-like {SIZE[0]}x{SIZE[1]} views per "
                   "optics blur sigma, the board's white margins 4 mm on 30 mm squares; errors against the truth)\n"),
                  "| blur sigma px | method | corners found / visible | corner RMS px | corner median px | worst px |",
                  "|---|---|---|---|---|---|"]
        for blur, row in result["defocus"].items():
            for m, s in row.items():
                lines.append(f"| {blur} | {m} | {s['found']}/{s['visible']} | {fmt(s['corner_rms_px'])} | "
                             f"{fmt(s['corner_median_px'])} | {fmt(s['corner_max_px'], 2)} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=ROUNDS,
                    help="timing rounds: each detection and solve counts its fastest (the errors do not change)")
    ap.add_argument("--out", default=str(ROOT / "bench/results"))
    args = ap.parse_args(argv)
    seeds = list(range(args.sets))
    result = {"machine": {"python": sys.version.split()[0], "opencv": cv2.__version__, "numpy": np.__version__,
                          "platform": platform.platform(), "cores": len(__import__("os").sched_getaffinity(0))},
              "seeds": seeds, "rounds": args.rounds, "methods": run(seeds, args.rounds),
              "grid": run_grid(seeds, args.rounds), "defocus": run_defocus()}
    result["steady"] = steady().summary()
    write_results(args.out, "calibrate", result, markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
