"""Compare two runs of the benches: every number in the Markdown results of one folder against
the same place in another, listing those that differ by more than a tolerance.

    python bench/compare.py bench/results /tmp/rerun            # after: python bench/X.py --out /tmp/rerun
    python bench/compare.py OLD NEW --tol 0.15 --only sim markers

Numbers are matched by position: the same file, line and cell (table rows) or the same line and
order (prose lines). A pair counts as different when it differs by more than ``--tol`` of the
larger and by more than one unit of the last digit printed (0.43 against 0.44 is rounding, not a
change). Files whose tables changed shape are named and skipped. Where both runs' JSON record
the host's normal reference time and how often the timing waited for the host
(``bench/_timing.py``), they are printed beside the file's count: a timing that moved with them
moved with the host. Exit status 0 when every number is within the tolerance, 1 when one is
not, 2 on bad input.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

NUMBER = re.compile(r"-?\d+(?:\.\d+)?")


def _unit(text: str) -> float:
    """One unit of the last digit of a printed number ("0.43" -> 0.01, "12" -> 1)."""
    return 10.0 ** -len(text.split(".")[1]) if "." in text else 1.0


def differs(a: str, b: str, tol: float) -> bool:
    """Whether printed numbers ``a`` and ``b`` differ by more than ``tol`` of the larger and by
    more than one unit of the coarser last digit."""
    x, y = float(a), float(b)
    big = max(abs(x), abs(y))
    return big > 0 and abs(x - y) > tol * big and abs(x - y) > max(_unit(a), _unit(b)) + 1e-12


def _fields(line: str) -> list[list[str]]:
    """The numbers of a line: one list per table cell, or one list for a prose line."""
    if line.startswith("|"):
        return [NUMBER.findall(cell) for cell in line.strip().strip("|").split("|")]
    return [NUMBER.findall(line)]


def compare_file(old: Path, new: Path, tol: float) -> tuple[list[str], int]:
    """The differing numbers of one results file (as readable lines) and how many were compared."""
    a, b = old.read_text().splitlines(), new.read_text().splitlines()
    if len(a) != len(b):
        return [f"{new.name}: {len(a)} lines against {len(b)}: not compared"], 0
    out, count = [], 0
    for k, (la, lb) in enumerate(zip(a, b), start=1):
        fa, fb = _fields(la), _fields(lb)
        if len(fa) != len(fb):
            out.append(f"{new.name}:{k}: the line changed shape: not compared")
            continue
        label = lb.strip("| ").split("|")[0].strip()[:40]
        for col, (ca, cb) in enumerate(zip(fa, fb)):
            for u, v in zip(ca, cb):
                count += 1
                if differs(u, v, tol):
                    out.append(f"{new.name}:{k} [{label}] cell {col}: {u} -> {v}")
    return out, count


def host_reference(old: Path, new: Path) -> str:
    """``" (host reference workload: OLD ms -> NEW ms; waited at OLD -> NEW checks)"`` from two
    runs' JSON (``steady``: the normal reference time, and how many of its checks found the
    host slow and waited), or "" where either does not record it. A run timed in one of the
    host's slow periods waits at more of its checks than the same bench's run at normal speed,
    even where its normal reference time hardly moves (2026-12-07: real photos, flow and
    localize 20-45 % slower than their tables waited at 63, 24 and 23 % of their checks, the
    tables' runs at 11, 2 and 9 %); compare the share within a bench, not across benches."""
    steady, refs = [], []
    for path in (old, new):
        try:
            steady.append(json.loads(path.read_text())["steady"])
            refs.append(float(steady[-1]["reference_ms_normal"]))
        except (OSError, ValueError, KeyError, TypeError):
            return ""
    text = f" (host reference workload: {refs[0]:.3f} -> {refs[1]:.3f} ms"
    if all(isinstance(s.get("checks"), int) and isinstance(s.get("waits"), int) for s in steady):
        text += "; waited at " + " -> ".join(f"{s['waits']}/{s['checks']}" for s in steady) + " checks"
    return text + ")"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old", type=Path, help="a results folder (e.g. bench/results)")
    ap.add_argument("new", type=Path, help="another run's results folder")
    ap.add_argument("--tol", type=float, default=0.15, help="relative tolerance (default 0.15)")
    ap.add_argument("--only", nargs="*", default=None, help="bench names to compare (default: all in NEW)")
    args = ap.parse_args(argv)
    for d in (args.old, args.new):
        if not d.is_dir():
            print(f"error: {d} is not a folder", file=sys.stderr)
            return 2
    if not 0 <= args.tol < 1:
        print(f"error: --tol must be in [0, 1), got {args.tol}", file=sys.stderr)
        return 2
    names = args.only or sorted(p.stem for p in args.new.glob("*.md"))
    bad = 0
    for name in names:
        old, new = args.old / f"{name}.md", args.new / f"{name}.md"
        if not (old.is_file() and new.is_file()):
            print(f"{name}: missing in {'OLD' if not old.is_file() else 'NEW'}")
            bad += 1
            continue
        lines, count = compare_file(old, new, args.tol)
        ref = host_reference(args.old / f"{name}.json", args.new / f"{name}.json")
        print(f"== {name}: {count} numbers compared, {len(lines)} beyond {args.tol:.0%}{ref}")
        for line in lines:
            print("  " + line)
        bad += len(lines)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
