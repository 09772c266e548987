"""The detector's design figures: what one stage or option changes, visloc against itself on
renders with exact ground truth (the figures the README's "How the detector works" and the
ChArUco notes quote).

- Stage 4: how many outer borders a camera-like 640x480 frame has, and how many enclose a
  hole (only those go on to stage 5).
- Stage 8: corner error on camera-like 640x480 hard frames after the two first refinement
  passes only (``refine_max_iterations=2``) and with the further passes (the default).
- Linear light: corner error on camera-like 640x480 easy frames with the edges measured in
  the encoded grey levels (``response="linear"``) and through the sRGB curve (the default).
- Stage 8b: corner error on noise-free 640x480 renders through a webcam's barrel distortion
  (k1 = -0.15) with straight sides (``bend=False``) and curved ones (the default).
- ChArUco corners: time per 1280x720 calibration view of the default edge fit and of
  ``method="saddle"``, interleaved view by view, each view's fastest of 5 rounds.

Usage: ``python bench/design.py [--scenes 20] [--out bench/results]``; writes ``design.json``
and ``design.md``.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from _results import fmt, write_results
from _timing import best_per_item, steady
from refine_window import corner_errors

from visloc.boards import detect_charuco
from visloc.markers import MarkerDetector
from visloc.synth import CameraEffects, random_scene
from visloc.synth.calibration import calibration_views

ROOT = Path(__file__).resolve().parents[1]
SIZE = (640, 480)
#: a webcam's barrel distortion, noise-free (as tests/markers/test_detector.py renders it)
BARREL = CameraEffects(k1=-0.15, full_well=None, read_noise=0.0, jpeg_quality=None, vignetting=0.0)


def _scenes(difficulty: str, n: int, camera, seed: int) -> list:
    return [random_scene(np.random.default_rng([seed, k]), size=SIZE, dictionary="DICT_4X4_50",
                         difficulty=difficulty, camera=camera) for k in range(n)]


def borders(scenes: list) -> dict:
    """Stage 4 on the first search pass: outer borders per frame, and those enclosing a hole."""
    det = MarkerDetector("DICT_4X4_50")
    all_, kept = [], []
    for scene in scenes:
        first = det.trace(scene.image).passes[0]
        all_.append(len(first.contours))
        kept.append(int(np.count_nonzero(first.enclosing)))
    return {"frames": len(scenes), "borders_median": float(np.median(all_)), "enclosing_median": float(np.median(kept))}


def saddle_time(views: int = 12, rounds: int = 5) -> dict:
    """Milliseconds per ChArUco view, the default edge fit against ``method="saddle"``,
    interleaved view by view; each view's fastest round (every view starting when the host runs
    at its normal speed, ``_timing.Steady``), averaged over the views."""
    from calibrate import BOARD

    images = [v.image for v in calibration_views(BOARD, views, size=(1280, 720), seed=5)]
    spent = {"edges": [], "saddle": []}
    for r in range(rounds):
        for img in images:
            for method in (("edges", "saddle") if r % 2 == 0 else ("saddle", "edges")):
                steady().wait(every=0.25)
                t0 = time.perf_counter()
                detect_charuco(img, BOARD, method=method)
                spent[method].append(time.perf_counter() - t0)
    out = {m: 1e3 * float(np.mean(best_per_item(v, rounds))) for m, v in spent.items()}
    return {**out, "ratio": out["saddle"] / out["edges"], "views": views, "rounds": rounds}


def run(n: int) -> dict:
    easy = _scenes("easy", n, True, 11)
    hard = _scenes("hard", n, True, 12)
    bent = _scenes("easy", n, BARREL, 13)
    return {
        "scenes": n,
        "stage4": borders(easy[:10]),
        "stage8_passes": {"two passes": corner_errors(MarkerDetector("DICT_4X4_50", refine_max_iterations=2), hard),
                          "up to six (default)": corner_errors(MarkerDetector("DICT_4X4_50"), hard)},
        "response": {"encoded grey levels (response='linear')": corner_errors(
                         MarkerDetector("DICT_4X4_50", response="linear"), easy),
                     "linear light (response='srgb', default)": corner_errors(MarkerDetector("DICT_4X4_50"), easy)},
        "bend": {"straight sides (bend=False)": corner_errors(MarkerDetector("DICT_4X4_50", bend=False), bent),
                 "curved sides (default)": corner_errors(MarkerDetector("DICT_4X4_50"), bent)},
        "charuco_ms_per_view": saddle_time(),
    }


def markdown(r: dict) -> str:
    s4 = r["stage4"]
    lines = [(f"**Stage 4** ({s4['frames']} camera-like 640x480 easy frames, first search pass; median per frame): "
              f"{fmt(s4['borders_median'], 0)} outer borders, {fmt(s4['enclosing_median'], 0)} enclosing a hole."), ""]
    for key, title in (("stage8_passes", "Stage 8's passes, camera-like 640x480 hard frames"),
                       ("response", "Edges in linear light, camera-like 640x480 easy frames"),
                       ("bend", "Stage 8b, noise-free 640x480 renders through barrel distortion k1 = -0.15")):
        lines += [f"**{title}** ({r['scenes']} scenes; corner error against the truth)", "",
                  "| variant | found / visible | corner RMS px | corner median px |", "|---|---|---|---|"]
        for name, e in r[key].items():
            lines.append(f"| {name} | {e['found']}/{e['markers']} | {fmt(e['rms_px'])} | {fmt(e['median_px'])} |")
        lines.append("")
    c = r["charuco_ms_per_view"]
    lines.append(f"**ChArUco corners** ({c['views']} calibration views, 1280x720, each view's fastest of "
                 f"{c['rounds']} interleaved rounds, mean over the views): "
                 f"{fmt(c['edges'], 1)} ms per view with the edge fit (default), {fmt(c['saddle'], 1)} ms with "
                 f"`method=\"saddle\"` ({fmt(c['ratio'], 2)}x).")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=20, help="scenes per set (default 20)")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results"))
    args = ap.parse_args(argv)
    if args.scenes < 1:
        ap.error("--scenes must be at least 1")
    result = run(args.scenes)
    result["steady"] = steady().summary()
    result["machine"] = {"python": sys.version.split()[0], "opencv": cv2.__version__, "platform": platform.platform()}
    write_results(args.out, "design", result, markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
