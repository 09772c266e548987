"""``visloc batch`` on Dask against plain ``visloc`` processes on the same recordings, in one run
(issue 19): the speed-up two local workers reach against the one two plain ``visloc detect``
processes side by side reach, and the engine's overhead with one worker against a plain serial
loop (Dask's start-up included).

    python bench/batch.py              # writes bench/results/batch.{json,md}

The recordings: one rendered 640x480 marker video (``visloc render markers --video``) copied
``--recordings`` times. Every configuration runs ``visloc detect REC --out ... --quiet`` per
recording: a serial loop of processes (a shell loop), two processes side by side (half the
recordings each), ``visloc batch`` with 1 and with 2 local workers. Configurations alternate
over rounds; the fastest round of each is kept (a slow spell of the host only lengthens a
round), and the speed-ups are ratios of those fastest rounds. Each run starts when the host
runs at its normal speed (``_timing.Steady``: the host has slow spells of a few seconds).

Then the cost of a task beyond its frames: short and longer videos (2 and 20 frames) through
``visloc batch`` on one warm worker; the fastest round's time per task against the frames per
task is a straight line whose intercept is the fixed cost of a task.
"""

from __future__ import annotations

import argparse
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _results import fmt, write_results
from _timing import steady

ROOT = Path(__file__).resolve().parents[1]
VISLOC = [sys.executable, "-m", "visloc"]


def _serial(recs: list[Path], out: Path) -> None:
    for r in recs:
        subprocess.run([*VISLOC, "detect", str(r), "--out", str(out / f"{r.stem}.jsonl"), "--quiet"], check=True)


def _two_processes(recs: list[Path], out: Path) -> None:
    halves = [recs[0::2], recs[1::2]]
    script = "; ".join(f"{' '.join(VISLOC)} detect {r} --out {out / (r.stem + '.jsonl')} --quiet" for r in halves[0])
    other = "; ".join(f"{' '.join(VISLOC)} detect {r} --out {out / (r.stem + '.jsonl')} --quiet" for r in halves[1])
    procs = [subprocess.Popen(["bash", "-c", s]) for s in (script, other)]
    for p in procs:
        if p.wait() != 0:
            raise RuntimeError("a plain visloc detect failed")


def _batch(recs: list[Path], out: Path, workers: int) -> None:
    subprocess.run([*VISLOC, "batch", "detect", *map(str, recs), "--outdir", str(out), "--workers", str(workers),
                    "--force", "--quiet"], check=True)


def run(frames: int, recordings: int, rounds: int, work: Path) -> dict:
    subprocess.run([*VISLOC, "render", "markers", str(work / "render"), "--video", "--n", str(frames), "--size",
                    "640x480", "--seed", "7"], check=True, capture_output=True)
    recs = []
    for k in range(recordings):
        recs.append(Path(shutil.copy(work / "render" / "markers.mp4", work / f"rec{k}.mp4")))
    configs = {"serial loop of visloc detect": lambda o: _serial(recs, o),
               "two visloc detect side by side": lambda o: _two_processes(recs, o),
               "visloc batch, 1 worker": lambda o: _batch(recs, o, 1),
               "visloc batch, 2 workers": lambda o: _batch(recs, o, 2)}
    spent: dict[str, list[float]] = {k: [] for k in configs}
    for r in range(rounds):
        for name in (list(configs) if r % 2 == 0 else list(configs)[::-1]):
            out = work / f"out_{r}_{abs(hash(name))}"
            out.mkdir()
            steady().wait()
            t0 = time.perf_counter()
            configs[name](out)
            spent[name].append(time.perf_counter() - t0)
            assert len(list(out.glob("rec*.jsonl"))) == recordings
            shutil.rmtree(out)
    best = {k: float(np.min(v)) for k, v in spent.items()}
    serial = best["serial loop of visloc detect"]
    two = serial / best["two visloc detect side by side"]
    b2 = serial / best["visloc batch, 2 workers"]
    return {"frames_per_recording": frames, "recordings": recordings, "rounds": rounds,
            "seconds": best, "seconds_median": {k: float(np.median(v)) for k, v in spent.items()},
            "speedup_two_processes": two, "speedup_batch_2_workers": b2,
            "batch_vs_processes": b2 / two, "overhead_1_worker": best["visloc batch, 1 worker"] / serial - 1.0,
            "ms_per_frame_serial": 1e3 * serial / (frames * recordings)}


def task_overhead(work: Path, tasks: int = 30, rounds: int = 9, lengths: tuple[int, int] = (2, 20)) -> dict:
    """Milliseconds per task beyond its frames: ``tasks`` copies of a short and of a longer
    video (``lengths`` frames) through ``run_batch`` on one warm local worker, the two lengths
    alternating over ``rounds`` rounds. From the fastest round of each length, the wall time per
    task is a straight line in the frames per task: its slope is the time per frame in a worker
    (reading and detection), its intercept the fixed cost of a task (scheduling, opening the
    video, writing the output)."""
    from dask.distributed import LocalCluster

    from visloc.batch import run_batch

    recs = {}
    for n in lengths:
        subprocess.run([*VISLOC, "render", "markers", str(work / f"v{n}"), "--video", "--n", str(n), "--size",
                        "640x480", "--seed", "3"], check=True, capture_output=True)
        recs[n] = [str(shutil.copy(work / f"v{n}" / "markers.mp4", work / f"v{n}_{k:03d}.mp4")) for k in range(tasks)]
    walls: dict[int, list[float]] = {n: [] for n in lengths}
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster:
        run_batch("detect", recs[lengths[1]][:2], "", work / "warm", scheduler=cluster.scheduler_address, force=True)
        for r in range(rounds):
            for n in (lengths if r % 2 == 0 else lengths[::-1]):
                steady().wait()
                t0 = time.perf_counter()
                run_batch("detect", recs[n], "", work / f"out{n}", scheduler=cluster.scheduler_address, force=True)
                walls[n].append(time.perf_counter() - t0)
    short, long_ = (1e3 * float(np.min(walls[n])) / tasks for n in lengths)
    per_frame = (long_ - short) / (lengths[1] - lengths[0])
    return {"tasks": tasks, "rounds": rounds, "lengths": list(lengths),
            "ms_per_task": {str(n): v for n, v in zip(lengths, (short, long_))},
            "ms_per_frame": per_frame, "ms_fixed": short - lengths[0] * per_frame}


def markdown(r: dict) -> str:
    lines = [(f"**visloc batch** ({r['recordings']} recordings of {r['frames_per_recording']} rendered 640x480 frames, "
             f"`detect`; fastest of {r['rounds']} alternating rounds, wall time)"), "",
             "| configuration | s | speed-up vs the serial loop |", "|---|---|---|"]
    serial = r["seconds"]["serial loop of visloc detect"]
    for k, v in r["seconds"].items():
        lines.append(f"| {k} | {fmt(v, 2)} | {fmt(serial / v, 2)} |")
    lines += ["", (f"Two workers reach {fmt(r['batch_vs_processes'], 2)} of the two plain processes' speed-up; "
                  f"one worker took {fmt(1.0 + r['overhead_1_worker'], 2)} of the serial loop's time, Dask's start-up included; detection {fmt(r['ms_per_frame_serial'], 2)} ms per frame in the serial loop.")]
    o = r.get("overhead")
    if o:
        short, long_ = (o["ms_per_task"][str(n)] for n in o["lengths"])
        share = 100 * o["ms_fixed"] / (o["ms_fixed"] + 100 * o["ms_per_frame"])
        lines += ["", (f"Per task: {o['tasks']} videos of {o['lengths'][0]} and of {o['lengths'][1]} frames on one warm "
                       f"worker, the two lengths alternating over {o['rounds']} rounds, take {fmt(short, 1)} and "
                       f"{fmt(long_, 1)} ms per task (fastest round). The straight line through them: "
                       f"{fmt(o['ms_per_frame'], 1)} ms per frame (reading and detection) and a fixed "
                       f"{fmt(o['ms_fixed'], 0)} ms per task (scheduling, opening the video, writing the output; "
                       "printed to the whole millisecond, runs on this host spread about 1 ms), about "
                       f"{fmt(share, 0)} % of a 100-frame recording's time.")]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=1200)
    ap.add_argument("--recordings", type=int, default=4)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--out", default=str(ROOT / "bench/results"))
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as work:
        result = run(args.frames, args.recordings, args.rounds, Path(work))
        result["overhead"] = task_overhead(Path(work), tasks=60, rounds=15)
    result["machine"] = {"python": sys.version.split()[0], "platform": platform.platform()}
    result["steady"] = steady().summary()
    write_results(args.out, "batch", result, markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
