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
        try:
            total = len(source)
        except TypeError:
            total = None
        if args.max_frames:
            total = min(total, args.max_frames) if total else args.max_frames
        bar = tqdm(source, total=total, unit="frame", disable=True if args.quiet else None, file=sys.stderr)
        for frame in bar:
            if args.max_frames and n_frames >= args.max_frames:
                break
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
    """``visloc render markers``: a synthetic dataset (images or a video) with ground truth."""
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
    print(f"Outputs in {out.resolve()}: frames/, annotated/, detections.jsonl")
    return 0 if found and not missed else 1
