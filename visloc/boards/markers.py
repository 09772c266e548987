"""visloc's own marker maps as calibration boards (issue 17): a printed :class:`GridMap` (or any
planar marker map) whose markers' four corners are the calibration points.

A marker map file (``visloc render map`` prints one to scale) serves as ``visloc calibrate
--board``: each detected marker of the map gives four points, numbered ``4 k + c`` for the
``k``-th marker of the map and its corner ``c`` (OpenCV's order), at their map positions.
The detector's corners are sub-pixel edge fits (the markers' stage 8), so no saddle fit is
needed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from visloc.boards.charuco import CharucoCorners
from visloc.markers import MarkerDetector
from visloc.pose.maps import MarkerMap
from visloc.types import FloatArray

__all__ = ["MarkerBoard", "detect_marker_board"]


class MarkerBoard:
    """A planar marker map used as a calibration board.

    Parameters
    ----------
    marker_map : MarkerMap
        The markers; every corner must lie in the map's ``z = 0`` plane.
    dictionary : str
        Their dictionary (default: the one the map records, else ``DICT_4X4_50``).

    Attributes
    ----------
    chessboard_corners : ndarray (4 M, 3) float64
        The calibration points: marker ``k``'s corner ``c`` is row ``4 k + c`` (the name is
        :class:`CharucoBoard`'s, so that :func:`visloc.boards.calibrate` takes either board).
    ids : ndarray (M,) int64
        The map's marker ids, in its order.
    """

    def __init__(self, marker_map: MarkerMap, dictionary: str | None = None) -> None:
        if not isinstance(marker_map, MarkerMap):
            raise TypeError(f"marker_map: expected a MarkerMap, got {type(marker_map).__name__}")
        self.marker_map = marker_map
        self.ids = np.asarray(marker_map.ids, np.int64)
        pts = np.concatenate([marker_map.corners_of(int(i)) for i in self.ids]).astype(np.float64)
        if np.abs(pts[:, 2]).max() > 1e-9:
            raise ValueError("a calibration board's markers must all lie in the map's z = 0 plane")
        self.chessboard_corners: FloatArray = pts
        self.dictionary = dictionary or getattr(marker_map, "dictionary", None) or "DICT_4X4_50"
        self._row = {int(i): k for k, i in enumerate(self.ids)}

    @classmethod
    def from_file(cls, path: str | Path, dictionary: str | None = None) -> MarkerBoard:
        """A marker map file (``MarkerMap.to_file``) as a board.

        Parameters
        ----------
        path : str or Path
            The marker map file (OpenCV FileStorage YAML), corners in the map frame (m by
            convention).
        dictionary : str, optional
            The markers' dictionary (default: the one the file records, else ``DICT_4X4_50``).

        Returns
        -------
        MarkerBoard

        Raises
        ------
        ValueError
            As :meth:`visloc.pose.maps.MarkerMap.from_file`, or markers off the z = 0 plane.
        """
        return cls(MarkerMap.from_file(path), dictionary)

    def row(self, marker_id: int) -> int | None:
        """The marker's position in the map (its points are rows ``4 row .. 4 row + 3``), or None.

        Parameters
        ----------
        marker_id : int
            A marker id.

        Returns
        -------
        int or None
            Its index ``k`` in :attr:`ids` (the map's order), so its corners are rows
            ``4 k .. 4 k + 3`` of ``chessboard_corners``; None when the map has no such marker.
        """
        return self._row.get(int(marker_id))


def detect_marker_board(image: NDArray, board: MarkerBoard, *, detector: MarkerDetector | None = None,
                        response: str | float = "srgb") -> CharucoCorners:
    """The board's points found in one image: the four corners of each of its markers detected.

    Parameters
    ----------
    image : ndarray (H, W) or (H, W, 3) uint8
        The view.
    board : MarkerBoard
        The board.
    detector : MarkerDetector, optional
        Default: one for the board's dictionary with ``response``.
    response : str or float
        How the image's grey levels encode light (:class:`visloc.markers.MarkerDetector`).

    Returns
    -------
    CharucoCorners
        ``ids`` the points' numbers (ascending), ``corners`` their image positions, and the
        markers found.
    """
    det = detector or MarkerDetector(board.dictionary, response=response)
    found = [(board.row(d.id), d) for d in det.detect(image)]
    found = sorted(((k, d) for k, d in found if k is not None), key=lambda kd: kd[0])
    if not found:
        return CharucoCorners(np.zeros(0, np.int64), np.zeros((0, 2)))
    ids = np.concatenate([4 * k + np.arange(4) for k, _ in found]).astype(np.int64)
    corners = np.concatenate([d.corners for _, d in found]).astype(np.float64)
    return CharucoCorners(ids, corners, np.array([d.id for _, d in found], np.int64),
                          np.array([d.corners for _, d in found], np.float64))
