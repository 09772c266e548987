"""Helpers shared by the commands: warnings, the frame loop, marker records, camera scaling."""

from __future__ import annotations

import argparse
import sys

import numpy as np
from tqdm import tqdm

from visloc.errors import UsageError
from visloc.markers import FAST_PASSES, MarkerDetector, MarkerTracker
from visloc.pose import Camera
from visloc.types import MarkerDetection, Pose


def warn(command: str, text: str) -> None:
    tqdm.write(f"visloc {command}: warning: {text}", file=sys.stderr)


def dictionary_for(args: argparse.Namespace, command: str, *maps) -> str:
    """The dictionary of a command that reads marker maps: ``--dict`` when given (a map that
    records another one is a :class:`visloc.cli.UsageError`), else the one the maps record,
    else DICT_4X4_50 with a warning. Sets ``args.dict``. A map id the dictionary does not
    hold (negative, or beyond its size: no marker could ever be found) is a usage error."""
    from visloc.markers.dictionary import load_dictionary

    recorded = {m.dictionary for m in maps if m.dictionary}
    if len(recorded) > 1:
        raise UsageError(f"the maps record different dictionaries: {', '.join(sorted(recorded))}")
    if args.dict is not None:
        if recorded and recorded != {args.dict}:
            raise UsageError(f"--dict {args.dict} but the map records {recorded.pop()}")
    elif recorded:
        args.dict = recorded.pop()
    else:
        args.dict = "DICT_4X4_50"
        warn(command, "the map records no dictionary: using DICT_4X4_50 (give --dict)")
    size = len(load_dictionary(args.dict))
    bad = sorted({int(i) for m in maps for i in m.ids if not 0 <= i < size})
    if bad:
        raise UsageError(f"map ids {bad[:10]} are not in dictionary {args.dict} (ids 0 to {size - 1})")
    return args.dict


def detector_for(args: argparse.Namespace) -> MarkerDetector:
    """The marker detector of ``--dict``, ``--response``, ``--border-bits`` and ``--inverted``;
    with ``--fast`` it searches shrunk images (:data:`visloc.markers.FAST_PASSES`)."""
    options = {"response": args.response, "border_bits": args.border_bits,
               "inverted": {"no": False, "yes": True, "both": "both"}[args.inverted]}
    if args.fast:
        options["passes"] = FAST_PASSES
    return MarkerDetector(args.dict, **options)


def finder_for(detector: MarkerDetector, args: argparse.Namespace) -> MarkerDetector | MarkerTracker:
    """What finds the markers of each frame in turn (its ``detect(image)``): ``detector``, or
    with ``--redetect-every N`` (N > 1) a :class:`visloc.markers.MarkerTracker` on it (the
    full search every Nth frame, the markers of the last frames followed between)."""
    every = getattr(args, "redetect_every", 1)
    return MarkerTracker(detector, redetect_every=every) if every > 1 else detector


def frames_of(source, args: argparse.Namespace):
    """The frames of an open source with a progress bar (unless ``--quiet``), stopping after
    ``--max-frames`` frames processed; with ``--frame-range START:STOP`` only the frames whose index is in
    ``[START, STOP)`` (the source is read from its start, so each frame keeps the index, time
    and name it has in the whole source; a range that starts past the source's end is a
    :class:`~visloc.errors.UsageError`). From the first frame on, ``args.started`` is True: the inputs were
    accepted, so an exception from here on is visloc's fault (:func:`visloc.cli.main` reports
    a ``ValueError`` as an internal error then, not as a usage error)."""
    try:
        total = len(source)
    except TypeError:
        total = None
    start, stop = getattr(args, "frame_range", None) or (0, None)
    if total and stop is not None:
        total = min(total, stop)
    if args.max_frames:  # frames read: those skipped before START, then at most --max-frames processed
        total = min(total, start + args.max_frames) if total else start + args.max_frames
    bar = tqdm(source, total=total, unit="frame", disable=True if args.quiet else None, file=sys.stderr)
    done = seen = 0
    for frame in bar:
        seen += 1
        if frame.index < start:  # read, not processed: indices and times stay the whole source's
            continue
        if stop is not None and frame.index >= stop:
            break
        args.started = True
        done += 1
        yield frame
        if args.max_frames and done >= args.max_frames:  # stop before reading another frame
            break
    if start > 0 and done == 0:  # a range past the end: say so rather than succeed with nothing
        raise UsageError(f"--frame-range {start}:{'' if stop is None else stop} starts past the end of the source "
                         f"({seen} frames)")

def marker_records(dets: list[MarkerDetection], poses: list[Pose | None] | None) -> list[dict]:
    """JSON records of detections, with pose fields (``rvec``, ``tvec``, ``R``, Euler angles,
    reprojection RMS, ``distance_m``) where a pose is given."""
    out = []
    for k, d in enumerate(dets):
        rec = d.to_dict()
        pose = poses[k] if poses else None
        if pose is not None:
            rec.update(pose.to_dict())
            rec["distance_m"] = float(np.linalg.norm(pose.t))
        out.append(rec)
    return out

def camera_for(camera: Camera, shape: tuple[int, ...], warned: list[bool], command: str = "detect") -> Camera:
    """The camera scaled to a frame's size when its file names another size (``command``
    warns once: ``warned[0]`` says whether it has)."""
    h, w = shape[:2]
    if camera.size is None or tuple(camera.size) == (w, h):
        return camera
    if not warned[0]:
        warn(command, f"camera file is for {camera.size[0]}x{camera.size[1]}, frames are {w}x{h}: scaling it")
        warned[0] = True
    return camera.scaled(w, h)


def open_timed_source(stack, args: argparse.Namespace):
    """Open ``args.source`` in ``stack`` for a command that needs real frame times (velocities):
    image folders and globs carry no times, so they need ``--fps``."""
    from visloc.errors import UsageError
    from visloc.io import ImageListSource, open_source

    source = stack.enter_context(open_source(args.source, fps=args.fps, topic=args.topic))
    if isinstance(source, ImageListSource) and args.fps is None:
        raise UsageError("image folders and globs need --fps (the time between frames)")
    return source


def read_columns(path: str, option: str, columns: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The named ``columns`` of the CSV at ``path`` (header row required), as 1-d float arrays,
    one entry per data row: a row with another number of fields than the header, or a field
    that is not a number, gives NaN there (the caller says which rows it skips). A missing or
    unreadable file or a missing column is a :class:`visloc.cli.UsageError` naming ``option``."""
    import csv

    from visloc.errors import UsageError

    try:
        with open(path, newline="") as fh:
            rows = [r for r in csv.reader(fh) if r]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise UsageError(f"cannot read {option} {path}: {exc}") from None
    header = [h.strip() for h in rows[0]] if rows else []
    if not set(columns) <= set(header):
        names = ", ".join(columns[:-1]) + f" and {columns[-1]}"
        raise UsageError(f"{option} {path} needs a header with {names} columns")
    where = [header.index(k) for k in columns]
    data = np.full((len(rows) - 1, len(columns)), np.nan)
    for i, row in enumerate(rows[1:]):
        if len(row) != len(header):
            continue
        for j, k in enumerate(where):
            try:
                data[i, j] = float(row[k])
            except ValueError:
                pass
    return {k: data[:, j] for j, k in enumerate(columns)}


def finite_rows(path: str, option: str, columns: tuple[str, ...], command: str) -> np.ndarray:
    """(M, len(columns)) of the CSV's rows whose named fields are all finite numbers, in file
    order; the others (NaN, inf, text, a wrong field count) are said on one warning line. The
    first column is a time: it must increase (else a :class:`visloc.cli.UsageError`)."""
    from visloc.errors import UsageError

    cols = read_columns(path, option, columns)
    rows = np.column_stack([cols[k] for k in columns])
    good = np.isfinite(rows).all(axis=1)
    if not good.all():  # said, not silently dropped
        bad = np.flatnonzero(~good) + 2  # file line numbers (the header is line 1)
        shown = ", ".join(map(str, bad[:5])) + (" ..." if len(bad) > 5 else "")
        warn(command, f"{option} {path}: {len(bad)} rows without finite numbers skipped (lines {shown})")
    rows = rows[good]
    if len(rows) == 0 or (np.diff(rows[:, 0]) <= 0).any():
        raise UsageError(f"{option} {path}: times must be finite and increasing")
    return rows


#: The columns of an IMU log (``visloc render localize``'s ``imu.csv``, :func:`visloc.io.bags.read_bag_imu`).
IMU_COLUMNS = ("t", "gx", "gy", "gz", "fx", "fy", "fz")


def imu_input(args: argparse.Namespace, columns: tuple[str, ...], command: str) -> np.ndarray | None:
    """(M, len(columns)) IMU samples from ``--imu`` (a CSV with an ``IMU_COLUMNS`` header) or
    ``--imu-topic`` (the source recording's ``sensor_msgs/Imu``, its axes taken as the
    camera's), or None when neither is given."""
    from visloc.errors import UsageError

    if getattr(args, "imu", None):
        return finite_rows(args.imu, "--imu", columns, command)
    if not getattr(args, "imu_topic", None):
        return None
    from visloc.io.bags import is_recording, read_bag_imu

    if not is_recording(args.source):
        raise UsageError(f"--imu-topic reads a ROS bag or MCAP source; {args.source} is not one")
    imu = read_bag_imu(args.source, topic=args.imu_topic, image_topic=args.topic)
    if len(imu) == 0:
        raise UsageError(f"--imu-topic {args.imu_topic}: no IMU messages")
    return imu[:, [IMU_COLUMNS.index(c) for c in columns]]


def mean_between(rows: np.ndarray, t0: float, t1: float) -> np.ndarray | None:
    """The mean of the columns after the first (a time) over the rows with ``t0 < t <= t1`` (the
    IMU samples of one frame interval), or None when there is none."""
    sel = (rows[:, 0] > t0) & (rows[:, 0] <= t1)
    return rows[sel, 1:].mean(axis=0) if sel.any() else None
