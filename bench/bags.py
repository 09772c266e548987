"""Reading recorded flights: frames per second through ``visloc.io.open_source`` from ROS 1
bags, ROS 2 bags (SQLite, MCAP) and image folders holding the same frames (issue 18's "bag
reading >= the speed of reading the same frames from a PNG folder").

    python bench/bags.py               # writes bench/results/bags.{json,md}

The frames are the markers bench's camera-like 640x480 renders (grey), written once per
format with rosbags' writers (``visloc.io.bags.write_bag``) and as PNG / JPEG files; each
format is read whole, rounds interleaved (the order reversed every other round), each read
starting when the host runs at its normal speed (``_timing.Steady``); each format's fastest
round is kept, and the speeds relative to the PNG folder are ratios of those fastest rounds.
"""

from __future__ import annotations

import argparse
import platform
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from _results import fmt, write_results
from _timing import steady

from visloc.io import open_source
from visloc.io.bags import write_bag
from visloc.synth import random_scene

ROOT = Path(__file__).resolve().parents[1]


def _frames(n: int) -> list[np.ndarray]:
    out = []
    for k in range(n):
        img = random_scene(np.random.default_rng([5, k]), size=(640, 480), difficulty="easy", camera=True).image
        out.append(img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY))
    return out


def _read_all(path: Path, fps: float | None) -> int:
    with open_source(path, fps=fps) as src:
        return sum(f.image is not None for f in src)


def run(n: int, rounds: int, work: Path) -> dict:
    frames = _frames(n)
    times = [k / 30 for k in range(n)]
    sources = {}
    for ext in ("png", "jpg"):
        folder = work / f"folder_{ext}"
        folder.mkdir()
        for k, img in enumerate(frames):
            cv2.imwrite(str(folder / f"frame_{k:05d}.{ext}"), img)
        sources[f"{ext.upper()} folder"] = (folder, 30.0)
    for name, fmt_, enc, path in (("ROS 1 bag, mono8", "ros1", "mono8", "raw.bag"),
                                  ("ROS 2 bag (SQLite), mono8", "ros2", "mono8", "raw_sqlite"),
                                  ("ROS 2 bag (MCAP), mono8", "mcap", "mono8", "raw_mcap"),
                                  ("ROS 1 bag, CompressedImage png", "ros1", "png", "png.bag"),
                                  ("ROS 1 bag, CompressedImage jpeg", "ros1", "jpeg", "jpeg.bag")):
        sources[name] = (write_bag(work / path, frames, times, fmt=fmt_, encoding=enc), None)
    spent = {k: [] for k in sources}
    for r in range(rounds):
        for name in (list(sources) if r % 2 == 0 else list(sources)[::-1]):
            path, fps = sources[name]
            steady().wait()
            t0 = time.perf_counter()
            got = _read_all(path, fps)
            spent[name].append(time.perf_counter() - t0)
            assert got == n, (name, got)
    best = {k: float(np.min(v)) for k, v in spent.items()}
    return {"frames": n, "rounds": rounds, "size": [640, 480],
            "rows": {k: {"s_best": s, "s_median": float(np.median(spent[k])), "fps": n / s,
                         "speed_vs_png_folder": best["PNG folder"] / s} for k, s in best.items()}}


def markdown(result: dict) -> str:
    lines = [(f"**Reading recordings** ({result['frames']} grey 640x480 camera-like frames, fastest of "
             f"{result['rounds']} interleaved rounds; speed relative to the PNG folder, > 1 is faster)"), "",
             "| source | frames/s | speed vs PNG folder |", "|---|---|---|"]
    for k, r in result["rows"].items():
        lines.append(f"| {k} | {fmt(r['fps'], 0)} | {fmt(r['speed_vs_png_folder'], 2)} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--rounds", type=int, default=11)
    ap.add_argument("--out", default=str(ROOT / "bench/results"))
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as work:
        result = run(args.frames, args.rounds, Path(work))
    result["steady"] = steady().summary()
    result["machine"] = {"python": sys.version.split()[0], "opencv": cv2.__version__, "platform": platform.platform()}
    write_results(args.out, "bags", result, markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
