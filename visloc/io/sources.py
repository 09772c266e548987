"""Frame sources: one iterable over images, folders, glob patterns, videos and cameras.

:func:`open_source` turns a command-line style ``spec`` into a :class:`FrameSource` that yields
:class:`visloc.types.Frame` objects. Images are ``uint8`` grey or BGR (16-bit images are scaled
down, alpha is dropped). A file that cannot be decoded does not stop a batch run: it yields a
frame with ``image=None`` and ``error="cannot read image <path>"``.

Examples
--------
>>> with open_source("flight/*.png", fps=30) as source:  # doctest: +SKIP
...     for frame in source:
...         if frame.error is None:
...             process(frame.image)
"""

from __future__ import annotations

import glob
import math
import os
import time as _time
from abc import ABC, abstractmethod
from collections.abc import Iterator, Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc.images import to_uint8
from visloc.io.avi_index import avi_unreadable_frames
from visloc.io.closing import Closing
from visloc.types import Frame

__all__ = [
    "IMAGE_EXTENSIONS",
    "VIDEO_EXTENSIONS",
    "CameraSource",
    "FrameSource",
    "ImageListSource",
    "SourceError",
    "VideoSource",
    "open_source",
    "read_image",
]

IMAGE_EXTENSIONS: frozenset[str] = frozenset(
    {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp"}
)
"""File extensions (lower case) read as still images."""

VIDEO_EXTENSIONS: frozenset[str] = frozenset({".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v"})
"""File extensions (lower case) read as videos with ``cv2.VideoCapture``."""

_GLOB_CHARS = frozenset("*?[")


class SourceError(ValueError):
    """A frame source cannot be opened (missing path, no images, unreadable video or camera)."""


def _is_image_path(path: str) -> bool:
    return os.path.splitext(path)[1].lower() in IMAGE_EXTENSIONS


def _check_fps(fps: float | None) -> float | None:
    if fps is None:
        return None
    if isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating)):
        raise TypeError(f"fps must be a number or None, got {type(fps).__name__}")
    if not math.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps must be a positive finite number, got {fps!r}")
    return float(fps)


def _to_uint8(image: NDArray) -> NDArray[np.uint8]:
    """Convert a decoded image of any depth/channel count to uint8 grey or BGR.

    Raises
    ------
    ValueError
        If the dtype or channel count is not supported.
    """
    if image.ndim == 3:
        channels = image.shape[2]
        if channels in (1, 2):  # grey, or grey + alpha
            image = image[:, :, 0]
        elif channels == 4:  # BGRA: drop alpha
            image = image[:, :, :3]
        elif channels != 3:
            raise ValueError(f"unsupported channel count {channels}")
    elif image.ndim != 2:
        raise ValueError(f"unsupported image shape {image.shape}")
    try:
        out = to_uint8(image)
    except TypeError as exc:
        raise ValueError(str(exc)) from None
    return np.ascontiguousarray(out)


def read_image(path: str | os.PathLike[str]) -> tuple[NDArray[np.uint8] | None, str | None]:
    """Read an image file as uint8 grey or BGR, reporting failure instead of raising.

    The file is decoded with ``cv2.imdecode(..., IMREAD_UNCHANGED)`` (so non-ASCII paths work
    everywhere) and converted: 16-bit and floating-point pixels by :func:`visloc.images.to_uint8`
    (16-bit by the bit depth their values fit in, so 12-bit data in a 16-bit PNG is not read as
    nearly black; floats as 0..1 or 0..255 by their range), an alpha channel is dropped and
    single-channel images stay grey. Images smaller than 2 x 2 pixels are not read.

    Parameters
    ----------
    path : str or os.PathLike
        The image file.

    Returns
    -------
    image : ndarray (H, W) or (H, W, 3) uint8, or None
        The pixels, or ``None`` when the file cannot be read or decoded.
    error : str or None
        ``None`` on success, else a message starting with ``"cannot read image <path>"``.
    """
    name = os.fspath(path)
    try:
        data = np.fromfile(name, dtype=np.uint8)
    except OSError as exc:
        return None, f"cannot read image {name}: {exc.strerror or exc}"
    decoded = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if decoded is None:
        return None, f"cannot read image {name}"
    if decoded.shape[0] < 2 or decoded.shape[1] < 2:
        return None, f"cannot read image {name}: {decoded.shape[1]} x {decoded.shape[0]} px, at least 2 x 2 needed"
    try:
        return _to_uint8(decoded), None
    except ValueError as exc:
        return None, f"cannot read image {name}: {exc}"


class FrameSource(Closing, ABC):
    """An iterable of :class:`visloc.types.Frame`; also a context manager that closes it.

    ``len(source)`` is the number of frames when it is known in advance (image lists, videos
    whose container states a frame count); otherwise it raises ``TypeError`` as a generator
    does. ``description`` is a one-line summary for logs and progress bars.
    """

    description: str

    def __init__(self, description: str) -> None:
        self.description = description
        self._closed = False

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` has been called."""
        return self._closed

    def __iter__(self) -> Iterator[Frame]:
        if self._closed:
            raise ValueError(f"cannot iterate a closed frame source ({self.description})")
        return self._frames()

    @abstractmethod
    def _frames(self) -> Iterator[Frame]:
        """Yield the frames (called by ``__iter__`` on an open source)."""

    def _length(self) -> int | None:
        """Number of frames, or ``None`` when unknown."""
        return None

    def __len__(self) -> int:
        n = self._length()
        if n is None:
            raise TypeError(f"object of type '{type(self).__name__}' has no len()")
        return n

    def close(self) -> None:
        """Release the underlying resources; iterating afterwards raises ``ValueError``."""
        self._closed = True


    def __repr__(self) -> str:
        return f"<{type(self).__name__}: {self.description}>"


class ImageListSource(FrameSource):
    """Frames from a list of image files, read lazily in the given order.

    ``time`` is ``index / fps`` when ``fps`` is given, else ``index`` (i.e. one second per
    frame, so that ``time`` is always defined and monotonic). An unreadable file yields a frame
    with ``image=None`` and ``error`` set; iteration goes on. The source can be iterated
    several times.

    Parameters
    ----------
    paths : sequence of str
        Image files.
    fps : float, optional
        Frame rate used for ``time``.
    description : str, optional
        Summary; defaults to ``"<n> images"``.

    Raises
    ------
    TypeError
        ``paths`` is one path (a str, bytes or path object), not a sequence of them.
    """

    def __init__(
        self, paths: Sequence[str], *, fps: float | None = None, description: str | None = None
    ) -> None:
        if isinstance(paths, (str, bytes, os.PathLike)):  # a str would be a list of one-letter paths
            raise TypeError(f"paths: expected a sequence of image paths, got one path {paths!r}: pass [{paths!r}]")
        self.paths: list[str] = [os.fspath(p) for p in paths]
        self.fps = _check_fps(fps)
        super().__init__(description or f"{len(self.paths)} images")

    def _length(self) -> int:
        return len(self.paths)

    def _frames(self) -> Iterator[Frame]:
        for index, path in enumerate(self.paths):
            if self._closed:
                return
            image, error = read_image(path)
            t = index / self.fps if self.fps is not None else float(index)
            yield Frame(index, t, image, path, error)


#: failed reads in a row after which a video is taken to have ended
MAX_BAD_READS = 32


class VideoSource(FrameSource):
    """Frames of a video file read with ``cv2.VideoCapture``.

    ``time`` is the stream timestamp (``CAP_PROP_POS_MSEC`` after each read) in seconds. If
    ``fps`` is given it overrides the container and ``time = index / fps``; if the backend
    reports no usable timestamps, ``index / CAP_PROP_FPS`` is used, and from a first unusable
    one on (not finite, negative or not increasing) the times go on from the last stamp at
    ``CAP_PROP_FPS`` (never back). A frame the decoder cannot
    deliver (corrupt bytes) comes as a frame without an image at its own index (its time between
    its neighbours'), its ``error`` saying so, and reading goes on (the frames after keep their
    indices); the stream ends after :data:`MAX_BAD_READS` failed reads in a row. In an AVI file
    the frames whose chunks its index cannot find (:func:`visloc.io.avi_index.avi_unreadable_frames`)
    are such frames too, whether the backend fails their reads (OpenCV 5.0) or skips them
    without a word (5.1); the frames of such a file are timed ``index / fps`` (the container's
    stamps, renumbered past a skipped frame, are not used). Where a constant-rate stream's
    stamps skip frame periods (a demuxer that drops damaged frames without a failed read, as
    OpenCV 5.1's does in Matroska files), the frames missing are recorded at their indices the
    same way. When fewer
    frames arrived than the container declares (a truncated file), a last frame without an
    image says so in its ``error`` (the commands count and report both). Each new iteration
    starts again from the first frame.

    Parameters
    ----------
    path : str
        Video file.
    fps : float, optional
        Frame rate overriding the container's timestamps.

    Raises
    ------
    SourceError
        If OpenCV cannot open the video.
    """

    def __init__(self, path: str | os.PathLike[str], *, fps: float | None = None) -> None:
        self.path = os.fspath(path)
        self.fps = _check_fps(fps)
        self._capture = self._open()
        self._fresh = True
        self._unreadable = avi_unreadable_frames(self.path) or frozenset()
        count = int(self._capture.get(cv2.CAP_PROP_FRAME_COUNT))
        self.frame_count: int | None = count if count > 0 else None
        native = self._capture.get(cv2.CAP_PROP_FPS)
        self.native_fps: float | None = native if math.isfinite(native) and native > 0 else None
        parts = [f"{count} frames"] if self.frame_count else []
        if self.native_fps:
            parts.append(f"{self.native_fps:g} fps")
        extra = f" ({', '.join(parts)})" if parts else ""
        super().__init__(f"video {self.path}{extra}")

    def _open(self) -> cv2.VideoCapture:
        capture = cv2.VideoCapture(self.path)
        if not capture.isOpened():
            capture.release()
            raise SourceError(f"cannot open video {self.path}")
        return capture

    def _length(self) -> int | None:
        return self.frame_count

    def _frames(self) -> Iterator[Frame]:
        if not self._fresh:
            self._capture.release()
            self._capture = self._open()
        self._fresh = False
        capture = self._capture
        index = lost = bad = 0
        last_time = -math.inf
        skip = self._unreadable
        stamps = self.fps is None and not skip
        clock = _FrameClock(self.fps or self.native_fps, stamps=stamps)
        gaps = _StampGaps(self.native_fps if stamps else None)
        while not self._closed:
            ok, image = capture.read()
            if not ok or image is None:
                bad += 1
                if bad >= MAX_BAD_READS:
                    break
                continue
            # failed reads followed by a good frame: each lost one frame (OpenCV reads one frame
            # a call), recorded at its place so that the frames after keep their indices; as many
            # as a constant-rate stream's stamps skip, if more (a demuxer that drops frames
            # without a failed read); then the frames the AVI's index cannot find
            stamp = capture.get(cv2.CAP_PROP_POS_MSEC) / 1000.0
            failed, bad = bad, max(bad, gaps.missing(stamp))
            while index + bad in skip:
                bad += 1
            t = clock.time(index + bad, stamp)
            for k in range(bad):
                lost_t = (last_time + (t - last_time) * (k + 1) / (bad + 1) if math.isfinite(last_time)
                          else max(t - (bad - k) * clock.step, 0.0))
                yield self._lost(index, lost_t, by_stamps=not (failed or skip))
                index += 1
            lost += bad
            bad = 0
            last_time = t
            yield Frame(index, t, _to_uint8(image), f"{self.path}#{index}")
            index += 1
        if self._closed:
            return
        while index in skip:  # the last frames, unreadable by the AVI's index
            yield self._lost(index, clock.time(index, math.nan))
            index += 1
            lost += 1
        if self.frame_count is not None and index < self.frame_count:
            yield Frame(index, max(last_time, 0.0), None, f"{self.path}#end",
                        f"video {self.path}: {index} frames read of {self.frame_count} the container declares "
                        f"({lost} of them corrupt); the file ends early")

    def _lost(self, index: int, t: float, *, by_stamps: bool = False) -> Frame:
        """The row of a frame lost at ``index``: one the decoder or the AVI's index could not
        deliver, or (``by_stamps``: no failed read) one the stream's stamps skip."""
        why = ("is missing: the stream's timestamps skip it (corrupt or dropped)" if by_stamps
               else "could not be decoded (corrupt bytes)")
        return Frame(index, t, None, f"{self.path}#{index}", f"video {self.path}: frame {index} {why}; skipped")

    def close(self) -> None:
        """Release the capture."""
        self._capture.release()
        super().close()


class _StampGaps:
    """Frames missing from a constant-rate stream, told by its timestamps: while every step
    between stamps has been a whole number of frame periods (within :attr:`TOLERANCE` of one),
    a step of k periods holds k - 1 missing frames; from the first step that is not (a
    variable-rate stream, or no rate) no gap is told again."""

    TOLERANCE = 0.1  # of a period (Matroska stamps whole milliseconds: 33 or 34 ms at 30 fps)

    def __init__(self, rate: float | None) -> None:
        self.period = 1.0 / rate if rate else None
        self.last: float | None = None

    def missing(self, stamp: float) -> int:
        """The frames missing between the last stamp given and ``stamp`` (s)."""
        if self.period is None:
            return 0
        last, self.last = self.last, stamp
        if last is None:
            return 0
        k = round((stamp - last) / self.period) if math.isfinite(stamp - last) else 0
        if k < 1 or abs(stamp - last - k * self.period) > self.TOLERANCE * self.period:
            self.period = None  # not a constant-rate stream: its steps tell nothing
            return 0
        return k - 1


class _FrameClock:
    """A video's frame times: the stream's stamps (s) while they are usable (finite, >= 0 and
    increasing), then, from the first that is not, ``1 / rate`` after the last time given (the
    stamps' clock goes on at the frame rate: no jump back to ``index / rate``); ``index /
    rate`` throughout without stamps (``stamps=False``); ``rate`` None or 0: one second per
    frame."""

    def __init__(self, rate: float | None, *, stamps: bool) -> None:
        self.step = 1.0 / rate if rate else 1.0
        self.stamps = stamps
        self.offset = 0.0  # added to index * step once the stamps are given up
        self.last = -math.inf

    def time(self, index: int, stamp: float) -> float:
        """The time (s) of frame ``index`` whose stream stamp is ``stamp`` (s)."""
        if self.stamps and (not math.isfinite(stamp) or stamp < 0 or stamp <= self.last):
            self.stamps = False  # backend without usable timestamps from here on
            if math.isfinite(self.last):
                self.offset = self.last + self.step - index * self.step
        self.last = stamp if self.stamps else self.offset + index * self.step
        return self.last


class CameraSource(FrameSource):
    """Live frames from a camera opened with ``cv2.VideoCapture(index)``.

    ``time`` is the wall-clock time (monotonic clock) since the first frame of the iteration.
    Iteration stops when the camera stops delivering frames or the source is closed; the
    length is unknown (``len()`` raises ``TypeError``).

    Parameters
    ----------
    index : int
        Camera index (0 is the default camera).

    Raises
    ------
    SourceError
        If the camera cannot be opened.
    """

    def __init__(self, index: int) -> None:
        self.index = int(index)
        self._capture = cv2.VideoCapture(self.index)
        if not self._capture.isOpened():
            self._capture.release()
            raise SourceError(f"cannot open camera {self.index}")
        super().__init__(f"camera {self.index}")

    def _frames(self) -> Iterator[Frame]:
        start: float | None = None
        index = 0
        while not self._closed:
            ok, image = self._capture.read()
            now = _time.monotonic()
            if not ok or image is None:
                return
            if start is None:
                start = now
            yield Frame(index, now - start, _to_uint8(image), f"camera{self.index}#{index}")
            index += 1

    def close(self) -> None:
        """Release the camera."""
        self._capture.release()
        super().close()


def _image_list(spec: str, paths: list[str], kind: str, fps: float | None) -> ImageListSource:
    images = sorted(p for p in paths if _is_image_path(p) and os.path.isfile(p))
    if not images:
        found = "matches" if kind == "glob" else "contains"
        raise SourceError(f"{kind} {spec} {found} no image file")
    noun = "image" if len(images) == 1 else "images"
    return ImageListSource(images, fps=fps, description=f"{kind} {spec} ({len(images)} {noun})")


def _open_file(path: str, fps: float | None) -> FrameSource:
    """An existing file as a source: a single image (by its extension), else a video; a file
    with another extension that is no readable video is a :class:`SourceError` naming it."""
    if _is_image_path(path):
        return ImageListSource([path], fps=fps, description=f"image {path}")
    ext = os.path.splitext(path)[1].lower()
    try:
        return VideoSource(path, fps=fps)
    except SourceError:
        if ext in VIDEO_EXTENSIONS:
            raise
        raise SourceError(
            f"cannot open {path}: not an image or a readable video (extension {ext or 'none'})"
        ) from None


def open_source(spec: str | int | os.PathLike[str], *, fps: float | None = None,
                topic: str | None = None) -> FrameSource:
    """Open a frame source from a path, glob pattern, video file, recording or camera index.

    ``spec`` is interpreted in this order:

    1. an ``int``, or a string of digits such as ``"0"``: a camera index (write ``"./0"`` for
       a file or folder named ``0``);
    2. a recording: a ROS 1 ``.bag``, a ``.mcap`` file or a ROS 2 bag folder (one with
       ``metadata.yaml``): the images of ``topic`` (:class:`visloc.io.bags.BagSource`, needs
       the extra ``visloc[ros]``);
    3. an existing folder: its image files (non-recursive), sorted by name;
    4. an existing file: a single image if its extension is an image extension
       (:data:`IMAGE_EXTENSIONS`, case-insensitive), otherwise a video (any other extension
       is tried with ``cv2.VideoCapture`` too);
    5. a string containing ``*``, ``?`` or ``[``: a glob pattern (``**`` recurses), keeping the
       matching image files sorted by path.

    Parameters
    ----------
    spec : str, int or os.PathLike
        What to read, as above.
    fps : float, optional
        Frame rate. For image lists ``time = index / fps``; without it ``time = index`` (one
        second per frame). For videos it overrides the container's timestamps. Cameras ignore
        it (their time is the wall-clock time since the first frame), and so do recordings
        (their times are the messages' stamps).
    topic : str, optional
        A recording's image topic (needed when it has more than one); only for recordings.

    Returns
    -------
    FrameSource
        Iterable of :class:`visloc.types.Frame`; use it as a context manager to release
        videos and cameras.

    Raises
    ------
    SourceError
        If the path does not exist, a folder or glob holds no image file, or a video or camera
        cannot be opened. The one-line message names ``spec``.
    TypeError
        If ``spec`` or ``fps`` has the wrong type.
    ValueError
        If ``fps`` is not positive and finite.
    """
    fps = _check_fps(fps)
    if isinstance(spec, bool) or not isinstance(spec, (str, int, os.PathLike)):
        raise TypeError(f"spec must be a path, glob pattern or camera index, got {spec!r}")
    if isinstance(spec, int):
        if spec < 0:
            raise SourceError(f"camera index must be >= 0, got {spec}")
        return CameraSource(spec)
    text = os.fspath(spec)
    if not isinstance(text, str):
        raise TypeError(f"spec must be a str path, got {type(text).__name__}")
    if not text.strip():
        raise SourceError("spec is empty: expected a path, glob pattern or camera index")
    if text.strip().isdigit() and text.strip().isascii():
        return CameraSource(int(text.strip()))
    from visloc.io.bags import BagSource, is_recording

    if is_recording(text):
        return BagSource(text, topic=topic)
    if topic is not None:
        raise SourceError(f"a topic ({topic}) is for ROS bags and MCAP files; {text} is not one")
    if os.path.isdir(text):
        names = [os.path.join(text, n) for n in os.listdir(text)]
        return _image_list(text, names, "folder", fps)
    if os.path.isfile(text):
        return _open_file(text, fps)
    if _GLOB_CHARS & set(text):
        return _image_list(text, glob.glob(text, recursive=True), "glob", fps)
    if os.path.exists(text):  # a device, a pipe, a socket
        raise SourceError(f"{text} is neither a file nor a folder")
    raise SourceError(f"path does not exist: {text}")
