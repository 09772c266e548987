"""Dead-reckoning drift: ``visloc flow`` on rendered 10 s flights against pyramidal LK.

Each flight is rendered by the CLI (``visloc render flow OUT --seconds 10``: PNG frames, its
camera file, ground truth and heights), and a second time through a camera
(``bench/flow.py``'s ``FLOW_CAMERA``: optics blur, shot and read noise, vignetting, the sRGB
curve, 8-bit quantisation, and each frame's motion blur over half the frame interval). On each folder:

- ``visloc`` and ``visloc_direct``: the CLI itself, ``visloc flow DIR --camera camera.yml
  --height-csv heights.csv --fps 60 [--direct] --out track.csv``, whose ``x, y`` columns are
  the dead-reckoned track in the first frame's camera axes;
- ``lk``: the same frames through ``goodFeaturesToTrack`` + ``calcOpticalFlowPyrLK`` +
  ``estimateAffinePartial2D`` (``bench/flow.py``'s peer), turned into velocities by
  ``ground_velocity`` with the same heights and integrated as ``EgoMotion`` integrates.

The truth is ``ground_truth.csv`` moved into the first frame's camera axes. Printed per set:
the position error at the end (m and % of the distance flown) and its largest value along the
track. Usage: ``python bench/flow_drift.py [--flights 3] [--seconds 10]``; writes
``bench/results/flow_drift.json`` and ``flow_drift.md``.
"""

from __future__ import annotations

import argparse
import csv
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from _results import fmt, write_results
from flow import FLOW_CAMERA, make_methods, moving

from visloc.flow import ground_velocity
from visloc.pose import Camera
from visloc.synth.camera import apply_camera

ROOT = Path(__file__).resolve().parents[1]
TEXTURES = ("grass", "gravel", "brick")


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def truth_track(gt: list[dict]) -> np.ndarray:
    """(N, 2) truth positions relative to frame 0, in frame 0's camera x, y axes (camera x =
    world (cos psi, sin psi), camera y = world (sin psi, -cos psi): the camera looks down)."""
    xy = np.array([[float(r["x"]), float(r["y"])] for r in gt])
    psi = float(gt[0]["yaw"])
    d = xy - xy[0]
    c, s = np.cos(psi), np.sin(psi)
    return np.stack([c * d[:, 0] + s * d[:, 1], s * d[:, 0] - c * d[:, 1]], axis=1)


def cli_track(folder: Path, direct: bool) -> tuple[np.ndarray, float]:
    """The dead-reckoned track (N, 2) of ``visloc flow`` on the folder, and its wall time."""
    out = folder.parent / f"{folder.name}_{'direct' if direct else 'plain'}.csv"  # not inside the input folder
    cmd = [sys.executable, "-m", "visloc", "flow", str(folder), "--camera", str(folder / "camera.yml"),
           "--height-csv", str(folder / "heights.csv"), "--fps", "60", "--out", str(out), "--quiet"]
    t0 = time.perf_counter()
    subprocess.run(cmd + (["--direct"] if direct else []), check=True)
    spent = time.perf_counter() - t0
    return np.array([[float(r["x"]), float(r["y"])] for r in _rows(out)]), spent


def lk_track(folder: Path, heights: np.ndarray, camera: Camera, size: tuple[int, int]) -> np.ndarray:
    """LK + partial affine per pair, ``ground_velocity``, integrated as ``EgoMotion`` does."""
    lk = make_methods(size)["lk"]
    frames = sorted(folder.glob("frame_*.png"))
    prev = cv2.imread(str(frames[0]), cv2.IMREAD_GRAYSCALE)
    pos, yaw, track = np.zeros(2), 0.0, [np.zeros(2)]
    for k in range(1, len(frames)):
        img = cv2.imread(str(frames[k]), cv2.IMREAD_GRAYSCALE)
        motion, _ = lk(prev, img)
        gv = ground_velocity(motion, camera, float(heights[k]), 1 / 60.0)  # at the second frame, as visloc flow
        c, s = np.cos(yaw), np.sin(yaw)
        step = gv.v / 60.0
        pos = pos + np.array([c * step[0] - s * step[1], s * step[0] + c * step[1]])
        yaw += gv.yaw_rate / 60.0
        track.append(pos.copy())
        prev = img
    return np.array(track)


def camera_like(src: Path, dst: Path, seed: int) -> None:
    """The flight's frames through ``FLOW_CAMERA`` (linear light in, 8-bit sRGB out), each with
    the motion blur of its speed (``bench/flow.py``'s ``moving``, from ``ground_truth.csv``)."""
    dst.mkdir()
    for name in ("camera.yml", "heights.csv", "ground_truth.csv"):
        (dst / name).write_bytes((src / name).read_bytes())
    K = Camera.from_file(src / "camera.yml").K
    with (src / "ground_truth.csv").open() as fh:
        truth = {int(r["frame"]): r for r in csv.DictReader(fh)}
    rng = np.random.default_rng(seed)
    for k, f in enumerate(sorted(src.glob("frame_*.png"))):
        img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE).astype(np.float64)
        row = truth[k]
        cam = moving(FLOW_CAMERA, (float(row["vx"]), float(row["vy"])), float(row["height"]), float(K[0, 0]))
        cv2.imwrite(str(dst / f.name), apply_camera(img, K, cam, rng=rng)[0])


def errors(est: np.ndarray, truth: np.ndarray) -> dict:
    n = min(len(est), len(truth))
    err = np.linalg.norm(est[:n] - truth[:n], axis=1)
    path = float(np.linalg.norm(np.diff(truth[:n], axis=0), axis=1).sum())
    return {"final_m": float(err[-1]), "final_pct_of_path": 100 * float(err[-1]) / path, "max_m": float(err.max()),
            "path_m": path}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--out", default=str(ROOT / "bench/results"))
    args = ap.parse_args(argv)
    result = {"machine": {"python": sys.version.split()[0], "opencv": cv2.__version__, "numpy": np.__version__,
                          "platform": platform.platform()}, "seconds": args.seconds, "flights": []}
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.flights):
            texture = TEXTURES[i % len(TEXTURES)]
            rendered = Path(tmp) / f"flight{i}"
            subprocess.run([sys.executable, "-m", "visloc", "render", "flow", str(rendered), "--seconds",
                            str(args.seconds), "--seed", str(20 + i), "--texture", texture], check=True,
                           stdout=subprocess.DEVNULL)
            camlike = Path(tmp) / f"flight{i}_camera"
            camera_like(rendered, camlike, 20 + i)
            for set_name, folder in (("rendered", rendered), ("camera-like", camlike)):
                print(f"flow drift: flight {i} ({texture}), {set_name} ...", file=sys.stderr, flush=True)
                gt = _rows(folder / "ground_truth.csv")
                truth = truth_track(gt)
                heights = np.array([float(r["height"]) for r in gt])
                camera = Camera.from_file(folder / "camera.yml")
                size = cv2.imread(str(folder / "frame_00000.png"), cv2.IMREAD_GRAYSCALE).shape[::-1]
                row = {"flight": i, "texture": texture, "set": set_name, "methods": {}}
                for name, direct in (("visloc", False), ("visloc_direct", True)):
                    track, spent = cli_track(folder, direct)
                    row["methods"][name] = errors(track, truth) | {"cli_seconds": spent}
                row["methods"]["lk"] = errors(lk_track(folder, heights, camera, size), truth)
                result["flights"].append(row)
    write_results(args.out, "flow_drift", result, markdown(result))
    return 0


def markdown(result: dict) -> str:
    title = (f"\n**Dead-reckoning drift over {result['seconds']:.0f} s flights** (320x240, 60 FPS; position error "
             "against the truth in the first frame's axes: at the end, m and % of the distance flown, and the "
             "largest along the track)\n")
    header = ("| flight | set | path m | visloc end m (%) | visloc_direct end m (%) | lk end m (%) | "
              "visloc max m | visloc_direct max m | lk max m |")
    lines = [title, header, "|---|---|---|---|---|---|---|---|---|"]
    totals: dict = {}
    for row in result["flights"]:
        m = row["methods"]
        cells = [f"{fmt(m[k]['final_m'], 4)} ({fmt(m[k]['final_pct_of_path'], 2)})" for k in ("visloc", "visloc_direct", "lk")]
        lines.append(f"| {row['flight']} ({row['texture']}) | {row['set']} | {fmt(m['lk']['path_m'], 1)} | "
                     + " | ".join(cells) + " | " + " | ".join(fmt(m[k]["max_m"], 4) for k in ("visloc", "visloc_direct", "lk"))
                     + " |")
        for k in m:
            totals.setdefault((row["set"], k), []).append(m[k]["final_pct_of_path"])
    lines.append("\n| set | method | median end error, % of path | largest, % |\n|---|---|---|---|")
    for (set_name, k), v in totals.items():
        lines.append(f"| {set_name} | {k} | {fmt(float(np.median(v)), 2)} | {fmt(float(np.max(v)), 2)} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
