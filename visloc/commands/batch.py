"""``visloc batch``: one command over many recordings on Dask (:mod:`visloc.batch`)."""

from __future__ import annotations

import argparse
import glob
import sys

from tqdm import tqdm


def _expand(patterns: list[str]) -> list[str]:
    """The recordings: each argument as given, or the paths its glob pattern matches."""
    out: list[str] = []
    for p in patterns:
        hits = sorted(glob.glob(p)) if any(c in p for c in "*?[") else []
        out.extend(hits or [p])
    return out


def batch(args: argparse.Namespace) -> int:
    """``visloc batch``: run ``args.batch_command`` over ``args.recordings`` into ``args.outdir``.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``visloc batch`` command line (:func:`visloc.cli.build_parser`).

    Returns
    -------
    int
        0 when every recording's output is complete without unreadable frames; 1 when a
        recording failed or had unreadable frames (see ``summary.csv``).
    """
    from visloc.batch import run_batch

    recordings = _expand(args.recordings)
    bar = tqdm(total=len(recordings), unit="recording", disable=True if args.quiet else None, file=sys.stderr)

    def progress(res) -> None:
        bar.update(1)
        if res.status == "failed":
            tqdm.write(f"visloc batch: warning: {res.recording}: {res.message}", file=sys.stderr)

    try:
        results = run_batch(args.batch_command, recordings, args.options, args.outdir, workers=args.workers,
                            scheduler=args.scheduler, force=args.force, chunk=args.chunk, progress=progress,
                            dashboard=None if args.quiet else lambda url: tqdm.write(f"visloc batch: Dask dashboard at {url}",
                                                                                     file=sys.stderr))
    finally:
        bar.close()
    counts = {s: sum(r.status == s for r in results) for s in ("done", "partial", "failed", "skipped")}
    if not args.quiet:
        print(f"visloc batch: {len(results)} recordings: {counts['done']} done, {counts['partial']} with unreadable "
              f"frames, {counts['failed']} failed, {counts['skipped']} up to date; {args.outdir}/summary.csv",
              file=sys.stderr)
    return 1 if counts["failed"] or counts["partial"] else 0
