"""Marker dictionaries: bit patterns, loading, drawing and matching (pipeline stage 10).

A dictionary is a set of ``n`` square bit patterns of ``s x s`` cells (1 = white), each
surrounded on the printed marker by a black border one cell wide. Patterns are read from
OpenCV's predefined dictionaries (``cv2.aruco.getPredefinedDictionary``) or from an OpenCV
dictionary YAML file (``nmarkers``, ``markersize``, ``marker_<i>`` bit strings, row-major).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc._checks import check_int
from visloc._storage import open_storage

#: OpenCV predefined dictionary names visloc accepts (case-insensitive for the family tag).
PREDEFINED = tuple(
    sorted({n for n in dir(cv2.aruco) if n.startswith("DICT_") and not n.endswith(("H5", "H9", "H10", "H11", "H12"))})
)


@dataclass(frozen=True, eq=False)
class Dictionary:
    """A marker dictionary.

    Attributes
    ----------
    name : str
        Predefined name or file path it came from.
    bits : ndarray (n, s, s) uint8
        Bit pattern of every marker (1 = white cell), row 0 at the marker's top; read-only
        (a loaded dictionary is shared by every caller that loads it).
    max_correction : int
        Bits the dictionary can correct by design: ``(d_min - 1) // 2`` where ``d_min`` is the
        smallest Hamming distance between two markers in any rotation (OpenCV's
        ``maxCorrectionBits``).
    codes : ndarray (n, 4) uint64
        Packed bits of each marker rotated by ``r`` quarter turns counter-clockwise
        (``np.rot90(bits, r)``), for matching; read-only.
    """

    name: str
    bits: NDArray[np.uint8]
    max_correction: int
    codes: NDArray[np.uint64]

    @property
    def marker_size(self) -> int:
        """Cells per side of the bit pattern, without the border."""
        return int(self.bits.shape[1])

    @property
    def white_range(self) -> tuple[int, int]:
        """Fewest and most white bits of any marker: a bit grid outside this range, widened by
        the bits the match may correct, cannot match."""
        w = self.bits.reshape(len(self), -1).sum(axis=1)
        return int(w.min()), int(w.max())

    def __len__(self) -> int:
        return int(self.bits.shape[0])

    def marker_image(self, marker_id: int, *, cell_px: int = 10, border_bits: int = 1) -> NDArray[np.uint8]:
        """Draw marker ``marker_id`` as a uint8 image, black border included, no white margin.

        The image is ``(s + 2 * border_bits) * cell_px`` pixels square, 0 = black, 255 = white.

        Parameters
        ----------
        marker_id : int
            Index of the marker in the dictionary, ``0 <= marker_id < len(self)``.
        cell_px : int
            Side of one cell (bit), px, >= 1.
        border_bits : int
            Width of the black border, cells (>= 0; 1 is the ArUco default).

        Returns
        -------
        ndarray (S, S) uint8
            The marker, ``S = (s + 2 * border_bits) * cell_px`` px, row 0 at the marker's
            top (``bits[marker_id]`` unrotated).

        Raises
        ------
        TypeError
            If ``marker_id``, ``cell_px`` or ``border_bits`` is not an integer (a bool is not).
        ValueError
            If ``marker_id`` is not in ``[0, len(self) - 1]``, ``cell_px`` < 1 or
            ``border_bits`` < 0.
        """
        check_int(marker_id, "marker_id", low=0, high=len(self) - 1)
        check_int(cell_px, "cell_px", low=1)
        check_int(border_bits, "border_bits", low=0)
        grid = np.pad(self.bits[marker_id], border_bits).astype(np.uint8) * 255
        return np.kron(grid, np.ones((cell_px, cell_px), np.uint8))

    def match(self, bits: NDArray[np.uint8], max_errors: int) -> tuple[int, int, int] | None:
        """Find the marker closest to an observed ``(s, s)`` bit grid.

        Every marker is compared in its four rotations (Hamming distance of the packed
        :attr:`codes`); of equally close ones the lowest id, then the lowest rotation, wins.

        Parameters
        ----------
        bits : ndarray (s, s)
            The observed cells without the border, 0/1 (1 = white), laid out as :attr:`bits`
            holds a marker's.
        max_errors : int
            Most flipped bits accepted.

        Returns
        -------
        tuple of (int, int, int) or None
            ``(id, rotation, hamming)`` where the observed grid equals
            ``np.rot90(self.bits[id], rotation)`` (``rotation`` quarter turns counter-clockwise,
            0-3) up to ``hamming`` flipped bits, or ``None`` when no marker is within
            ``max_errors`` bits.

        Raises
        ------
        ValueError
            If ``bits`` is not ``(s, s)`` or holds values other than 0 and 1.
        """
        s = self.marker_size
        if np.shape(bits) != (s, s):
            raise ValueError(f"bits must be ({s}, {s}) for this dictionary, got shape {np.shape(bits)}")
        code = pack_bits(bits)
        dist = np.bitwise_count(self.codes ^ code)
        flat = int(np.argmin(dist))
        i, r = divmod(flat, 4)
        h = int(dist[i, r])
        if h > max_errors:
            return None
        return i, r, h


def pack_bits(bits: NDArray) -> np.uint64:
    """Pack a grid of 0/1 values into one uint64.

    Parameters
    ----------
    bits : ndarray (s, s) or any shape
        0/1 values (or bools), at most 64 of them, read row-major.

    Returns
    -------
    numpy.uint64
        Value ``i`` (row-major) in bit ``i``, least significant first (as :class:`Dictionary`
        packs its ``codes``).

    Raises
    ------
    ValueError
        If ``bits`` holds more than 64 values or values other than 0 and 1.
    """
    b = np.asarray(bits)
    if b.size > 64:
        raise ValueError(f"bits: a uint64 packs at most 64 values, got {b.size}")
    _check_binary(b, "bits")
    flat = b.astype(np.uint64).ravel()
    weights = np.left_shift(np.uint64(1), np.arange(flat.size, dtype=np.uint64))
    return np.uint64(np.sum(flat * weights, dtype=np.uint64))


def _check_binary(b: NDArray, name: str) -> None:
    """Raise a ValueError naming ``name`` unless every value of ``b`` is 0 or 1: one
    vectorised look (the maximum of unsigned integers, none for bools)."""
    kind = b.dtype.kind
    if kind == "b" or not b.size or (b.max() <= 1 if kind == "u" else ((b == 0) | (b == 1)).all()):
        return
    bad = b[(b != 0) & (b != 1)].flat[0]
    raise ValueError(f"{name} must hold only 0 and 1, got {bad}")


def _build(name: str, bits: NDArray[np.uint8], max_correction: int | None, *, check: bool = False) -> Dictionary:
    """A :class:`Dictionary` from bit patterns (n, s, s). ``max_correction`` ``None``: the
    design capacity ``(d_min - 1) // 2``; ``check``: a given value must not exceed it (a file's
    ``maxCorrectionBits``: more would match texture and other markers' codes to an id)."""
    n, s, _ = bits.shape
    if s * s > 64:
        raise ValueError(f"markers of {s}x{s} bits are not supported (at most 8x8)")
    weights = np.left_shift(np.uint64(1), np.arange(s * s, dtype=np.uint64))
    codes = np.empty((n, 4), np.uint64)
    for r in range(4):
        rot = np.rot90(bits, r, axes=(1, 2)).reshape(n, -1).astype(np.uint64)
        codes[:, r] = np.sum(rot * weights, axis=1, dtype=np.uint64)
    capacity = (_min_distance(codes) - 1) // 2
    if max_correction is None:
        max_correction = capacity
    elif check and max_correction > capacity:
        raise ValueError(f"dictionary {name!r}: maxCorrectionBits {max_correction} exceeds what its markers allow "
                         f"({max(capacity, 0)}: their smallest distance in any rotation, less one, halved)")
    bits.setflags(write=False)  # shared: _predefined hands the same Dictionary to every caller
    codes.setflags(write=False)
    return Dictionary(name, bits, int(max(max_correction, 0)), codes)


def _min_distance(codes: NDArray[np.uint64]) -> int:
    """Smallest Hamming distance between rotation 0 of a marker and any rotation of any
    other marker, or a non-trivial rotation of itself (for one marker: its rotations only, so
    a rotation-symmetric pattern has distance 0)."""
    base = codes[:, :1]
    d_other = np.bitwise_count(base[:, None, :] ^ codes[None, :, :])  # (n, n, 4)
    n = codes.shape[0]
    d_other[np.arange(n), np.arange(n), 0] = 255
    return int(d_other.min())


@lru_cache(maxsize=32)
def _predefined(name: str) -> Dictionary:
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))
    s = int(d.markerSize)
    n = d.bytesList.shape[0]
    bits = np.stack(
        [cv2.aruco.Dictionary.getBitsFromByteList(d.bytesList[i : i + 1], s) for i in range(n)]
    ).astype(np.uint8)
    return _build(name, bits, int(d.maxCorrectionBits))


def _from_yaml(path: str) -> Dictionary:
    fs = open_storage(path, "dictionary file")
    try:
        n = fs.getNode("nmarkers")
        s = fs.getNode("markersize")
        if n.empty() or s.empty():
            raise ValueError(f"dictionary file {path!r} lacks 'nmarkers' or 'markersize'")
        n, s = int(n.real()), int(s.real())
        if n < 1 or s < 2:
            raise ValueError(f"dictionary file {path!r}: nmarkers={n}, markersize={s} are not valid")
        bits = np.zeros((n, s, s), np.uint8)
        for i in range(n):
            text = fs.getNode(f"marker_{i}").string()
            if text is None or len(text) != s * s or set(text) - {"0", "1"}:
                raise ValueError(f"dictionary file {path!r}: marker_{i} is not a string of {s * s} bits")
            bits[i] = np.frombuffer(text.encode(), np.uint8).reshape(s, s) - ord("0")
        mc = fs.getNode("maxCorrectionBits")
        max_corr = None if mc.empty() or int(mc.real()) <= 0 else int(mc.real())
    finally:
        fs.release()
    return _build(path, bits, max_corr, check=True)


def load_dictionary(spec: str | Dictionary) -> Dictionary:
    """Load a dictionary by OpenCV predefined name or from an OpenCV dictionary YAML file.

    Parameters
    ----------
    spec : str or Dictionary
        The path of an existing OpenCV dictionary YAML file, or an OpenCV predefined name
        (``"DICT_4X4_50"``, ``"DICT_APRILTAG_36h11"``, ``"DICT_ARUCO_ORIGINAL"``, ...; case and
        the ``DICT_`` prefix optional). A :class:`Dictionary` is returned as it is.

    Returns
    -------
    Dictionary

    Raises
    ------
    TypeError
        If ``spec`` is neither a str nor a Dictionary.
    ValueError
        Unknown name, missing file, or a malformed file.
    """
    if isinstance(spec, Dictionary):
        return spec
    if not isinstance(spec, str):
        raise TypeError(f"dictionary must be a name or a path, got {type(spec).__name__}")
    if os.path.isfile(spec):
        return _from_yaml(spec)
    key = spec.strip()
    if not key.upper().startswith("DICT_"):
        key = "DICT_" + key
    candidates = {n.upper(): n for n in dir(cv2.aruco) if n.startswith("DICT_")}
    if key.upper() in candidates:
        return _predefined(candidates[key.upper()])
    raise ValueError(
        f"unknown dictionary {spec!r}: not a file and not one of {', '.join(PREDEFINED)}"
    )
