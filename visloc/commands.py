"""The work behind ``visloc detect``, ``visloc render`` and ``visloc demo``.

Each function takes the parsed arguments of :mod:`visloc.cli` and returns an exit status.
Results are written and flushed frame by frame; a frame that cannot be read is reported on
one line, recorded as an error in the JSONL output, and the run goes on.
"""

from __future__ import annotations

import argparse
import sys
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np
from tqdm import tqdm

from visloc.cli import UsageError
from visloc.io import AnnotationSink, JsonlWriter, RerunLogger, draw_markers, open_source
from visloc.markers import MarkerDetector
from visloc.pose import Camera, estimate_marker_pose, pose_error
from visloc.types import MarkerDetection, Pose

__all__ = ["demo", "detect", "marker_records", "render"]


def _warn(command: str, text: str) -> None:
    tqdm.write(f"visloc {command}: warning: {text}", file=sys.stderr)


def _frames(source, args: argparse.Namespace):
    """The frames of an open source with a progress bar (unless ``--quiet``), stopping after
    ``--max-frames``."""
    try:
        total = len(source)
    except TypeError:
        total = None
    if args.max_frames:
        total = min(total, args.max_frames) if total else args.max_frames
    bar = tqdm(source, total=total, unit="frame", disable=True if args.quiet else None, file=sys.stderr)
    for n, frame in enumerate(bar):
        if args.max_frames and n >= args.max_frames:
            break
        yield frame


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


def _camera_for(camera: Camera, shape: tuple[int, ...], warned: list[bool]) -> Camera:
    """The camera scaled to a frame's size when its file names another size (warn once)."""
    h, w = shape[:2]
    if camera.size is None or tuple(camera.size) == (w, h):
        return camera
    if not warned[0]:
        _warn("detect", f"camera file is for {camera.size[0]}x{camera.size[1]}, frames are {w}x{h}: scaling it")
        warned[0] = True
    return camera.scaled(w, h)


def detect(args: argparse.Namespace) -> int:
    """``visloc detect``: markers (and poses) of every frame of a source."""
    detector = MarkerDetector(args.dict)
    camera = Camera.from_file(args.camera) if args.camera else None
    if (camera is None) != (args.marker_length is None):
        raise UsageError("poses need both --camera FILE and --marker-length M")
    failed = n_frames = n_markers = 0
    times: list[float] = []
    warned = [False]
    with ExitStack() as stack:
        source = stack.enter_context(open_source(args.source, fps=args.fps))
        out = stack.enter_context(JsonlWriter(args.out)) if args.out else None
        sink = stack.enter_context(AnnotationSink(args.annotate)) if args.annotate else None
        rec = stack.enter_context(RerunLogger(args.rerun)) if args.rerun else None
        explain_dir = Path(args.explain) if args.explain else None
        for frame in _frames(source, args):
            n_frames += 1
            if frame.image is None:
                failed += 1
                _warn("detect", frame.error or f"cannot read {frame.name}")
                if out:
                    out.write({"frame": frame.index, "source": frame.name, "error": frame.error})
                continue
            t0 = time.perf_counter()
            if explain_dir is not None:
                from visloc.markers.explain import write_explain

                trace = detector.trace(frame.image)
                dets = trace.detections
                write_explain(trace, explain_dir, stem=f"frame_{frame.index:06d}")
            else:
                dets = detector.detect(frame.image)
            poses = None
            cam = None
            if camera is not None:
                cam = _camera_for(camera, frame.image.shape, warned)
                poses = [estimate_marker_pose(d.corners, args.marker_length, cam) for d in dets]
            times.append(time.perf_counter() - t0)
            n_markers += len(dets)
            if out:
                out.write({"frame": frame.index, "source": frame.name, "time": frame.time,
                           "markers": marker_records(dets, poses)})
            if sink:
                sink.write(draw_markers(frame.image, dets, poses, cam, args.marker_length), frame.name)
            if rec:
                rec.log_frame(frame.index, frame.time, frame.image, dets, poses, cam, args.marker_length)
    if not args.quiet:
        ms = f", median {1e3 * float(np.median(times)):.1f} ms per frame" if times else ""
        print(f"visloc detect: {n_frames} frames, {n_markers} markers, {failed} unreadable{ms}", file=sys.stderr)
    return 1 if failed else 0


def render(args: argparse.Namespace) -> int:
    """``visloc render markers|flow``: a synthetic dataset with ground truth."""
    if args.what == "flow":
        return _render_flow(args)
    if args.what == "map":
        return _render_map(args)
    if args.what == "localize":
        return _render_localize(args)
    from visloc.synth import render_dataset, render_video

    out = Path(args.outdir)
    bar = tqdm(total=args.n, unit="frame", disable=None, file=sys.stderr)
    try:
        if args.video:
            out.mkdir(parents=True, exist_ok=True)
            path = render_video(out / "markers.mp4", args.n, seed=args.seed, size=args.size,
                                dictionary=args.dict, progress=lambda i: bar.update(1))
        else:
            path = render_dataset(out, args.n, seed=args.seed, size=args.size, dictionary=args.dict,
                                  difficulty=args.difficulty, progress=lambda i: bar.update(1))
    finally:
        bar.close()
    print(f"visloc render: wrote {args.n} frames and ground_truth.json to {path}")
    return 0


def demo(args: argparse.Namespace) -> int:
    """``visloc demo``: render frames with known truth, detect, estimate poses, compare."""
    import cv2

    from visloc.synth import MARKER_LENGTH, random_scene

    out = Path(args.out)
    (out / "frames").mkdir(parents=True, exist_ok=True)
    detector = MarkerDetector("DICT_4X4_50")
    rng = np.random.default_rng(args.seed)
    rows = []
    with JsonlWriter(out / "detections.jsonl") as jsonl, AnnotationSink(out / "annotated") as sink:
        for i in range(args.frames):
            scene = random_scene(rng, size=(640, 480), difficulty="easy" if i % 2 == 0 else "hard")
            camera = Camera(scene.K, size=(640, 480))
            name = f"frame_{i:03d}.png"
            cv2.imwrite(str(out / "frames" / name), scene.image)
            t0 = time.perf_counter()
            dets = detector.detect(scene.image)
            poses = [estimate_marker_pose(d.corners, MARKER_LENGTH, camera) for d in dets]
            ms = 1e3 * (time.perf_counter() - t0)
            jsonl.write({"frame": i, "source": name, "time": float(i), "markers": marker_records(dets, poses)})
            sink.write(draw_markers(scene.image, dets, poses, camera, MARKER_LENGTH), name)
            truth = {m.id: m for m in scene.markers if m.visible}
            found = {d.id for d in dets}
            for d, p in zip(dets, poses, strict=True):
                gt = truth.get(d.id)
                if gt is None:
                    rows.append((i, d.id, "false", "", "", "", f"{ms:.1f}"))
                    continue
                corner = float(np.sqrt(((d.corners - gt.corners) ** 2).sum(axis=1).mean()))
                rot, trans = pose_error(p, gt.pose.R, gt.pose.t)
                rows.append((i, d.id, "found", f"{corner:.3f}", f"{np.degrees(rot):.2f}",
                             f"{1e3 * trans:.1f}", f"{ms:.1f}"))
            for mid in sorted(set(truth) - found):
                rows.append((i, mid, "MISSED", "", "", "", f"{ms:.1f}"))
    head = ("frame", "id", "status", "corner RMS px", "rot err deg", "pos err mm", "ms/frame")
    widths = [max(len(h), *(len(str(r[k])) for r in rows)) if rows else len(h) for k, h in enumerate(head)]
    print("  ".join(h.rjust(w) for h, w in zip(head, widths, strict=True)))
    for r in rows:
        print("  ".join(str(v).rjust(w) for v, w in zip(r, widths, strict=True)))
    found = [r for r in rows if r[2] == "found"]
    missed = sum(r[2] == "MISSED" for r in rows)
    if found:
        med = np.median([float(r[3]) for r in found])
        print(f"\n{len(found)} markers found, {missed} missed; median corner error {med:.3f} px "
              f"against the exact ground truth.")
    flow_ok = _demo_flow(out)
    loc_ok = _demo_localize()
    print(f"Outputs in {out.resolve()}: frames/, annotated/, detections.jsonl, flow.csv")
    return 0 if found and not missed and flow_ok and loc_ok else 1


def _demo_localize() -> bool:
    """The localisation part of the demo: 1 s over a marker grid, pose + Kalman filter."""
    from visloc.estimation.kalman import PositionVelocityKF
    from visloc.pose.map_pose import estimate_camera_pose
    from visloc.pose.maps import GridMap
    from visloc.synth.grid import render_map_flight

    grid = GridMap(**LOCALIZE_GRID)
    flight = render_map_flight(1.0, 30.0, grid, seed=4, dictionary="DICT_4X4_100", background="gravel",
                               blur_sigma=0.5, noise_sigma=1.0)
    camera = Camera(flight.K, size=(320, 240))
    detector = MarkerDetector("DICT_4X4_100")
    kf = PositionVelocityKF(3, model="cv", accel_noise=2.0)
    tr = flight.track
    pos_err, vel_err = [], []
    for k, img in enumerate(flight.frames):
        mp = estimate_camera_pose(detector.detect(img), grid, camera)
        kf.predict(float(tr.t[k]))
        if mp is not None:
            kf.update_position(mp.position, std=0.002)
            pos_err.append(np.linalg.norm(mp.position - tr.position[k]))
        if k >= 5:
            vel_err.append(np.linalg.norm(kf.velocity - tr.velocity[k]))
    print(f"Localisation over a 10 x 10 marker grid ({len(tr.t)} frames, 320x240, 1 s, height "
          f"{tr.position[:, 2].mean():.2f} m): {len(pos_err)} poses, median position error "
          f"{1e3 * np.median(pos_err):.2f} mm; Kalman velocity error median {1e3 * np.median(vel_err):.0f} mm/s.")
    return len(pos_err) == len(tr.t) and bool(np.median(pos_err) < 0.005)


def _demo_flow(out: Path) -> bool:
    """The flow part of the demo: a 1 s rendered flight, velocities against the truth."""
    from visloc.flow import EgoMotion
    from visloc.io import CsvWriter
    from visloc.synth.flight import render_flight

    flight = render_flight(1.0, 60.0, seed=3)
    tr = flight.track
    ego = EgoMotion(Camera(flight.K, size=(320, 240)), fps=60.0)
    errs = []
    with CsvWriter(out / "flow.csv", ["frame", "vx", "vy", "true_vx", "true_vy", "yaw_rate", "true_yaw_rate", "quality"]) as csv:
        for k, img in enumerate(flight.frames):
            gv = ego.update(img, height=float(tr.position[max(k - 1, 0), 2]))
            if gv is None:
                continue
            errs.append(np.linalg.norm(gv.v - tr.pair_v[k]) / max(np.linalg.norm(tr.pair_v[k]), 0.05))
            csv.write({"frame": k, "vx": gv.v[0], "vy": gv.v[1], "true_vx": tr.pair_v[k, 0], "true_vy": tr.pair_v[k, 1],
                       "yaw_rate": gv.yaw_rate, "true_yaw_rate": tr.pair_yaw_rate[k], "quality": gv.quality})
    true_end = tr.position[-1, :2] - tr.position[0, :2]
    print(f"\nGround velocity over a rendered 1 s flight ({len(errs)} frame pairs, 320x240, 60 FPS, "
          f"speed {np.linalg.norm(tr.pair_v[1:], axis=1).mean():.2f} m/s): median velocity error "
          f"{100 * np.median(errs):.1f} %, dead-reckoned path {np.linalg.norm(ego.position):.3f} m "
          f"(true {np.linalg.norm(true_end):.3f} m).")
    return bool(np.median(errs) < 0.1)


def _render_flow(args: argparse.Namespace) -> int:
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
    try:
        heights = {int(r["frame"]): float(r["height"]) for r in rows}
    except ValueError as exc:
        raise UsageError(f"--height-csv {path}: {exc}") from None
    bad = [f for f, h in heights.items() if not 0 < h < float("inf")]
    if bad:
        raise UsageError(f"--height-csv {path}: non-positive height at frame {bad[0]}")
    return heights


FLOW_COLUMNS = ["frame", "time", "source", "vx", "vy", "speed", "yaw_rate", "quality", "reason", "x", "y", "yaw"]


def flow(args: argparse.Namespace) -> int:
    """``visloc flow``: ground velocity and integrated track of a downward camera."""
    from visloc.flow import EgoMotion
    from visloc.io import CsvWriter, ImageListSource

    camera = Camera.from_file(args.camera)
    heights = _read_heights(args.height_csv) if args.height_csv else None
    failed = n_frames = 0
    times: list[float] = []
    qualities: list[float] = []
    with ExitStack() as stack:
        source = stack.enter_context(open_source(args.source, fps=args.fps))
        if isinstance(source, ImageListSource) and args.fps is None:
            raise UsageError("image folders and globs need --fps (the time between frames)")
        out = stack.enter_context(CsvWriter(args.out, FLOW_COLUMNS)) if args.out else None
        rec = stack.enter_context(RerunLogger(args.rerun)) if args.rerun else None
        ego: EgoMotion | None = None
        last_time = 0.0
        for frame in _frames(source, args):
            n_frames += 1
            row = {"frame": frame.index, "time": frame.time, "source": frame.name}
            if frame.image is None:
                failed += 1
                _warn("flow", frame.error or f"cannot read {frame.name}")
                if out:
                    out.write(row | {"quality": 0.0, "reason": f"unreadable: {frame.error}"})
                continue
            height = args.height
            if heights is not None:
                height = heights.get(frame.index)
                if height is None:
                    raise UsageError(f"--height-csv has no height for frame {frame.index}")
            cam = _camera_for(camera, frame.image.shape, [True])
            if ego is None or ego.frame_shape != frame.image.shape[:2]:
                if ego is not None:
                    _warn("flow", f"{frame.name} has another size than the frame before: the track restarts")
                ego = EgoMotion(cam, options={"method": args.method})
                ego.update(frame.image, height=height)
                last_time = frame.time
                if out:
                    out.write(row | {"quality": 0.0, "reason": "first frame", "x": 0.0, "y": 0.0, "yaw": 0.0})
                if rec:
                    rec.log_flow(frame.index, frame.time, frame.image, None, None, (0.0, 0.0))
                continue
            dt = frame.time - last_time
            if not dt > 0:
                raise UsageError(f"frame times must increase; {frame.name} is at {frame.time} s after {last_time} s")
            t0 = time.perf_counter()
            gv = ego.update(frame.image, dt=dt, height=height)
            times.append(time.perf_counter() - t0)
            qualities.append(gv.quality)
            last_time = frame.time
            x, y = ego.position
            if out:
                out.write(row | {"vx": gv.v[0], "vy": gv.v[1], "speed": float(np.hypot(*gv.v)), "yaw_rate": gv.yaw_rate,
                                 "quality": gv.quality, "reason": gv.reason, "x": x, "y": y, "yaw": ego.yaw})
            if rec:
                rec.log_flow(frame.index, frame.time, frame.image, ego.last_field, gv, (x, y))
    if not args.quiet:
        ms = f", median {1e3 * float(np.median(times)):.2f} ms per pair" if times else ""
        q = f", median quality {float(np.median(qualities)):.2f}" if qualities else ""
        print(f"visloc flow: {n_frames} frames, {failed} unreadable{ms}{q}", file=sys.stderr)
    return 1 if failed else 0


def _render_map(args: argparse.Namespace) -> int:
    """``visloc render map``: the markers of a map drawn to scale in its z = 0 plane."""
    import cv2

    from visloc.markers.dictionary import load_dictionary
    from visloc.pose.maps import MarkerMap

    mmap = MarkerMap.from_file(args.map)
    dic = load_dictionary(args.dict)
    pts = np.concatenate([mmap.corners_of(int(i)) for i in mmap.ids])
    if np.abs(pts[:, 2]).max() > 1e-6:
        raise UsageError(f"map {args.map} has markers off the z = 0 plane: it cannot be printed as one sheet")
    bad = [int(i) for i in mmap.ids if i >= len(dic)]
    if bad:
        raise UsageError(f"map ids {bad} are not in dictionary {args.dict} ({len(dic)} markers)")
    px_per_m = args.dpi / 0.0254
    margin = 0.02  # m of white around the outermost markers
    lo = pts[:, :2].min(axis=0) - margin
    hi = pts[:, :2].max(axis=0) + margin
    w, h = (int(np.ceil(v)) for v in (hi - lo) * px_per_m)
    canvas = np.full((h, w), 255, np.uint8)
    cells = dic.marker_size + 2
    for i in mmap.ids:
        c = mmap.corners_of(int(i))[:, :2]
        img_pts = np.stack([(c[:, 0] - lo[0]) * px_per_m, (hi[1] - c[:, 1]) * px_per_m], axis=1)  # y up -> down
        cell_px = max(1, round(float(np.linalg.norm(img_pts[1] - img_pts[0])) / cells))
        marker = dic.marker_image(int(i), cell_px=cell_px)
        s = marker.shape[0]
        src = np.float32([[-0.5, -0.5], [s - 0.5, -0.5], [s - 0.5, s - 0.5]])
        M = cv2.getAffineTransform(src, np.float32(img_pts[:3] - 0.5))  # canvas pixel centres at integers
        mask = cv2.warpAffine(np.full_like(marker, 255), M, (w, h), flags=cv2.INTER_NEAREST)
        warped = cv2.warpAffine(marker, M, (w, h), flags=cv2.INTER_NEAREST)
        canvas[mask > 0] = warped[mask > 0]
    if not cv2.imwrite(args.output, canvas):
        raise OSError(f"cannot write {args.output}")
    print(f"visloc render: wrote {args.output} ({w} x {h} px at {args.dpi:g} dpi, {len(mmap)} markers)")
    return 0


def track(args: argparse.Namespace) -> int:
    """``visloc track``: pose of a body relative to reference markers, per frame, with an
    observer velocity (report eq. 3.14), as JSON lines and optionally UDP datagrams."""
    import json
    import socket

    from visloc.estimation import LuenbergerObserver
    from visloc.pose.maps import MarkerMap
    from visloc.pose.relative import track_body

    detector = MarkerDetector(args.dict)
    camera = Camera.from_file(args.camera)
    body = MarkerMap.from_file(args.body)
    reference = MarkerMap.from_file(args.reference)
    target = None
    if args.udp:
        host, _, port = args.udp.rpartition(":")
        if not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise UsageError(f"--udp must be HOST:PORT, got {args.udp!r}")
        target = (host, int(port))
    failed = n_frames = lost = 0
    observer = None
    last_time = None
    with ExitStack() as stack:
        source = stack.enter_context(open_source(args.source, fps=args.fps))
        out = stack.enter_context(JsonlWriter(args.out)) if args.out else None
        sock = stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_DGRAM)) if target else None
        for frame in _frames(source, args):
            n_frames += 1
            rec: dict = {"frame": frame.index, "source": frame.name, "time": frame.time}
            if frame.image is None:
                failed += 1
                _warn("track", frame.error or f"cannot read {frame.name}")
                rec["error"] = frame.error
            else:
                cam = _camera_for(camera, frame.image.shape, [True])
                bp = track_body(detector.detect(frame.image), body, reference, cam)
                dt = None if last_time is None else frame.time - last_time
                if dt is not None and not dt > 0:
                    raise UsageError(f"frame times must increase; {frame.name} is at {frame.time} s")
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
    if not args.quiet:
        print(f"visloc track: {n_frames} frames, {lost} without both maps, {failed} unreadable", file=sys.stderr)
    return 1 if failed else 0


LOCALIZE_GRID = {"rows": 10, "cols": 10, "marker_length": 0.10, "spacing": 0.05}
LOCALIZE_COLUMNS = ["frame", "time", "source", "x", "y", "z", "vx", "vy", "vz", "std_x", "std_y", "std_z",
                    "markers", "fix", "error_m"]


def _render_localize(args: argparse.Namespace) -> int:
    import cv2

    from visloc.pose.maps import GridMap
    from visloc.synth import write_camera_yml
    from visloc.synth.grid import render_map_flight

    grid = GridMap(**LOCALIZE_GRID)
    flight = render_map_flight(args.seconds, args.fps, grid, seed=args.seed, dictionary="DICT_4X4_100",
                               background="gravel", blur_sigma=0.5, noise_sigma=1.0)
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


def _read_imu(path: str) -> np.ndarray:
    """(M, 4) ``t, fx, fy, fz`` (specific force in camera axes, m/s^2) from an IMU CSV with
    columns ``t,gx,gy,gz,fx,fy,fz`` (as ``visloc render localize`` writes), sorted by time."""
    try:
        data = np.genfromtxt(path, delimiter=",", names=True)
    except (OSError, ValueError) as exc:
        raise UsageError(f"cannot read --imu {path}: {exc}") from None
    if data.dtype.names is None or not {"t", "fx", "fy", "fz"} <= set(data.dtype.names):
        raise UsageError(f"--imu {path} needs a header with t, fx, fy and fz columns")
    imu = np.column_stack([np.atleast_1d(data[k]) for k in ("t", "fx", "fy", "fz")])
    imu = imu[np.isfinite(imu).all(axis=1)]
    if len(imu) == 0 or (np.diff(imu[:, 0]) <= 0).any():
        raise UsageError(f"--imu {path}: times must be finite and increasing")
    return imu


def _read_truth(path: str) -> dict[str, np.ndarray]:
    try:
        data = np.genfromtxt(path, delimiter=",", names=True)
    except (OSError, ValueError) as exc:
        raise UsageError(f"cannot read --truth {path}: {exc}") from None
    if data.dtype.names is None or not {"t", "x", "y", "z"} <= set(data.dtype.names):
        raise UsageError(f"--truth {path} needs a header with t, x, y and z columns")
    return {k: np.atleast_1d(data[k]) for k in ("t", "x", "y", "z")}


def localize(args: argparse.Namespace) -> int:
    """``visloc localize``: the camera's position over a marker map per frame, filtered by a
    constant-velocity Kalman filter (filterpy) into position and velocity with uncertainty."""
    from visloc.estimation.kalman import PositionVelocityKF
    from visloc.io import CsvWriter, ImageListSource
    from visloc.pose.map_pose import estimate_camera_pose
    from visloc.pose.maps import MarkerMap

    detector = MarkerDetector(args.dict)
    camera = Camera.from_file(args.camera)
    mmap = MarkerMap.from_file(args.map)
    truth = _read_truth(args.truth) if args.truth else None
    imu = _read_imu(args.imu) if args.imu else None
    kf = PositionVelocityKF(3, model="cv", accel_noise=args.accel_noise)
    gravity = np.array([0.0, 0.0, -9.81])  # the map's z axis points up, out of the markers
    R_map_cam = None
    last_t = None
    failed = n_frames = fixes = 0
    errors: list[float] = []
    with ExitStack() as stack:
        source = stack.enter_context(open_source(args.source, fps=args.fps))
        if isinstance(source, ImageListSource) and args.fps is None:
            raise UsageError("image folders and globs need --fps (the time between frames)")
        out = stack.enter_context(CsvWriter(args.out, LOCALIZE_COLUMNS)) if args.out else None
        rec = stack.enter_context(RerunLogger(args.rerun)) if args.rerun else None
        for frame in _frames(source, args):
            n_frames += 1
            row: dict = {"frame": frame.index, "time": frame.time, "source": frame.name}
            if frame.image is None:
                failed += 1
                _warn("localize", frame.error or f"cannot read {frame.name}")
                if out:
                    out.write(row | {"fix": "unreadable"})
                continue
            cam = _camera_for(camera, frame.image.shape, [True])
            mp = estimate_camera_pose(detector.detect(frame.image), mmap, cam)
            accel = None
            if imu is not None and R_map_cam is not None and last_t is not None:
                # mean specific force over the interval, turned into the map frame: a = R f + g
                sel = (imu[:, 0] > last_t) & (imu[:, 0] <= frame.time)
                if sel.any():
                    accel = R_map_cam @ imu[sel, 1:].mean(axis=0) + gravity
            kf.predict(frame.time, accel=accel)
            last_t = frame.time
            if mp is not None:
                R_map_cam = mp.R_map_cam
            fix = "none"
            if mp is not None:
                # the pose's own covariance, floored at 1 mm (model errors the corners don't show)
                cov = mp.position_covariance
                R = np.eye(3) * 1e-6 if cov is None else cov + np.eye(3) * 1e-6
                fix = "used" if kf.update_position(mp.position, R=R) else "rejected"
                fixes += fix == "used"
            pos, vel = kf.position, kf.velocity
            sd = np.sqrt(np.clip(np.diag(kf.P)[:: kf.order], 0, None)) if kf.P is not None else np.full(3, np.nan)
            row |= {"x": pos[0], "y": pos[1], "z": pos[2], "vx": vel[0], "vy": vel[1], "vz": vel[2],
                    "std_x": sd[0], "std_y": sd[1], "std_z": sd[2],
                    "markers": len(mp.used) if mp is not None else 0, "fix": fix}
            true_pos = None
            if truth is not None:
                true_pos = np.array([np.interp(frame.time, truth["t"], truth[k]) for k in ("x", "y", "z")])
                row["error_m"] = float(np.linalg.norm(pos - true_pos))
                errors.append(row["error_m"])
            if out:
                out.write(row)
            if rec:
                rec.log_localize(frame.index, frame.time, frame.image, pos, true_pos)
    if not args.quiet:
        err = f", median position error {1e3 * float(np.median(errors)):.1f} mm" if errors else ""
        print(f"visloc localize: {n_frames} frames, {fixes} position fixes, {failed} unreadable{err}", file=sys.stderr)
    return 1 if failed else 0


def model_summary() -> dict:
    """The identified AR.Drone 2.0 parameters (report chapter 2), the hover trim per motor and
    the open-loop poles of the rigid-body model linearised at hover (numerical Jacobian)."""
    from visloc.model import ARDRONE2, hover_pwm
    from visloc.model.rigid_body import derivatives

    p = ARDRONE2
    u0 = np.array([p.mass * p.g, 0.0, 0.0, 0.0])  # T0 = m g (report section 4.1)
    x0 = np.zeros(12)
    h = 1e-6
    A = np.column_stack([(derivatives(x0 + h * e, u0, p) - derivatives(x0 - h * e, u0, p)) / (2 * h)
                         for e in np.eye(12)])
    poles = np.linalg.eigvals(A)
    trim = hover_pwm(p)
    return {
        "mass_kg": p.mass, "inertia_kg_m2": [p.Ixx, p.Iyy, p.Izz], "g": p.g,
        "thrust_coefficient_c_mean": p.c_mean, "thrust_coefficient_c_std": p.c_std,
        "torque_coefficient_d_mean": p.d_mean, "torque_coefficient_d_std": p.d_std, "pwm_shift_k": p.k,
        "hover_thrust_N": p.mass * p.g, "hover_pwm_percent": [trim] * 4,
        "open_loop_poles": [[float(v.real), float(v.imag)] for v in poles],
        "state_order": "x y z u v w phi theta psi p q r (NED)",
    }


def model(args: argparse.Namespace) -> int:
    """``visloc model``: print :func:`model_summary` as a table or JSON."""
    import json

    s = model_summary()
    if args.json:
        print(json.dumps(s, indent=1))
        return 0
    print(f"AR.Drone 2.0 (report chapter 2): mass {s['mass_kg']} kg, inertia "
          f"{s['inertia_kg_m2']} kg m^2, g {s['g']} m/s^2")
    print(f"propulsion (eqs. 2.15-2.16): c = {s['thrust_coefficient_c_mean']:.4e} +- "
          f"{s['thrust_coefficient_c_std']:.3e} N/%^2, d = {s['torque_coefficient_d_mean']:.4e} +- "
          f"{s['torque_coefficient_d_std']:.3e} N m/%^2, k = {s['pwm_shift_k']} %")
    print(f"hover: T0 = m g = {s['hover_thrust_N']:.4f} N, pwm per motor "
          f"{s['hover_pwm_percent'][0]:.2f} % (sqrt(m g / (4 c)) - k)")
    real = [p[0] for p in s["open_loop_poles"]]
    print(f"open-loop poles at hover: {len(real)}, largest real part {max(real):.3g} "
          "(a chain of integrators: the model needs feedback)")
    return 0
