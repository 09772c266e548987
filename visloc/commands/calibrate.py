"""``visloc calibrate``, ``visloc render board`` and ``visloc render calibration``: camera
calibration from a ChArUco board, the board printed to scale, and board views with truth."""

from __future__ import annotations

import argparse
import json
import math
import sys
from contextlib import ExitStack
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from visloc.boards import CharucoBoard, MarkerBoard, calibrate, detect_charuco, detect_marker_board
from visloc.commands._common import frames_of, warn
from visloc.errors import UsageError
from visloc.io import open_source, to_jsonable
from visloc.io.closing import commit_staged, staged_path

#: below this many degrees between the board's normal and the optical axis in every view, the
#: focal length is poorly fixed (Zhang's method needs the board tilted): ``calibrate`` says so
MIN_TILT_DEG = 20.0
#: the image is cut into GRID x GRID cells; fewer than COVERAGE of them holding a corner is
#: reported (the distortion is then fitted from the centre only)
GRID, COVERAGE = 4, 0.75


def _board(path: str) -> CharucoBoard | MarkerBoard:
    """A ChArUco board file (``board_type: charuco``), or a marker map file as a board."""
    try:
        text = Path(path).read_text(errors="replace")
        if "board_type" in text:
            return CharucoBoard.from_file(path)
        if "markers" not in text:
            raise ValueError(f"--board {path}: neither a ChArUco board file (board_type: charuco) nor a marker map "
                             "(a 'markers' list)")
        return MarkerBoard.from_file(path)
    except (ValueError, OSError, OverflowError) as exc:
        raise UsageError(str(exc)) from None


def _charuco_board(path: str) -> CharucoBoard:
    """A ChArUco board file: what ``render board`` and ``render calibration`` draw."""
    board = _board(path)
    if not isinstance(board, CharucoBoard):
        raise UsageError(f"--board {path}: a marker map, not a ChArUco board file (board_type: charuco); "
                         "'visloc render map' draws a map")
    return board


def _find(image, board: CharucoBoard | MarkerBoard, response):
    """The board's points in one image (ChArUco corners, or a marker map's marker corners)."""
    if isinstance(board, MarkerBoard):
        return detect_marker_board(image, board, response=response)
    return detect_charuco(image, board, response=response)


def calibrate_camera(args: argparse.Namespace) -> int:
    """``visloc calibrate``: a camera file from views of a ChArUco board.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``visloc calibrate`` command line (:func:`visloc.cli.build_parser`).

    Returns
    -------
    int
        Exit status: 0; 1 when some frames could not be read (each named on a warning line).
    """
    board = _board(args.board)
    views, names, size, failed = [], [], None, 0
    with ExitStack() as stack:
        source = stack.enter_context(open_source(args.source, fps=None, topic=args.topic))
        for n, frame in enumerate(frames_of(source, args)):
            if n % args.every:
                continue
            if frame.image is None:
                failed += 1
                warn("calibrate", frame.error or f"cannot read {frame.name}")
                continue
            shape = frame.image.shape[1::-1]
            if size is None:
                size = shape
            elif shape != size:
                warn("calibrate", f"{frame.name} is {shape[0]}x{shape[1]}, the first frame {size[0]}x{size[1]}: "
                                  "left out")
                continue
            found = _find(frame.image, board, args.response)
            if len(found) < args.min_corners:
                warn("calibrate", f"{frame.name}: {len(found)} board corners, fewer than --min-corners "
                                  f"{args.min_corners}: left out")
                continue
            views.append(found)
            names.append(frame.name)
    if args.coverage and not cv2.haveImageWriter(args.coverage):
        raise UsageError(f"cannot write {args.coverage}: the name must end in an image extension (e.g. .png)")
    if len(views) < 3:
        raise UsageError(f"calibration needs at least 3 views showing the board with {args.min_corners} or more "
                         f"corners; {len(views)} found in {args.source}")
    try:
        cal = calibrate(views, board, size, model=args.model, min_corners=args.min_corners)
    except (ValueError, cv2.error) as exc:
        raise UsageError(f"calibration failed: {exc}") from None
    staged = staged_path(Path(args.out))
    cal.to_file(staged)
    commit_staged(staged, Path(args.out), keep=True)
    if args.coverage:
        _write_coverage(Path(args.coverage), cal, views, board)
    advice = _advice(cal, views, size)
    if args.json:
        print(json.dumps(to_jsonable(_summary(cal, names) | {"advice": advice}), indent=1))  # NaN: null
    elif not args.quiet:
        _print_summary(cal, names, advice, args.out)
    return 1 if failed else 0


#: residual arrows are drawn this many times their length
ARROW_SCALE = 50.0


def _write_coverage(path: Path, cal, views, board: CharucoBoard) -> None:
    """The coverage picture: the image's GRID x GRID cells, every used view's corners (one
    colour per view) and each corner's reprojection residual as an arrow ARROW_SCALE times its
    length (the calibration's own poses)."""
    w, h = cal.size
    img = np.full((h, w, 3), 255, np.uint8)
    for k in range(1, GRID):
        cv2.line(img, (k * w // GRID, 0), (k * w // GRID, h - 1), (200, 200, 200), 1)
        cv2.line(img, (0, k * h // GRID), (w - 1, k * h // GRID), (200, 200, 200), 1)
    for n, i in enumerate(cal.views):
        v = views[i]
        colour = tuple(int(c) for c in cv2.applyColorMap(np.uint8([[n * 255 // max(len(cal.views) - 1, 1)]]),
                                                           cv2.COLORMAP_TURBO)[0, 0])
        proj = cal.project(board.chessboard_corners[v.ids], n)
        starts = np.rint(v.corners).astype(int)
        ends = np.rint(v.corners + ARROW_SCALE * (proj - v.corners)).astype(int)
        for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
            cv2.circle(img, tuple(a), 3, colour, -1)
            cv2.arrowedLine(img, tuple(a), tuple(b), (0, 0, 0), 1, tipLength=0.3)
    cv2.putText(img, f"{len(cal.views)} views, RMS {cal.rms:.3f} px; arrows x{ARROW_SCALE:g}", (10, 24),
                cv2.FONT_HERSHEY_SIMPLEX, 0.7, (0, 0, 0), 2)
    staged = staged_path(path)
    if not cv2.imwrite(str(staged), img):
        raise UsageError(f"cannot write {path}")
    commit_staged(staged, path, keep=True)


def _summary(cal, names: list[str]) -> dict:
    return {"views": len(cal.views), "rms_px": cal.rms, "fx": cal.K[0, 0], "fy": cal.K[1, 1], "cx": cal.K[0, 2],
            "cy": cal.K[1, 2], "dist": cal.dist.tolist(), "std_fx_fy_cx_cy_dist": cal.std.tolist(),
            "model": cal.model, "size": list(cal.size),
            "per_view_rms_px": {names[i]: float(e) for i, e in zip(cal.views, cal.per_view, strict=True)}}


def _advice(cal, views, size) -> list[str]:
    """Plain advice when the views' coverage of the image or their tilt is poor."""
    out = []
    cells = set()
    for v in views:
        for x, y in v.corners:
            cells.add((min(int(GRID * x / size[0]), GRID - 1), min(int(GRID * y / size[1]), GRID - 1)))
    if len(cells) < COVERAGE * GRID * GRID:
        out.append(f"the corners fall in {len(cells)} of the image's {GRID * GRID} cells ({GRID}x{GRID}): add views "
                   "with the board near the image's edges and corners, where the lens distorts most")
    tilts = [math.degrees(math.acos(min(1.0, abs(Rotation.from_rotvec(r).as_matrix()[2, 2])))) for r in cal.rvecs]
    if max(tilts) < MIN_TILT_DEG:
        out.append(f"the board is within {max(tilts):.0f} degrees of facing the camera in every view: add views "
                   f"tilted {MIN_TILT_DEG:.0f}-45 degrees, which fix the focal length")
    return out


def _print_summary(cal, names: list[str], advice: list[str], out: str) -> None:
    s = [f"{v:.2f}" if math.isfinite(v) else "n/a" for v in cal.std.tolist()]  # fisheye: none from OpenCV
    print(f"calibrated from {len(cal.views)} views ({cal.model}): RMS reprojection error {cal.rms:.3f} px",
          file=sys.stderr)
    print(f"  fx {cal.K[0, 0]:.2f} +- {s[0]}  fy {cal.K[1, 1]:.2f} +- {s[1]}  cx {cal.K[0, 2]:.2f} +- "
          f"{s[2]}  cy {cal.K[1, 2]:.2f} +- {s[3]} px", file=sys.stderr)
    print("  distortion " + " ".join(f"{v:.5f}" for v in cal.dist), file=sys.stderr)
    worst = np.argsort(cal.per_view)[::-1][:3]
    print("  worst views: " + ", ".join(f"{names[cal.views[i]]} {cal.per_view[i]:.3f} px" for i in worst),
          file=sys.stderr)
    for line in advice:
        print(f"  advice: {line}", file=sys.stderr)
    print(f"wrote {out}", file=sys.stderr)


def render_board(args: argparse.Namespace) -> int:
    """``visloc render board``: a ChArUco board file printed to scale.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``visloc render board`` command line (:func:`visloc.cli.build_parser`).

    Returns
    -------
    int
        Exit status: 0.
    """
    if not cv2.haveImageWriter(args.output):
        raise UsageError(f"cannot write {args.output}: the name must end in an image extension (e.g. .png)")
    board = _charuco_board(args.board)
    px = round(board.square_length / 0.0254 * args.dpi)
    if px < 8:
        raise UsageError(f"--dpi {args.dpi} gives {px} px per square: at least 8 are needed")
    if max(board.squares_x, board.squares_y) * px > 40000:
        raise UsageError(f"the sheet would be more than 40000 px on a side at --dpi {args.dpi}")
    image = board.image(px, margin=px // 2)
    out = Path(args.output)
    staged = staged_path(out)
    if not cv2.imwrite(str(staged), image):
        raise UsageError(f"cannot write {out}")
    commit_staged(staged, out, keep=True)
    mm = (image.shape[1] * 25.4 / args.dpi, image.shape[0] * 25.4 / args.dpi)
    print(f"visloc render: wrote {out}, {image.shape[1]}x{image.shape[0]} px = {mm[0]:.0f} x {mm[1]:.0f} mm at "
          f"{args.dpi:g} dpi (squares of {board.square_length * 1000:g} mm: print at 100 %)", file=sys.stderr)
    return 0


def render_calibration(args: argparse.Namespace) -> int:
    """``visloc render calibration``: camera-like views of a ChArUco board with the true camera.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``visloc render calibration`` command line (:func:`visloc.cli.build_parser`).

    Returns
    -------
    int
        Exit status: 0.
    """
    from visloc.synth.calibration import render_calibration_views

    board = _charuco_board(args.board)
    outdir = Path(args.outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    try:
        paths = render_calibration_views(outdir, board, n=args.n, size=args.size, seed=args.seed)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    print(f"visloc render: wrote {len(paths)} views, camera_truth.yml and ground_truth.json to {outdir}",
          file=sys.stderr)
    return 0
