"""``visloc`` command line: argparse sub-commands, one-line errors, exit codes.

Exit codes: 0 success; 1 some frames failed (unreadable images, ...); 2 usage or
configuration errors (missing path, unknown dictionary, malformed camera file, an output that
would overwrite an input, ...); 3 an internal error (a bug: one line, ``--debug`` anywhere on
the line shows the traceback); 130 interrupted (everything already computed is kept).
"""

from __future__ import annotations

import argparse
import glob
import importlib
import os
import sys
from collections.abc import Sequence
from functools import lru_cache
from pathlib import Path
from typing import NoReturn

from visloc import __version__
from visloc.errors import UsageError

__all__ = ["UsageError", "build_parser", "check_inputs", "check_outputs", "main"]



def _positive(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (0 < v < float("inf")):  # also rejects NaN
        raise argparse.ArgumentTypeError(f"must be a positive finite number, got {text!r}")
    return v


def _at_most(limit: float, why: str):
    """An argparse type: a positive finite number no larger than ``limit`` (``why`` says why)."""

    def parse(text: str) -> float:
        v = _positive(text)
        if v > limit:
            raise argparse.ArgumentTypeError(f"must be at most {limit:g} ({why}), got {text!r}")
        return v

    return parse


def _seed(text: str) -> int:
    """An argparse type: a random seed, a whole number >= 0 (numpy's seeds)."""
    return _whole(text, 0, " (a random seed)")


#: most frames ``render localize`` and ``render flow`` hold in memory (seconds x fps)
MAX_RENDER_FRAMES = 5000


def _response(text: str) -> str | float:
    if text in ("srgb", "linear"):
        return text
    try:
        g = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected srgb, linear or a gamma, got {text!r}") from None
    if not (0 < g < 10):
        raise argparse.ArgumentTypeError(f"a gamma must be in (0, 10), got {text!r}")
    return g


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 640x480, got {text!r}") from None
    if w < 16 or h < 16:
        raise argparse.ArgumentTypeError(f"image size must be at least 16x16, got {text!r}")
    return w, h


def _frame_range(text: str) -> tuple[int, int | None]:
    """``START:STOP`` (frame indices, STOP excluded) or ``START:`` (to the end)."""
    a, sep, b = text.partition(":")
    try:
        start, stop = int(a), (int(b) if b.strip() else None)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected START:STOP or START: (frame indices), got {text!r}") from None
    if not sep or start < 0 or (stop is not None and stop <= start):
        raise argparse.ArgumentTypeError(f"expected START:STOP with 0 <= START < STOP, or START:, got {text!r}")
    return start, stop


def _whole(text: str, low: int, note: str = "") -> int:
    """A whole number of at least ``low`` (``note`` says what it is), or an argparse error."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if v < low:
        raise argparse.ArgumentTypeError(f"must be at least {low}{note}, got {text!r}")
    return v


def _count(text: str) -> int:
    return _whole(text, 1)


def _demo_frames(text: str) -> int:
    """``demo --frames``: 1 to 1000 (a demonstration; ``visloc render markers`` makes datasets)."""
    v = _whole(text, 1)
    if v > 1000:
        raise argparse.ArgumentTypeError(f"must be at most 1000 (a demonstration: 'visloc render markers' "
                                         f"makes datasets), got {text!r}")
    return v


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line on stderr (exit status 2)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


#: help of ``--fast`` (detect, localize, track): ``visloc.markers.FAST_PASSES``
_FAST_HELP = "search shrunk images only: about 15-30%% faster at 640x480 and above, misses markers under about 20 px"
#: help of ``--response`` (detect, localize, track): ``DetectorParams.response``
_RESPONSE_HELP = ("how grey levels encode light, for sub-pixel corners: srgb (cameras, most image files; "
                  "the default), linear (linear sensor data, renders made with --linear) or a gamma")


def build_parser() -> argparse.ArgumentParser:
    """The ``visloc`` argument parser with its sub-commands."""
    parser = _Parser(
        prog="visloc",
        description="Visual localisation for small drones and robots: square fiducial markers "
        "(the report's staged detector) and their poses, camera pose over marker maps, ground "
        "velocity from a downward camera, state estimation, and synthetic renders with exact truth.",
    )
    parser.add_argument("--version", action="version", version=f"visloc {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    _add_detect(sub)
    _add_render(sub)
    _add_flow(sub)
    _add_calibrate(sub)
    _add_localize(sub)
    _add_track(sub)
    _add_model(sub)
    _add_robust(sub)
    _add_sim(sub)
    _add_demo(sub)
    _add_info(sub)
    _add_batch(sub)
    return parser


def _add_detect(sub: argparse._SubParsersAction) -> None:
    """The ``visloc detect`` sub-command's arguments."""
    d = sub.add_parser("detect", help="detect markers (and poses) in images, folders, videos or a camera")
    d.add_argument("source", help="image, folder, glob pattern, video file, ROS bag / MCAP or camera index")
    _topic(d)
    d.add_argument("--dict", default="DICT_4X4_50", metavar="NAME|FILE",
                   help="OpenCV dictionary name or dictionary YAML file (default: DICT_4X4_50)")
    d.add_argument("--camera", metavar="FILE", help="camera file (OpenCV YAML) for poses")
    d.add_argument("--marker-length", type=_positive, metavar="M",
                   help="marker side in metres (black border included) for poses")
    d.add_argument("--out", metavar="FILE.jsonl", help="write one JSON object per frame")
    d.add_argument("--annotate", metavar="DIR|FILE.mp4", help="write annotated frames")
    d.add_argument("--rerun", metavar="FILE.rrd", help="write a rerun recording")
    d.add_argument("--explain", metavar="DIR", help="write every detector stage's picture per frame")
    d.add_argument("--fps", type=_positive, help="frame rate for image lists (frame times)")
    d.add_argument("--mavlink", nargs="?", const="udpout:127.0.0.1:14550", metavar="URL",
                   help="send the --target-id marker as LANDING_TARGET (precision landing) to a flight stack: a "
                        "pymavlink connection string (default udpout:127.0.0.1:14550; needs visloc[mavlink])")
    d.add_argument("--target-id", type=int, metavar="N", help="the landing pad's marker id (with --mavlink)")
    d.add_argument("--frame-range", type=_frame_range, metavar="START:STOP",
                   help="only frames START <= index < STOP (START: to the end), with their indices and times in the "
                        "whole source (visloc batch --chunk splits a video this way)")
    _detection_tail(d)


def _add_render(sub: argparse._SubParsersAction) -> None:
    """The ``visloc render`` sub-command's arguments."""
    r = sub.add_parser("render", help="render synthetic data with exact ground truth")
    rs = r.add_subparsers(dest="what", metavar="WHAT", parser_class=_Parser)
    rm = rs.add_parser("markers", help="random marker scenes (images or a video) + ground_truth.json")
    rm.add_argument("outdir", help="output folder")
    rm.add_argument("--n", type=_count, default=100, help="number of frames (default 100)")
    rm.add_argument("--seed", type=_seed, default=1, help="random seed (default 1)")
    rm.add_argument("--size", type=_size, default=(640, 480), help="WIDTHxHEIGHT (default 640x480)")
    rm.add_argument("--dict", default="DICT_4X4_50", metavar="NAME|FILE", help="dictionary")
    rm.add_argument("--difficulty", default="easy", choices=["easy", "hard", "small", "dark", "empty"])
    rm.add_argument("--linear", action="store_true",
                    help="linear renders (grey levels linear in light, no lens) instead of camera-like "
                         "frames (lens distortion, blur, noise, vignetting, sRGB, JPEG)")
    rm.add_argument("--video", action="store_true", help="write markers.mp4 of a moving camera instead")
    rp = rs.add_parser("map", help="a printable image of a marker map (its z = 0 plane)")
    rp.add_argument("map", help="marker map (OpenCV YAML)")
    rp.add_argument("output", help="output image (.png)")
    rp.add_argument("--dict", default=None, metavar="NAME|FILE", help="marker dictionary (default: the one the map records, else DICT_4X4_50)")
    rp.add_argument("--dpi", type=_at_most(2400, "a printer's resolution"), default=300.0,
                    help="dots per inch (default 300, at most 2400)")
    rl = rs.add_parser("localize", help="a downward camera flying over a marker grid + ground truth")
    rl.add_argument("outdir", help="output folder")
    rl.add_argument("--seconds", type=_positive, default=5.0, help="duration (default 5 s)")
    rl.add_argument("--fps", type=_positive, default=30.0, help="frame rate (default 30)")
    rl.add_argument("--seed", type=_seed, default=1, help="random seed (default 1)")
    rf = rs.add_parser("flow", help="a downward camera's flight over ground + ground_truth.csv")
    rf.add_argument("outdir", help="output folder")
    rf.add_argument("--seconds", type=_positive, default=10.0, help="duration (default 10 s)")
    rf.add_argument("--fps", type=_positive, default=60.0, help="frame rate (default 60)")
    rf.add_argument("--seed", type=_seed, default=1, help="random seed (default 1)")
    rf.add_argument("--size", type=_size, default=(320, 240), help="WIDTHxHEIGHT (default 320x240)")
    rf.add_argument("--texture", default="grass", choices=["grass", "gravel", "brick", "noise"])
    rf.add_argument("--video", action="store_true", help="write flight.mp4 instead of PNG frames")
    rb = rs.add_parser("board", help="a ChArUco board file printed to scale (PNG)")
    rb.add_argument("board", help="board file (YAML: board_type charuco, squares_x, squares_y, ...)")
    rb.add_argument("output", help="output image (.png)")
    rb.add_argument("--dpi", type=_at_most(2400, "a printer's resolution"), default=300.0,
                    help="dots per inch (default 300, at most 2400)")
    rc = rs.add_parser("calibration", help="camera-like views of a ChArUco board + the true camera")
    rc.add_argument("outdir", help="output folder")
    rc.add_argument("--board", required=True, metavar="BOARD.yml", help="board file")
    rc.add_argument("--n", type=_count, default=30, help="number of views (default 30, at most 500)")
    rc.add_argument("--size", type=_size, default=(1280, 720), help="WIDTHxHEIGHT (default 1280x720)")
    rc.add_argument("--seed", type=_seed, default=0, help="random seed (default 0)")


def _add_calibrate(sub: argparse._SubParsersAction) -> None:
    """The ``visloc calibrate`` sub-command's arguments."""
    cb = sub.add_parser("calibrate", help="a camera file from views of a ChArUco board (cv2.calibrateCamera)")
    cb.add_argument("source", help="image folder, glob pattern, video file or ROS bag / MCAP of the board")
    _topic(cb)
    cb.add_argument("--board", required=True, metavar="BOARD.yml", help="board file (see visloc render board)")
    cb.add_argument("--out", required=True, metavar="CAMERA.yml", help="camera file to write (OpenCV YAML)")
    cb.add_argument("--model", default="k1k2p1p2k3", choices=("pinhole-k1k2", "k1k2p1p2k3", "rational", "fisheye"),
                    help="distortion model (default k1k2p1p2k3, OpenCV's five coefficients; fisheye: "
                         "cv2.fisheye's four, for lenses of 120 degrees and more)")
    cb.add_argument("--every", type=_count, default=1, metavar="N", help="use every Nth frame (default 1)")
    cb.add_argument("--min-corners", type=_count, default=6, metavar="N",
                    help="views with fewer board corners are left out (default 6, at least 6)")
    cb.add_argument("--response", type=_response, default="srgb", metavar="srgb|linear|GAMMA", help=_RESPONSE_HELP)
    cb.add_argument("--max-frames", type=_count, metavar="N", help="stop after N frames")
    cb.add_argument("--coverage", metavar="FILE.png",
                    help="write a picture of where the corners fell and their residuals (arrows x50)")
    cb.add_argument("--json", action="store_true", help="print the result as JSON")
    cb.add_argument("--quiet", action="store_true", help="no progress bar or summary")


def _add_flow(sub: argparse._SubParsersAction) -> None:
    """The ``visloc flow`` sub-command's arguments."""
    fl = sub.add_parser("flow", help="ground velocity of a downward camera from its frames (block flow)")
    fl.add_argument("source", help="folder, glob pattern, video file, ROS bag / MCAP or camera index")
    _topic(fl)
    fl.add_argument("--camera", required=True, metavar="FILE", help="camera file (OpenCV YAML)")
    hg = fl.add_mutually_exclusive_group(required=True)
    hg.add_argument("--height", type=_positive, metavar="H", help="height above the ground, m")
    hg.add_argument("--height-csv", metavar="FILE", help="CSV with columns frame,height (e.g. heights.csv)")
    fl.add_argument("--fps", type=_positive, help="frame rate (required for image folders)")
    fl.add_argument("--method", default="similarity", choices=["similarity", "cir"],
                    help="global-motion solver (default: similarity; cir = report Appendix H)")
    fl.add_argument("--direct", action="store_true",
                    help="add the sub-pixel stage (direct alignment of the similarity): more accurate, slower")
    fl.add_argument("--shadows", action="store_true",
                    help="with --direct: align each frame divided by its local mean, so moving shadows, vignetting "
                         "and uneven light do not read as motion (about 0.25 ms more per frame at 320x240)")
    fl.add_argument("--out", metavar="FILE.csv", help="write one row per frame")
    fl.add_argument("--rerun", metavar="FILE.rrd", help="write a rerun recording")
    gy = fl.add_mutually_exclusive_group()
    gy.add_argument("--imu", metavar="FILE.csv", help="IMU log (t,gx,gy,gz,... rad/s in camera axes): each pair's "
                                                    "roll and pitch rotation is removed from its flow")
    gy.add_argument("--imu-topic", metavar="TOPIC", help="the sensor_msgs/Imu topic of a ROS bag or MCAP source, as "
                                                         "--imu (its axes taken as the camera's)")
    fl.add_argument("--mavlink", nargs="?", const="udpout:127.0.0.1:14550", metavar="URL",
                    help="send each pair's flow as OPTICAL_FLOW_RAD (camera axes) to a flight stack: a pymavlink "
                         "connection string (default udpout:127.0.0.1:14550; needs visloc[mavlink])")
    fl.add_argument("--max-frames", type=_count, metavar="N", help="stop after N frames")
    fl.add_argument("--quiet", action="store_true", help="no progress bar or summary")


def _add_localize(sub: argparse._SubParsersAction) -> None:
    """The ``visloc localize`` sub-command's arguments."""
    lz = sub.add_parser("localize", help="camera position and velocity over a marker map (pose + Kalman filter)")
    _source_and_camera(lz)
    lz.add_argument("--map", required=True, metavar="MAP.yml", help="marker map (OpenCV YAML)")
    lz.add_argument("--dict", default=None, metavar="NAME|FILE", help="marker dictionary (default: the one the map records, else DICT_4X4_50)")
    lz.add_argument("--fps", type=_positive, help="frame rate (required for image folders)")
    lz.add_argument("--accel-noise", type=_positive, default=2.0, metavar="A",
                    help="Kalman process noise: white acceleration std, m/s^2 (default 2)")
    imu = lz.add_mutually_exclusive_group()
    imu.add_argument("--imu", metavar="FILE.csv", help="IMU log (t,gx,gy,gz,fx,fy,fz; specific force in camera axes)")
    imu.add_argument("--imu-topic", metavar="TOPIC", help="the sensor_msgs/Imu topic of a ROS bag or MCAP source "
                                                         "(its axes taken as the camera's)")
    lz.add_argument("--truth", metavar="FILE.csv", help="ground truth (t,x,y,z columns) to compare with")
    lz.add_argument("--out", metavar="FILE.csv", help="write one row per frame")
    lz.add_argument("--rerun", metavar="FILE.rrd", help="write a rerun recording (estimate vs truth)")
    _mavlink_options(lz, "every fix as VISION_POSITION_ESTIMATE (or ODOMETRY)")
    lz.add_argument("--mavlink-message", choices=("vision", "odometry"), default="vision",
                    help="VISION_POSITION_ESTIMATE (default) or ODOMETRY (with velocity)")
    _detection_tail(lz)


def _mavlink_options(p: argparse.ArgumentParser, what: str) -> None:
    """``--mavlink`` and ``--map-frame`` (visloc.io.mavlink)."""
    p.add_argument("--mavlink", nargs="?", const="udpout:127.0.0.1:14550", metavar="URL",
                   help=f"send {what} to a flight stack: a pymavlink connection string (default "
                        "udpout:127.0.0.1:14550; needs visloc[mavlink])")
    p.add_argument("--map-frame", choices=("nwu", "enu"), default="nwu",
                   help="how the map's x, y, z lie in the flight stack's NED frame: nwu (x north, y west, z up; "
                        "default) or enu (x east, y north, z up)")


def _add_track(sub: argparse._SubParsersAction) -> None:
    """The ``visloc track`` sub-command's arguments."""
    tk = sub.add_parser("track", help="a body's markers relative to reference markers, seen by a fixed camera")
    _source_and_camera(tk)
    tk.add_argument("--body", required=True, metavar="BODY.yml", help="marker map of the tracked body")
    tk.add_argument("--reference", required=True, metavar="REF.yml", help="marker map of the reference")
    tk.add_argument("--dict", default=None, metavar="NAME|FILE", help="marker dictionary (default: the one the map records, else DICT_4X4_50)")
    tk.add_argument("--out", metavar="FILE.jsonl", help="write one JSON pose per frame")
    tk.add_argument("--udp", nargs="?", const="127.0.0.1:5005", metavar="HOST:PORT",
                    help="also send each JSON pose as a UDP datagram (default 127.0.0.1:5005)")
    tk.add_argument("--fps", type=_positive, help="frame rate (required for image folders: the observer needs frame times)")
    tk.add_argument("--poles", type=float, nargs=2, default=(-4.0, -4.0), metavar="P",
                    help="velocity observer poles, 1/s (report eq. 3.14; default -4 -4)")
    _mavlink_options(tk, "the body's pose as VISION_POSITION_ESTIMATE (the reference map is the local frame)")
    _detection_tail(tk)


def _add_batch(sub: argparse._SubParsersAction) -> None:
    """The ``visloc batch`` sub-command's arguments."""
    b = sub.add_parser("batch", help="one command over many recordings on Dask (local cores or a cluster)")
    b.add_argument("batch_command", metavar="COMMAND", nargs="?", choices=("detect", "localize", "flow", "track"),
                   help="detect, localize, flow or track (or in --job)")
    b.add_argument("recordings", nargs="*", metavar="RECORDING",
                   help="videos, image folders, bags (glob patterns are expanded; or in --job)")
    b.add_argument("--job", metavar="JOB.toml", help="a job file: command, recordings, outdir, options, workers, "
                                                     "scheduler, chunk, force (the command line's values win)")
    b.add_argument("--outdir", metavar="DIR", help="one output per recording (NAME.jsonl or NAME.csv) and summary.csv")
    b.add_argument("--options", default=None, metavar="'OPTIONS'",
                   help="the command's options as one quoted string, e.g. '--dict DICT_4X4_100 --fps 30'")
    b.add_argument("--workers", type=_count, metavar="N", help="local worker processes (default: one per core)")
    b.add_argument("--scheduler", metavar="ADDRESS", help="a running Dask scheduler, e.g. tcp://10.0.0.5:8786")
    b.add_argument("--force", action="store_true", help="run every recording, even those with an up-to-date output")
    b.add_argument("--chunk", type=_count, metavar="FRAMES",
                   help="detect only: split each recording into tasks of FRAMES frames; the outputs are joined in "
                        "frame order (the same file as one task's)")
    b.add_argument("--quiet", action="store_true", help="no progress bar or summary")


def _add_info(sub: argparse._SubParsersAction) -> None:
    """The ``visloc info`` sub-command's arguments."""
    inf = sub.add_parser("info", help="what a source holds: a recording's topics, a video's or folder's frames")
    inf.add_argument("source", help="ROS bag / MCAP, video file, image, folder or glob pattern")
    inf.add_argument("--json", action="store_true", help="print JSON instead of a table")


def _add_model(sub: argparse._SubParsersAction) -> None:
    """The ``visloc model`` sub-command's arguments."""
    md = sub.add_parser("model", help="the AR.Drone 2.0 model: identified parameters, hover trim, linear poles")
    md.add_argument("--json", action="store_true", help="print JSON instead of a table")


def _add_robust(sub: argparse._SubParsersAction) -> None:
    """The ``visloc robust`` sub-command's arguments."""
    rb = sub.add_parser("robust", help="robust stability of the hover controller over the propulsion box")
    rb.add_argument("--sigma", type=float, default=3.0, metavar="N",
                    help="box half-width in standard deviations of c and d (default 3)")
    rb.add_argument("--tilt", type=float, default=0.0, metavar="DEG",
                    help="the tracking loop's check: also linearised in steady sideways accelerations at +-DEG "
                         "roll (a trajectory's tilt; 768 matrices, one Lyapunov matrix for all); default 0: hover")
    rb.add_argument("--json", action="store_true", help="print JSON instead of a table")


def _add_sim(sub: argparse._SubParsersAction) -> None:
    """The ``visloc sim`` sub-command's arguments."""
    sm = sub.add_parser("sim", help="closed-loop simulation: model, sensors, visloc's estimators, controller")
    sm.add_argument("scenario", choices=("hover", "sidestep", "push", "hover-vision", "step", "square", "figure8"),
                    help="hover 10 s; sidestep: 1 m in y (report Fig. 4.6); push: 4 N for 0.1 s "
                         "(Fig. 4.5); hover-vision: 30 s on the marker-grid vision pipeline; step: --distance "
                         "m in y along a minimum-jerk trajectory with feed-forward (--plain: a set-point step); square: "
                         "--side m at up to --speed m/s (--vision: on the marker-grid vision); figure8: --side m wide, as square")
    sm.add_argument("--distance", type=_at_most(100, "a side step in a room or a field"), default=5.0, metavar="M",
                    help="the step scenario's distance, m (default 5)")
    sm.add_argument("--plain", action="store_true", help="step: jump the set point as the report does, no trajectory")
    sm.add_argument("--unbounded", action="store_true",
                    help="without the report's bound on the set-point torques (section 4.4): the controller before it, "
                         "which large --plain steps tip over")
    sm.add_argument("--side", type=_at_most(100, "a square in a room or a field"), default=1.25, metavar="M",
                    help="the square scenario's side, m (default 1.25)")
    sm.add_argument("--speed", type=_positive, default=0.5, metavar="M/S", help="the square's speed limit (default 0.5)")
    sm.add_argument("--vision", action="store_true", help="square: fly on visloc's marker-grid vision")
    sm.add_argument("--seconds", type=_at_most(3600, "an hour of flight; every control step is kept"),
                    help="simulated duration (default: the scenario's; at most 3600)")
    sm.add_argument("--sigma", type=float, default=0.0, metavar="N",
                    help="draw each motor's c, d at +-N standard deviations (signs from --seed; default 0)")
    sm.add_argument("--seed", type=_seed, default=0, help="seed of motor signs, sensor noise, turbulence (default 0)")
    sm.add_argument("--warmup", type=float, metavar="S",
                    help="seconds of hover before t = 0 so the integrators absorb the motor spread "
                         "(default 20 with --sigma > 0, else 0)")
    sm.add_argument("--camera-rate", type=_positive, default=30.0, metavar="HZ",
                    help="bottom-camera rate for hover-vision (default 30)")
    sm.add_argument("--redetect-every", type=_count, default=10, metavar="N",
                    help="vision scenarios: N > 1 follows the markers from frame to frame, the map's markers in "
                         "the last fix's view joining at once, with a full marker detection only when following "
                         "fails (any N > 1 alike); 1: the full detection on every frame (default 10)")
    sm.add_argument("--motor-lag", type=float, default=0.0, metavar="S",
                    help="first-order motor time constant, s (report eq. 2.13; default 0)")
    sm.add_argument("--out", metavar="RUN.csv", help="write time, state, estimate, set point, pwm per control step")
    sm.add_argument("--plot", metavar="OUT.png", help="plot position, attitude and motor commands")
    sm.add_argument("--rerun", metavar="OUT.rrd", help="write a rerun recording")
    sm.add_argument("--json", action="store_true", help="print JSON instead of a table")
    sm.add_argument("--quiet", action="store_true", help="no progress bar")


def _add_demo(sub: argparse._SubParsersAction) -> None:
    """The ``visloc demo`` sub-command's arguments."""
    m = sub.add_parser("demo", help="render a few frames, detect markers and poses, print a table")
    m.add_argument("--out", default="visloc-demo", metavar="DIR", help="output folder (default ./visloc-demo)")
    m.add_argument("--frames", type=_demo_frames, default=6, help="number of frames, 1-1000 (default 6)")
    m.add_argument("--seed", type=_seed, default=7, help="random seed (default 7)")


def _source_and_camera(p: argparse.ArgumentParser) -> None:
    """The frame source and the required camera file of ``localize`` and ``track``."""
    p.add_argument("source", help="image, folder, glob pattern, video file, ROS bag / MCAP or camera index")
    _topic(p)
    p.add_argument("--camera", required=True, metavar="FILE", help="camera file (OpenCV YAML)")


def _topic(p: argparse.ArgumentParser) -> None:
    """``--topic``: a recording's image topic."""
    p.add_argument("--topic", metavar="TOPIC", help="the image topic of a ROS bag or MCAP source (sensor_msgs/Image "
                                                   "or CompressedImage; needed when it has several; needs visloc[ros])")


def _detection_tail(p: argparse.ArgumentParser) -> None:
    """``--max-frames``, the detector options and ``--quiet``, last of ``detect``, ``localize``, ``track``."""
    p.add_argument("--max-frames", type=_count, metavar="N", help="stop after N frames")
    _detector_arguments(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")


def _detector_arguments(p: argparse.ArgumentParser) -> None:
    """The marker detector's options, shared by ``detect``, ``localize`` and ``track``."""
    p.add_argument("--fast", action="store_true", help=_FAST_HELP)
    p.add_argument("--response", type=_response, default="srgb", metavar="srgb|linear|GAMMA", help=_RESPONSE_HELP)
    p.add_argument("--border-bits", type=int, default=1, choices=(1, 2, 3),
                   help="width of the markers' black border in cells (default 1)")
    p.add_argument("--inverted", default="no", choices=("no", "yes", "both"),
                   help="white-on-black markers: no (default), yes (only those), both")
    p.add_argument("--redetect-every", type=_count, default=1, metavar="N",
                   help="videos: the full marker search every Nth frame only, the markers of the last frames "
                        "followed between (confirmed by the edge refinement and the cell read; one that fails is "
                        "dropped, and a frame where a quarter fail gets the full search); markers coming into "
                        "view wait for the next full search, except in localize: there the map's markers in the "
                        "last fix's view are followed too, and the full search runs only when following fails, "
                        "whatever N > 1 (default 1: every frame)")


#: sub-command -> (module of visloc.commands, function)
_COMMANDS = {"detect": ("markers", "detect"), "render": ("markers", "render"), "demo": ("demo", "demo"),
             "flow": ("flow", "flow"), "track": ("localize", "track"), "localize": ("localize", "localize"),
             "model": ("model", "model"), "robust": ("robust", "robust"), "sim": ("sim", "sim"),
             "calibrate": ("calibrate", "calibrate_camera"), "info": ("info", "info"),
             "batch": ("batch", "batch")}

#: options naming files or folders a command reads, and those it writes
_INPUTS = ("source", "camera", "map", "height_csv", "imu", "truth", "dict", "body", "reference", "board", "job")
_OUTPUTS = ("out", "annotate", "rerun", "explain", "plot", "outdir", "output", "coverage")


def _input_options(args: argparse.Namespace) -> list[tuple[str, str]]:
    """(option, value) of every input option given on a parsed command line."""
    return [(name, v) for name in _INPUTS if isinstance(v := getattr(args, name, None), str) and v]


def _inputs(args: argparse.Namespace) -> tuple[list[Path], list[Path]]:
    """The input files and folders of a parsed command line (globs expanded), resolved."""
    files, folders = [], []
    for name, v in _input_options(args):
        p = Path(v)
        if p.is_dir():
            folders.append(p.resolve())
        elif p.is_file():
            files.append(p.resolve())
        elif name == "source" and glob.has_magic(v):
            files += [Path(f).resolve() for f in glob.glob(v)]
    return files, folders


def check_inputs(args: argparse.Namespace) -> None:
    """Refuse (:class:`UsageError`) an input file or folder that does not exist, before the
    command's modules are imported. A ``source`` that is a camera index, a glob pattern or a
    URL is left to the command, as is ``--dict`` (a dictionary name or a file).

    Parameters
    ----------
    args : argparse.Namespace
        A parsed command line (:func:`build_parser`).

    Raises
    ------
    UsageError
        Naming the option and the path.
    """
    for name, v in _input_options(args):
        if name == "dict" or name == "source" and (v.isdigit() or glob.has_magic(v) or "://" in v):
            continue
        if not Path(v).exists():
            if name == "source":
                raise UsageError(f"path does not exist: {v}")
            raise UsageError(f"{name.replace('_', '-')} file {v} does not exist")


def check_outputs(args: argparse.Namespace) -> None:
    """Refuse (:class:`UsageError`) an output path that is one of the command's input files,
    is or lies inside an input folder, or is a folder holding an input file (the run would
    overwrite what it reads), or that cannot be written (checked before any work is done).

    Parameters
    ----------
    args : as :func:`check_inputs`

    Raises
    ------
    UsageError
        Naming the output and the input it would overwrite, or why it cannot be written.
    """
    files, folders = _inputs(args)
    for name in _OUTPUTS:
        v = getattr(args, name, None)
        if not isinstance(v, str) or not v:
            continue
        out = Path(v).resolve()
        what = f"--{name.replace('_', '-')} {v}" if name != "outdir" else f"output folder {v}"
        same = out in files or (out.is_file() and any(os.path.samefile(out, f) for f in files))
        if same:
            raise UsageError(f"{what} is an input of this run: it would be overwritten")
        for f in folders:
            if out == f or f in out.parents:
                raise UsageError(f"{what} lies in the input folder {f}: write outputs elsewhere")
        for f in files:
            if out in f.parents:
                raise UsageError(f"{what} holds the input {f}: write outputs elsewhere")
        near = next(a for a in (out, *out.parents) if a.exists())  # the nearest folder that exists
        if near != out and not near.is_dir():
            raise UsageError(f"{what}: cannot write there ({near} is a file, not a folder)")
        if not os.access(near if near.is_dir() else near.parent, os.W_OK):
            raise UsageError(f"{what}: cannot write there ({near} is not writable)")


@lru_cache(maxsize=1)
def _shared_parser() -> argparse.ArgumentParser:
    """The process's one parser, built at the first call. Building it takes about 10 ms: most
    of a ``visloc batch`` task on a short recording, where :func:`main` runs once per task in
    the same worker process. Parsing does not change the parser, so one serves every call."""
    return build_parser()


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``visloc`` command line.

    Parameters
    ----------
    argv : sequence of str, optional
        The arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit status: 0 success, 1 some frames could not be read (or the command's own
        meaning, e.g. ``sim``: crashed), 2 a usage or configuration problem, 3 an internal
        error, 130 interrupted (README, "Exit status").
    """
    parser = _shared_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv  # accepted anywhere on the line
    args = parser.parse_args([a for a in argv if a != "--debug"])
    args.debug = debug
    if args.command is None:
        parser.print_help(sys.stderr)
        return 2
    if args.command == "render" and args.what is None:
        parser.parse_args(["render", "--help"])
    if args.command == "render" and args.what in ("localize", "flow") and args.seconds * args.fps > MAX_RENDER_FRAMES:
        print(f"visloc render: error: render {args.what}: --seconds x --fps is {args.seconds * args.fps:g} frames, "
              f"at most {MAX_RENDER_FRAMES} (they are rendered in memory)", file=sys.stderr)
        return 2
    # only the sub-command's own module is imported (late: `visloc --help`, `visloc model` and
    # configuration errors stay fast)
    module, name = _COMMANDS[args.command]
    try:
        check_inputs(args)  # before the command's imports: a missing file is said at once
        check_outputs(args)
        run = getattr(importlib.import_module(f"visloc.commands.{module}"), name)
        return run(args)
    except KeyboardInterrupt:
        print("visloc: interrupted; results written so far are kept", file=sys.stderr)
        return 130
    except (UsageError, ValueError, OSError) as exc:
        if args.debug:
            raise
        if type(exc) is ValueError and getattr(args, "started", False):  # inputs accepted: a bug
            return _internal(args, exc)
        print(f"visloc {args.command}: error: {exc}", file=sys.stderr)  # the input's or configuration's fault
        return 2
    except Exception as exc:  # a bug, not the user's input (TypeError included: the commands build
        # every object the library is given)
        if args.debug:
            raise
        return _internal(args, exc)


def _internal(args: argparse.Namespace, exc: BaseException) -> int:
    """Report an internal error on one line (exit status 3)."""
    print(f"visloc {args.command}: internal error: {type(exc).__name__}: {exc} (rerun with --debug for the "
          "traceback)", file=sys.stderr)
    return 3


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
