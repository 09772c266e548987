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


_JOB_KEYS = {"command": str, "recordings": list, "outdir": str, "options": str, "workers": int, "scheduler": str,
             "chunk": int, "force": bool}


def _job(args: argparse.Namespace) -> None:
    """Fill ``args`` from ``--job JOB.toml`` where the command line left a value out; the job's
    relative paths are relative to its own folder."""
    import tomllib
    from pathlib import Path

    from visloc.errors import UsageError

    if args.job:
        path = Path(args.job)
        try:
            job = tomllib.loads(path.read_text())
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            raise UsageError(f"--job {args.job}: {exc}") from None
        unknown = sorted(set(job) - set(_JOB_KEYS))
        if unknown:
            raise UsageError(f"--job {args.job}: unknown keys {', '.join(unknown)} (known: {', '.join(_JOB_KEYS)})")
        for key, kind in _JOB_KEYS.items():
            if key in job and (not isinstance(job[key], kind) or (kind is int and isinstance(job[key], bool))):
                raise UsageError(f"--job {args.job}: {key} must be a {kind.__name__}, got {job[key]!r}")
        base = path.parent

        def here(p: str) -> str:
            return p if Path(p).is_absolute() or p.startswith("tcp:") else str(base / p)

        if args.batch_command is None:
            args.batch_command = job.get("command")
        if not args.recordings and "recordings" in job:
            args.recordings = [here(str(r)) for r in job["recordings"]]
        if args.outdir is None and "outdir" in job:
            args.outdir = here(job["outdir"])
        for key in ("options", "workers", "scheduler", "chunk"):
            if getattr(args, key) is None and key in job:
                setattr(args, key, job[key])
        args.force = args.force or bool(job.get("force", False))
    missing = [name for name, v in (("COMMAND", args.batch_command), ("RECORDING", args.recordings),
                                    ("--outdir", args.outdir)) if not v]
    if missing:
        raise UsageError(f"batch needs {', '.join(missing)} (on the command line or in --job)")
    if args.batch_command not in ("detect", "localize", "flow", "track"):
        raise UsageError(f"batch runs detect, localize, flow or track, not {args.batch_command!r}")
    if args.options is None:
        args.options = ""


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

    _job(args)
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
