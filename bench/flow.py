"""Flow benchmark: visloc's ground velocity vs OpenCV's DIS, pyramidal LK and phase correlation.

The same rendered frame pairs for every method (a downward camera over CC0 ground photographs,
exact per-pair ground truth), at 320x240 and 640x480, 60 FPS, speeds up to 2 m/s, heights
0.5-2.5 m, yaw rates up to 1.5 rad/s. Every method turns its image motion into a velocity the
same way (visloc's ``ground_velocity``), so the comparison is of the image motion:

- ``visloc``: ``block_flow`` + ``global_motion`` (similarity) + ``ground_velocity``;
  ``visloc_direct``: the same plus the sub-pixel stage (``visloc.flow.direct.refine_motion``,
  ``estimate_ground_velocity(..., direct=True)``); ``visloc_stream``: ``EgoMotion(camera,
  options={"direct": True})`` fed each flight's frames in order, as ``visloc flow --direct``
  runs (the previous pair's motion steers the block sums, and after a good pair the next is
  tracked by the direct alignment from it alone, the block sums every 30th pair);
  ``visloc_stream_shadows``: the same with ``"shadows": True`` (``visloc flow --direct
  --shadows``: each frame divided by its local mean before the alignment);
  ``visloc_cir``: the report's Appendix H solver;
- ``dis``: ``cv2.DISOpticalFlow`` PRESET_ULTRAFAST dense flow, sampled on a grid,
  + ``cv2.estimateAffinePartial2D`` (RANSAC);
- ``lk``: ``goodFeaturesToTrack`` + ``calcOpticalFlowPyrLK`` + ``estimateAffinePartial2D``;
- ``phase``: ``cv2.phaseCorrelate`` (translation only).

More sets pass the same flights through a camera (``FLOW_CAMERA``: optics blur, shot and read
noise, vignetting, the sRGB curve, 8-bit quantisation, and the motion blur of each frame's
flight speed over an exposure of half the frame interval): at 320x240 and at 640x480; at 320x240
with every other frame exposed 20 % more (auto exposure stepping); slow flight (under 0.3 m/s
at 1.5-2.5 m: the image moves less than a pixel per frame, the hover regime); and a moving
shadow (a soft band of 40 % less light drifting 0.5 px per frame over the ground). Each pair's
velocity is scaled by the height when its second frame was taken (``ground_velocity``'s
convention). Timing is interleaved per pair (each method in turn, several rounds, every set's
round 1 before any set's round 2, so a pair's rounds lie a minute or more apart and a slow spell
of the host as long as one set moves at most one of them: ``_timing.time_sections``) and covers
image motion plus velocity; each pair's time is its best over the rounds, ``ms/pair`` the
median over the pairs; every quarter second the timing waits until the host runs at its
normal speed (``_timing.Steady``: the host has slow spells of a few seconds). Usage:
``python bench/flow.py [--quick] [--rounds 3]``; writes ``bench/results/flow.json`` and
``flow.md``.
"""

from __future__ import annotations

import argparse
import platform
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
from _results import fmt, write_results
from _timing import steady, time_sections

from visloc.flow import EgoMotion, block_flow, global_motion, ground_velocity
from visloc.flow.direct import refine_motion
from visloc.pose import Camera
from visloc.synth.camera import CameraEffects, apply_camera
from visloc.synth.flight import render_flight
from visloc.types import GlobalMotion

ROOT = Path(__file__).resolve().parents[1]


def _motion_from_affine(M: np.ndarray | None, size: tuple[int, int]) -> GlobalMotion:
    """A 2x3 partial affine (content motion) as a GlobalMotion about the image centre."""
    if M is None:
        return GlobalMotion(np.zeros(2), 0.0, 1.0, None, float("nan"), 0, "affine")
    w, h = size
    c = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    t = M[:, :2] @ c + M[:, 2] - c
    return GlobalMotion(t, float(np.arctan2(M[1, 0], M[0, 0])), float(np.hypot(M[0, 0], M[1, 0])), None, 0.0, 99, "affine")


def make_methods(size: tuple[int, int]) -> dict:
    w, h = size
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST)
    step = max(4, w // 40)
    ys, xs = np.mgrid[step // 2 : h : step, step // 2 : w : step]
    grid = np.stack([xs.ravel(), ys.ravel()], axis=1).astype(np.float32)

    def visloc(a, b, method="similarity"):
        f = block_flow(a, b)
        return global_motion(f, method=method), f

    def visloc_direct(a, b):
        f = block_flow(a, b)
        m = global_motion(f)
        return (refine_motion(a, b, m) if m.inliers >= 3 else m), f

    K = np.array([[300.0, 0.0, (w - 1) / 2.0], [0.0, 300.0, (h - 1) / 2.0], [0.0, 0.0, 1.0]])

    def streamed(options):
        stream: dict = {"ego": None, "last": None}

        def run(a, b):
            # EgoMotion(direct=True) over consecutive pairs: a pair whose first frame is the
            # previous pair's second continues the stream (tracking from the prior), else a new
            # stream starts (its first frame's priming counted in this pair's time); the image
            # motion does not depend on the camera or height given here
            if stream["last"] is not a:
                stream["ego"] = EgoMotion(Camera(K, size=size), options=options)
                stream["ego"].update(a, dt=1 / 60.0, height=1.0)
            gv = stream["ego"].update(b, dt=1 / 60.0, height=1.0)
            stream["last"] = b
            return gv.motion, stream["ego"].last_field

        return run

    def run_dis(a, b):
        flow = dis.calc(a, b, None)
        d = flow[grid[:, 1].astype(int), grid[:, 0].astype(int)]
        M, _ = cv2.estimateAffinePartial2D(grid, grid + d, method=cv2.RANSAC)
        return _motion_from_affine(M, size), None

    def run_lk(a, b):
        p0 = cv2.goodFeaturesToTrack(a, 200, 0.01, max(4, w // 40))
        if p0 is None:
            return _motion_from_affine(None, size), None
        p1, st, _ = cv2.calcOpticalFlowPyrLK(a, b, p0, None)
        ok = st.ravel() == 1
        if ok.sum() < 3:
            return _motion_from_affine(None, size), None
        M, _ = cv2.estimateAffinePartial2D(p0[ok], p1[ok], method=cv2.RANSAC)
        return _motion_from_affine(M, size), None

    def run_phase(a, b):
        (dx, dy), _ = cv2.phaseCorrelate(a.astype(np.float32), b.astype(np.float32))
        return GlobalMotion(np.array([dx, dy]), 0.0, 1.0, None, 0.0, 99, "phase"), None

    return {"visloc": visloc, "visloc_direct": visloc_direct, "visloc_stream": streamed({"direct": True}),
            "visloc_stream_shadows": streamed({"direct": True, "shadows": True}),
            "visloc_cir": lambda a, b: visloc(a, b, "cir"),
            "dis": run_dis, "lk": run_lk, "phase": run_phase}


#: the camera of the camera-like sets: optics blur, shot and read noise, vignetting, the sRGB
#: curve, 8-bit quantisation; no lens distortion (every method maps image motion to velocity
#: through the same pinhole model); each frame also gets the motion blur of its flight speed
#: (:func:`moving`)
FLOW_CAMERA = CameraEffects(blur_sigma=0.7, full_well=5000.0, read_noise=1.0, vignetting=0.2, k1=0.0,
                            jpeg_quality=None)

#: exposure time of the camera-like frames, as a fraction of the frame interval (1/120 s at
#: 60 FPS, an auto exposure indoors)
FLOW_EXPOSURE = 0.5


def moving(camera: CameraEffects, v_cam, height: float, f: float, fps: float = 60.0) -> CameraEffects:
    """``camera`` with the linear motion blur of a frame taken at velocity ``v_cam`` (m/s along
    the camera's x and y) and ``height`` (m) with focal length ``f`` (px): the ground's image
    moves ``f |v| / height`` px/s during ``FLOW_EXPOSURE / fps`` s (rotation is not counted)."""
    length = float(np.hypot(v_cam[0], v_cam[1])) * f / height * FLOW_EXPOSURE / fps
    return replace(camera, motion_blur=length, motion_angle=float(np.arctan2(v_cam[1], v_cam[0])))


#: the moving-shadow set: a band of 40 % less light, a third of the image wide with soft edges,
#: drifting across the ground at 0.5 px per frame (a cloud's or a structure's shadow)
SHADOW_DEPTH, SHADOW_SPEED = 0.4, 0.5


def _shadow(shape, k):
    """The light (H, W) of frame ``k`` under the moving shadow: 1 outside the band."""
    h, w = shape
    x = np.arange(w) - (0.2 * w + SHADOW_SPEED * k)
    y = np.arange(h)[:, None]
    d = x[None, :] + 0.3 * (y - h / 2)  # a slanted band
    inside = 0.5 * (np.tanh(d / 6.0) - np.tanh((d - w / 3.0) / 6.0))
    return 1.0 - SHADOW_DEPTH * inside


def _frames(fl, camera, exposure_step, seed, shadow=False):
    """The flight's frames as rendered (linear, with its noise), or through ``camera``; with
    ``exposure_step`` every other frame is exposed 20 % more (auto exposure stepping); with
    ``shadow`` a moving shadow darkens a band of the ground (:func:`_shadow`)."""
    if camera is None:
        return list(fl.frames)
    rng = np.random.default_rng(seed)
    out = []
    tr = fl.track
    for k, f in enumerate(fl.frames):
        fx = moving(camera, tr.v_cam[k], float(tr.position[k, 2]), float(fl.K[0, 0]))
        fx = replace(fx, exposure=1.2) if exposure_step and k % 2 else fx
        light = f.astype(np.float64) * (_shadow(f.shape, k) if shadow else 1.0)
        out.append(apply_camera(light, fl.K, fx, rng=rng)[0])
    return out


def flow_pairs(size, n_flights, seconds, seed0, camera=None, exposure_step=False, slow=False, shadow=False) -> list:
    """One set's frame pairs: per consecutive pair of frames of ``n_flights`` rendered flights,
    (first frame, second frame, :class:`Camera`, the height when the second frame was taken, the
    true velocity, the true yaw rate)."""
    pairs = []
    for i in range(n_flights):
        speed, heights = ((0.3, (1.5, 2.5)) if slow else (2.0, (0.5, 2.5)))  # slow: under 1 px per frame
        fl = render_flight(seconds, 60.0, size=size, seed=seed0 + i, max_speed=speed, height=heights,
                           max_yaw_rate=1.5, noise_sigma=1.0 if camera is None else 0.0,
                           texture=("grass", "gravel", "brick")[i % 3])
        cam = Camera(fl.K, size=size)
        tr = fl.track
        frames = _frames(fl, camera, exposure_step, seed0 + i, shadow)
        for k in range(1, len(tr)):
            # the height when the second frame was taken, as ground_velocity takes it (and
            # visloc flow reads it: the newest frame's)
            pairs.append((frames[k - 1], frames[k], cam, float(tr.position[k, 2]),
                          tr.pair_v[k], float(tr.pair_yaw_rate[k])))
    return pairs


def pair_methods(size) -> dict:
    """name -> function(pair of :func:`flow_pairs`) -> :class:`GroundVelocity`: each method's
    image motion (:func:`make_methods`, one set's own instances: the streams keep their state
    within the set) turned into a velocity by ``ground_velocity``, the work the timing covers."""

    def with_velocity(motion_of):
        def run(pair):
            a, b, cam, height = pair[:4]
            motion, field = motion_of(a, b)
            return ground_velocity(motion, cam, height, 1 / 60.0, field=field)
        return run

    return {m: with_velocity(fn) for m, fn in make_methods(size).items()}


def score(pairs, best, results) -> dict:
    """One set's statistics per method from :func:`time_sections`' best times (s per pair) and
    first-round velocities for ``pairs`` (:func:`flow_pairs`)."""
    speed = np.array([np.linalg.norm(p[4]) for p in pairs])
    stats = {}
    for m in results:
        abs_err = np.array([np.linalg.norm(gv.v - p[4]) for gv, p in zip(results[m], pairs, strict=True)])
        rel = abs_err / np.maximum(speed, 0.05)
        yaw = np.array([abs(gv.yaw_rate - p[5]) for gv, p in zip(results[m], pairs, strict=True)])
        stats[m] = {"ms_median": 1e3 * float(np.median(best[m])), "abs_err_median": float(np.median(abs_err)),
                    "abs_err_p90": float(np.percentile(abs_err, 90)), "rel_err_median": float(np.median(rel)),
                    "rel_err_p90": float(np.percentile(rel, 90)), "yaw_rate_err_median": float(np.median(yaw)),
                    "yaw_rate_err_p90": float(np.percentile(yaw, 90))}
    return {"pairs": len(pairs), "speed_m_s_p10_p50_p90": np.percentile(speed, [10, 50, 90]).round(2).tolist(),
            "heights_m_min_max": [float(min(p[3] for p in pairs)), float(max(p[3] for p in pairs))],
            "yaw_rate_abs_p90": float(np.percentile([abs(p[5]) for p in pairs], 90)), "methods": stats}


def still_frames(size):
    """|v| at 1 m for identical frames and for frames differing only by sensor noise."""
    fl = render_flight(0.05, 60.0, size=size, seed=99, max_speed=0.0, max_yaw_rate=0.0, noise_sigma=0.0)
    cam = Camera(fl.K, size=size)
    a = fl.frames[0]
    rng = np.random.default_rng(0)
    n1 = np.clip(a + rng.normal(0, 2.0, a.shape), 0, 255).astype(np.uint8)
    n2 = np.clip(a + rng.normal(0, 2.0, a.shape), 0, 255).astype(np.uint8)
    out = {}
    for name, (x, y) in {"identical": (a, a), "noise_only": (n1, n2)}.items():
        f = block_flow(x, y)
        gv = ground_velocity(global_motion(f), cam, 1.0, 1 / 60.0, field=f)
        out[name] = float(np.linalg.norm(gv.v))
    return out


def markdown(result) -> str:
    lines = []
    for key, res in result["sizes"].items():
        base = res["methods"]["dis"]["ms_median"]
        lines.append(f"\n**{key}**: {res['pairs']} pairs, speed p10/p50/p90 {res['speed_m_s_p10_p50_p90']} m/s, "
                     f"heights {res['heights_m_min_max'][0]:.2f}-{res['heights_m_min_max'][1]:.2f} m, "
                     f"|yaw rate| p90 {res['yaw_rate_abs_p90']:.2f} rad/s; ms/pair: each pair's best of "
                     f"{result['rounds']} rounds, the median over the pairs\n")
        lines.append("| method | ms/pair | ratio to DIS | rel. err median | rel. err p90 | abs. err median m/s | abs. err p90 m/s | yaw-rate err median rad/s | p90 |")
        lines.append("|---|---|---|---|---|---|---|---|---|")
        for m, s in res["methods"].items():
            lines.append(f"| {m} | {fmt(s['ms_median'])} | {fmt(s['ms_median'] / base, 2)} | {fmt(s['rel_err_median'], 4)} | "
                         f"{fmt(s['rel_err_p90'], 4)} | {fmt(s['abs_err_median'], 4)} | {fmt(s['abs_err_p90'], 4)} | "
                         f"{fmt(s['yaw_rate_err_median'], 4)} | {fmt(s['yaw_rate_err_p90'], 4)} |")
        st = res["still"]
        lines.append(f"\nStill camera at 1 m: |v| = {st['identical']:.4f} m/s for identical frames, "
                     f"{st['noise_only']:.4f} m/s for frames differing by sensor noise (sigma 2).")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", default=str(ROOT / "bench/results"))
    args = ap.parse_args(argv)
    n_flights, seconds = (2, 0.5) if args.quick else (6, 2.0)
    result = {"machine": {"python": sys.version.split()[0], "opencv": cv2.__version__, "numpy": np.__version__,
                          "platform": platform.platform()}, "rounds": args.rounds, "sizes": {}}
    sets = [((320, 240), None, False, False, False), ((640, 480), None, False, False, False),
            ((320, 240), FLOW_CAMERA, False, False, False), ((640, 480), FLOW_CAMERA, False, False, False),
            ((320, 240), FLOW_CAMERA, True, False, False),
            ((320, 240), FLOW_CAMERA, False, True, False), ((320, 240), FLOW_CAMERA, False, False, True)]
    sections, keys = [], []
    for size, camera, step, slow, shadow in sets:
        keys.append(f"{size[0]}x{size[1]}" + ("" if camera is None else ", camera-like") + (
            ", +20 % exposure every other frame" if step else "") + (
            ", slow flight (under 0.3 m/s at 1.5-2.5 m: under a pixel per frame)" if slow else "") + (
            f", a moving shadow ({100 * SHADOW_DEPTH:.0f} % less light in a band drifting {SHADOW_SPEED} px per frame)"
            if shadow else ""))
        print(f"flow {keys[-1]}: rendering ...", file=sys.stderr, flush=True)
        sections.append((flow_pairs(size, n_flights, seconds, 10, camera, step, slow, shadow), pair_methods(size)))
    print(f"timing {len(sections)} sets, {args.rounds} rounds ...", file=sys.stderr, flush=True)
    timed = time_sections(sections, args.rounds)
    for key, (size, *_), (pairs, _), (best, results) in zip(keys, sets, sections, timed, strict=True):
        res = score(pairs, best, results)
        res["still"] = still_frames(size)
        result["sizes"][key] = res
    result["steady"] = steady().summary()
    write_results(args.out, "flow", result, markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
