"""``visloc demo``: renders frames with known truth and runs every part on them."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from visloc.commands._common import marker_records
from visloc.commands.localize import LOCALIZE_GRID
from visloc.io import AnnotationSink, JsonlWriter, draw_markers
from visloc.markers import MarkerDetector
from visloc.pose import Camera, estimate_marker_pose, pose_error


def demo(args: argparse.Namespace) -> int:
    """``visloc demo``: render frames with known truth, detect, estimate poses, compare.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``visloc demo`` command line (:func:`visloc.cli.build_parser`).

    Returns
    -------
    int
        Exit status: 0 when every check passed (markers found, flow, localisation and the
        simulated flights within their bounds), else 1.
    """
    import cv2

    from visloc.synth import MARKER_LENGTH, random_scene

    out = Path(args.out)
    (out / "frames").mkdir(parents=True, exist_ok=True)
    detector = MarkerDetector("DICT_4X4_50")
    rng = np.random.default_rng(args.seed)
    rows = []
    with JsonlWriter(out / "detections.jsonl") as jsonl, AnnotationSink(out / "annotated") as sink:
        for i in range(args.frames):
            # camera-like frames: lens, blur, noise, vignetting, sRGB, JPEG (visloc.synth.camera)
            scene = random_scene(rng, size=(640, 480), difficulty="easy" if i % 2 == 0 else "hard", camera=True)
            camera = Camera(scene.K, scene.dist, size=(640, 480))
            name = f"frame_{i:03d}.png"
            cv2.imwrite(str(out / "frames" / name), scene.image)
            t0 = time.perf_counter()
            dets = detector.detect(scene.image)
            poses = [estimate_marker_pose(d.corners, MARKER_LENGTH, camera) for d in dets]
            ms = 1e3 * (time.perf_counter() - t0)
            jsonl.write({"frame": i, "source": name, "time": float(i), "markers": marker_records(dets, poses)})
            sink.write(draw_markers(scene.image, dets, poses=poses, camera=camera, marker_length=MARKER_LENGTH), name)
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
    sim_ok = _demo_closed_loop(out)
    print(f"Outputs in {out.resolve()}: frames/, annotated/, detections.jsonl, flow.csv, sidestep.csv")
    return 0 if found and not missed and flow_ok and loc_ok and sim_ok else 1

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
            gv = ego.update(img, height=float(tr.position[k, 2]))
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

def _demo_localize() -> bool:
    """The localisation part of the demo: 1 s over a marker grid, pose + Kalman filter."""
    from visloc.estimation.fusion import MapFixFusion
    from visloc.pose.map_pose import estimate_camera_pose
    from visloc.pose.maps import GridMap
    from visloc.synth.grid import FLIGHT_CAMERA, render_map_flight

    grid = GridMap(**LOCALIZE_GRID)
    flight = render_map_flight(1.0, 15.0, grid, seed=4, dictionary="DICT_4X4_100", background="gravel",
                               camera=FLIGHT_CAMERA)
    camera = Camera(flight.K, size=(320, 240))
    detector = MarkerDetector("DICT_4X4_100")
    fusion = MapFixFusion()  # localize's fusion, without the IMU
    tr = flight.track
    pos_err, vel_err = [], []
    for k, img in enumerate(flight.frames):
        mp = estimate_camera_pose(detector.detect(img), grid, camera)
        fusion.predict(float(tr.t[k]))
        if mp is not None:
            fusion.fix(mp.position, mp.position_covariance)
            pos_err.append(np.linalg.norm(mp.position - tr.position[k]))
        if k >= 5:
            vel_err.append(np.linalg.norm(fusion.velocity - tr.velocity[k]))
    print(f"Localisation over a 10 x 10 marker grid ({len(tr.t)} frames, 320x240, 1 s, height "
          f"{tr.position[:, 2].mean():.2f} m): {len(pos_err)} poses, median position error "
          f"{1e3 * np.median(pos_err):.2f} mm; Kalman velocity error median {1e3 * np.median(vel_err):.0f} mm/s.")
    return len(pos_err) == len(tr.t) and bool(np.median(pos_err) < 0.005)


def _demo_closed_loop(out: Path) -> bool:
    """The control part of the demo: the report's 1 m side step on the non-linear model, and
    5 s of hover on visloc's own marker-grid vision."""
    from visloc.sim import SimStatus, simulate
    from visloc.sim.output import write_csv

    step = simulate("sidestep")
    write_csv(step, out / "sidestep.csv")
    m = step.metrics
    print(f"Closed loop, 1 m side step (non-linear model, report Fig. 4.6): {step.status.value}, "
          f"settles to 5 % in {m['settling_time_s']:.2f} s, overshoot {m['overshoot_pct']:.1f} %, "
          f"height dip {100 * m['height_dip_m']:.1f} cm (linear model: {100 * m['linear_height_dip_m']:.1f} cm).")
    hover = simulate("hover-vision", seconds=5.0, seed=1)
    h = hover.metrics
    print(f"Hover on visloc's vision (5 s, {h['camera_frames']} camera frames through the marker tracker "
          f"and the map localiser): {hover.status.value}, position RMS {100 * h['position_rms_m']:.1f} cm, estimate "
          f"error RMS {1e3 * h['estimate_rms_m']:.2f} mm, {h['realtime_factor']:.1f}x real time.")
    return step.status is SimStatus.SETTLED and hover.status in (SimStatus.SETTLED, SimStatus.COMPLETED)
