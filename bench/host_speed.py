"""Host speed log: how steady this machine's speed is, for reading the other benches' timings.

Every ``--every`` s for ``--seconds`` s it times (best of 3 each) the host reference workload of
``bench/_timing.py`` (a numpy sort and a Python loop, one thread, what ``Steady`` waits on), an
OpenCV blur and adaptive threshold of a 640x480 image (OpenCV's default threads), OpenCV's
``ArucoDetector`` and visloc's ``MarkerDetector`` on one camera-like 640x480 render. It prints,
per window of ``--window`` s, each workload's fastest time in the window relative to its usual
fastest (the 10th percentile over the windows), then per workload the share of windows more than
15 % slow, the slowest window and the correlation of the windows with visloc's detector. On a
quiet machine every column stays near 1.00; where the detectors' columns move and the
reference's does not, ``Steady`` cannot see the spell and absolute timings of the other benches
move with it (their ratios, timed interleaved, do not). The last two columns, the share of the
samples within 15 % of the usual fastest and the median sample against it, tell how much of the
time the host runs at its fast speed.

With ``--busy-cpu N`` the log runs pinned to the other CPUs while a child process keeps CPU ``N``
busy with a Python loop: run once with and once without to see whether the slow spells come from
this machine's own other CPU (a sibling sharing a core) or from outside it.

    python bench/host_speed.py [--seconds 120] [--every 0.25] [--window 10] [--busy-cpu N] [--out DIR]

With ``--out`` it also writes ``host_speed.json`` (every sample) and ``host_speed.md`` there.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import sys
import time

import cv2
import numpy as np
from _results import fmt, write_results
from _timing import reference_workload

from visloc.markers import MarkerDetector
from visloc.synth import random_scene

SLOW = 1.15  # a window this much slower than usual counts as slow
NAMES = ["reference", "blur+threshold", "opencv detect", "visloc detect"]


def workloads() -> dict:
    """name -> function() timed by the log."""
    scene = random_scene(np.random.default_rng([1, 640, 0, 3]), size=(640, 480), dictionary="DICT_4X4_50",
                         difficulty="easy", camera=True)
    noise = np.random.default_rng(0).integers(0, 256, (480, 640), np.uint8)
    aruco = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    visloc = MarkerDetector("DICT_4X4_50")

    def image():
        cv2.adaptiveThreshold(cv2.GaussianBlur(noise, (5, 5), 0), 255, cv2.ADAPTIVE_THRESH_MEAN_C,
                              cv2.THRESH_BINARY, 9, 5)

    return dict(zip(NAMES, (reference_workload, image, lambda: aruco.detectMarkers(scene.image),
                            lambda: visloc.detect(scene.image))))


def sample(work: dict) -> dict:
    """Each workload's best of 3 times, ms."""
    out = {}
    for name, fn in work.items():
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            fn()
            best = min(best, time.perf_counter() - t0)
        out[name] = 1e3 * best
    return out


def windows(times: np.ndarray, ms: np.ndarray, window: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Window start times (s from the first sample, (windows,)), each workload's usual fastest
    time (the 10th percentile of the windows' fastest, (workloads,)) and each window's fastest
    time per workload relative to it ((windows, workloads))."""
    index = ((times - times[0]) // window).astype(int)
    starts = np.unique(index)
    fastest = np.array([ms[index == k].min(axis=0) for k in starts])
    usual = np.percentile(fastest, 10, axis=0)
    return starts * window, usual, fastest / usual


def fast_share(ms: np.ndarray, usual: np.ndarray) -> np.ndarray:
    """Per workload, the share of the samples ``ms`` (samples, workloads) at most ``SLOW`` times
    its ``usual`` fastest time (workloads,)."""
    return (ms <= SLOW * usual).mean(axis=0)


def _spin() -> None:
    """Keep this process's CPU busy until killed."""
    while True:
        pass


def busy(cpu: int) -> multiprocessing.Process:
    """Pin this process to every allowed CPU but ``cpu`` and start a child spinning on ``cpu``
    (terminate it when done).

    Parameters
    ----------
    cpu : int
        The CPU to keep busy, one of ``os.sched_getaffinity(0)``.

    Returns
    -------
    multiprocessing.Process
        The spinning child (a daemon).

    Raises
    ------
    ValueError
        ``cpu`` is not one this process may run on, or it is the only one.
    """
    allowed = os.sched_getaffinity(0)
    if cpu not in allowed or len(allowed) < 2:
        raise ValueError(f"--busy-cpu {cpu}: needs one of this process's CPUs {sorted(allowed)}, "
                         "and another left for the log")
    os.sched_setaffinity(0, allowed - {cpu})
    child = multiprocessing.get_context("fork").Process(target=_spin, daemon=True)
    child.start()
    os.sched_setaffinity(child.pid, {cpu})
    return child


def markdown(result: dict) -> str:
    """The log's window table and summary as Markdown."""
    names, rel = result["workloads"], np.asarray(result["relative"])
    busy_note = (f"; CPU {result['busy_cpu']} kept busy by another process, the log on the others"
                 if result.get("busy_cpu") is not None else "")
    lines = [(f"\n**Host speed** ({result['seconds']:.0f} s from {result['start']}, a sample every "
              f"{result['every']} s{busy_note}; per {result['window']:.0f}-s window each workload's fastest time relative to "
              "its usual fastest, the 10th percentile over the windows)\n"),
             "| window start s | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    lines += [f"| {s:.0f} | " + " | ".join(fmt(v, 2) for v in row) + " |" for s, row in zip(result["starts"], rel)]
    lines += ["", (f"| workload | usual fastest ms | windows > {SLOW:.2f}x | slowest window | corr. with visloc detect "
                   f"| samples within {SLOW:.2f}x of the usual fastest | median sample |"),
              "|---|---|---|---|---|---|---|"]
    for name in names:
        s = result["summary"][name]
        lines.append(f"| {name} | {fmt(s['usual_ms'], 3)} | {s['slow_windows']}/{len(rel)} | {fmt(s['slowest'], 2)}x | "
                     f"{fmt(s['corr_visloc'], 2)} | {fmt(s['fast_share'], 2)} | {fmt(s['median'], 2)}x |")
    return "\n".join(lines) + "\n"


def log(work: dict, seconds: float, every: float) -> tuple[np.ndarray, list[float], str]:
    """Sample ``work`` every ``every`` s for ``seconds`` s: the times (samples, workloads) ms, the
    samples' clock readings (s) and the start as text."""
    start, rows, stamps = time.strftime("%Y-%m-%d %H:%M:%S"), [], []
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        stamps.append(time.perf_counter())
        rows.append(list(sample(work).values()))
        time.sleep(every)
        if len(rows) % 100 == 0:
            print(f"  {len(rows)} samples", file=sys.stderr, flush=True)
    return np.array(rows), stamps, start


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=120.0, help="how long to log (s)")
    ap.add_argument("--every", type=float, default=0.25, help="pause between samples (s)")
    ap.add_argument("--window", type=float, default=10.0, help="window of the table (s)")
    ap.add_argument("--busy-cpu", type=int, default=None,
                    help="keep this CPU busy with another process and log on the others")
    ap.add_argument("--out", default=None, help="folder for host_speed.json/.md (default: print only)")
    args = ap.parse_args(argv)
    if args.every < 0 or args.window <= 0 or args.seconds < 2 * args.window:
        ap.error("--window must be positive, --every not negative and --seconds at least two windows")
    spinner = None
    if args.busy_cpu is not None:
        try:
            spinner = busy(args.busy_cpu)
        except ValueError as exc:
            ap.error(str(exc))
    try:
        ms, stamps, start = log(workloads(), args.seconds, args.every)
    finally:
        if spinner is not None:
            spinner.terminate()
    starts, usual, rel = windows(np.array(stamps), ms, args.window)
    vis = rel[:, NAMES.index("visloc detect")]
    share = fast_share(ms, usual)
    summary = {name: {"usual_ms": float(usual[k]), "slow_windows": int((rel[:, k] > SLOW).sum()),
                      "slowest": float(rel[:, k].max()),
                      "corr_visloc": float(np.corrcoef(rel[:, k], vis)[0, 1]) if np.ptp(rel[:, k]) > 0 else None,
                      "fast_share": float(share[k]), "median": float(np.median(ms[:, k]) / usual[k])}
               for k, name in enumerate(NAMES)}
    result = {"start": start, "seconds": args.seconds, "every": args.every, "window": args.window,
              "busy_cpu": args.busy_cpu, "workloads": NAMES, "starts": starts.tolist(),
              "relative": rel.round(4).tolist(), "summary": summary, "samples_ms": ms.round(4).tolist()}
    text = markdown(result)
    if args.out:
        write_results(args.out, "host_speed", result, text)  # prints the table too
    else:
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
