"""Result writers that never lose finished work: JSON Lines, CSV and annotated images/video.

Every writer flushes after each record, so a run that is interrupted (Ctrl-C, crash, power
cut after the OS wrote its buffers) keeps every frame already written. Files are written
under a temporary name next to the output (:func:`visloc.io.closing.staged_path`) and renamed
over it when the writer closes with at least one record, so a run that fails before its first
record never truncates an earlier result (after a hard crash the frames are in the
``.name.partial.ext`` file). All are context managers.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, TextIO

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc.images import check_image
from visloc.io.closing import Closing, commit_staged, staged_path
from visloc.io.draw import draw_markers

__all__ = ["AnnotationSink", "CsvWriter", "JsonlWriter", "draw_markers", "to_jsonable"]

VIDEO_FOURCC: dict[str, str] = {".mp4": "mp4v", ".avi": "MJPG"}
"""Codec used by :class:`AnnotationSink` for each video extension."""


def to_jsonable(obj: Any, *, _where: str = "obj") -> Any:
    """Convert ``obj`` recursively into plain JSON types.

    numpy scalars become Python numbers, arrays become nested lists, tuples and sets become
    lists, ``pathlib.Path`` becomes ``str``, objects with a ``to_dict()`` method (such as
    :class:`visloc.types.MarkerDetection` and :class:`visloc.types.Pose`) and other dataclasses
    become dicts, mapping keys become strings, and non-finite floats (NaN, inf) become ``None``
    so the output is strict JSON.

    Parameters
    ----------
    obj : object
        The value to convert.
    _where : str
        Internal: the location of ``obj`` named in error messages.

    Returns
    -------
    None, bool, int, float, str, list or dict
        The value in plain JSON types (nested lists and dicts with str keys).

    Raises
    ------
    TypeError
        If some value has no JSON form, or two keys of a mapping have the same string form
        (``{1: ..., "1": ...}``: one value would be lost); the message gives the location, e.g.
        ``obj['pose']``.
    """
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, int):
        return int(obj)
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, np.generic):
        item = obj.item()
        if isinstance(item, np.generic):  # np.longdouble and its complex: item() is numpy's again
            if not isinstance(item, np.floating):
                raise TypeError(f"{_where} has type {type(obj).__name__}, which cannot be written as JSON")
            item = float(item)
        return to_jsonable(item, _where=_where)
    if isinstance(obj, np.ndarray):
        if obj.dtype == np.longdouble:
            obj = obj.astype(np.float64)
        return to_jsonable(obj.tolist(), _where=_where)
    if isinstance(obj, Mapping):
        out = {_json_key(k, _where): to_jsonable(v, _where=f"{_where}[{k!r}]") for k, v in obj.items()}
        if len(out) != len(obj):  # two keys with one string form: one value would be lost
            seen: dict[str, object] = {}
            for k in obj:
                if (key := _json_key(k, _where)) in seen:
                    raise TypeError(f"{_where}: the keys {seen[key]!r} and {k!r} both become {key!r} in JSON")
                seen[key] = k
        return out
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v, _where=f"{_where}[{i}]") for i, v in enumerate(obj)]
    if isinstance(obj, (set, frozenset)):
        return [to_jsonable(v, _where=_where) for v in sorted(obj, key=repr)]
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if callable(getattr(obj, "to_dict", None)):
        return to_jsonable(obj.to_dict(), _where=_where)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return to_jsonable(dataclasses.asdict(obj), _where=_where)
    raise TypeError(f"{_where} has type {type(obj).__name__}, which cannot be written as JSON")


def _json_key(key: Any, where: str) -> str:
    if isinstance(key, np.generic):
        key = key.item()
    if isinstance(key, (str, int, float, bool)) or key is None:
        return key if isinstance(key, str) else json.dumps(key)
    raise TypeError(f"{where} has a key of type {type(key).__name__}; JSON keys must be strings")


def _open_text(path: str | os.PathLike[str], name: str, **kwargs: Any) -> tuple[Path, TextIO]:
    """Open the staged file of ``path`` for writing text, creating missing parent folders."""
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{name} must be a str or os.PathLike, got {type(path).__name__}")
    p = Path(path)
    if p.is_dir():
        raise ValueError(f"{name} is a directory, expected a file path: {p}")
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        return p, open(staged_path(p), "w", encoding="utf-8", **kwargs)
    except OSError as exc:  # named as the user gave it, not as its staged file
        err = OSError(f"cannot write {p}: {exc.strerror or exc}")
        err.errno = exc.errno
        raise err from None


def _close_text(file: TextIO, path: Path, count: int) -> None:
    """Close a staged text file and put it in place when it holds a record."""
    if not file.closed:
        file.close()
        commit_staged(staged_path(path), path, keep=count > 0)


class JsonlWriter(Closing):
    """Write one compact JSON object per line, flushing after every line.

    Parameters
    ----------
    path : str or os.PathLike
        Output file; parent folders are created. An existing file is replaced when the writer
        closes having written a record.

    Attributes
    ----------
    path : pathlib.Path
        The output file.
    count : int
        Lines written so far.

    Examples
    --------
    >>> with JsonlWriter(tmp / "detections.jsonl") as out:  # doctest: +SKIP
    ...     out.write({"frame": 0, "markers": detections})
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path, self._file = _open_text(path, "path", newline="\n")
        self.count = 0

    @property
    def closed(self) -> bool:
        """Whether the file has been closed."""
        return self._file.closed

    def write(self, obj: Mapping[str, Any]) -> None:
        """Append ``obj`` as one JSON line and flush it to the OS.

        Values are converted with :func:`to_jsonable` (numpy types, arrays, ``Pose`` and
        ``MarkerDetection`` objects; NaN and inf become ``null``).

        Parameters
        ----------
        obj : Mapping
            The record, e.g. ``{"frame": 0, "markers": detections}``; keys become strings
            (non-str keys as their JSON text), values as :func:`to_jsonable` converts them.

        Raises
        ------
        TypeError
            If ``obj`` is not a mapping or holds a key or value with no JSON form.
        ValueError
            If the writer is closed.
        """
        if not isinstance(obj, Mapping):
            raise TypeError(f"obj must be a dict, got {type(obj).__name__}")
        if self._file.closed:
            raise ValueError(f"cannot write to closed JsonlWriter({self.path})")
        line = json.dumps(to_jsonable(obj), separators=(",", ":"), allow_nan=False)
        self._file.write(line + "\n")
        self._file.flush()
        self.count += 1

    def close(self) -> None:
        """Close the file and rename it over ``path`` when a record was written, else leave an
        earlier ``path`` untouched (idempotent)."""
        _close_text(self._file, self.path, self.count)


def _csv_value(value: Any) -> Any:
    value = to_jsonable(value, _where="value")
    if value is None:
        return ""
    if isinstance(value, (list, dict)):
        return json.dumps(value, separators=(",", ":"))
    return value


class CsvWriter(Closing):
    """Write rows to a CSV file with a header line, flushing after every row.

    Parameters
    ----------
    path : str or os.PathLike
        Output file; parent folders are created. An existing file is replaced when the writer
        closes having written a record.
    fieldnames : sequence of str
        Column names, in order; the header is written at once.

    Notes
    -----
    Missing fields and ``None`` are written as empty cells, numpy values as plain numbers,
    lists/arrays/dicts as compact JSON text, and NaN as an empty cell.
    """

    def __init__(self, path: str | os.PathLike[str], fieldnames: Sequence[str]) -> None:
        if isinstance(fieldnames, str) or not isinstance(fieldnames, Sequence):
            raise TypeError(
                f"fieldnames must be a sequence of str, got {type(fieldnames).__name__}"
            )
        names = list(fieldnames)
        if not names or not all(isinstance(n, str) for n in names):
            raise ValueError(f"fieldnames must be a non-empty sequence of str, got {names!r}")
        if len(set(names)) != len(names):
            raise ValueError(f"fieldnames must be unique, got {names!r}")
        self.fieldnames = names
        self.path, self._file = _open_text(path, "path", newline="")
        self._writer = csv.DictWriter(self._file, fieldnames=names, restval="")
        self._writer.writeheader()
        self._file.flush()
        self.count = 0

    @property
    def closed(self) -> bool:
        """Whether the file has been closed."""
        return self._file.closed

    def write(self, row: Mapping[str, Any]) -> None:
        """Write one row and flush it.

        Parameters
        ----------
        row : Mapping
            Column name -> value; columns left out are empty cells. Values are converted as
            the class notes say (:func:`to_jsonable`; ``None``, NaN and inf: empty cells; lists,
            arrays and dicts: compact JSON text).

        Raises
        ------
        TypeError
            If ``row`` is not a mapping, or holds a value with no JSON form (nothing is
            written then).
        ValueError
            If ``row`` has keys not in ``fieldnames`` or the writer is closed.
        """
        if not isinstance(row, Mapping):
            raise TypeError(f"row must be a dict, got {type(row).__name__}")
        extra = [k for k in row if k not in self.fieldnames]
        if extra:
            raise ValueError(f"row has fields not in fieldnames: {extra!r}")
        if self._file.closed:
            raise ValueError(f"cannot write to closed CsvWriter({self.path})")
        self._writer.writerow({k: _csv_value(v) for k, v in row.items()})
        self._file.flush()
        self.count += 1

    def close(self) -> None:
        """Close the file and rename it over ``path`` when a record was written, else leave an
        earlier ``path`` untouched (idempotent)."""
        _close_text(self._file, self.path, self.count)


_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


def _frame_stem(name: str) -> str:
    """File stem for a frame name: ``"a/b/img_01.jpg"`` -> ``"img_01"``,
    ``"clip.mp4#12"`` -> ``"clip_000012"``, ``"camera0#3"`` -> ``"camera0_000003"``."""
    base, _, fragment = os.path.basename(name.replace("\\", "/")).partition("#")
    stem = os.path.splitext(base)[0]
    if fragment:
        stem += "_" + (f"{int(fragment):06d}" if fragment.isdigit() else fragment)
    stem = _UNSAFE.sub("_", stem).strip("._")
    return stem or "frame"


#: suffixes of files an annotation folder is not named with (``--annotate out.png`` is a mistake)
_FILE_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".txt", ".csv", ".json",
                            ".jsonl", ".yml", ".yaml", ".rrd", ".mkv", ".mov", ".webm", ".gif"})


class AnnotationSink(Closing):
    """Save annotated frames as a video or as one PNG per frame.

    If ``target`` ends with ``.mp4`` (codec ``mp4v``) or ``.avi`` (``MJPG``) the frames go
    into a video written with ``cv2.VideoWriter``; its size is taken from the first frame and
    later frames of another size are resized to it. Otherwise ``target`` is a folder
    (created if missing) receiving ``<stem>.png`` per frame, the stem taken from the frame's
    name (``"dir/img_07.jpg"`` -> ``img_07.png``, ``"clip.mp4#12"`` -> ``clip_000012.png``);
    a repeated stem gets a ``_1``, ``_2``... suffix instead of overwriting.

    Parameters
    ----------
    target : str or os.PathLike
        Video file or output folder.
    fps : float, default 30
        Frame rate of the video (unused for folders).

    Raises
    ------
    ValueError
        If ``fps`` is not positive, ``target`` is an existing file that is not a video, a
        ``.mp4`` / ``.avi`` target is an existing folder, or a new ``target`` is named as
        another kind of file (``.png``, ``.txt``, ``.mkv``, ...).
    """

    def __init__(self, target: str | os.PathLike[str], *, fps: float = 30.0) -> None:
        if not isinstance(target, (str, os.PathLike)):
            raise TypeError(f"target must be a str or os.PathLike, got {type(target).__name__}")
        if isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating)):
            raise TypeError(f"fps must be a number, got {type(fps).__name__}")
        if not math.isfinite(fps) or fps <= 0:
            raise ValueError(f"fps must be a positive finite number, got {fps!r}")
        self.target = Path(target)
        self.fps = float(fps)
        self.count = 0
        self._writer: cv2.VideoWriter | None = None
        self._size: tuple[int, int] | None = None
        self._used: set[str] = set()
        self._closed = False
        suffix = self.target.suffix.lower()
        self.fourcc: str | None = VIDEO_FOURCC.get(suffix)
        if self.fourcc is not None:
            if self.target.is_dir():  # refused now, not when the finished video is moved there
                raise ValueError(f"target {target} is a folder: give a {suffix} file's path, or the folder without "
                                 f"the {suffix} suffix for image files")
            self.target.parent.mkdir(parents=True, exist_ok=True)
        else:
            if self.target.exists() and not self.target.is_dir():
                raise ValueError(
                    f"target must be a folder or a .mp4/.avi file, got existing file {target}"
                )
            if not self.target.exists() and suffix in _FILE_SUFFIXES:  # a file's name, not a folder's
                raise ValueError(f"target {target} names a {suffix} file: give a folder for PNG files, or a "
                                 ".mp4/.avi file for a video")
            self.target.mkdir(parents=True, exist_ok=True)

    @property
    def is_video(self) -> bool:
        """Whether frames go into a video file (else into a folder of PNGs)."""
        return self.fourcc is not None

    def write(self, image: NDArray[np.uint8], name: str | None = None) -> Path:
        """Add one frame.

        Parameters
        ----------
        image : ndarray (H, W) or (H, W, 3) uint8
            Grey or BGR frame (BGRA accepted, alpha dropped).
        name : str, optional
            Frame name (e.g. :attr:`visloc.types.Frame.name`) giving the PNG file name;
            defaults to the running frame number. Ignored for videos.

        Returns
        -------
        pathlib.Path
            The file written (the video file for videos).

        Raises
        ------
        TypeError, ValueError
            If ``image`` is not a uint8 grey/BGR image.
        ValueError
            If the sink is closed.
        OSError
            If the video writer cannot be opened or a PNG cannot be written.
        """
        if self._closed:
            raise ValueError(f"cannot write to closed AnnotationSink({self.target})")
        img = check_image(image, name="image")
        if img.ndim == 3 and img.shape[2] == 4:
            img = img[:, :, :3]
        elif img.ndim == 3 and img.shape[2] == 1:
            img = img[:, :, 0]
        if self.is_video:
            self._write_video(img)
            self.count += 1
            return self.target
        stem = _frame_stem(name) if name else f"{self.count:06d}"
        unique, k = stem, 0
        while unique in self._used:
            k += 1
            unique = f"{stem}_{k}"
        self._used.add(unique)
        path = self.target / f"{unique}.png"
        if not cv2.imwrite(str(path), img):
            raise OSError(f"cannot write image {path}")
        self.count += 1
        return path

    def _write_video(self, img: NDArray[np.uint8]) -> None:
        if img.ndim == 2:
            img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
        h, w = img.shape[:2]
        if self._writer is None:
            fourcc = cv2.VideoWriter_fourcc(*self.fourcc)  # type: ignore[misc]
            writer = cv2.VideoWriter(str(staged_path(self.target)), fourcc, self.fps, (w, h), True)
            if not writer.isOpened():
                raise OSError(
                    f"cannot open video writer for {self.target} (codec {self.fourcc}, "
                    f"{w}x{h}); try an .avi target (MJPG) or a folder of PNGs"
                )
            self._writer, self._size = writer, (w, h)
        if (w, h) != self._size:
            img = cv2.resize(img, self._size, interpolation=cv2.INTER_AREA)
        self._writer.write(np.ascontiguousarray(img))

    def close(self) -> None:
        """Finish the video and rename it over ``target`` (idempotent); PNGs are written in
        place, one per frame."""
        if self._writer is not None:
            self._writer.release()
            self._writer = None
        if self.is_video and not self._closed:
            commit_staged(staged_path(self.target), self.target, keep=self.count > 0)
        self._closed = True
