"""Which frames of an AVI file are damaged beyond reading, from the file's own index.

An AVI's ``idx1`` chunk lists every frame's chunk (its four-character id, its offset and its
size). A frame whose chunk header no longer matches its index entry (corrupt or zeroed bytes)
cannot be found by a demuxer: OpenCV 5.0's FFmpeg backend failed the read of such a frame,
OpenCV 5.1's skips it without a word and numbers the frames after it one earlier (their
``CAP_PROP_POS_MSEC`` too). :class:`visloc.io.VideoSource` asks this module which frames those
are, so that it can record each at its own index and keep the frames after in their places.
"""

from __future__ import annotations

import os
import struct

import numpy as np

__all__ = ["avi_unreadable_frames"]

_ENTRY = np.dtype([("id", "S4"), ("flags", "<u4"), ("offset", "<u4"), ("size", "<u4")])


def _chunks(data: np.memmap) -> tuple[int | None, tuple[int, int] | None]:
    """The position of the ``movi`` list's type tag and the ``idx1`` chunk's (start, size) in
    the first RIFF of an AVI file; None for what is not there."""
    movi = idx1 = None
    pos, end = 12, len(data)
    while pos + 8 <= end:
        cid, size, kind = struct.unpack("<4sI4s", data[pos : pos + 12].tobytes().ljust(12, b"\0"))
        if cid == b"LIST" and kind == b"movi":
            movi = pos + 8
        elif cid == b"idx1":
            idx1 = pos + 8, min(size, end - pos - 8)
        pos += 8 + size + (size & 1)
    return movi, idx1


def avi_unreadable_frames(path: str | os.PathLike[str]) -> frozenset[int] | None:
    """The indices of an AVI's video frames whose chunks do not lie where the file's index says.

    Parameters
    ----------
    path : str or os.PathLike
        A video file.

    Returns
    -------
    frozenset of int or None
        Frame indices (0-based, in the order of the index) of the first video stream whose chunk
        header (id and size) differs from its ``idx1`` entry; None when the file is not an AVI or
        has no usable ``idx1`` index (a truncated file loses it: it is written last).
    """
    try:
        raw = np.memmap(path, np.uint8, mode="r")  # unmapped when the last view goes
    except (OSError, ValueError):  # unreadable, or empty (nothing to map)
        return None
    if len(raw) < 12 or raw[:4].tobytes() != b"RIFF" or raw[8:12].tobytes() != b"AVI ":
        return None
    movi, idx1 = _chunks(raw)
    if movi is None or idx1 is None:
        return None
    start, size = idx1
    entries = np.frombuffer(raw[start : start + size // 16 * 16].tobytes(), _ENTRY)
    video = np.char.endswith(entries["id"], b"dc") | np.char.endswith(entries["id"], b"db")
    if not video.any():
        return None
    stream = entries["id"][np.argmax(video)][:2]  # the first video stream's number
    entries = entries[video & np.char.startswith(entries["id"], stream)]
    best = None
    for base in (movi, 0):  # offsets count from the 'movi' tag (usual) or from the file's start
        at = entries["offset"].astype(np.int64) + base
        inside = at + 8 <= len(raw)
        heads = np.zeros((len(at), 8), np.uint8)
        heads[inside] = raw[at[inside, None] + np.arange(8)]
        ok = inside & (heads[:, :4].copy().view("S4")[:, 0] == entries["id"])
        ok &= heads[:, 4:].copy().view("<u4")[:, 0] == entries["size"]
        if best is None or ok.sum() > best.sum():
            best = ok
    return frozenset(int(k) for k in np.flatnonzero(~best))
