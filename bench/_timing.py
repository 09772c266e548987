"""Timing on a shared host: wait out the host's slow spells before a timed chunk of work.

Measured on the 2-core host these benches ran on (2026-12-06, a workload of one OpenCV blur +
threshold and a Python loop, timed back to back and every 0.65 s for minutes): the host runs
at its normal speed most of the time, but in spells of a few milliseconds to about 15 s
(several in a row now and then) the same work takes 1.4-1.9x as long, OpenCV and Python
alike. A bench whose tables are timed partly in such spells moves by 15-30 % from run to run
while its ratios (visloc and the peer interleaved) hold.
The reference below slows down with image work: logged with a 1280x720 OpenCV blur and
adaptive threshold every 0.4 s for 45 s of a slow spell (2026-12-07), the two moved together
(correlation 0.96), and the image work was more than 15 % slow in 2 % of the samples where the
reference passed.

:class:`Steady` times a small reference workload (about 0.5 ms, one thread) before a chunk of
timed work and, while it runs more than ``tolerance`` times slower than its normal time (the
20th percentile of the last 500 checks in this process: one lucky check does not raise the
bar), sleeps and tries again (for at most ``max_wait`` s per call). The work itself is timed
as before; only when it starts changes. Each bench's JSON records how often and how long it
waited (``Steady.summary``).

A short bench that starts in a slow spell would take the spell's speed for normal (the
MAVLink bench, 2 s long, once did: its normal time was 0.585 ms against 0.37-0.41 ms in the
other benches of that run, and its p90 doubled). So a bench
that made 100 checks or more leaves its normal time in a file in the temporary folder, and a
process starting within the hour counts that time as 20 of its checks: it waits out a spell it
starts in, and if the host has really slowed down, its own checks outvote the stored time
after 80 of them (its 20 first and some 12 s of waiting).

A spell that starts after the check only slows that chunk down, so the benches keep each
item's best over their rounds (:func:`best_per_item`).

Usage::

    for r in range(rounds):
        for frame in frames:
            steady().wait(every=0.25)     # at most one check per 0.25 s
            t0 = time.perf_counter(); work(frame); times.append(time.perf_counter() - t0)
    best = best_per_item(times, rounds)   # (frames,) s
"""

from __future__ import annotations

import json
import tempfile
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path

import numpy as np

_VALUES = np.random.default_rng(0).random(8000)

#: where a bench leaves its normal reference time for the next (see the module doc)
STORE = Path(tempfile.gettempdir()) / "visloc-bench-steady.json"


def reference_workload() -> float:
    """Seconds for the reference workload (about 0.5 ms, on the calling thread only): a numpy
    sort and a Python loop."""
    t0 = time.perf_counter()
    np.sort(_VALUES)
    s = 0
    for i in range(5000):
        s += i * i
    return time.perf_counter() - t0


class Steady:
    """Wait, before timed work, until the host runs at its normal speed (see the module doc).

    Parameters
    ----------
    tolerance : float
        A check passes when the reference workload takes at most this many times its normal
        time (:attr:`normal`).
    max_wait : float
        Longest wait (s) of one :meth:`wait` call; past it the work runs anyway (counted in
        ``summary()["gave_up"]``).
    store : Path or None
        File that carries the normal time from one bench process to the next (see the module
        doc); None: none read or written.
    """

    def __init__(self, tolerance: float = 1.15, max_wait: float = 60.0, store: Path | None = None) -> None:
        self.tolerance, self.max_wait, self.store = tolerance, max_wait, store
        self._history: deque[float] = deque(maxlen=500)
        self.seeded = _stored_normal(store)
        if self.seeded is not None:
            self._history.extend([self.seeded] * 20)
        for _ in range(20):
            self._probe()
        self.checks = self.waits = self.gave_up = 0
        self.waited_s = 0.0
        self._last = -np.inf

    @property
    def normal(self) -> float:
        """The reference workload's normal time, s: the 20th percentile of the last 500 checks."""
        return float(np.percentile(self._history, 20))

    def _probe(self) -> bool:
        """Time the reference (best of 3) and record it; whether it ran at the normal speed."""
        t = min(reference_workload() for _ in range(3))
        self._history.append(t)
        return t <= self.tolerance * self.normal

    def wait(self, every: float = 0.0) -> None:
        """Return once the reference runs within ``tolerance`` of its normal time (or after
        ``max_wait`` s); with ``every`` > 0, skip the check if the last one was under
        ``every`` s ago."""
        now = time.perf_counter()
        if now - self._last < every:
            return
        self.checks += 1
        start = now
        if not self._probe():
            self.waits += 1
            while not self._probe():
                if time.perf_counter() - start > self.max_wait:
                    self.gave_up += 1
                    break
                time.sleep(0.2)
            self.waited_s += time.perf_counter() - start
        self._last = time.perf_counter()

    def summary(self) -> dict:
        """Checks made, waits, give-ups and seconds waited, and the normal reference time
        (with the one read from :attr:`store` at the start, if any), for the bench's JSON; after
        100 checks or more, also leaves the normal time in :attr:`store`."""
        if self.store is not None and self.checks >= 100:
            try:
                self.store.write_text(json.dumps({"normal_s": self.normal, "time": time.time()}))
            except OSError:
                pass  # a read-only temporary folder: the next bench calibrates on its own
        seeded = None if self.seeded is None else round(1e3 * self.seeded, 3)
        return {"checks": self.checks, "waits": self.waits, "gave_up": self.gave_up,
                "waited_s": round(self.waited_s, 1), "reference_ms_normal": round(1e3 * self.normal, 3),
                "reference_ms_stored": seeded}


def _stored_normal(store: Path | None, max_age: float = 3600.0) -> float | None:
    """The normal reference time (s) a bench left in ``store`` under ``max_age`` s ago, or None."""
    if store is None:
        return None
    try:
        d = json.loads(store.read_text())
        normal, age = float(d["normal_s"]), time.time() - float(d["time"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return normal if 0 < normal and 0 <= age < max_age else None


def best_per_item(seconds: list[float], rounds: int) -> np.ndarray:
    """Each item's best time over the rounds (items,), from times appended round by round
    (``rounds`` x items values, every round over the same items in the same order)."""
    return np.asarray(seconds).reshape(rounds, -1).min(axis=0)


_SHARED: Steady | None = None


def steady() -> Steady:
    """The process's one :class:`Steady`, made at the first call (after a bench has pinned its
    core, so the reference's normal time is that core's)."""
    global _SHARED
    if _SHARED is None:
        _SHARED = Steady(store=STORE)
    return _SHARED


def time_sections(sections: list[tuple[list, dict]], rounds: int,
                  between: Callable[[], None] | None = None) -> list[tuple[dict, dict]]:
    """Time every section's items with each of its methods, interleaved, the rounds spread over
    all the sections: round 1 of every section, then round 2 of every section, ... so an item's
    rounds lie tens of seconds apart and a slow spell of the host as long as one section (a
    markers table once ran 23 % slow while the tables around it did not) moves at most one of
    them. Every item waits for the host (:func:`steady`, at most one check per 0.25 s); its
    methods run in turn, in reverse order every other item and round.

    ``sections``: (items, {method: function(item) -> output, or a tuple (output, seconds the
    peer measured itself): so a method's own output must not be a tuple}). ``between``: called
    after every section's round (``rounds`` x sections calls, spread over the whole timing;
    ``markers.StageSplit.run_pass``). Returns, per section, ({method: each item's best time over
    the rounds, s (items,)}, {method: each item's output of the first round}).
    """
    times = [{m: [] for m in run} for _, run in sections]
    outputs = [{m: [None] * len(items) for m in run} for items, run in sections]
    for r in range(rounds):
        for s, (items, run) in enumerate(sections):
            for k, item in enumerate(items):
                steady().wait(every=0.25)
                for m in list(run) if (r + k) % 2 == 0 else list(run)[::-1]:
                    t0 = time.perf_counter()
                    out = run[m](item)
                    spent = time.perf_counter() - t0
                    if isinstance(out, tuple):  # a peer in a child process timed itself
                        out, spent = out
                    times[s][m].append(spent)
                    if r == 0:
                        outputs[s][m][k] = out
            if between is not None:
                between()
    return [({m: best_per_item(t, rounds) for m, t in tm.items()}, out) for tm, out in zip(times, outputs)]
