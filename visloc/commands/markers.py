"""``visloc detect`` and ``visloc render markers|map``: markers in frames, synthetic marker data."""

from __future__ import annotations

import argparse
import sys
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np
from tqdm import tqdm

from visloc.commands._common import (
    camera_for,
    detector_for,
    dictionary_for,
    finder_for,
    frames_of,
    marker_records,
    warn,
)
from visloc.commands.calibrate import render_board, render_calibration
from visloc.commands.flow import render_flow
from visloc.commands.localize import render_localize
from visloc.errors import UsageError
from visloc.io import AnnotationSink, JsonlWriter, RerunLogger, draw_markers, open_source
from visloc.pose import Camera, estimate_marker_pose


def detect(args: argparse.Namespace) -> int:
    """``visloc detect``: markers (and poses) of every frame of a source.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``visloc detect`` command line (:func:`visloc.cli.build_parser`).

    Returns
    -------
    int
        Exit status: 0; 1 when some frames could not be read (each named on a warning line).
    """
    detector = detector_for(args)
    find = finder_for(detector, args).detect
    camera = Camera.from_file(args.camera) if args.camera else None
    if (camera is None) != (args.marker_length is None):
        raise UsageError("poses need both --camera FILE and --marker-length M")
    if getattr(args, "mavlink", None) and (camera is None or args.target_id is None):
        raise UsageError("--mavlink sends LANDING_TARGET: it needs --camera, --marker-length and --target-id")
    failed = n_frames = n_markers = 0
    times: list[float] = []
    warned = [False]
    with ExitStack() as stack:
        source = stack.enter_context(open_source(args.source, fps=args.fps, topic=args.topic))
        out = stack.enter_context(JsonlWriter(args.out)) if args.out else None
        sink = stack.enter_context(AnnotationSink(args.annotate)) if args.annotate else None
        rec = stack.enter_context(RerunLogger(args.rerun)) if args.rerun else None
        link = None
        if getattr(args, "mavlink", None):
            from visloc.io.mavlink import MavlinkSink

            link = stack.enter_context(MavlinkSink(args.mavlink))
        explain_dir = Path(args.explain) if args.explain else None
        if explain_dir is not None and explain_dir.exists() and not explain_dir.is_dir():
            raise UsageError(f"--explain {explain_dir}: a file, not a folder for the explanations")
        for frame in frames_of(source, args):
            n_frames += 1
            if frame.image is None:
                failed += 1
                warn("detect", frame.error or f"cannot read {frame.name}")
                if out:
                    out.write({"frame": frame.index, "time": frame.time, "source": frame.name, "error": frame.error})
                continue
            t0 = time.perf_counter()
            if explain_dir is not None:
                from visloc.markers.explain import write_explain

                trace = detector.trace(frame.image)
                dets = trace.detections
                write_explain(trace, explain_dir, stem=f"frame_{frame.index:06d}")
            else:
                dets = find(frame.image)
            poses = None
            cam = None
            if camera is not None:
                cam = camera_for(camera, frame.image.shape, warned)
                poses = [estimate_marker_pose(d.corners, args.marker_length, cam) for d in dets]
            times.append(time.perf_counter() - t0)
            n_markers += len(dets)
            if out:
                out.write({"frame": frame.index, "source": frame.name, "time": frame.time,
                           "markers": marker_records(dets, poses)})
            if sink:
                sink.write(draw_markers(frame.image, dets, poses=poses, camera=cam, marker_length=args.marker_length),
                           frame.name)
            if rec:
                rec.log_frame(frame.index, frame.time, frame.image, dets, poses=poses, camera=cam,
                              marker_length=args.marker_length)
            if link is not None:
                pads = [p for d, p in zip(dets, poses or [], strict=False) if d.id == args.target_id and p is not None]
                if pads:  # the best-fitting view of the pad
                    pad = min(pads, key=lambda p: p.reprojection_rms)
                    link.send_landing_target(frame.time, pad.t, args.marker_length, target_num=args.target_id)
    if not args.quiet:
        ms = f", median {1e3 * float(np.median(times)):.1f} ms per frame" if times else ""
        print(f"visloc detect: {n_frames} frames, {n_markers} markers, {failed} unreadable{ms}", file=sys.stderr)
    return 1 if failed else 0

def render(args: argparse.Namespace) -> int:
    """``visloc render markers|flow``: a synthetic dataset with ground truth.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``visloc render WHAT`` command line (:func:`visloc.cli.build_parser`);
        ``what`` picks markers (here), ``flow``, ``map`` or ``localize``.

    Returns
    -------
    int
        Exit status: 0.
    """
    if args.what == "flow":
        return render_flow(args)
    if args.what == "map":
        return render_map(args)
    if args.what == "localize":
        return render_localize(args)
    if args.what == "board":
        return render_board(args)
    if args.what == "calibration":
        return render_calibration(args)
    from visloc.synth import render_dataset, render_video

    out = Path(args.outdir)
    if args.video and args.n < 2:  # before the folder is made
        raise UsageError(f"--n must be at least 2 for --video (a flight), got {args.n}")
    bar = tqdm(total=args.n, unit="frame", disable=None, file=sys.stderr)
    try:
        if args.video:
            out.mkdir(parents=True, exist_ok=True)
            path = render_video(out / "markers.mp4", args.n, seed=args.seed, size=args.size,
                                dictionary=args.dict, progress=lambda i: bar.update(1))
        else:
            path = render_dataset(out, args.n, seed=args.seed, size=args.size, dictionary=args.dict,
                                  difficulty=args.difficulty, camera=not args.linear,
                                  progress=lambda i: bar.update(1))
    finally:
        bar.close()
    print(f"visloc render: wrote {args.n} frames and ground_truth.json to {path}")
    return 0

#: largest map image (pixels, 200 MB as uint8): a 1.2 m square sheet at 300 dpi
MAX_MAP_PIXELS = 200_000_000


def render_map(args: argparse.Namespace) -> int:
    """``visloc render map``: the markers of a map drawn to scale in its z = 0 plane.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``visloc render map`` command line (:func:`visloc.cli.build_parser`).

    Returns
    -------
    int
        Exit status: 0.
    """
    import cv2

    from visloc.markers.dictionary import load_dictionary
    from visloc.pose.maps import MarkerMap

    if not cv2.haveImageWriter(args.output):
        raise UsageError(f"render map: OpenCV cannot write an image named {args.output}: use .png, .jpg, .tif, ...")
    mmap = MarkerMap.from_file(args.map)
    dic = load_dictionary(dictionary_for(args, "render", mmap))
    pts = np.concatenate([mmap.corners_of(int(i)) for i in mmap.ids])
    if np.abs(pts[:, 2]).max() > 1e-6:
        raise UsageError(f"map {args.map} has markers off the z = 0 plane: it cannot be printed as one sheet")
    px_per_m = args.dpi / 0.0254
    margin = 0.02  # m of white around the outermost markers
    lo = pts[:, :2].min(axis=0) - margin
    hi = pts[:, :2].max(axis=0) + margin
    w, h = (int(np.ceil(v)) for v in (hi - lo) * px_per_m)
    if w * h > MAX_MAP_PIXELS:
        raise UsageError(f"render map: {w} x {h} px at {args.dpi:g} dpi is over {MAX_MAP_PIXELS / 1e6:g} Mpx: "
                         "lower --dpi")
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
