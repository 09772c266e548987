"""Localisation benchmark, grid part: camera pose from a marker grid, visloc vs OpenCV's route.

The same rendered 320x240 bottom-camera frames (AR.Drone 2.0 intrinsics) of a 6 x 6 grid of
DICT_4X4_50 markers (10 cm, 5 cm apart) on gravel, 0.6-1.6 m above it, tilts up to 20 deg, any
yaw, through a camera model (``visloc.synth.camera.CameraEffects``: linear light, optics blur,
sensor noise, vignetting, the sRGB curve; no lens distortion, as the camera file has none), and
a harder set with more blur, motion blur, noise and dim light:

- ``visloc``: ``MarkerDetector`` + ``estimate_camera_pose`` (joint Gauss-Newton over all
  corners, from the best single-marker pose, inconsistent markers dropped);
- ``opencv``: ``cv2.aruco.ArucoDetector`` (default parameters) + ``cv2.solvePnP``
  (SOLVEPNP_ITERATIVE) over all detected board corners; ``opencv_subpix``: the same with
  CORNER_REFINE_SUBPIX.

Timing is interleaved per frame (detection + pose), five rounds; every quarter second it
waits until the host runs at its normal speed (``_timing.Steady``). Each frame's time is its
best over the rounds (a slow spell of the host that the check missed moves one round, not the
table); the tables give the median (and on the video the mean) over the frames. A failure is no pose, or a
position more than 5 cm off.

``grid flight``: a 30 fps video of a smooth flight over the same grid (``render_map_flight``,
up to 0.4 m/s, 0.8-1.3 m up, roll and pitch up to 0.1 rad; the clean set's camera), where each
method reads the frames in order, whole video by whole video, the order of the methods turned
round every round; ``visloc_tracker`` is ``MarkerTracker`` (the full search every 10th frame,
the markers of the last frames followed between) + the same joint pose; ``visloc_tracker_map``
the same tracker also told the map's markers in the last fix's view (``markers_in_view``), so
the full search runs only when following fails, as ``visloc localize --redetect-every 10``
does; on the video the visloc
rows start each frame's joint fit from the last frame's pose, as ``visloc localize`` does. Besides the median
time per frame, the mean (the tracker's full searches are its slowest frames) and the markers
used per frame. Usage: ``python bench/localize.py [--quick]``; writes
``bench/results/localize.json`` and ``localize.md``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from _results import write_results
from _timing import best_per_item, steady
from scipy.spatial.transform import Rotation

from visloc.markers import MarkerDetector, MarkerTracker
from visloc.pose import Camera
from visloc.pose.map_pose import estimate_camera_pose, markers_in_view
from visloc.pose.maps import GridMap
from visloc.synth.camera import CameraEffects
from visloc.synth.grid import FLIGHT_CAMERA, random_map_view, render_map_flight

ROOT = Path(__file__).resolve().parents[1]
K = np.array([[320.067, 0, 159.5], [0, 320.067, 119.5], [0, 0, 1]])
FAIL_M = 0.05


def methods(grid, video=False):
    """visloc's and OpenCV's routes; ``video``: visloc's fit starts from the last frame's pose,
    as ``visloc localize`` does (reset by ``start()`` before each pass over the video)."""
    cam = Camera(K, size=(320, 240))
    vl = MarkerDetector("DICT_4X4_50")
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    p_sub = cv2.aruco.DetectorParameters()
    p_sub.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    cv_default = cv2.aruco.ArucoDetector(d, cv2.aruco.DetectorParameters())
    cv_subpix = cv2.aruco.ArucoDetector(d, p_sub)

    def run_visloc(img):
        t0 = time.perf_counter()
        dets = vl.detect(img)
        run_visloc.detect_s.append(time.perf_counter() - t0)
        mp = estimate_camera_pose(dets, grid, cam, start=run_visloc.last if video else None)
        run_visloc.last = None if mp is None else mp.pose
        run_visloc.markers.append(len(dets))
        return None if mp is None else (mp.pose.R, mp.pose.t)

    run_visloc.detect_s = []  # the detection's share of each call (the rest is the joint pose)
    run_visloc.markers = []
    run_visloc.last = None
    if video:
        run_visloc.start = lambda: setattr(run_visloc, "last", None)

    def run_cv(det):
        def f(img):
            corners, ids, _ = det.detectMarkers(img)
            f.markers.append(0 if ids is None else len(ids))
            if ids is None:
                return None
            keep = [(c, int(i)) for c, i in zip(corners, ids.ravel(), strict=True) if int(i) in grid]
            if not keep:  # only ids the grid does not hold (OpenCV 5.1 found such on a hard frame)
                return None
            obj = np.concatenate([grid.corners_of(i) for _, i in keep])
            img_pts = np.concatenate([c.reshape(4, 2) for c, _ in keep])
            ok, rvec, tvec = cv2.solvePnP(obj, img_pts.astype(np.float64), K, None, flags=cv2.SOLVEPNP_ITERATIVE)
            return (cv2.Rodrigues(rvec)[0], tvec.ravel()) if ok else None
        f.markers = []
        return f

    return {"visloc": run_visloc, "opencv": run_cv(cv_default), "opencv_subpix": run_cv(cv_subpix)}


def _tracked(grid, guided=False):
    """visloc with :class:`MarkerTracker` (a new tracker per pass over the video); ``guided``:
    each frame told the map's markers in the last fix's view (``markers_in_view``), as
    ``visloc localize --redetect-every N`` does."""
    cam = Camera(K, size=(320, 240))
    detector = MarkerDetector("DICT_4X4_50")

    def f(img):
        expected = markers_in_view(grid, cam, f.last) if guided and f.last is not None else None
        dets = f.tracker.detect(img, expected=expected)
        f.markers.append(len(dets))
        mp = estimate_camera_pose(dets, grid, cam, start=f.last)  # from the last frame's pose
        f.last = None if mp is None else mp.pose
        return None if mp is None else (mp.pose.R, mp.pose.t)

    def start():
        f.tracker, f.last = MarkerTracker(detector, redetect_every=10), None

    f.start = start
    f.markers = []
    return f


def _errors(truth, out) -> dict:
    """Failures and position / rotation errors of poses ``out`` against ``truth`` [(C, R_cam_map)]."""
    pos_err, rot_err, fails = [], [], 0
    for (C, R_true), res in zip(truth, out, strict=True):
        if res is None:
            fails += 1
            continue
        R, t = res
        e = float(np.linalg.norm(-R.T @ t - C))
        if e > FAIL_M:
            fails += 1
            continue
        pos_err.append(e)
        rot_err.append(float(np.degrees(Rotation.from_matrix(R @ R_true.T).magnitude())))
    return {"failures": fails,
            "pos_err_median_mm": 1e3 * float(np.median(pos_err)) if pos_err else None,
            "pos_err_p90_mm": 1e3 * float(np.percentile(pos_err, 90)) if pos_err else None,
            "rot_err_median_deg": float(np.median(rot_err)) if rot_err else None}


def run_flight(seconds, rounds):
    """The methods over one rendered 30 fps flight, each reading the frames in order."""
    grid = GridMap(6, 6, 0.10, 0.05)
    flight = render_map_flight(seconds, 30.0, grid, seed=5, imu_rate=None, background="gravel",
                               camera=FLIGHT_CAMERA)
    truth = []
    for k in range(len(flight.frames)):
        R_world_cam, C = flight.track.pose(k)
        truth.append((C, R_world_cam.T))
    ms = methods(grid, video=True)
    ms["visloc_tracker"] = _tracked(grid)
    ms["visloc_tracker_map"] = _tracked(grid, guided=True)
    times = {m: [] for m in ms}
    out = {}
    for r in range(rounds):
        for m in (list(ms) if r % 2 == 0 else list(ms)[::-1]):
            if hasattr(ms[m], "start"):
                ms[m].start()
            got = []
            for img in flight.frames:
                steady().wait(every=0.25)
                t0 = time.perf_counter()
                got.append(ms[m](img))
                times[m].append(time.perf_counter() - t0)
            out.setdefault(m, got)
    stats = {}
    for m in ms:
        best = best_per_item(times[m], rounds)
        stats[m] = {"ms_median": 1e3 * float(np.median(best)), "ms_mean": 1e3 * float(np.mean(best)),
                    **_errors(truth, out[m])}
        if hasattr(ms[m], "markers"):
            stats[m]["markers_per_frame"] = float(np.mean(ms[m].markers))
        if hasattr(ms[m], "tracker"):
            stats[m]["full_searches"] = ms[m].tracker.full_detections  # in the last pass over the video
    return {"frames": len(flight.frames), "stats": stats}


def run(n, rounds, hard):
    grid = GridMap(6, 6, 0.10, 0.05)
    rng = np.random.default_rng(7 if hard else 3)
    camera = (CameraEffects(blur_sigma=1.2, motion_blur=3.0, read_noise=4.0, exposure=0.5, k1=0.0, jpeg_quality=None)
              if hard else FLIGHT_CAMERA)
    views = [random_map_view(rng, grid, K, (320, 240), "DICT_4X4_50", background="gravel", camera=camera)
             for _ in range(n)]
    ms = methods(grid)
    times = {m: [] for m in ms}
    out = {m: [None] * n for m in ms}
    for r in range(rounds):
        for k, v in enumerate(views):
            steady().wait(every=0.25)
            for m in (list(ms) if (r + k) % 2 == 0 else list(ms)[::-1]):
                t0 = time.perf_counter()
                res = ms[m](v.render.image)
                times[m].append(time.perf_counter() - t0)
                if r == 0:
                    out[m][k] = res
    stats = {}
    detect_ms = 1e3 * float(np.median(best_per_item(ms["visloc"].detect_s, rounds)))
    truth = [(v.position, v.T_cam_map.R) for v in views]
    for m in ms:
        stats[m] = {"ms_median": 1e3 * float(np.median(best_per_item(times[m], rounds))), **_errors(truth, out[m])}
    return {"frames": n, "stats": stats, "visloc_detect_ms_median": detect_ms}


def attitude(minutes: float = 10.0) -> dict:
    """Roll/pitch RMS (deg) over a synthetic IMU stream: 200 Hz, gyro bias (0.05, -0.03, 0.02)
    rad/s, noise, 2 m/s^2 body accelerations in 0.2-2 Hz, 10 s at rest before take-off."""
    from visloc.estimation import ComplementaryFilter, GyroIntegrator, SwitchingFilter, accel_tilt
    from visloc.synth.imu import imu_stream

    s = imu_stream(60.0 * minutes, 200.0, seed=7, rest_seconds=10.0)

    def rms_deg(est):
        e = (np.asarray(est) - s.attitude + np.pi) % (2 * np.pi) - np.pi
        return float(np.degrees(np.sqrt(np.mean(e * e))))

    c = 2 * np.pi * 0.01
    spent = []
    for _ in range(3):  # the best of three runs
        steady().wait()
        t0 = time.perf_counter()
        cf = ComplementaryFilter(0.01, bias_gain=c * c / 4, settle_seconds=10.0, settle_hz=0.2).run(s.gyro, s.accel,
                                                                                                     s.dt)
        spent.append(time.perf_counter() - t0)
    cf_us = 1e6 * min(spent) / len(s.t)
    plain = ComplementaryFilter(0.1).run(s.gyro, s.accel, s.dt)
    gyro = GyroIntegrator(s.roll[0], s.pitch[0], s.yaw[0]).run(s.gyro, s.dt)[:, :2]
    roll, pitch = accel_tilt(s.accel)
    sw = SwitchingFilter(0.1, 30.0)
    swe = sw.run(s.gyro, s.accel, s.dt)
    return {"minutes": minutes, "samples": len(s.t), "rms_deg": {
        "complementary (0.01 Hz, bias estimate)": rms_deg(cf), "complementary (report: gain only, 0.1 Hz)": rms_deg(plain),
        "gyro only": rms_deg(gyro), "accelerometer only": rms_deg(np.column_stack([roll, pitch])),
        f"switching (report 3.6-3.11; {sw.resets} resets)": rms_deg(swe)}, "complementary_us_per_sample": cf_us}


def markdown(result) -> str:
    lines = []
    for name, res in result["sets"].items():
        base = res["stats"]["opencv"]["ms_median"]
        video = "ms_mean" in res["stats"]["opencv"]
        lines.append(f"\n**{name}** ({res['frames']} frames, 320x240{', in order' if video else ''}; each frame's "
                     f"time its best of {result['rounds']} rounds)\n")
        if video:
            lines.append("| method | ms/frame median | ratio | ms/frame mean | ratio | markers/frame | failures | "
                         "position err median mm | p90 mm | rotation err median deg |")
            lines.append("|---|---|---|---|---|---|---|---|---|---|")
        else:
            lines.append("| method | ms/frame | ratio | failures | position err median mm | p90 mm | "
                         "rotation err median deg |")
            lines.append("|---|---|---|---|---|---|---|")
        for m, s in res["stats"].items():
            f = (lambda v, d=2: "–" if v is None else f"{v:.{d}f}")
            mean = (f"{f(s['ms_mean'])} | {f(s['ms_mean'] / res['stats']['opencv']['ms_mean'])} | "
                    f"{f(s.get('markers_per_frame'), 1)} | ") if video else ""
            lines.append(f"| {m} | {f(s['ms_median'])} | {f(s['ms_median'] / base)} | {mean}{s['failures']} | "
                         f"{f(s['pos_err_median_mm'])} | {f(s['pos_err_p90_mm'])} | {f(s['rot_err_median_deg'], 3)} |")
        searches = {m: s["full_searches"] for m, s in res["stats"].items() if "full_searches" in s}
        if searches:
            lines.append(f"\nFull searches in one pass over the {res['frames']} frames: "
                         + ", ".join(f"{m} {n}" for m, n in searches.items()) + ".")
        if "visloc_detect_ms_median" in res:
            lines.append(f"\nvisloc's time: marker detection {res['visloc_detect_ms_median']:.2f} ms (median), "
                         "the joint map pose the rest.")
    att = result.get("attitude")
    if att:
        lines.append(f"\n**Attitude** ({att['minutes']:.0f} min at 200 Hz, {att['samples']} samples; roll/pitch RMS)\n")
        lines.append("| estimator | RMS deg |")
        lines.append("|---|---|")
        for k, v in att["rms_deg"].items():
            lines.append(f"| {k} | {v:.2f} |")
        lines.append(f"\nComplementary filter: {att['complementary_us_per_sample']:.1f} us per sample (best of 3 runs).")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--out", default=str(ROOT / "bench/results"))
    args = ap.parse_args(argv)
    n = 15 if args.quick else 100
    result = {"sets": {"grid clean": run(n, args.rounds, False), "grid hard": run(n, args.rounds, True),
                       "grid flight": run_flight(2.0 if args.quick else 10.0, args.rounds)},
              "attitude": attitude(1.0 if args.quick else 10.0), "rounds": args.rounds}
    result["steady"] = steady().summary()
    write_results(args.out, "localize", result, markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
