"""Marker maps: marker id -> the 3-D corners of that marker in a map (world) frame.

Corners are in OpenCV order: the marker's own top-left, top-right, bottom-right, bottom-left.
A map is saved as OpenCV FileStorage YAML::

    %YAML:1.0
    markers:
       - { id: 0, corners: [ x0, y0, z0, x1, y1, z1, x2, y2, z2, x3, y3, z3 ] }
       ...
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from visloc._checks import marker_id
from visloc._storage import open_storage
from visloc.types import Pose

__all__ = ["GridMap", "MarkerMap"]

FloatArray = NDArray[np.float64]


def _marker_frame(corners: FloatArray) -> tuple[Pose, float]:
    """The marker's own frame in the map (origin at the centre, x right, y up, z out of the
    face) as ``T_map_marker``, and its side length; checks the corners form a square."""
    c = corners
    side = np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1)
    diag = np.linalg.norm(c[[2, 3]] - c[[0, 1]], axis=1)
    L = float(side.mean())
    if L <= 0 or np.abs(side - L).max() > 1e-3 * L + 1e-9 or np.abs(diag - L * np.sqrt(2)).max() > 1e-3 * L + 1e-9:
        raise ValueError("not a square")
    x = c[1] - c[0]
    y = c[0] - c[3]
    z = np.cross(x, y)
    R = np.stack([x / np.linalg.norm(x), y / np.linalg.norm(y), z / np.linalg.norm(z)], axis=1)
    u, _, vt = np.linalg.svd(R)  # nearest rotation (the square is not exactly orthogonal)
    R = u @ vt
    if np.linalg.det(R) < 0 or np.abs(c.mean(axis=0) @ R[:, 2] - c @ R[:, 2]).max() > 1e-3 * L + 1e-9:
        raise ValueError("not planar")
    return Pose(R, c.mean(axis=0)), L


@dataclass(frozen=True, eq=False)
class MarkerMap:
    """Markers at known places: id -> (4, 3) corners in the map frame.

    Parameters
    ----------
    corners : dict of int -> array_like (4, 3)
        Each marker's corners in OpenCV order (its own top-left, top-right, bottom-right,
        bottom-left), metres. They must form a planar square. The map keeps read-only copies.
    dictionary : str or None
        The marker dictionary the map's ids belong to (an OpenCV name such as
        ``"DICT_4X4_100"``), saved with the map; ``None``: not recorded.

    Raises
    ------
    ValueError
        Duplicate ids (when built from a list), an id with a fraction, corners that are not
        finite, not (4, 3), not a square or not planar.
    TypeError
        An id that is not a number (or is a bool).
    """

    corners: dict[int, FloatArray]
    dictionary: str | None = None
    _frames: dict[int, Pose] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        if self.dictionary is not None and (not isinstance(self.dictionary, str) or not self.dictionary.strip()):
            raise ValueError(f"dictionary must be a name or None, got {self.dictionary!r}")
        clean: dict[int, FloatArray] = {}
        for k, v in dict(self.corners).items():
            k = marker_id(k, "corners")
            arr = np.array(v, dtype=np.float64)  # a copy: the caller's array stays theirs
            arr.setflags(write=False)
            if arr.shape != (4, 3):
                raise ValueError(f"marker {k}: corners must be (4, 3), got shape {arr.shape}")
            if not np.isfinite(arr).all():
                raise ValueError(f"marker {k}: corners must be finite, got {arr.tolist()}")
            try:
                frame, _ = _marker_frame(arr)
            except ValueError as exc:
                raise ValueError(f"marker {k}: its corners are {exc} (within 0.1 % of the side)") from None
            clean[k] = arr
            self._frames[k] = frame
        object.__setattr__(self, "corners", clean)

    @classmethod
    def from_list(cls, markers: list[tuple[int, ArrayLike]], dictionary: str | None = None) -> MarkerMap:
        """A map from ``[(id, corners (4, 3)), ...]``; duplicate ids raise ValueError.

        Parameters
        ----------
        markers : list of (int, array_like (4, 3))
            Each marker's id and corners in OpenCV order (its own top-left, top-right,
            bottom-right, bottom-left), m, map frame; they must form a planar square.
        dictionary : str or None
            The markers' dictionary name, recorded with the map (as :class:`MarkerMap`).

        Returns
        -------
        MarkerMap

        Raises
        ------
        ValueError
            Duplicate ids, or what :class:`MarkerMap` rejects: an id with a fraction, corners
            that are not finite, not (4, 3), not a square or not planar, a ``dictionary``
            neither None nor a non-empty str.
        TypeError
            An id that is not a number.
        """
        ids = [marker_id(i, "markers") for i, _ in markers]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"duplicate marker ids in the map: {dup}")
        return cls(dict(zip(ids, (c for _, c in markers), strict=True)), dictionary)

    @cached_property
    def stacked(self) -> tuple[NDArray[np.int64], FloatArray]:
        """``(ids (M,), corners (M, 4, 3))``: every marker at once, ids sorted (built once)."""
        ids = self.ids
        corners = np.stack([self.corners[int(i)] for i in ids]) if len(ids) else np.zeros((0, 4, 3))
        corners.setflags(write=False)
        ids.setflags(write=False)
        return ids, corners

    @property
    def ids(self) -> NDArray[np.int64]:
        """Marker ids, sorted."""
        return np.array(sorted(self.corners), dtype=np.int64)

    def __contains__(self, marker_id: object) -> bool:
        return marker_id in self.corners

    def __len__(self) -> int:
        return len(self.corners)

    def corners_of(self, marker_id: int) -> FloatArray:
        """(4, 3) corners of ``marker_id`` in the map frame; KeyError if it is not in the map.

        Parameters
        ----------
        marker_id : int
            The marker's id.

        Returns
        -------
        ndarray (4, 3) float64
            Its corners in OpenCV order (its own top-left, top-right, bottom-right,
            bottom-left), m, map frame; the map's stored array (read-only).

        Raises
        ------
        KeyError
            If ``marker_id`` is not in the map (an id with a fraction never is).
        """
        return self.corners[_map_key(marker_id)]

    def marker_pose(self, marker_id: int) -> Pose:
        """``T_map_marker``: the marker's own frame (centre, x right, y up, z out) in the map.

        Parameters
        ----------
        marker_id : int
            Which marker.

        Returns
        -------
        Pose
            ``T_map_marker``: ``p_map = R @ p_marker + t``; ``R``'s columns are the marker's
            axes in map coordinates (the nearest rotation to its corners' edges), ``t`` its
            centre (the corners' mean), m, map frame.

        Raises
        ------
        KeyError
            If ``marker_id`` is not in the map (an id with a fraction never is).
        """
        return self._frames[_map_key(marker_id)]

    def to_file(self, path: str | Path) -> None:
        """Save as OpenCV FileStorage YAML (see the module docstring).

        Markers are written in id order, with the ``dictionary`` name when it is recorded;
        :meth:`from_file` reads the file back.

        Parameters
        ----------
        path : str or Path
            The file to write (replaced if it exists; its folder must exist).

        Raises
        ------
        ValueError
            If the map has no markers (:meth:`from_file` refuses such a file).
        OSError
            If the file cannot be written; the message names it.
        """
        if not self.corners:
            raise ValueError(f"cannot save an empty marker map to {path}: it has no markers")
        lines = ["%YAML:1.0"] + ([f'dictionary: "{self.dictionary}"'] if self.dictionary else []) + ["markers:"]
        for i in self.ids:
            nums = ", ".join(repr(float(v)) for v in self.corners[int(i)].ravel())
            lines.append(f"   - {{ id: {int(i)}, corners: [ {nums} ] }}")
        try:
            Path(path).write_text("\n".join(lines) + "\n")
        except OSError as exc:
            raise OSError(f"cannot write marker map {path}: {exc.strerror}") from None

    @classmethod
    def from_file(cls, path: str | Path) -> MarkerMap:
        """Load a map saved by :meth:`to_file` (or written by hand in that format).

        Parameters
        ----------
        path : str or Path
            The map file (OpenCV FileStorage: a ``markers`` list of ``{id, corners}`` entries,
            12 corner numbers each, m; an optional ``dictionary`` name).

        Returns
        -------
        MarkerMap
            The markers, corners in the map frame, m, and the recorded dictionary (None when
            the file names none).

        Raises
        ------
        ValueError
            A missing, empty or unreadable file, no ``markers`` list or an empty one, an entry
            without ``id`` and 12 corner numbers, an id that is not a whole number, duplicate
            ids, or corners that are not a planar square.
        """
        p = Path(path)
        fs = open_storage(p, "marker map")
        try:
            node = fs.getNode("markers")
            if node.empty() or not node.isSeq():
                raise ValueError(f"marker map {p} has no 'markers' list")
            if node.size() == 0:
                raise ValueError(f"marker map {p} has no markers")
            dn = fs.getNode("dictionary")
            dictionary = None if dn.empty() else (dn.string() or None)
            items = []
            for k in range(node.size()):
                entry = node.at(k)
                mid, cn = entry.getNode("id"), entry.getNode("corners")
                if mid.empty() or cn.empty():
                    raise ValueError(f"marker map {p}: entry {k} needs 'id' and 'corners'")
                vals = cn.mat() if cn.isMap() else np.array([cn.at(j).real() for j in range(cn.size())])
                if vals is None or np.size(vals) != 12:
                    raise ValueError(f"marker map {p}: entry {k} must have 12 corner numbers")
                items.append((marker_id(mid.real(), f"marker map {p}: entry {k}"), np.asarray(vals, float).reshape(4, 3)))
        finally:
            fs.release()
        return cls.from_list(items, dictionary)


def _map_key(value: object) -> int:
    """A map's key for the id ``value``; KeyError for what no map holds (a fraction, a bool,
    not a number), as for an id the map lacks."""
    try:
        return marker_id(value, "marker_id")
    except (TypeError, ValueError):
        raise KeyError(value) from None


def GridMap(rows: int, cols: int, marker_length: float, spacing: float, *, first_id: int = 0,
            dictionary: str | None = None) -> MarkerMap:
    """A ``rows x cols`` grid of square markers in the map's z = 0 plane.

    Ids run row by row from ``first_id`` (left to right, top to bottom). The map frame has its
    origin at the top-left corner of the first marker, x to the right along a row, y up (so
    the rows lie at negative y) and z out of the printed face, like a marker's own frame.
    Marker (r, c) has its top-left corner at ``(c (L + s), -r (L + s), 0)``.

    Parameters
    ----------
    rows, cols : int
        Grid size (>= 1).
    marker_length : float
        Side of each marker's black square, m (> 0).
    spacing : float
        Gap between neighbouring markers, m (>= 0).
    first_id : int
        Id of the top-left marker (>= 0).
    dictionary : str, optional
        The markers' dictionary, recorded with the map (:class:`MarkerMap`).

    Returns
    -------
    MarkerMap
        ``rows * cols`` markers with ids ``first_id`` to ``first_id + rows * cols - 1``,
        corners in the map frame above, m.

    Raises
    ------
    ValueError
        ``rows`` or ``cols`` not an integer >= 1, ``marker_length`` not finite and > 0,
        ``spacing`` not finite and >= 0, ``first_id`` < 0 or with a fraction, or ``dictionary`` neither None nor a
        non-empty str.
    """
    for name, v in (("rows", rows), ("cols", cols)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
    if not (0 < float(marker_length) < float("inf")):
        raise ValueError(f"marker_length must be positive and finite, got {marker_length!r}")
    if not (0 <= float(spacing) < float("inf")):
        raise ValueError(f"spacing must be >= 0 and finite, got {spacing!r}")
    first_id = marker_id(first_id, "first_id")
    if first_id < 0:
        raise ValueError(f"first_id must be >= 0, got {first_id!r}")
    L, pitch = float(marker_length), float(marker_length) + float(spacing)
    square = np.array([[0, 0, 0], [L, 0, 0], [L, -L, 0], [0, -L, 0]], dtype=np.float64)
    markers = {}
    for r in range(rows):
        for c in range(cols):
            markers[int(first_id) + r * cols + c] = square + (c * pitch, -r * pitch, 0.0)
    return MarkerMap(markers, dictionary)
