"""``visloc flow`` and ``visloc render flow``: ground velocity of a downward camera."""

from __future__ import annotations

import argparse
import sys
import time
from contextlib import ExitStack

import numpy as np
from tqdm import tqdm

from visloc.commands._common import (
    camera_for,
    frames_of,
    imu_input,
    mean_between,
    open_timed_source,
    warn,
)
from visloc.errors import UsageError
from visloc.io import RerunLogger
from visloc.pose import Camera


def render_flow(args: argparse.Namespace) -> int:
    """``visloc render flow``: the synthetic data and its ground truth.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``visloc render flow`` command line (:func:`visloc.cli.build_parser`).

    Returns
    -------
    int
        Exit status: 0.
    """
    from visloc.synth.flight import render_flight, write_flight

    n = max(1, round(args.seconds * args.fps))
    with tqdm(total=n, unit="frame", disable=None, file=sys.stderr) as bar:
        flight = render_flight(args.seconds, args.fps, size=args.size, seed=args.seed, texture=args.texture,
                               progress=lambda k: bar.update(1))
    out = write_flight(args.outdir, flight, video=args.video)
    what = "flight.mp4" if args.video else f"{len(flight.frames)} frames"
    print(f"visloc render: wrote {what}, ground_truth.csv, heights.csv and camera.yml to {out}")
    return 0

def _read_heights(path: str) -> dict[int, float]:
    """frame -> height (m) from a CSV with a header naming ``frame`` and ``height``."""
    import csv

    try:
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise UsageError(f"cannot read --height-csv {path}: {exc.strerror}") from None
    if not rows or "frame" not in rows[0] or "height" not in rows[0]:
        raise UsageError(f"--height-csv {path} needs a header with 'frame' and 'height' columns")
    heights, bad = {}, []
    for line, r in enumerate(rows, start=2):  # file line numbers (the header is line 1)
        try:
            frame, height = int(r["frame"]), float(r["height"])
        except (TypeError, ValueError):
            frame, height = -1, float("nan")
        if frame < 0 or not 0 < height < float("inf"):
            bad.append(line)
        else:
            heights[frame] = height
    if bad:  # a bad row costs its frame only (it is then recorded as without a height)
        shown = ", ".join(map(str, bad[:5])) + (" ..." if len(bad) > 5 else "")
        warn("flow", f"--height-csv {path}: {len(bad)} rows without a frame number and a positive height "
                     f"skipped (lines {shown})")
    if not heights:
        raise UsageError(f"--height-csv {path}: no row has a frame number and a positive height")
    return heights

FLOW_COLUMNS = ["frame", "time", "source", "vx", "vy", "speed", "yaw_rate", "quality", "reason", "x", "y", "yaw"]

def _skip(out, row: dict, reason: str, warning: str | None = None) -> None:
    """Warn (``warning``, else ``reason``) and record a frame the run skips: its row with
    quality 0 and the reason."""
    warn("flow", warning or reason)
    if out:
        out.write(row | {"quality": 0.0, "reason": reason})


def _height_or_skip(frame, height: float | None, heights: dict[int, float] | None
                    ) -> tuple[float | None, tuple[str, str] | None]:
    """The frame's height (``--height``, or its ``--height-csv`` row), and, for a frame the
    run skips (unreadable, no height, under 16 x 16 px), its ``(reason, warning)``."""
    if frame.image is None:
        return None, (f"unreadable: {frame.error}", frame.error or f"cannot read {frame.name}")
    if heights is not None:
        height = heights.get(frame.index)
        if height is None:
            reason = f"--height-csv has no height for frame {frame.index}"
            return None, (reason, reason)
    if min(frame.image.shape[:2]) < 16:  # the block flow needs 16 x 16 px
        reason = f"{frame.image.shape[1]} x {frame.image.shape[0]} px, smaller than 16 x 16"
        return None, (reason, f"{frame.name}: {reason}; skipped")
    return height, None


def _say_unused(args: argparse.Namespace, gyro_log, gyro_used: int, pairs: int, unmeasured: int) -> None:
    """Warn about an ``--imu`` log outside the frames' times and a run that measured no pair."""
    if gyro_log is not None and pairs and not gyro_used:
        warn("flow", f"--imu {args.imu or args.imu_topic}: its times {gyro_log[0, 0]:g} .. {gyro_log[-1, 0]:g} s do not "
                     "overlap the frame pairs': the IMU was not used")
    if pairs and unmeasured == pairs:
        warn("flow", f"no motion could be measured in any of the {pairs} frame pairs (too little texture?)")


def _start_track(args: argparse.Namespace, ego, frame, cam: Camera, height: float | None, row: dict, out, rec):
    """A new ``EgoMotion`` (the track's origin) fed ``frame``, the run's first frame or one of
    another size than ``ego``'s (a warning then); its row (``"first frame"``, position 0) is
    written and logged. Returns the new ``EgoMotion``."""
    from visloc.flow import EgoMotion

    if ego is not None:
        warn("flow", f"{frame.name} has another size than the frame before: the track restarts")
    ego = EgoMotion(cam, options={"method": args.method, "direct": args.direct, "shadows": args.shadows})
    ego.update(frame.image, height=height)
    if out:
        out.write(row | {"quality": 0.0, "reason": "first frame", "x": 0.0, "y": 0.0, "yaw": 0.0})
    if rec:
        rec.log_flow(frame.index, frame.time, frame.image, None, None, (0.0, 0.0))
    return ego


def flow(args: argparse.Namespace) -> int:
    """``visloc flow``: ground velocity and integrated track of a downward camera.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``visloc flow`` command line (:func:`visloc.cli.build_parser`).

    Returns
    -------
    int
        Exit status: 0; 1 when some frames could not be read or lacked a height (each named on a warning line).
    """
    from visloc.flow import EgoMotion
    from visloc.io import CsvWriter

    if args.shadows and not args.direct:
        raise UsageError("--shadows acts on the sub-pixel stage: give --direct with it")
    camera = Camera.from_file(args.camera)
    heights = _read_heights(args.height_csv) if args.height_csv else None
    gyro_log = imu_input(args, ("t", "gx", "gy", "gz"), "flow")  # body rates in camera axes, rad/s
    failed = n_frames = pairs = unmeasured = gyro_used = 0
    times: list[float] = []
    qualities: list[float] = []
    with ExitStack() as stack:
        source = open_timed_source(stack, args)
        out = stack.enter_context(CsvWriter(args.out, FLOW_COLUMNS)) if args.out else None
        rec = stack.enter_context(RerunLogger(args.rerun)) if args.rerun else None
        link = None
        if getattr(args, "mavlink", None):
            from visloc.io.mavlink import MavlinkSink

            link = stack.enter_context(MavlinkSink(args.mavlink))
        ego: EgoMotion | None = None
        last_time = 0.0
        warned = [False]
        for frame in frames_of(source, args):
            n_frames += 1
            row = {"frame": frame.index, "time": frame.time, "source": frame.name}
            height, skipped = _height_or_skip(frame, args.height, heights)
            if skipped is not None:  # recorded and skipped, the run goes on
                failed += 1
                _skip(out, row, *skipped)
                continue
            cam = camera_for(camera, frame.image.shape, warned, "flow")
            if ego is None or ego.frame_shape != frame.image.shape[:2]:
                ego = _start_track(args, ego, frame, cam, height, row, out, rec)
                last_time = frame.time
                continue
            dt = frame.time - last_time
            if not dt > 0:  # recorded and skipped, the run goes on from the last good frame
                failed += 1
                reason = f"time {frame.time} s not after the previous frame's {last_time} s"
                _skip(out, row, reason, f"{frame.name}: {reason}; skipped")
                continue
            gyro = mean_between(gyro_log, last_time, frame.time) if gyro_log is not None else None
            gyro_used += gyro is not None
            t0 = time.perf_counter()
            gv = ego.update(frame.image, dt=dt, height=height, gyro=gyro)
            times.append(time.perf_counter() - t0)
            qualities.append(gv.quality)
            last_time = frame.time
            x, y = ego.position
            measured = gv.motion is not None and gv.motion.inliers > 0  # else no velocity: its columns stay empty
            pairs += 1
            unmeasured += not measured
            if out:
                v = {"vx": gv.v[0], "vy": gv.v[1], "speed": float(np.hypot(*gv.v)), "yaw_rate": gv.yaw_rate} if measured else {}
                out.write(row | v | {"quality": gv.quality, "reason": gv.reason, "x": x, "y": y, "yaw": ego.yaw})
            if rec:
                rec.log_flow(frame.index, frame.time, frame.image, ego.last_field, gv, (x, y))
            if link is not None:
                link.send_optical_flow(frame.time, dt, gv.v, height, gv.quality, gyro=gyro)
    _say_unused(args, gyro_log, gyro_used, pairs, unmeasured)
    if not args.quiet:
        ms = f", median {1e3 * float(np.median(times)):.2f} ms per pair" if times else ""
        q = f", median quality {float(np.median(qualities)):.2f}" if qualities else ""
        print(f"visloc flow: {n_frames} frames, {failed} unreadable or without a height{ms}{q}", file=sys.stderr)
    return 1 if failed else 0
