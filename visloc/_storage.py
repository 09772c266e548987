"""Opening OpenCV FileStorage files (camera, map, board and dictionary files) with one clear
error for a missing, empty or malformed file."""

from __future__ import annotations

import re
from pathlib import Path

import cv2


def cv_message(exc: BaseException) -> str:
    """The useful part of an OpenCV error message (its text after the source location).

    Parameters
    ----------
    exc : BaseException
        A ``cv2.error`` (or the ``SystemError`` the binding wraps one in).

    Returns
    -------
    str
        The message, or ``"parse error"`` when it has no text.
    """
    cause = exc.__cause__ if isinstance(exc, SystemError) and exc.__cause__ else exc
    text = " ".join(str(cause).split())
    m = re.search(r"error: \([-\d]+:[^)]*\) (.*)$", text)
    return m.group(1) if m else (text or "parse error")


def open_storage(path: str | Path, what: str) -> cv2.FileStorage:
    """Open ``path`` for reading with ``cv2.FileStorage``.

    Parameters
    ----------
    path : str or Path
        The file (YAML, XML or JSON).
    what : str
        What the file is, for the messages (``"camera file"``, ``"marker map"``, ...).

    Returns
    -------
    cv2.FileStorage
        Open for reading; the caller releases it.

    Raises
    ------
    ValueError
        ``"<what> <path> does not exist"``, ``"... is empty"``, or ``"... is not OpenCV
        FileStorage: <OpenCV's reason>"`` (garbage, binary or malformed text: OpenCV's parser
        raises, and its Python binding wraps that in a ``SystemError``).
    """
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{what} {str(p)!r} does not exist")
    if p.stat().st_size == 0:
        raise ValueError(f"{what} {str(p)!r} is empty")
    try:
        fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:
        raise ValueError(f"{what} {str(p)!r} is not OpenCV FileStorage: {cv_message(exc)}") from None
    if not fs.isOpened():
        raise ValueError(f"{what} {str(p)!r} is not OpenCV FileStorage: it could not be opened")
    return fs
