"""``visloc localize``, ``visloc track`` and ``visloc render localize``: pose over marker maps."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from visloc.commands._common import (
    camera_for,
    detector_for,
    dictionary_for,
    finder_for,
    finite_rows,
    frames_of,
    imu_input,
    mean_between,
    open_timed_source,
    warn,
)
from visloc.errors import UsageError
from visloc.io import JsonlWriter, RerunLogger
from visloc.pose import Camera
from visloc.types import Pose

if TYPE_CHECKING:
    from visloc.pose.maps import MarkerMap

LOCALIZE_GRID = {"rows": 10, "cols": 10, "marker_length": 0.10, "spacing": 0.05}

LOCALIZE_COLUMNS = ["frame", "time", "source", "x", "y", "z", "vx", "vy", "vz", "std_x", "std_y", "std_z",
                    "markers", "fix", "error_m"]

def render_localize(args: argparse.Namespace) -> int:
    """``visloc render localize``: the synthetic data and its ground truth.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``visloc render localize`` command line (:func:`visloc.cli.build_parser`).

    Returns
    -------
    int
        Exit status: 0.
    """
    import cv2

    from visloc.pose.maps import GridMap
    from visloc.synth import write_camera_yml
    from visloc.synth.grid import FLIGHT_CAMERA, render_map_flight

    grid = GridMap(**LOCALIZE_GRID, dictionary="DICT_4X4_100")
    flight = render_map_flight(args.seconds, args.fps, grid, seed=args.seed, dictionary="DICT_4X4_100",
                               background="gravel", camera=FLIGHT_CAMERA)
    out = Path(args.outdir)
    out.mkdir(parents=True, exist_ok=True)
    for k, img in enumerate(flight.frames):
        if not cv2.imwrite(str(out / f"frame_{k:05d}.png"), img):
            raise OSError(f"cannot write {out / f'frame_{k:05d}.png'}")
    tr = flight.track
    rows = np.column_stack([np.arange(len(tr.t)), tr.t, tr.position, tr.velocity, tr.yaw, tr.roll, tr.pitch])
    np.savetxt(out / "ground_truth.csv", rows, delimiter=",", comments="",
               header="frame,t,x,y,z,vx,vy,vz,yaw,roll,pitch", fmt=["%d"] + ["%.10g"] * (rows.shape[1] - 1))
    np.savetxt(out / "imu.csv", flight.imu, delimiter=",", comments="", header="t,gx,gy,gz,fx,fy,fz", fmt="%.10g")
    grid.to_file(out / "map.yml")
    write_camera_yml(out / "camera.yml", flight.K, (flight.frames.shape[2], flight.frames.shape[1]))
    print(f"visloc render: wrote {len(tr.t)} frames, map.yml (DICT_4X4_100), camera.yml, imu.csv and "
          f"ground_truth.csv to {out}")
    return 0

def _truth(path: str | None) -> dict[str, np.ndarray] | None:
    """The ``--truth`` CSV's columns ``t, x, y, z`` (None without one)."""
    if not path:
        return None
    return dict(zip(("t", "x", "y", "z"), finite_rows(path, "--truth", ("t", "x", "y", "z"), "localize").T, strict=True))


def localize(args: argparse.Namespace) -> int:
    """``visloc localize``: the camera's position over a marker map per frame, filtered by a
    constant-velocity Kalman filter (filterpy) into position and velocity with uncertainty.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``visloc localize`` command line (:func:`visloc.cli.build_parser`).

    Returns
    -------
    int
        Exit status: 0; 1 when some frames could not be read (each named on a warning line).
    """
    from visloc.estimation.fusion import MapFixFusion
    from visloc.io import CsvWriter
    from visloc.io.mavlink import MavlinkSink
    from visloc.pose.map_pose import estimate_camera_pose
    from visloc.pose.maps import MarkerMap

    mmap = MarkerMap.from_file(args.map)
    dictionary_for(args, "localize", mmap)
    find = _map_finder(args, mmap)
    camera = Camera.from_file(args.camera)
    truth = _truth(args.truth)
    imu = imu_input(args, ("t", "fx", "fy", "fz"), "localize")
    fusion = MapFixFusion(accel_noise=args.accel_noise)  # the map's z axis points up: gravity (0, 0, -9.81)
    R_map_cam = None
    last_t = None
    last_pose = None
    failed = n_frames = fixes = imu_used = outside = 0
    frame_times: list[float] = []
    errors: list[float] = []
    with ExitStack() as stack:
        source = open_timed_source(stack, args)
        out = stack.enter_context(CsvWriter(args.out, LOCALIZE_COLUMNS)) if args.out else None
        rec = stack.enter_context(RerunLogger(args.rerun)) if args.rerun else None
        link = stack.enter_context(MavlinkSink(args.mavlink)) if getattr(args, "mavlink", None) else None
        warned = [False]
        for frame in frames_of(source, args):
            n_frames += 1
            row: dict = {"frame": frame.index, "time": frame.time, "source": frame.name}
            back = frame.image is not None and last_t is not None and frame.time < last_t  # recorded, skipped
            if frame.image is None or back:
                failed += 1
                _skip_frame(out, row, frame, back, last_t)
                continue
            cam = camera_for(camera, frame.image.shape, warned, "localize")
            mp = estimate_camera_pose(find(frame.image, cam, last_pose), mmap, cam, start=last_pose)  # from the last fix
            last_pose = None if mp is None else mp.pose
            force = None
            if imu is not None and R_map_cam is not None and last_t is not None:
                # mean specific force over the interval (camera axes), turned into the map frame
                force = mean_between(imu, last_t, frame.time)
                imu_used += force is not None
            fix = _fuse(fusion, frame.time, force, R_map_cam, mp)
            fixes += fix == "used"
            last_t = frame.time
            frame_times.append(frame.time)
            if mp is not None:
                R_map_cam = mp.R_map_cam
            columns, pos = _estimate(fusion)
            row |= {"markers": len(mp.used) if mp is not None else 0, "fix": fix} | columns
            true_pos = _truth_at(truth, frame.time)
            outside += truth is not None and true_pos is None
            if true_pos is not None and pos is not None:
                row["error_m"] = float(np.linalg.norm(pos - true_pos))
                errors.append(row["error_m"])
            if out:
                out.write(row)
            if link is not None and fix == "used":
                _send_fix(link, args, fusion, mp.R_map_cam, frame.time)
            if rec:
                rec.log_localize(frame.index, frame.time, frame.image, pos, true_pos)
    _say_unused(args, imu, imu_used, frame_times, truth, outside, fixes if n_frames > failed else None)
    if not args.quiet:
        _say_done(n_frames, fixes, failed, imu_used if imu is not None else None, errors)
    return 1 if failed else 0


def _skip_frame(out, row: dict, frame, back: bool, last_t: float | None) -> None:
    """Warn about and record (``fix`` column) a frame the run skips: unreadable, or (``back``)
    timed before the previous frame's ``last_t`` (s)."""
    warn("localize", f"{frame.name}: time {frame.time} s before the previous frame's {last_t} s; skipped"
         if back else frame.error or f"cannot read {frame.name}")
    if out:
        out.write(row | {"fix": "time went back" if back else "unreadable"})


def _fuse(fusion, t: float, force: np.ndarray | None, R_map_cam: np.ndarray | None, mp) -> str:
    """One filter step at frame time ``t`` (s): predict with the mean specific force (camera
    axes, turned into the map frame by ``R_map_cam``) if any, then the pose's position fix if
    any; returns the row's ``fix`` column (``"used"``, ``"rejected"`` or ``"none"``)."""
    fusion.predict(t, force, R_map_cam if force is not None else None)
    if mp is None:
        return "none"
    # the pose's own covariance, floored (visloc.estimation.fusion)
    return "used" if fusion.fix(mp.position, mp.position_covariance) else "rejected"


def _say_done(n_frames: int, fixes: int, failed: int, imu_used: int | None, errors: list[float]) -> None:
    """The run's summary line on stderr: frames, fixes, unreadable frames, frame pairs the IMU
    was used between (``imu_used`` None: no IMU) and the median position error (``errors``, m)."""
    err = f", median position error {1e3 * float(np.median(errors)):.1f} mm" if errors else ""
    used = f", IMU between {imu_used} frame pairs" if imu_used is not None else ""
    print(f"visloc localize: {n_frames} frames, {fixes} position fixes, {failed} unreadable{used}{err}",
          file=sys.stderr)


def _estimate(fusion) -> tuple[dict, np.ndarray | None]:
    """The filter's position, velocity and standard deviation columns, and its position;
    none before its first fix (its prior is no position)."""
    if not fusion.fixes:
        return {}, None
    pos, vel, sd = fusion.position, fusion.velocity, fusion.position_std
    return {"x": pos[0], "y": pos[1], "z": pos[2], "vx": vel[0], "vy": vel[1], "vz": vel[2],
            "std_x": sd[0], "std_y": sd[1], "std_z": sd[2]}, pos


def _truth_at(truth: dict[str, np.ndarray] | None, t: float) -> np.ndarray | None:
    """The ``--truth`` position at time ``t`` (interpolated), None outside its times (not
    clamped to its first or last row) or without a truth file."""
    if truth is None or not truth["t"][0] <= t <= truth["t"][-1]:
        return None
    return np.array([np.interp(t, truth["t"], truth[k]) for k in ("x", "y", "z")])


def _say_unused(args: argparse.Namespace, imu, imu_used: int, frame_times: list[float],
                truth: dict[str, np.ndarray] | None, outside: int, fixes: int | None) -> None:
    """Warn about inputs a run could not use: an IMU log outside the frames' times, frames
    outside the truth's, no fix at all (``fixes`` None: no frame was read)."""
    if imu is not None and len(frame_times) > 1 and imu_used == 0:
        warn("localize", f"--imu {args.imu or args.imu_topic}: its times {imu[0, 0]:g} .. {imu[-1, 0]:g} s do not overlap the frames' "
                         f"{frame_times[0]:g} .. {frame_times[-1]:g} s (or no frame had a fix to turn it into the "
                         "map frame): the IMU was not used")
    if truth is not None and outside:
        warn("localize", f"--truth {args.truth}: its times {truth['t'][0]:g} .. {truth['t'][-1]:g} s leave out "
                         f"{outside} frame(s); their error_m is empty")
    if fixes == 0:
        warn("localize", "no frame gave a position fix (no map marker found): the position columns are empty")


def _map_finder(args: argparse.Namespace, mmap: MarkerMap) -> Callable[[np.ndarray, Camera, Pose | None], list]:
    """What finds each frame's markers for ``localize``: ``find(image, camera, last_pose)``,
    the detector (:func:`finder_for`), or with ``--redetect-every N`` (N > 1) a
    :class:`visloc.markers.MarkerTracker` also told the map's markers in the last fix's view
    (:func:`visloc.pose.markers_in_view`): they join at once, and the full search runs only
    when following fails."""
    from visloc.markers import MarkerTracker
    from visloc.pose.map_pose import markers_in_view

    finder = finder_for(detector_for(args), args)

    def markers(image: np.ndarray, camera: Camera, last_pose: Pose | None) -> list:
        if not isinstance(finder, MarkerTracker) or last_pose is None:
            return finder.detect(image)
        h, w = image.shape[:2]
        return finder.detect(image, expected=markers_in_view(mmap, camera, last_pose, size=(w, h)))

    return markers


def _send_fix(link, args: argparse.Namespace, fusion, R_map_cam: np.ndarray, t: float) -> None:
    """The filter's estimate after a fix, to the flight stack (``--mavlink``): position (and
    velocity) in its local NED frame, the body's attitude from the camera's (a downward camera,
    ``visloc.io.mavlink``), the filter's position (and velocity) covariance; the attitude's
    variances are unknown (NaN: the flight stack uses its own noise setting)."""
    from visloc.io.mavlink import MAP_FRAMES, body_attitude_ned
    from visloc.pose.rotations import matrix_to_euler_list

    F = MAP_FRAMES[args.map_frame]
    R = body_attitude_ned(R_map_cam, map_frame=args.map_frame)
    kf = fusion.kf
    pose_cov = np.full((6, 6), np.nan)
    pose_cov[:3, :3] = F @ kf.position_covariance @ F.T
    if args.mavlink_message == "odometry":
        vel_cov = np.full((6, 6), np.nan)
        vel_cov[:3, :3] = F @ kf.velocity_covariance @ F.T
        link.send_odometry(t, F @ fusion.position, R, F @ fusion.velocity, pose_covariance=pose_cov,
                           velocity_covariance=vel_cov, reset_counter=kf.resets)
    else:
        link.send_vision_position(t, F @ fusion.position, matrix_to_euler_list(R[None])[0], covariance=pose_cov,
                                  reset_counter=kf.resets)


def _send_body(link, map_frame: str, bp, t: float) -> None:
    """A tracked body's pose to the flight stack (``track --mavlink``): the report's ceiling
    camera sending the drone its own position. The body's marker map has x forward, y left,
    z up (``visloc.io.mavlink``); its attitude goes out as FRD in NED."""
    from visloc.io.mavlink import MAP_FRAMES
    from visloc.pose.rotations import matrix_to_euler_list

    F = MAP_FRAMES[map_frame]
    R = F @ bp.T_ref_body.R @ np.diag([1.0, -1.0, -1.0])  # FRD body axes -> FLU marker axes -> map -> NED
    link.send_vision_position(t, F @ bp.position, matrix_to_euler_list(R[None])[0])


def _check_track_inputs(body: MarkerMap, reference: MarkerMap, poles) -> None:
    """Refuse, before any frame, body and reference maps sharing marker ids (``track_body``
    would refuse every frame) and observer poles ``LuenbergerObserver`` refuses: a
    :class:`UsageError` each."""
    from visloc.estimation import LuenbergerObserver

    shared = sorted(set(body.ids.tolist()) & set(reference.ids.tolist()))
    if shared:  # track_body would refuse every frame
        raise UsageError(f"--body and --reference share marker ids {shared[:10]}: a detection could not be told apart")
    try:
        LuenbergerObserver(poles, 1.0 / 30.0)
    except ValueError as exc:
        raise UsageError(f"--poles: {exc}") from None


def _udp_target(udp: str | None) -> tuple[str, int] | None:
    """``--udp HOST:PORT`` as a socket address (None without it); a malformed one is a
    :class:`UsageError`."""
    if not udp:
        return None
    host, _, port = udp.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise UsageError(f"--udp must be HOST:PORT, got {udp!r}")
    return (host, int(port))


def track(args: argparse.Namespace) -> int:
    """``visloc track``: pose of a body relative to reference markers, per frame, with an
    observer velocity (report eq. 3.14), as JSON lines and optionally UDP datagrams.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``visloc track`` command line (:func:`visloc.cli.build_parser`).

    Returns
    -------
    int
        Exit status: 0; 1 when some frames could not be read (each named on a warning line).
    """
    import json
    import socket

    from visloc.estimation import LuenbergerObserver
    from visloc.io.mavlink import MavlinkSink
    from visloc.pose.maps import MarkerMap
    from visloc.pose.relative import track_body

    body = MarkerMap.from_file(args.body)
    reference = MarkerMap.from_file(args.reference)
    _check_track_inputs(body, reference, args.poles)  # before any frame
    dictionary_for(args, "track", body, reference)
    find = finder_for(detector_for(args), args).detect
    camera = Camera.from_file(args.camera)
    target = _udp_target(args.udp)
    failed = n_frames = lost = 0
    observer = None
    last_time = None
    with ExitStack() as stack:
        source = open_timed_source(stack, args)
        out = stack.enter_context(JsonlWriter(args.out)) if args.out else None
        sock = stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_DGRAM)) if target else None
        link = stack.enter_context(MavlinkSink(args.mavlink)) if getattr(args, "mavlink", None) else None
        warned = [False]
        for frame in frames_of(source, args):
            n_frames += 1
            rec: dict = {"frame": frame.index, "source": frame.name, "time": frame.time}
            dt = None if last_time is None else frame.time - last_time
            if frame.image is None:
                failed += 1
                warn("track", frame.error or f"cannot read {frame.name}")
                rec["error"] = frame.error
            elif dt is not None and not dt > 0:  # recorded and skipped, the run goes on from the last good frame
                failed += 1
                rec["error"] = f"time {frame.time} s not after the previous frame's {last_time} s"
                warn("track", f"{frame.name}: {rec['error']}; skipped")
            else:
                cam = camera_for(camera, frame.image.shape, warned, "track")
                bp = track_body(find(frame.image), body, reference, cam)
                if bp is None:
                    lost += 1
                    rec["lost"] = True
                    if observer is not None and dt is not None:
                        p, v = observer.update(None, dt)
                        rec |= {"predicted_x": float(p[0]), "predicted_y": float(p[1]),
                                "vx": float(v[0]), "vy": float(v[1])}
                else:
                    rec |= bp.to_dict()
                    if observer is None:
                        observer = LuenbergerObserver(args.poles, 1.0 / 30.0, initial_position=bp.position[:2])
                        rec |= {"vx": 0.0, "vy": 0.0}
                    else:
                        _, v = observer.update(bp.position[:2], dt)
                        rec |= {"vx": float(v[0]), "vy": float(v[1])}
                last_time = frame.time
            if out:
                out.write(rec)
            if sock is not None:
                sock.sendto(json.dumps(rec).encode(), target)
            if link is not None and "x" in rec:
                _send_body(link, args.map_frame, bp, frame.time)
    if not args.quiet:
        print(f"visloc track: {n_frames} frames, {lost} without both maps, {failed} unreadable", file=sys.stderr)
    return 1 if failed else 0
