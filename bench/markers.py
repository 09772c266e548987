"""Marker benchmark: visloc vs OpenCV ArUco (+ solvePnP IPPE_SQUARE) vs AprilTag 3, one run.

Same rendered frames for every detector. The headline frames are camera-like
(:class:`visloc.synth.CameraEffects`: linear light, lens distortion, optics blur, vignetting,
shot and read noise, the sRGB curve, 8-bit quantisation, JPEG) at 320x240, 640x480 and
1280x720: easy, hard (strong blur, motion blur, noise, dim light, JPEG 60-80), small markers,
dark frames (mean grey below 30) and empty frames. Linear renders (grey levels linear in light,
no lens, the renderer of the first round) are one named case at 640x480, where visloc is told
so (``response="linear"``). Real photographs: ``bench/real_photos.py``.

Peers, with the settings their docs recommend (``bench/_peers.py``): OpenCV ``ArucoDetector``
with default parameters and with ``CORNER_REFINE_SUBPIX``; AprilTag 3 (pupil-apriltags,
``quad_decimate=1, refine_edges=True``, one thread, in a child process that times itself).
Poses: visloc's own; OpenCV ``solvePnP(IPPE_SQUARE)`` on its SUBPIX corners (and AprilTag's),
all with the frame's true intrinsics and distortion.

Timing is interleaved (every frame: each detector in turn, several rounds, every table's
round 1 before any table's round 2, so a frame's rounds lie tens of seconds apart); each frame's time
is its best over the rounds, and the tables give the median over the frames and ratios to
OpenCV's default detector. Every quarter second the timing waits until the host runs at its
normal speed (``_timing.Steady``: the host has slow spells of a few seconds). The split of
visloc's time over its stages (:class:`StageSplit`) makes one pass through one size's frames
after each table's round, so its passes too are spread over the whole timing.

Usage::

    python bench/markers.py [--quick] [--rounds 3] [--out bench/results]

Writes ``markers.json`` and ``markers.md`` (the table the README shows).
"""

from __future__ import annotations

import argparse
import itertools
import os
import platform
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np
from _peers import AprilTagProcess
from _results import fmt, write_results
from _timing import steady, time_sections

from visloc.markers import FAST_PASSES, MarkerDetector
from visloc.pose import Camera, estimate_marker_pose, rotation_angle
from visloc.synth import MARKER_LENGTH, random_board_scene, random_scene

ROOT = Path(__file__).resolve().parents[1]
SIZES = [(320, 240), (640, 480), (1280, 720)]
SETS = {"easy": 30, "hard": 40, "small": 30, "dark": 20, "empty": 15}
FLIP_DEG = 10.0  # a pose whose rotation error exceeds this took the wrong planar solution


def opencv_detector(dict_name: str | None, subpix: bool, dictionary=None) -> cv2.aruco.ArucoDetector:
    d = dictionary if dictionary is not None else cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dict_name))
    p = cv2.aruco.DetectorParameters()
    if subpix:
        p.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    return cv2.aruco.ArucoDetector(d, p)


_APRILTAG: list[AprilTagProcess] = []


def make_methods(dict_name: str, with_apriltag: bool, response: str = "srgb") -> dict:
    """name -> function(gray image) -> list of (id, corners (4, 2) in OpenCV order and pixel
    convention), or (that list, seconds measured by the peer itself)."""
    vl = MarkerDetector(dict_name, response=response)
    vl_fast = MarkerDetector(dict_name, passes=FAST_PASSES, response=response)
    cv_default = opencv_detector(dict_name, False)
    cv_subpix = opencv_detector(dict_name, True)

    def run_cv(det):
        def f(img):
            corners, ids, _ = det.detectMarkers(img)
            return [] if ids is None else [(int(i), c.reshape(4, 2).astype(np.float64)) for c, i in zip(corners, ids.ravel())]
        return f

    methods = {
        "visloc": lambda img: [(d.id, d.corners) for d in vl.detect(img)],
        "visloc_fast": lambda img: [(d.id, d.corners) for d in vl_fast.detect(img)],
        "opencv": run_cv(cv_default),
        "opencv_subpix": run_cv(cv_subpix),
    }
    if with_apriltag:
        if not _APRILTAG:
            _APRILTAG.append(AprilTagProcess())
        family = "tag" + dict_name.split("_")[-1]

        def run_at(img):  # OpenCV order and convention; the child's own detect time
            return _APRILTAG[0].detect(img, family)

        methods["apriltag3"] = run_at
    return methods


def match(dets, truth):
    """Pairs (det corners, truth marker) by id and position; the rest are false positives."""
    pairs, fp = [], 0
    used = set()
    for mid, c in dets:
        best = None
        for k, m in enumerate(truth):
            if k in used or m.id != mid:
                continue
            if np.abs(c.mean(axis=0) - m.corners.mean(axis=0)).max() < 0.25 * np.sqrt(abs(cv2.contourArea(m.corners.astype(np.float32)))) + 2:
                best = k
                break
        if best is None:
            fp += 1
        else:
            used.add(best)
            pairs.append((c, truth[best]))
    return pairs, fp


def corner_alignment(c, gt):
    """Corner errors (4,) for the best cyclic alignment (AprilTag's order is converted, but
    a detector reporting a rotated order would otherwise count as a huge error)."""
    return np.sqrt(((c - gt) ** 2).sum(axis=1))


def pose_of(method: str, corners, camera: Camera):
    if method.startswith("visloc"):
        p = estimate_marker_pose(corners, MARKER_LENGTH, camera)
        return p.R, p.t
    L = MARKER_LENGTH
    obj = np.array([[-L / 2, L / 2, 0], [L / 2, L / 2, 0], [L / 2, -L / 2, 0], [-L / 2, -L / 2, 0]])
    ok, rvec, tvec = cv2.solvePnP(obj, corners.astype(np.float64), camera.K, camera.dist,
                                  flags=cv2.SOLVEPNP_IPPE_SQUARE)
    if not ok:
        return None
    return cv2.Rodrigues(rvec)[0], tvec.ravel()


def rendered_scenes(size, dict_name, sets, seed0, camera=True) -> list:
    """The (set name, :class:`visloc.synth.Scene`) frames of one rendered table."""
    return [(name, random_scene(np.random.default_rng([seed0, size[0], list(SETS).index(name), i]), size=size,
                                dictionary=dict_name, difficulty=name, camera=camera))
            for name, n in sets.items() for i in range(n)]


def score_rendered(scenes, sets, best, outputs) -> dict:
    """One rendered table's statistics per method and set, from :func:`time_sections`' times
    and outputs for ``scenes`` (:func:`rendered_scenes`)."""
    methods = list(best)
    matched = {m: [match(outputs[m][k], [t for t in sc.markers if t.visible]) for k, (_, sc) in enumerate(scenes)]
               for m in methods}
    # the markers every method of the table found, per frame: corner errors on the same markers
    common = [set.intersection(*({gt.id for _, gt in matched[m][k][0]} for m in methods)) for k in range(len(scenes))]
    stats = {}
    for m in methods:
        per_set = {}
        for name in sets:
            idx = [k for k, (s, _) in enumerate(scenes) if s == name]
            n_truth = tp = fp = flips = 0
            cerr, rot, trans, shared = [], [], [], []
            for k in idx:
                sc = scenes[k][1]
                truth = [t for t in sc.markers if t.visible]
                n_truth += len(truth)
                pairs, f = matched[m][k]
                fp += f
                tp += len(pairs)
                camera = Camera(sc.K, sc.dist)
                for c, gt in pairs:
                    err = corner_alignment(c, gt.corners)
                    cerr.extend(err)
                    if gt.id in common[k]:
                        shared.extend(err)
                    pose_corners = c
                    meth = m
                    if m == "opencv":  # IPPE_SQUARE on SUBPIX corners is scored under opencv_subpix
                        continue
                    pr = pose_of(meth, pose_corners, camera)
                    if pr is None:
                        continue
                    e = np.degrees(rotation_angle(pr[0] @ gt.pose.R.T))
                    rot.append(e)
                    trans.append(np.linalg.norm(pr[1] - gt.pose.t) / np.linalg.norm(gt.pose.t))
                    flips += e > FLIP_DEG
            per_set[name] = {
                "frames": len(idx),
                "markers": n_truth,
                "recall": tp / n_truth if n_truth else None,
                "false_positives_per_frame": fp / len(idx),
                "corner_rms_px": float(np.sqrt(np.mean(np.square(cerr)))) if cerr else None,
                "corner_median_px": float(np.median(cerr)) if cerr else None,
                "common_markers": len(shared) // 4,
                "common_corner_rms_px": float(np.sqrt(np.mean(np.square(shared)))) if shared else None,
                "common_corner_median_px": float(np.median(shared)) if shared else None,
                "rot_err_median_deg": float(np.median(rot)) if rot else None,
                "trans_err_median_pct": float(100 * np.median(trans)) if trans else None,
                "flip_rate": flips / len(rot) if rot else None,
            }
        stats[m] = {"ms_median": 1e3 * float(np.median(best[m])), "ms_mean": 1e3 * float(np.mean(best[m])),
                    "sets": per_set}
    return stats


BOARD_SETS = {"camera-like easy": ("easy", True), "camera-like hard": ("hard", True),
              "linear sharp": ("easy", False), "linear hard": ("hard", False)}


def board_section(n: int, seed0: int = 9) -> tuple[list, dict]:
    """AprilGrid-style boards (tags touching the grid's corner squares, Kalibr's layout;
    :func:`visloc.synth.random_board_scene`), 640x480, ``n`` per set of :data:`BOARD_SETS`:
    the (set name, scene) frames and the methods, for :func:`time_sections` (items: (image,
    camera-like?)). ``visloc_boards`` is ``MarkerDetector(..., erode=2)`` (stage 3b); visloc
    reads the linear renders with ``response="linear"``."""
    frames = [(name, random_board_scene(np.random.default_rng([seed0, k, i]), difficulty=diff, camera=cam))
              for k, (name, (diff, cam)) in enumerate(BOARD_SETS.items()) for i in range(n)]
    methods = {(m, cam): MarkerDetector("DICT_APRILTAG_36h11", erode=e, response="srgb" if cam else "linear")
               for m, e in (("visloc", 0), ("visloc_boards", 2)) for cam in (True, False)}
    cv_det = opencv_detector("DICT_APRILTAG_36h11", False)
    run = {m: (lambda item, m=m: [(x.id, x.corners) for x in methods[m, item[1]].detect(item[0])])
           for m in ("visloc", "visloc_boards")}
    run["opencv"] = lambda item: [] if (r := cv_det.detectMarkers(item[0]))[1] is None else [
        (int(i), c.reshape(4, 2).astype(np.float64)) for c, i in zip(r[0], r[1].ravel())]
    return frames, run


def score_boards(frames, best, out) -> dict:
    """The boards' recall (right id, every corner within 3 px of the truth), corner RMS and ms
    per frame (each frame's best of the rounds, the median over the frames) per method, from
    :func:`time_sections`' times and outputs for :func:`board_section`'s frames."""
    stats = {}
    for m in best:
        per = {}
        for name in BOARD_SETS:
            found = total = 0
            errs = []
            for k, (set_name, sc) in enumerate(frames):
                if set_name != name:
                    continue
                truth = {t.id: t.corners for t in sc.markers if t.visible}
                total += len(truth)
                for mid, c in out[m][k]:
                    if mid in truth and np.abs(c - truth[mid]).max() < 3:
                        found += 1
                        errs.extend(np.sqrt(((c - truth[mid]) ** 2).sum(axis=1)))
            per[name] = {"found": found, "tags": total, "recall": found / total if total else None,
                         "corner_rms_px": float(np.sqrt(np.mean(np.square(errs)))) if errs else None}
        stats[m] = {"ms_median": 1e3 * float(np.median(best[m])), "sets": per}
    return stats


#: the detector's stage functions whose time :class:`StageSplit` measures, in pipeline order
STAGES = {"blur": "2 blur", "threshold": "3 threshold", "find_candidates": "4-5 contours + filter",
          "fit_quads": "6-7 corner split + line fits",
          "refine_quads": "8 edge refinement", "read_cells": "9 cells read (first look and stage 9)",
          "sample_cells": "9 second reads: samples", "read_bits": "9 second reads: bits",
          "cell_white_fractions": "9 area read (confidence)", "decode": "10 dictionary"}


@contextmanager
def _stage_timers():
    """Within the block, the detector's stage functions (:data:`STAGES`) add their time (s) to
    the dict the block gets (stage function name -> s, from 0) and its search passes all run on
    the calling thread (so the stage times add up); both undone on leaving."""
    import visloc.markers.detector as det_mod

    spent = dict.fromkeys(STAGES, 0.0)
    originals = {name: getattr(det_mod, name) for name in STAGES}
    threaded = det_mod._THREAD_MAX_PIXELS

    def timed(name, fn):
        def run(*a, **k):
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                spent[name] += time.perf_counter() - t0
        return run

    try:
        det_mod._THREAD_MAX_PIXELS = 0
        for name, fn in originals.items():
            setattr(det_mod, name, timed(name, fn))
        yield spent
    finally:
        det_mod._THREAD_MAX_PIXELS = threaded
        for name, fn in originals.items():
            setattr(det_mod, name, fn)


class StageSplit:
    """Where visloc's time goes: ms per frame in each stage function of the detector over
    ``images`` ({"WxH": the frames of that size}: ``main`` gives the camera-like DICT_4X4_50
    tables' own frames).

    Each :meth:`run_pass` makes one pass through the frames of the next size in turn (the stage
    functions timed only during the pass, :func:`_stage_timers`). ``main`` runs one after every
    table's round (:func:`time_sections`' ``between``: 3 rounds of the 6 tables give each of the 3
    sizes 6 passes), so a size's passes lie spread over the whole timing rather than in a block
    at its end (timed so on 2026-12-07, one run's split came out 26-28 % slower than the run
    before's while its tables came out 15-20 % faster). :meth:`result` keeps each size's fastest
    pass, whole, so its parts add up.
    """

    def __init__(self, images: dict[str, list]) -> None:
        self.images = images
        self.passes: dict[str, list[dict]] = {key: [] for key in images}
        self.detector = MarkerDetector("DICT_4X4_50")
        self._sizes = itertools.cycle(images)

    def run_pass(self) -> None:
        """One pass through the next size's frames (sizes in turn)."""
        key = next(self._sizes)
        with _stage_timers() as spent:
            self.passes[key].append(_stage_pass(self.detector, self.images[key], spent))

    def result(self) -> dict:
        """Per size with at least one pass, the stage split of its fastest pass (ms per frame per
        stage, the rest and the total) and ``"passes"``, the count it is the fastest of."""
        return {key: {**min(rows, key=lambda row: row["total"]), "passes": len(rows)}
                for key, rows in self.passes.items() if rows}


def _stage_pass(vl, frames, spent) -> dict:
    """One pass of :class:`StageSplit` through ``frames``: ms per frame per stage (``spent``,
    filled by the stage timers, :func:`_stage_timers`) and in total."""
    total = 0.0
    for img in frames:
        steady().wait(every=0.25)
        t0 = time.perf_counter()
        vl.detect(img)
        total += time.perf_counter() - t0
    n = len(frames)
    row = {STAGES[k]: 1e3 * v / n for k, v in spent.items()}
    row["rest (Python glue, duplicates, results)"] = 1e3 * (total - sum(spent.values())) / n
    row["total"] = 1e3 * total / n
    return row


def _plain(o):
    """JSON fallback for numpy scalars."""
    return o.item() if hasattr(o, "item") else str(o)


def markdown(result) -> str:
    lines = []
    for key, res in result["rendered"].items():
        lines.append(f"\n**{key}** (ms per frame: each frame's best of the rounds, the median over all sets; ratio to "
                     "OpenCV default; `common`: the "
                     "corners of the markers every method in the table found, RMS / median px)\n")
        base = res["opencv"]["ms_median"]
        lines.append("| method | ms/frame | ratio | set | recall | FP/frame | corner RMS px | corner median px | common "
                     "(markers: RMS / median px) | rot err median ° | trans err median % | flips |")
        lines.append("|---|---|---|---|---|---|---|---|---|---|---|---|")
        for m, st in res.items():
            for k, (name, s) in enumerate(st["sets"].items()):
                head = (m, fmt(st["ms_median"], 2), fmt(st["ms_median"] / base, 2)) if k == 0 else ("", "", "")
                shared = (f"{s['common_markers']}: {fmt(s['common_corner_rms_px'])} / {fmt(s['common_corner_median_px'])}"
                          if s["common_markers"] else "–")
                lines.append("| " + " | ".join([*head, name, fmt(s["recall"]), fmt(s["false_positives_per_frame"], 2),
                                                 fmt(s["corner_rms_px"]), fmt(s["corner_median_px"]), shared,
                                                 fmt(s["rot_err_median_deg"], 2),
                                                 fmt(s["trans_err_median_pct"], 2), fmt(s["flip_rate"], 3)]) + " |")
    if result.get("boards"):
        lines.append("\n**AprilGrid-style boards**, 640x480 DICT_APRILTAG_36h11 (tags touching the grid's corner "
                     "squares; found = right id and every corner within 3 px; `visloc`: defaults, stage 3c on; `visloc_boards` = `erode=2`, stage 3b on every frame; "
                     "ms/frame: each frame's best of the rounds, the median over the frames)\n")
        lines.append("| method | ms/frame | set | found | recall | corner RMS px |")
        lines.append("|---|---|---|---|---|---|")
        for m, st in result["boards"].items():
            for k, (name, r) in enumerate(st["sets"].items()):
                head = (m, fmt(st["ms_median"], 2)) if k == 0 else ("", "")
                lines.append(f"| {head[0]} | {head[1]} | {name} | {r['found']}/{r['tags']} | {fmt(r['recall'])} | "
                             f"{fmt(r['corner_rms_px'])} |")
    if result.get("stages"):
        sizes = list(result["stages"])
        counts = sorted({result["stages"][sz]["passes"] for sz in sizes})
        lines.append("\n**Where visloc's time goes** (ms per frame in each stage over the same camera-like "
                     f"DICT_4X4_50 frames, the pass through them with the lowest total of "
                     f"{'-'.join(map(str, counts))}, the passes spread over the timing of the tables above, "
                     "every pass on one thread; the timers add a little)\n")
        lines.append("| stage | " + " | ".join(sizes) + " |")
        lines.append("|---|" + "---|" * len(sizes))
        for stage in [k for k in result["stages"][sizes[0]] if k != "passes"]:
            lines.append(f"| {stage} | " + " | ".join(fmt(result["stages"][sz][stage], 2) for sz in sizes) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer frames (a smoke run)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--sizes", default=",".join(f"{w}x{h}" for w, h in SIZES))
    ap.add_argument("--out", default=str(ROOT / "bench/results"))
    args = ap.parse_args(argv)
    sets = {k: max(3, v // 5) for k, v in SETS.items()} if args.quick else SETS
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    result = {"machine": {"python": sys.version.split()[0], "opencv": cv2.__version__, "numpy": np.__version__,
                          "platform": platform.platform(), "cv_threads": cv2.getNumThreads()},
              "rounds": args.rounds, "sets": sets, "rendered": {}}
    tables = {}  # key: (scenes, sets, methods)
    for size in sizes:
        tables[f"{size[0]}x{size[1]} DICT_4X4_50, camera-like"] = (
            rendered_scenes(size, "DICT_4X4_50", sets, 1), sets, make_methods("DICT_4X4_50", False))
    at_sets = {k: v for k, v in sets.items() if k in ("easy", "hard", "dark")}
    tables["640x480 DICT_APRILTAG_36h11, camera-like"] = (
        rendered_scenes((640, 480), "DICT_APRILTAG_36h11", at_sets, 2), at_sets, make_methods("DICT_APRILTAG_36h11", True))
    lin_sets = {k: v for k, v in sets.items() if k in ("easy", "hard", "small")}
    tables["640x480 DICT_4X4_50, linear renders (named case: no camera model)"] = (
        rendered_scenes((640, 480), "DICT_4X4_50", lin_sets, 1, camera=False), lin_sets,
        make_methods("DICT_4X4_50", False, "linear"))
    boards, board_run = board_section(4 if args.quick else 12)
    sections = [([sc.image for _, sc in scenes], methods) for scenes, _, methods in tables.values()]
    sections.append(([(sc.image, BOARD_SETS[name][1]) for name, sc in boards], board_run))
    split = StageSplit({f"{w}x{h}": [sc.image for _, sc in tables[f"{w}x{h} DICT_4X4_50, camera-like"][0]]
                        for w, h in sizes})
    print(f"timing {len(sections)} tables, {args.rounds} rounds (a stage-split pass after each) ...",
          file=sys.stderr, flush=True)
    timed = time_sections(sections, args.rounds, between=split.run_pass)
    for (key, (scenes, table_sets, _)), (best, outputs) in zip(tables.items(), timed):
        result["rendered"][key] = score_rendered(scenes, table_sets, best, outputs)
    result["boards"] = score_boards(boards, *timed[-1])
    result["stages"] = split.result()
    for at in _APRILTAG:
        at.close()
    result["steady"] = steady().summary()
    write_results(args.out, "markers", result, markdown(result), default=_plain)
    return 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    # pupil-apriltags' detector can corrupt the heap when it is destroyed at interpreter exit
    # (seen here with 1.0.4.post11); everything is written by now, so leave without teardown
    os._exit(code)
