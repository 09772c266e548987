"""How many rounds the real-photo bench needs: per-image bests of separate runs, compared.

Given several runs of ``bench/real_photos.py`` (folders holding its ``real_photos.json``, which
keeps every round's time), this compares the runs two at a time: for every image and method,
the best round of one run against the best round of the other, counting the pairs more than
``--tol`` apart. It then pools the runs two at a time (a best over both runs' rounds, as one run
of twice the rounds would give, its rounds spread over two runs' time) and compares disjoint
pooled pairs the same way. It prints both counts' range and mean over the comparisons.

    python bench/real_photos_rounds.py bench/results/rounds-15 bench/results/rerun ...

Exit status 0, or 2 on bad input (fewer than two runs, a missing file, runs of other images).
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from pathlib import Path


def rounds_of(folder: Path) -> dict[tuple[str, str], list[float]]:
    """(image file, method) -> that run's per-round times (ms) from ``folder/real_photos.json``."""
    data = json.loads((folder / "real_photos.json").read_text())
    return {(row["file"], m): r["ms_rounds"] for row in data["images"]
            for m, r in row["methods"].items() if r and r.get("ms_rounds")}


def count_apart(a: dict, b: dict, tol: float) -> int:
    """How many keys' values in ``a`` and ``b`` differ by more than ``tol`` of the larger."""
    return sum(abs(a[k] - b[k]) > tol * max(a[k], b[k]) for k in a)


def bests(runs: list[dict], group: tuple[int, ...]) -> dict:
    """Per key, the best time over every round of the runs in ``group``."""
    return {k: min(min(runs[i][k]) for i in group) for k in runs[0]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+", help="folders of real_photos.json runs")
    ap.add_argument("--tol", type=float, default=0.15, help="relative tolerance (default 0.15)")
    args = ap.parse_args(argv)
    try:
        runs = [rounds_of(d) for d in args.runs]
    except (OSError, ValueError, KeyError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if len(runs) < 2 or any(r.keys() != runs[0].keys() for r in runs):
        print("error: give two or more runs of the same images and methods", file=sys.stderr)
        return 2
    n = len(runs)
    rounds = sorted({len(v) for r in runs for v in r.values()})
    print(f"{n} runs, {len(runs[0])} image/method bests each, rounds per run {rounds}, tol {args.tol:.0%}")
    pairs = [((a,), (b,)) for a, b in itertools.combinations(range(n), 2)]
    pooled = [(g, h) for g, h in itertools.combinations(itertools.combinations(range(n), 2), 2)
              if not set(g) & set(h)]
    for label, comps in (("one run", pairs), ("two runs pooled", pooled)):
        if not comps:
            print(f"{label}: too few runs to compare")
            continue
        counts = [count_apart(bests(runs, g), bests(runs, h), args.tol) for g, h in comps]
        print(f"{label}: {len(comps)} comparisons, bests more than {args.tol:.0%} apart "
              f"{min(counts)}-{max(counts)}, mean {sum(counts) / len(counts):.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
