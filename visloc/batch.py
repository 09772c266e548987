"""Many recordings through one command on Dask (``dask.distributed``, the optional extra
``visloc[batch]``): one task per recording, on a local cluster (one worker process per core,
no setup) or on a running scheduler.

Each task runs the command as ``visloc COMMAND RECORDING OPTIONS --out TMP --quiet`` would, in
the worker's own process, and renames ``TMP`` to its final name only when the command finished
(exit status 0, or 1: some frames unreadable, each recorded in the output): an interrupted or
failed task leaves no partial file, and a task re-run after a worker died simply writes again.
A manifest (``batch.json``) records the command, its options and the outputs finished under
them; a later batch with the same command and options skips each recording whose output is
listed there, exists and is newer than the recording (:func:`run_batch` says when it is written).
"""

from __future__ import annotations

import contextlib
import io
import json
import multiprocessing
import os
import shlex
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

from visloc.errors import UsageError

__all__ = ["BATCH_COMMANDS", "RecordingResult", "output_name", "plan", "run_batch", "run_one"]

#: The commands a batch runs, and the extension of their ``--out`` file.
BATCH_COMMANDS = {"detect": ".jsonl", "localize": ".csv", "flow": ".csv", "track": ".jsonl"}

#: Suffixes of the recordings read as ROS 1 bags and MCAP files (:func:`visloc.io.bags.is_recording`).
RECORDING_SUFFIXES = frozenset({".bag", ".mcap"})

MANIFEST = "batch.json"
SUMMARY = "summary.csv"
SUMMARY_COLUMNS = ("recording", "output", "status", "exit", "rows", "seconds", "message")


@dataclass(frozen=True)
class RecordingResult:
    """What one recording's task did.

    Attributes
    ----------
    recording : str
        The input path.
    output : str
        Its output file.
    status : str
        ``"done"`` (exit 0), ``"partial"`` (exit 1: some frames unreadable, each recorded),
        ``"failed"`` (no output) or ``"skipped"`` (an up-to-date output was there).
    exit : int
        The command's exit status (0 for skipped).
    rows : int
        Lines of the output (frames and error lines), 0 when failed.
    seconds : float
        Wall time of the task.
    message : str
        The command's last stderr line when it did not exit 0, else empty.
    """

    recording: str
    output: str
    status: str
    exit: int
    rows: int
    seconds: float
    message: str


def output_name(recording: str | os.PathLike[str], command: str) -> str:
    """The output file's name for a recording: its file or folder name with the command's
    extension (``flight.mp4`` -> ``flight.jsonl`` for ``detect``).

    The name depends on the path alone, never on what is on disk (a recording missing in one
    run and there in the next keeps its output).

    Parameters
    ----------
    recording : str or os.PathLike
        The input. A video, image, ``.bag`` or ``.mcap`` suffix (any case;
        :data:`visloc.io.VIDEO_EXTENSIONS`, :data:`visloc.io.IMAGE_EXTENSIONS`) is dropped;
        any other name is kept whole, e.g. a folder's (``run.2024-05-01`` ->
        ``run.2024-05-01.jsonl``) or a file's with another suffix (``flight.mpg`` ->
        ``flight.mpg.jsonl``).
    command : str
        A key of :data:`BATCH_COMMANDS` (another raises ``KeyError``).

    Returns
    -------
    str
        The bare file name (no folder), e.g. ``"flight.jsonl"``.
    """
    from visloc.io.sources import IMAGE_EXTENSIONS, VIDEO_EXTENSIONS

    p = Path(recording)
    known = p.suffix.lower() in VIDEO_EXTENSIONS | IMAGE_EXTENSIONS | RECORDING_SUFFIXES
    return f"{p.stem if known else p.name}{BATCH_COMMANDS[command]}"


def _count_rows(path: Path, command: str) -> int:
    with path.open() as fh:
        n = sum(1 for _ in fh)
    return n - 1 if BATCH_COMMANDS[command] == ".csv" else n


_MALLOC_SET = False


def _plain_malloc() -> None:
    """Undo Dask's ``MALLOC_TRIM_THRESHOLD_`` in this worker process (glibc only, once).

    Dask's nanny starts workers with ``MALLOC_TRIM_THRESHOLD_=65536``; glibc then stops
    adapting its mmap threshold, so every image-sized buffer is mmapped and unmapped again:
    detection ran 1.5x slower than in a plain process on the bench. Large thresholds put the
    buffers back on the heap and keep them there between frames."""
    global _MALLOC_SET
    if _MALLOC_SET or "MALLOC_TRIM_THRESHOLD_" not in os.environ:
        return
    _MALLOC_SET = True
    with contextlib.suppress(OSError, AttributeError):
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-3, 64 << 20)  # M_MMAP_THRESHOLD: 64 MiB
        libc.mallopt(-1, 128 << 20)  # M_TRIM_THRESHOLD: 128 MiB


def run_one(command: str, recording: str, options: Sequence[str], output: str) -> RecordingResult:
    """Run ``visloc COMMAND RECORDING OPTIONS`` into ``output`` (a task; also usable alone).

    Parameters
    ----------
    command : str
        A key of :data:`BATCH_COMMANDS`.
    recording : str
        The input (video, folder, bag, ...).
    options : sequence of str
        The command's options (not ``--out``, ``--quiet``).
    output : str
        The final output path; the command writes ``output + ".part"``, renamed at the end.

    Returns
    -------
    RecordingResult
    """
    from visloc.cli import main

    _plain_malloc()
    part = f"{output}.part"
    err = io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stderr(err):
        try:
            code = main([command, recording, *options, "--out", part, "--quiet"])
        except SystemExit as exc:  # argparse's usage errors
            code = int(exc.code or 0)
    seconds = time.perf_counter() - t0
    lines = [x for x in err.getvalue().splitlines() if x.strip()]
    message = lines[-1] if code and lines else ""
    if code in (0, 1) and os.path.exists(part):
        os.replace(part, output)
        rows = _count_rows(Path(output), command)
        return RecordingResult(recording, output, "done" if code == 0 else "partial", code, rows, seconds, message)
    with contextlib.suppress(FileNotFoundError):
        os.remove(part)
    return RecordingResult(recording, output, "failed", code, 0, seconds, message or f"exit status {code}")


def plan(command: str, recordings: Sequence[str], options: Sequence[str], outdir: str | os.PathLike[str], *,
         force: bool = False) -> tuple[list[tuple[str, str]], list[RecordingResult]]:
    """Which recordings need a task: ``(to run [(recording, output)], skipped results)``.

    A recording is skipped when the manifest in ``outdir`` holds the same command and options
    and lists its output as finished under them, and that output exists and is newer than the
    recording (``force``: never).

    Parameters
    ----------
    command : str
        A key of :data:`BATCH_COMMANDS`.
    recordings : sequence of str
        The inputs (videos, folders, bags, ...); each one's output is ``outdir /``
        :func:`output_name`.
    options : sequence of str
        The command's options, compared with the manifest's (as a list, order included).
    outdir : str or os.PathLike
        The output folder, holding the manifest (``batch.json``) of an earlier batch if any;
        nothing is written.
    force : bool
        Skip nothing: every recording gets a task.

    Returns
    -------
    todo : list of (str, str)
        ``(recording, output path)`` of each recording to run, in the order given.
    skipped : list of RecordingResult
        One ``"skipped"`` result per up-to-date output (exit 0, ``rows`` counted from the
        output as for a finished task, 0 s).

    Raises
    ------
    visloc.errors.UsageError
        An unknown command, no recordings, two recordings with the same output name, or an
        output folder that is one of the recordings.
    """
    if command not in BATCH_COMMANDS:
        raise UsageError(f"batch runs {', '.join(BATCH_COMMANDS)}, not {command!r}")
    if not recordings:
        raise UsageError("batch: no recordings given")
    out = Path(outdir)
    names: dict[str, str] = {}
    for r in recordings:
        name = output_name(r, command)
        if name in names:
            raise UsageError(f"batch: {r} and {names[name]} would both write {name}: rename one")
        names[name] = r
        if Path(r).resolve() == out.resolve():
            raise UsageError(f"batch: the output folder {outdir} is a recording")
    finished = set() if force else _finished(out, command, list(options))
    todo, skipped = [], []
    for name, r in names.items():
        target = out / name
        if name in finished and target.is_file() and target.stat().st_mtime >= _mtime(r):
            skipped.append(RecordingResult(r, str(target), "skipped", 0, _count_rows(target, command), 0.0, ""))
        else:
            todo.append((r, str(target)))
    return todo, skipped


def _mtime(path: str) -> float:
    """The newest modification time of a file, or of a folder and the files in it."""
    p = Path(path)
    if not p.exists():
        return float("inf")  # a missing recording is never up to date (its task reports it)
    if p.is_dir():
        return max([p.stat().st_mtime] + [c.stat().st_mtime for c in p.iterdir() if c.is_file()])
    return p.stat().st_mtime


def _chunks(recording: str, chunk: int | None) -> list[tuple[int, int | None]]:
    """Frame ranges ``[start, stop)`` splitting a recording into tasks of ``chunk`` frames (the
    last one open-ended, so frames beyond a wrong declared count still go to it); one range
    when ``chunk`` is None, the length is unknown or it fits in one chunk."""
    if not chunk:
        return [(0, None)]
    from visloc.io import open_source

    try:
        with open_source(recording) as src:
            n = len(src)
    except Exception:  # noqa: BLE001 - unknown length or unreadable: one task (which reports it)
        return [(0, None)]
    starts = list(range(0, n, chunk))
    if len(starts) < 2:
        return [(0, None)]
    return [(a, a + chunk) for a in starts[:-1]] + [(starts[-1], None)]


def _merge(recording: str, output: str, parts: list[RecordingResult], command: str) -> RecordingResult:
    """One recording's result from its chunks' (in frame order): their outputs concatenated
    into ``output`` when every chunk finished, else a failure naming the first that did not."""
    files = [p.output for p in parts]
    seconds = sum(p.seconds for p in parts)
    failed = [p for p in parts if p.status == "failed"]
    if failed:
        for f in files:
            with contextlib.suppress(FileNotFoundError):
                os.remove(f)
        return RecordingResult(recording, output, "failed", failed[0].exit, 0, seconds, failed[0].message)
    part = f"{output}.part"
    with open(part, "wb") as out:
        for k, f in enumerate(files):
            with open(f, "rb") as fh:
                data = fh.read()
            if k and BATCH_COMMANDS[command] == ".csv":  # a chunk's header line again
                data = data.split(b"\n", 1)[1] if b"\n" in data else b""
            out.write(data)
    os.replace(part, output)
    for f in files:
        os.remove(f)
    code = max(p.exit for p in parts)
    message = next((p.message for p in parts if p.message), "")
    return RecordingResult(recording, output, "done" if code == 0 else "partial", code,
                           _count_rows(Path(output), command), seconds, message)


def _has_dashboard(client) -> bool:
    """Whether the scheduler serves Dask's dashboard (it needs bokeh)."""
    try:
        return bool(client.scheduler_info().get("services", {}).get("dashboard"))
    except Exception:  # noqa: BLE001 - an older scheduler: no dashboard said
        return False


def _write_atomic(path: Path, text: str) -> None:
    part = path.with_name(path.name + ".part")
    part.write_text(text)
    os.replace(part, path)


def _finished(outdir: Path, command: str, options: list[str]) -> set[str]:
    """The outputs the manifest in ``outdir`` lists as finished under ``command`` and
    ``options`` (none when it records others, or is missing or unreadable)."""
    with contextlib.suppress(ValueError, OSError, TypeError, AttributeError):
        old = json.loads((outdir / MANIFEST).read_text())
        if old.get("command") == command and old.get("options") == options:
            return {n for n in old.get("outputs", []) if isinstance(n, str)}
    return set()


def _write_manifest(outdir: Path, command: str, options: list[str], finished: set[str]) -> None:
    """``batch.json``: the command, its options and the outputs finished under them (names)."""
    text = json.dumps({"command": command, "options": options, "outputs": sorted(finished)}, indent=1)
    _write_atomic(outdir / MANIFEST, text + "\n")


def write_summary(outdir: str | os.PathLike[str], results: Sequence[RecordingResult]) -> Path:
    """``summary.csv`` in ``outdir``: one row per recording (written atomically), and the same
    table as ``summary.parquet`` where pyarrow is installed.

    Parameters
    ----------
    outdir : str or os.PathLike
        The batch's output folder (it exists).
    results : sequence of RecordingResult
        One per recording, in any order (the rows are sorted by recording); floats are written
        with three decimals, columns :data:`SUMMARY_COLUMNS`.

    Returns
    -------
    pathlib.Path
        The CSV file written.
    """
    import csv

    buf = io.StringIO()
    w = csv.DictWriter(buf, SUMMARY_COLUMNS, lineterminator="\n")
    w.writeheader()
    for r in sorted(results, key=lambda r: r.recording):
        w.writerow({k: (f"{v:.3f}" if isinstance(v, float) else v) for k, v in asdict(r).items()})
    path = Path(outdir) / SUMMARY
    _write_atomic(path, buf.getvalue())
    try:  # and as Parquet where pyarrow is installed (the same rows and columns)
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return path
    rows = [asdict(r) for r in sorted(results, key=lambda r: r.recording)]
    table = pa.table({k: [row[k] for row in rows] for k in SUMMARY_COLUMNS})
    part = path.with_suffix(".parquet.part")
    pq.write_table(table, part)
    os.replace(part, path.with_suffix(".parquet"))
    return path


def load_dask():
    """``dask.distributed`` or a :class:`visloc.errors.UsageError` naming the extra."""
    try:
        import dask.distributed as dd
    except ImportError:
        raise UsageError("visloc batch needs Dask: pip install 'visloc[batch]'") from None
    return dd


def _check_options(command: str, recording: str, opts: list[str]) -> None:
    """Parse ``opts`` as ``visloc COMMAND`` would, once, before any recording: a missing or
    malformed option is one :class:`UsageError`, not a failure of every recording."""
    from visloc.cli import build_parser

    said = io.StringIO()
    try:
        with contextlib.redirect_stderr(said):
            build_parser().parse_args([command, recording, *opts, "--out", "batch-check", "--quiet"])
    except SystemExit:
        lines = said.getvalue().strip().splitlines()
        reason = lines[-1].split(": error: ", 1)[-1] if lines else "not valid"
        raise UsageError(f"--options {shlex.join(opts)!r} for {command}: {reason}") from None


def _check_request(command: str, recordings: Sequence[str], opts: list[str], chunk: int | None) -> None:
    """Refuse (:class:`UsageError`) ``opts`` holding what batch sets itself, a ``chunk`` other than
    ``detect``'s or below 1, and options the command's parser refuses (checked on the first
    recording, once)."""
    if any(o in ("--out", "--quiet", "--frame-range") for o in opts):
        raise UsageError("batch writes each recording's --out (and --frame-range) itself: leave --out, --quiet and "
                         "--frame-range out of --options")
    if chunk is not None and (command != "detect" or chunk < 1):
        raise UsageError("--chunk needs detect (the other commands carry a filter from frame to frame) and >= 1 frame")
    if recordings:
        _check_options(command, recordings[0], opts)


def _client(stack: contextlib.ExitStack, dd, scheduler: str | None, workers: int | None):
    """A Dask client entered in ``stack``: on the running ``scheduler``, else on a local cluster
    of ``workers`` single-threaded worker processes (default one per core), all of them up."""
    if scheduler:
        return stack.enter_context(dd.Client(scheduler))
    import dask

    n = workers or os.cpu_count() or 1
    # workers started as plain processes are (no MALLOC_TRIM_THRESHOLD_: _plain_malloc);
    # forked where the platform can (Linux): a spawned worker imports Python, Dask and
    # visloc anew, about 1.5 s of the two cores before the first frame
    config = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}
    if "fork" in multiprocessing.get_all_start_methods() and sys.platform.startswith("linux"):
        config["distributed.worker.multiprocessing-method"] = "fork"
    stack.enter_context(dask.config.set(config))
    cluster = stack.enter_context(dd.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                                  dashboard_address=":0"))  # any free port
    client = stack.enter_context(dd.Client(cluster))
    # every worker up before the first task: tasks submitted while one worker is
    # connected all go to it (the others would sit idle until work stealing moves one)
    client.wait_for_workers(n)
    return client


def _submit(client, command: str, opts: list[str], todo: list[tuple[str, str]], chunk: int | None
            ) -> tuple[list, dict[str, tuple[int, int]], dict[int, list]]:
    """Submit one :func:`run_one` task per recording of ``todo``, or per ``chunk`` of frames:
    ``(futures, owner, pending)``, ``owner`` mapping a task's key to ``(recording index, chunk
    index)``, ``pending`` each recording's chunk results (None until they arrive)."""
    futures, owner = [], {}
    pending: dict[int, list] = {}
    for i, (rec, target) in enumerate(todo):
        ranges = _chunks(rec, chunk)
        pending[i] = [None] * len(ranges)
        for k, (a, b) in enumerate(ranges):
            extra = [] if len(ranges) == 1 else ["--frame-range", f"{a}:{'' if b is None else b}"]
            out_k = target if len(ranges) == 1 else f"{target}.chunk{k:05d}"
            fut = client.submit(run_one, command, rec, [*opts, *extra], out_k, pure=False,
                                key=f"visloc-{i}-{k}-{Path(rec).name}")
            futures.append(fut)
            owner[fut.key] = (i, k)
    return futures, owner, pending


def _run_tasks(command: str, opts: list[str], todo: list[tuple[str, str]], out: Path,
               results: list[RecordingResult], finished: set[str], *, chunk: int | None, workers: int | None,
               scheduler: str | None, progress: Callable[[RecordingResult], None] | None,
               dashboard: Callable[[str], None] | None) -> None:
    """Run ``todo`` on Dask: each recording's result appended to ``results`` (and given to
    ``progress``) as its last task finishes, its output added to ``finished`` and the manifest
    when it finished; on any exception the tasks are cancelled and the summary written."""
    dd = load_dask()
    with contextlib.ExitStack() as stack:
        client = _client(stack, dd, scheduler, workers)
        if dashboard is not None and _has_dashboard(client):
            dashboard(client.dashboard_link)
        futures, owner, pending = _submit(client, command, opts, todo, chunk)
        try:
            for fut in dd.as_completed(futures):
                i, k = owner[fut.key]
                pending[i][k] = fut.result()
                if any(p is None for p in pending[i]):
                    continue
                rec, target = todo[i]
                parts = pending[i]
                res = parts[0] if len(parts) == 1 else _merge(rec, target, parts, command)
                results.append(res)
                if res.status in ("done", "partial"):
                    finished.add(Path(target).name)
                    _write_manifest(out, command, opts, finished)
                if progress is not None:
                    progress(res)
        except BaseException:
            client.cancel(futures)
            write_summary(out, results)
            raise


def run_batch(command: str, recordings: Sequence[str], options: str | Sequence[str], outdir: str | os.PathLike[str],
              *, workers: int | None = None, scheduler: str | None = None, force: bool = False,
              chunk: int | None = None,
              progress: Callable[[RecordingResult], None] | None = None,
              dashboard: Callable[[str], None] | None = None) -> list[RecordingResult]:
    """Run ``command`` over ``recordings`` on Dask; outputs and ``summary.csv`` in ``outdir``.

    An output is skipped only when it was written under this command and these options: the
    manifest (``batch.json``) lists each output finished under the options it records. Before
    any task runs it is rewritten with this run's command and options and only the outputs
    already finished under them (so an output about to be written again, or left by other
    options, is listed by none); each output is added once its task has finished (``"done"`` or ``"partial"``). A run
    stopped at any point (Ctrl-C, a crash) therefore lists only outputs written under its own
    options, and the next run with them runs everything else again, the outputs of other
    options included; one with other options runs everything.

    Parameters
    ----------
    command : str
        ``"detect"``, ``"localize"``, ``"flow"`` or ``"track"``.
    recordings : sequence of str
        Videos, image folders, bags...
    options : str or sequence of str
        The command's options (a string is split as a shell would).
    outdir : str or os.PathLike
        Output folder (made if missing).
    workers : int, optional
        Local worker processes (default: one per core). Ignored with ``scheduler``.
    scheduler : str, optional
        A running Dask scheduler's address (``tcp://host:8786``).
    force : bool
        Run every recording, even those with an up-to-date output.
    chunk : int, optional
        ``detect`` only: split each recording into tasks of this many frames (``--frame-range``),
        their outputs concatenated in frame order: the same file as one task's, line for line.
    progress : callable, optional
        Called with each :class:`RecordingResult` as it arrives.
    dashboard : callable, optional
        Called with the Dask dashboard's address when the cluster serves one (bokeh installed).

    Returns
    -------
    list of RecordingResult
        Skipped ones first, then in the order they finished.

    Raises
    ------
    visloc.errors.UsageError
        ``options`` holding ``--out``, ``--quiet`` or ``--frame-range``, or options the
        command's parser refuses (a missing or malformed option: said once, before any
        recording); ``chunk`` with another command than ``detect`` or below 1.
    """
    opts = shlex.split(options) if isinstance(options, str) else list(options)
    _check_request(command, recordings, opts, chunk)
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    todo, results = plan(command, recordings, opts, out, force=force)
    for r in results:
        if progress is not None:
            progress(r)
    # the outputs this run writes again leave the list; those of recordings outside it stay
    finished = (_finished(out, command, opts) - {Path(t).name for _, t in todo}) | {Path(r.output).name for r in results}
    _write_manifest(out, command, opts, finished)
    if todo:
        _run_tasks(command, opts, todo, out, results, finished, chunk=chunk, workers=workers, scheduler=scheduler,
                   progress=progress, dashboard=dashboard)
    write_summary(out, results)
    return results
