"""The marker detectors visloc is compared with, configured as their documentation recommends.

Shared by the bench scripts, so every benchmark runs the same peers with the same settings:

- **OpenCV ArUco** (``cv2.aruco.ArucoDetector``): default ``DetectorParameters`` (corner
  refinement NONE: corners are integer contour vertices), and the same with
  ``cornerRefinementMethod = CORNER_REFINE_SUBPIX`` (OpenCV's defaults for the sub-pixel window,
  5 px half-size, 30 iterations, 0.1 min accuracy). Corners are in OpenCV's order and
  pixel-centre convention already.
- **AprilTag 3** through ``pupil_apriltags.Detector(families=F, nthreads=1, quad_decimate=1.0,
  quad_sigma=0.0, refine_edges=True, decode_sharpening=0.25)``: full-resolution quad search
  (decimation trades small tags for speed) and edge refinement, which AprilTag's docs
  recommend for accuracy. Only for the AprilTag families: ``DICT_APRILTAG_16h5`` -> ``tag16h5``,
  ``DICT_APRILTAG_25h9`` -> ``tag25h9``, ``DICT_APRILTAG_36h11`` -> ``tag36h11``. Corners are
  converted to OpenCV's order and convention: ``corners[[1, 0, 3, 2]] - 0.5``.

pupil-apriltags 1.0.4 with these settings corrupted the heap here on some images (a later
``malloc`` aborts the process, far from the cause), so AprilTag 3 runs in a child process
(:class:`AprilTagProcess`): a crash of the child raises :class:`PeerCrashed` for that image and
the next call starts a fresh child. The child times ``detect`` itself, so the figure excludes
the inter-process transfer. One detector per family is kept alive for the child's lifetime
(creating and dropping detectors in one process was another trigger of the corruption).

Usage::

    from _peers import AprilTagProcess, PeerCrashed, apriltag_family, opencv_detector, opencv_detect

    with AprilTagProcess() as at:
        dets, seconds = at.detect(gray, "tag36h11")   # [(id, corners (4, 2) OpenCV order)], s
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Self

import cv2
import numpy as np

# --- OpenCV -----------------------------------------------------------------------------------

OPENCV_METHODS = {"opencv": False, "opencv_subpix": True}  # name -> CORNER_REFINE_SUBPIX


def opencv_dictionary(dict_name_or_path: str) -> cv2.aruco.Dictionary:
    """A predefined dictionary by name (``"DICT_6X6_250"``) or one read from an OpenCV YAML file."""
    if dict_name_or_path.endswith((".yml", ".yaml")):
        fs = cv2.FileStorage(str(dict_name_or_path), cv2.FILE_STORAGE_READ)
        d = cv2.aruco.Dictionary()
        d.readDictionary(fs.root())
        fs.release()
        return d
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dict_name_or_path))


def opencv_detector(dict_name_or_path: str, subpix: bool) -> cv2.aruco.ArucoDetector:
    """OpenCV's ``ArucoDetector`` with default parameters, or with CORNER_REFINE_SUBPIX."""
    p = cv2.aruco.DetectorParameters()
    if subpix:
        p.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    return cv2.aruco.ArucoDetector(opencv_dictionary(dict_name_or_path), p)


def opencv_detect(detector: cv2.aruco.ArucoDetector, gray: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """[(id, corners (4, 2) float64, OpenCV order and pixel-centre convention)]."""
    corners, ids, _ = detector.detectMarkers(gray)
    if ids is None:
        return []
    return [(int(i), c.reshape(4, 2).astype(np.float64)) for c, i in zip(corners, ids.ravel())]


# --- AprilTag 3 -------------------------------------------------------------------------------

APRILTAG_FAMILIES = {
    "DICT_APRILTAG_16h5": "tag16h5",
    "DICT_APRILTAG_25h9": "tag25h9",
    "DICT_APRILTAG_36h11": "tag36h11",
}
APRILTAG_SETTINGS = {"nthreads": 1, "quad_decimate": 1.0, "quad_sigma": 0.0, "refine_edges": True,
                     "decode_sharpening": 0.25}
APRILTAG_ORDER = [1, 0, 3, 2]  # AprilTag corner k -> OpenCV corner position
APRILTAG_SHIFT = -0.5  # AprilTag pixel centres sit at +0.5 of OpenCV's


def apriltag_family(dict_name: str) -> str | None:
    """``DICT_APRILTAG_36h11`` -> ``tag36h11`` (16h5, 25h9 likewise); None for any other dictionary."""
    return APRILTAG_FAMILIES.get(Path(str(dict_name)).name)


class PeerCrashed(RuntimeError):
    """The AprilTag child process died (or hung) on this image; the next call starts a new one."""


def _describe_exit(code: int | None) -> str:
    if code is None:
        return "no answer (killed after the timeout)"
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"


class AprilTagProcess:
    """AprilTag 3 (pupil-apriltags) in a child process that may crash without taking the caller down.

    ``detect(gray, family)`` returns ``([(id, corners (4, 2))], seconds)`` with corners in OpenCV's
    order and pixel-centre convention and ``seconds`` the detector's own time measured in the child.
    If the child dies (heap corruption aborts it) or does not answer within ``timeout`` seconds,
    ``detect`` raises :class:`PeerCrashed`; the next call starts a new child.
    """

    def __init__(self, timeout: float = 60.0, settings: dict | None = None):
        self.timeout = timeout
        self.settings = dict(APRILTAG_SETTINGS if settings is None else settings)
        self.crashes = 0
        self.starts = 0
        self._proc: subprocess.Popen | None = None
        self._conn: Connection | None = None

    # the child is started lazily and replaced after a crash
    def _start(self) -> None:
        parent, child = socket.socketpair()
        fd = child.fileno()
        self._proc = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), "--apriltag-child", str(fd)],
            pass_fds=(fd,), stdin=subprocess.DEVNULL)
        child.close()
        self._conn = Connection(parent.detach())
        self._conn.send(("settings", self.settings))
        self.starts += 1

    def _stop(self, kill: bool) -> int | None:
        code = None
        if self._proc is not None:
            if kill and self._proc.poll() is None:
                self._proc.kill()
            try:
                code = self._proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                code = self._proc.wait()
        if self._conn is not None:
            self._conn.close()
        self._proc, self._conn = None, None
        return code

    def detect(self, gray: np.ndarray, family: str) -> tuple[list[tuple[int, np.ndarray]], float]:
        if gray.ndim != 2 or gray.dtype != np.uint8:
            raise ValueError("AprilTag needs a 2-D uint8 image")
        if self._proc is None:
            self._start()
        try:
            self._conn.send(("detect", np.ascontiguousarray(gray), family))
            if not self._conn.poll(self.timeout):
                raise TimeoutError
            status, payload, seconds = self._conn.recv()
        except (EOFError, OSError, TimeoutError) as e:
            hung = isinstance(e, TimeoutError)
            code = self._stop(kill=True)
            self.crashes += 1
            raise PeerCrashed(f"AprilTag child {_describe_exit(None if hung else code)}") from None
        if status != "ok":
            raise RuntimeError(f"AprilTag child: {payload}")
        return [(int(i), np.asarray(c, dtype=np.float64)) for i, c in payload], float(seconds)

    def close(self) -> None:
        if self._conn is not None:
            try:
                self._conn.send(("exit",))
            except OSError:
                pass
        self._stop(kill=False)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _child_main(fd: int) -> None:
    """The child's loop: one detector per family, kept for the process's lifetime."""
    import pupil_apriltags

    conn = Connection(fd)
    settings = dict(APRILTAG_SETTINGS)
    detectors: dict[str, object] = {}
    while True:
        try:
            msg = conn.recv()
        except EOFError:
            break
        if msg[0] == "exit":
            break
        if msg[0] == "settings":
            settings = msg[1]
            continue
        _, gray, family = msg
        try:
            det = detectors.get(family)
            if det is None:
                det = detectors[family] = pupil_apriltags.Detector(families=family, **settings)
            t0 = time.perf_counter()
            tags = det.detect(gray)
            seconds = time.perf_counter() - t0
            out = [(int(d.tag_id), d.corners[APRILTAG_ORDER] + APRILTAG_SHIFT) for d in tags]
            conn.send(("ok", out, seconds))
        except Exception as e:  # noqa: BLE001 (a Python-level error is an answer, not a crash)
            conn.send(("error", f"{type(e).__name__}: {e}", 0.0))
    conn.close()
    sys.stdout.flush()
    # the detectors' teardown at interpreter exit is another place the corruption surfaced
    os._exit(0)


if __name__ == "__main__" and len(sys.argv) == 3 and sys.argv[1] == "--apriltag-child":
    _child_main(int(sys.argv[2]))
