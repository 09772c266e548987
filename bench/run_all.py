"""Re-run every bench behind the README's tables into one folder, then check it against the tables.

    python bench/run_all.py --out /tmp/rerun                 # all thirteen, then compare.py
    python bench/run_all.py --out /tmp/rerun --only sim batch
    python bench/run_all.py --out bench/results --no-compare  # regenerate the tables themselves

The scripts run one after another, each in its own process (``python bench/NAME.py --out DIR``),
in the order of :data:`BENCHES`, which is the order the tables were run in; all of them take
about 40 minutes on a 2-core machine. A line on stderr says when each one starts and how long
it took; their own output goes to ``DIR/run_all.log``. A script that fails is reported and the
others still run. Then, unless ``--no-compare`` or DIR is ``bench/results`` itself,
``bench/compare.py bench/results DIR`` checks the new run number by number (its report is
printed, and written to ``DIR/compare.txt``).

Exit status 0 when every script ran and every number is within compare's tolerance, 1 when a
script failed or a number moved by more than it, 2 on bad arguments.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: The benches whose tables the README shows, in the order the tables' run ran them (real_truth,
#: added later and untimed, beside the other real-photo bench).
BENCHES = ("markers", "real_photos", "real_truth", "flow", "flow_drift", "refine_window", "design", "localize",
           "sim", "calibrate", "mavlink", "bags", "batch")


def run_benches(names: list[str], out: Path, *, bench_dir: Path = HERE) -> dict[str, tuple[int, float]]:
    """Run ``bench_dir/NAME.py --out out`` for each name in turn, their output appended to
    ``out/run_all.log`` (flushed as it comes), progress on stderr.

    Parameters
    ----------
    names : list of str
        Script names without ``.py``.
    out : Path
        Results folder (created if missing).
    bench_dir : Path
        Folder of the scripts (default: this one).

    Returns
    -------
    dict
        ``name -> (exit status, seconds)`` in run order.
    """
    out.mkdir(parents=True, exist_ok=True)
    done: dict[str, tuple[int, float]] = {}
    with open(out / "run_all.log", "a", buffering=1) as log:
        for k, name in enumerate(names, start=1):
            stamp = time.strftime("%Y-%m-%d %H:%M:%S")
            print(f"[{k}/{len(names)}] {name}: started {stamp}", file=sys.stderr, flush=True)
            log.write(f"==== {name}: started {stamp}\n")
            t0 = time.perf_counter()
            code = subprocess.run([sys.executable, str(bench_dir / f"{name}.py"), "--out", str(out)],
                                  stdout=log, stderr=subprocess.STDOUT, check=False).returncode
            spent = time.perf_counter() - t0
            done[name] = (code, spent)
            state = "done" if code == 0 else f"FAILED (exit {code}; see {out / 'run_all.log'})"
            print(f"[{k}/{len(names)}] {name}: {state} in {spent / 60:.1f} min", file=sys.stderr, flush=True)
            log.write(f"==== {name}: exit {code} after {spent:.0f} s\n")
    return done


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="folder for the new run's results")
    ap.add_argument("--only", nargs="+", default=None, metavar="NAME", help=f"run only these of {', '.join(BENCHES)}")
    ap.add_argument("--no-compare", action="store_true", help="skip compare.py against bench/results")
    args = ap.parse_args(argv)
    names = list(args.only or BENCHES)
    unknown = [n for n in names if n not in BENCHES]
    if unknown:
        ap.error(f"--only: unknown bench {', '.join(unknown)} (one of {', '.join(BENCHES)})")
    if args.out.exists() and not args.out.is_dir():
        ap.error(f"--out {args.out} exists and is not a folder")
    done = run_benches(names, args.out)
    failed = [n for n, (code, _) in done.items() if code != 0]
    total = sum(s for _, s in done.values())
    print(f"{len(done) - len(failed)} of {len(done)} benches ran in {total / 60:.1f} min"
          + (f"; failed: {', '.join(failed)}" if failed else ""), file=sys.stderr)
    status = 1 if failed else 0
    if not args.no_compare and args.out.resolve() != (HERE / "results").resolve():
        ran = [n for n in names if n not in failed]
        if ran:
            report = subprocess.run([sys.executable, str(HERE / "compare.py"), str(HERE / "results"), str(args.out),
                                     "--only", *ran], capture_output=True, text=True, check=False)
            print(report.stdout, end="")
            (args.out / "compare.txt").write_text(report.stdout)
            status = max(status, min(report.returncode, 1))  # compare: 1 a number moved, 2 bad input
    return status


if __name__ == "__main__":
    sys.exit(main())
