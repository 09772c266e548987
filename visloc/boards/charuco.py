"""ChArUco boards: geometry, board files, and their chessboard corners in images.

A ChArUco board (OpenCV's ``cv2.aruco.CharucoBoard``) is a chessboard of ``squares_x`` x
``squares_y`` squares of side ``square_length`` whose white squares each hold a marker of side
``marker_length``, ids ``first_id, first_id + 1, ...`` in OpenCV's order. Its calibration points
are the chessboard's inner corners, ``(squares_x - 1) (squares_y - 1)`` of them, numbered row by
row from the top-left as OpenCV numbers them.

Board frame (OpenCV's): origin at the board's top-left corner, x to the right along the first
row of squares, y down the board, z into it (away from a camera that sees the printed face);
units are those of the lengths (metres by convention). The geometry is taken from OpenCV's own
board object, so a board printed by either tool is the same board (the ``legacy`` flag selects
OpenCV's pre-4.6 pattern for boards with an even number of rows).

:func:`detect_charuco` finds a board's corners in an image: visloc's marker detector finds the
markers; each chessboard corner is predicted by the homography of the markers in the two white
squares that touch it (one suffices); then the black squares' edges are located in linear light
(the grey levels read through the camera's response, sRGB by default, as the marker detector's
stage 8 reads them) and each corner is where the board's two lines through it cross, each line
fitted to the edges of both black squares that meet there (``method="edges"``, the default), or
the saddle point of a quadratic fitted to the light around it (:func:`refine_saddles`).
"""

from __future__ import annotations

import math
from dataclasses import KW_ONLY, dataclass, field
from functools import cached_property
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc._storage import open_storage
from visloc.markers.binarize import to_gray
from visloc.markers.detector import MarkerDetector
from visloc.markers.dictionary import load_dictionary
from visloc.markers.refine import edge_points, refine_quads
from visloc.markers.response import response_lut

__all__ = ["CharucoBoard", "CharucoCorners", "detect_charuco", "refine_saddles"]

FloatArray = NDArray[np.float64]

#: ``board_type`` of a ChArUco board file
BOARD_TYPE = "charuco"


@dataclass(frozen=True)
class CharucoBoard:
    """A ChArUco board (module docstring).

    Attributes
    ----------
    squares_x, squares_y : int
        Squares along a row (x) and a column (y), each >= 2.
    square_length, marker_length : float
        Side of a chessboard square and of a marker (black border included), m; the marker is
        smaller than the square.
    dictionary : str
        OpenCV predefined dictionary name (e.g. ``"DICT_6X6_250"``).
    first_id : int
        Id of the first marker; the board uses ``first_id .. first_id + markers - 1``.
    legacy : bool
        OpenCV's legacy pattern (``setLegacyPattern``): boards made before OpenCV 4.6 with an even
        number of rows.
    """

    squares_x: int
    squares_y: int
    square_length: float
    marker_length: float
    dictionary: str = "DICT_6X6_250"
    _: KW_ONLY
    first_id: int = 0
    legacy: bool = False

    def __post_init__(self) -> None:
        for name in ("squares_x", "squares_y"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 2 <= v <= 1000:
                raise ValueError(f"board: {name} must be an integer in [2, 1000], got {v!r}")
        for name in ("square_length", "marker_length"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.number)) or not (np.isfinite(v) and v > 0):
                raise ValueError(f"board: {name} must be a finite number > 0, got {v!r}")
        if not self.marker_length < self.square_length:
            raise ValueError(f"board: marker_length ({self.marker_length}) must be less than square_length "
                             f"({self.square_length})")
        if not isinstance(self.dictionary, str) or not hasattr(cv2.aruco, self.dictionary):
            raise ValueError(f"board: dictionary must be an OpenCV predefined dictionary name, got {self.dictionary!r}")
        n = len(load_dictionary(self.dictionary))
        if isinstance(self.first_id, bool) or not isinstance(self.first_id, (int, np.integer)) or not (
                0 <= self.first_id and self.first_id + self.n_markers <= n):
            raise ValueError(f"board: first_id must leave room for {self.n_markers} markers in {self.dictionary} "
                             f"({n} ids), got {self.first_id!r}")
        if not isinstance(self.legacy, bool):
            raise TypeError(f"board: legacy must be true or false, got {self.legacy!r}")

    @property
    def n_markers(self) -> int:
        """Markers on the board (one per white square)."""
        return (self.squares_x * self.squares_y) // 2

    @cached_property
    def opencv(self) -> cv2.aruco.CharucoBoard:
        """The same board as OpenCV's ``cv2.aruco.CharucoBoard``."""
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        ids = np.arange(self.first_id, self.first_id + self.n_markers, dtype=np.int32)
        board = cv2.aruco.CharucoBoard((self.squares_x, self.squares_y), float(self.square_length),
                                       float(self.marker_length), d, ids)
        board.setLegacyPattern(self.legacy)
        return board

    @cached_property
    def marker_ids(self) -> NDArray[np.int64]:
        """(M,) the markers' ids, in OpenCV's order."""
        return np.asarray(self.opencv.getIds(), np.int64).ravel()

    @cached_property
    def marker_corners(self) -> FloatArray:
        """(M, 4, 3) each marker's corners in the board frame (m), from its own top-left,
        clockwise as seen on the printed face (OpenCV's order)."""
        return np.array(self.opencv.getObjPoints(), np.float64).reshape(-1, 4, 3)

    @cached_property
    def chessboard_corners(self) -> FloatArray:
        """(C, 3) the inner chessboard corners in the board frame (m); corner ``j`` has id ``j``."""
        return np.asarray(self.opencv.getChessboardCorners(), np.float64).reshape(-1, 3)

    @cached_property
    def adjacent_markers(self) -> list[NDArray[np.int64]]:
        """Per chessboard corner, the indices (into :attr:`marker_ids`) of the markers in the
        white squares that touch it (two inside the board, one on its edges)."""
        centres = self.marker_corners.mean(axis=1)[:, :2]
        out = []
        for c in self.chessboard_corners[:, :2]:
            d = np.abs(centres - c)
            out.append(np.flatnonzero((d < self.square_length).all(axis=1)))
        return out

    @cached_property
    def black_squares(self) -> tuple[FloatArray, NDArray[np.int64], list[NDArray[np.int64]]]:
        """The black squares: their corners (B, 4, 2) in the board plane (m, clockwise as seen
        on the printed face, from the top-left), per corner the chessboard corner id it is
        (B, 4; -1 on the board's outline), and per square the indices of the markers in the
        white squares next to it."""
        s = self.square_length
        centres = self.marker_corners.mean(axis=1)[:, :2]
        white = {(int(np.floor(c[1] / s)), int(np.floor(c[0] / s))) for c in centres}
        nx = self.squares_x - 1  # inner corners per row
        quads, ids, near = [], [], []
        for r in range(self.squares_y):
            for c in range(self.squares_x):
                if (r, c) in white:
                    continue
                quad = np.array([[c, r], [c + 1, r], [c + 1, r + 1], [c, r + 1]], np.float64)
                quads.append(quad * s)
                ids.append([(int(y) - 1) * nx + int(x) - 1 if 0 < x < self.squares_x and 0 < y < self.squares_y
                            else -1 for x, y in quad])
                d = np.abs(centres - (quad.mean(axis=0) * s))
                near.append(np.flatnonzero((d < 1.01 * s).all(axis=1) & (d.sum(axis=1) < 1.01 * s)))
        return np.array(quads), np.array(ids, np.int64), near

    def image(self, px_per_square: int, *, margin: int = 0) -> NDArray[np.uint8]:
        """The printed board, ``px_per_square`` pixels per square, ``margin`` px of white around
        it (OpenCV's ``generateImage``).

        Parameters
        ----------
        px_per_square : int
            Pixels per square side (>= 8).
        margin : int
            White border, px (>= 0).

        Returns
        -------
        ndarray (H, W) uint8
        """
        if isinstance(px_per_square, bool) or not isinstance(px_per_square, (int, np.integer)) or px_per_square < 8:
            raise ValueError(f"px_per_square must be an integer >= 8, got {px_per_square!r}")
        if isinstance(margin, bool) or not isinstance(margin, (int, np.integer)) or margin < 0:
            raise ValueError(f"margin must be an integer >= 0, got {margin!r}")
        size = (self.squares_x * px_per_square + 2 * margin, self.squares_y * px_per_square + 2 * margin)
        return self.opencv.generateImage(size, marginSize=margin)

    def to_file(self, path: str | Path) -> Path:
        """Write the board as an OpenCV FileStorage YAML board file.

        Parameters
        ----------
        path : str or Path
            Output file (``.yml`` or ``.yaml``).

        Returns
        -------
        Path
        """
        path = Path(path)
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
        try:
            fs.write("board_type", BOARD_TYPE)
            fs.write("squares_x", int(self.squares_x))
            fs.write("squares_y", int(self.squares_y))
            fs.write("square_length", float(self.square_length))
            fs.write("marker_length", float(self.marker_length))
            fs.write("dictionary", self.dictionary)
            fs.write("first_id", int(self.first_id))
            fs.write("legacy", int(self.legacy))
        finally:
            fs.release()
        return path

    @classmethod
    def from_file(cls, path: str | Path) -> CharucoBoard:
        """Read a board file written by :meth:`to_file` (or by hand with the same keys).

        Parameters
        ----------
        path : str or Path
            The board file.

        Returns
        -------
        CharucoBoard

        Raises
        ------
        ValueError
            The file is missing, not a ChArUco board file, or a key is missing or out of range
            (the message names it).
        """
        path = Path(path)
        fs = open_storage(path, "board file")
        key = "board_type"
        try:
            kind = fs.getNode("board_type").string()
            if kind != BOARD_TYPE:
                raise ValueError(f"board file {path}: board_type must be {BOARD_TYPE!r}, got {kind!r}")
            values = {}
            for key in ("squares_x", "squares_y", "square_length", "marker_length"):
                node = fs.getNode(key)
                if node.empty() or not node.isReal() and not node.isInt():
                    raise ValueError(f"board file {path}: {key} is missing or not a number")
                values[key] = node.real()
            key = "dictionary"
            dictionary = fs.getNode("dictionary").string() or "DICT_6X6_250"
            key = "first_id"
            first = _whole_node(fs.getNode("first_id"), path, key, 0)
            key = "legacy"
            legacy = _whole_node(fs.getNode("legacy"), path, key, 0)
            if legacy not in (0, 1):
                raise ValueError(f"board file {path}: legacy must be 0 or 1, got {legacy}")
            legacy = bool(legacy)
        except cv2.error:  # OpenCV asserts on some missing nodes
            raise ValueError(f"board file {path}: {key} is missing or malformed") from None
        finally:
            fs.release()
        sx, sy = values["squares_x"], values["squares_y"]
        if not (math.isfinite(sx) and math.isfinite(sy)) or sx != int(sx) or sy != int(sy):
            raise ValueError(f"board file {path}: squares_x and squares_y must be integers, got {sx}, {sy}")
        return cls(int(sx), int(sy), values["square_length"], values["marker_length"], dictionary,
                   first_id=first, legacy=legacy)


def _whole_node(node: cv2.FileNode, path: Path, key: str, default: int) -> int:
    """A board file's integer ``key`` (``default`` when it is absent): a ValueError naming it
    when it holds text or a fraction (``first_id: 2.7`` was read as 2 before)."""
    if node.empty():
        return default
    value = node.real() if node.isReal() or node.isInt() else math.nan
    if not math.isfinite(value) or value != int(value):
        shown = node.string() if node.isString() else value
        raise ValueError(f"board file {path}: {key} must be an integer, got {shown!r}")
    return int(value)


@dataclass(frozen=True, eq=False)
class CharucoCorners:
    """A board's corners found in one image.

    Attributes
    ----------
    ids : ndarray (N,) int64
        Chessboard corner ids (rows of :attr:`CharucoBoard.chessboard_corners`), ascending.
    corners : ndarray (N, 2) float64
        Their image positions, px (pixel centres at integer coordinates).
    marker_ids : ndarray (M,) int64
        The board's markers found.
    marker_corners : ndarray (M, 4, 2) float64
        Their corners, px, OpenCV's order.
    dropped : int
        Corners predicted from the markers whose saddle fit failed (left out).
    """

    ids: NDArray[np.int64]
    corners: FloatArray
    marker_ids: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    marker_corners: FloatArray = field(default_factory=lambda: np.zeros((0, 4, 2)))
    dropped: int = 0

    def __len__(self) -> int:
        return len(self.ids)


def detect_charuco(image: NDArray, board: CharucoBoard, *, detector: MarkerDetector | None = None,
                   response: str | float = "srgb", refine: bool = True, method: str = "edges") -> CharucoCorners:
    """A board's chessboard corners in an image (module docstring).

    Parameters
    ----------
    image : ndarray (H, W) or (H, W, 3) uint8
        Grey or BGR image.
    board : CharucoBoard
        The board.
    detector : MarkerDetector, optional
        Finds the markers (default ``MarkerDetector(board.dictionary, response=response)``).
    response : str or float
        How the grey levels encode light (:func:`visloc.markers.response.response_lut`):
        ``"srgb"`` (cameras), ``"linear"`` or a gamma; the saddle fit reads linear light.
    refine : bool
        Refine the predicted corners (False: the homography predictions).
    method : {"edges", "saddle"}
        ``"edges"``: each black square's edges fitted as the marker detector's stage 8 fits a
        marker's, then each corner where the board's two lines through it, fitted to the
        edges of both squares that meet there, cross; ``"saddle"``:
        :func:`refine_saddles`.

    Returns
    -------
    CharucoCorners
        The corners found (none when no marker of the board was found).
    """
    if not isinstance(board, CharucoBoard):
        raise TypeError(f"board must be a CharucoBoard, got {type(board).__name__}")
    if method not in ("edges", "saddle"):
        raise ValueError(f"method must be 'edges' or 'saddle', got {method!r}")
    gray = to_gray(image)
    det = detector if detector is not None else MarkerDetector(board.dictionary, response=response)
    index = {int(m): k for k, m in enumerate(board.marker_ids)}
    found: dict[int, FloatArray] = {}
    for m in det.detect(gray):
        k = index.get(int(m.id))
        if k is not None and k not in found:  # an id seen twice: the first (a board has each once)
            found[k] = m.corners
    if not found:
        return CharucoCorners(np.zeros(0, np.int64), np.zeros((0, 2)))
    ids, predicted, scale = _predict(board, found)
    marker_k = sorted(found)
    markers = (board.marker_ids[marker_k], np.array([found[k] for k in marker_k]))
    if not len(ids) or not refine:
        return CharucoCorners(ids, predicted, *markers)
    if method == "edges":
        corners, ok = _refine_by_squares(gray, board, found, ids, response)
        ok &= np.linalg.norm(corners - predicted, axis=1) <= 0.25 * scale
    else:
        light = response_lut(response)[gray]  # linear light (float), as stage 8 reads it
        radius = np.clip(np.floor(0.2 * scale), 2, 10).astype(int)
        corners, ok = refine_saddles(light, predicted, radius=radius, max_shift=0.25 * scale)
    return CharucoCorners(ids[ok], corners[ok], *markers, dropped=int((~ok).sum()))


def _refine_by_squares(gray: NDArray[np.uint8], board: CharucoBoard, found: dict[int, FloatArray],
                       ids: NDArray[np.int64], response: str | float) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Corners ``ids`` where the edges of the black squares meet. Each black square next to a
    found marker is predicted by those markers' homographies and refined by the marker
    detector's stage 8 (:func:`visloc.markers.refine.refine_quads`: its four edges fitted to
    the light across them, the corners where they meet; each side read by its own black and
    white levels along it: the light varies across a square of 100 px), with profiles half as
    wide as the white margin between the square and the markers beside it; squares not wholly
    inside the image are not refined. Then each corner where two squares meet is where the
    board's two lines through it cross, each fitted to both squares' edges
    (:func:`_joint_corners`); a corner without (its lines did not cross near the squares') is
    the mean of its refined squares' corners."""
    plane, corner_ids, near = board.black_squares
    H, have = _marker_homographies(board, found)
    predicted, ok = _mean_prediction(H, have, _padded(near), plane)  # the markers' predictions, averaged
    rows = np.flatnonzero(ok & (corner_ids >= 0).any(axis=1) & np.isfinite(predicted).all(axis=(1, 2))).tolist()
    quads = [predicted[b] for b in rows]
    sums = np.zeros((len(board.chessboard_corners), 2))
    counts = np.zeros(len(board.chessboard_corners))
    if quads:
        quads_arr = np.array(quads)
        x, y = quads_arr[..., 0], quads_arr[..., 1]
        side = np.sqrt(np.abs(0.5 * ((x * np.roll(y, -1, axis=1)).sum(1) - (np.roll(x, -1, axis=1) * y).sum(1))))
        margin = side * (board.square_length - board.marker_length) / (2.0 * board.square_length)
        radius = np.clip(np.floor(0.5 * margin), 1, 8).astype(int)
        h, w = gray.shape[:2]
        lo = radius[:, None] + 2.0  # every profile inside the image: squares cut by its edge are left out
        inside = ((quads_arr[..., 0] >= lo) & (quads_arr[..., 0] <= w - 1 - lo) & (quads_arr[..., 1] >= lo)
                  & (quads_arr[..., 1] <= h - 1 - lo)).all(axis=1)
        refined, ok = refine_quads(gray, quads_arr, radius=radius, response=response, bend=False, levels="side")
        ok &= inside
        for k in np.flatnonzero(ok).tolist():
            for i, cid in enumerate(corner_ids[rows[k]].tolist()):
                if cid >= 0:
                    sums[cid] += refined[k, i]
                    counts[cid] += 1
        if ok.any():
            squares = np.where(ok[:, None, None], refined, quads_arr)  # the others as predicted
            cids, joint = _joint_corners(gray, squares, ok, corner_ids[np.array(rows)], radius, response)
            sums[cids], counts[cids] = joint, 1.0
    have = counts[ids] > 0
    out = np.full((len(ids), 2), np.nan)
    out[have] = sums[ids[have]] / counts[ids[have], None]
    return out, have


#: per corner of a black square (TL, TR, BR, BL on the board), its side along the board's x
#: and along its y (side s runs from corner s to corner s + 1: top, right, bottom, left)
_ALONG_X = np.array([0, 0, 2, 2])
_ALONG_Y = np.array([3, 1, 1, 3])
#: widest profile of the joint fit, px: its sides start from refined squares, and a narrower
#: window sums less noise (corner RMS on camera-like 1280 x 720 views: 0.0176 px with the
#: squares' own half-widths of up to 8 px, 0.0161 with 4, 0.0155 with 3, 0.029 with 2)
_JOINT_RADIUS = 4
#: profiles per side of the joint fit: about one per pixel of a side (more lowered the corner
#: error on camera-like 1280 x 720 views until they were a pixel apart), within these bounds
_JOINT_COUNT = (16, 128)
_JOINT_GAP = 0.08  # fraction of each side left out at both ends


def _joint_corners(gray: NDArray[np.uint8], quads: FloatArray, refined: NDArray[np.bool_],
                   corner_ids: NDArray[np.int64], radius: NDArray,
                   response: str | float) -> tuple[NDArray[np.int64], FloatArray]:
    """The chessboard corners where two black squares (K, 4, 2) meet, each where two lines
    cross: along the board's x, the edge of one square that ends at the corner and the edge of
    the other that starts there (one straight line on the board), and the same along y. Each
    line is fitted to the edge points of both squares' sides at once (stage 8's edge points,
    :func:`visloc.markers.refine.edge_points`) as a quadratic about the corner (the lens bends
    it; a curvature within 3 standard errors of 0 is dropped), outliers of a first fit
    dropped: twice the points of either square's side, on both sides of the corner, where each
    square alone extrapolates its sides to their end. A square that was not ``refined`` (cut
    by the image's edge, or failed) lends the edge points of its predicted sides as far as
    they lie inside the image, if the other square was refined. Returns the
    corner ids (N,) and positions (N, 2) px; a corner whose lines do not cross within 1 px of
    the refined squares' corner, or with a line of fewer than 6 points, is left out."""
    radius = np.minimum(radius, _JOINT_RADIUS)
    ids = corner_ids.ravel()
    order = np.argsort(ids, kind="stable")
    ids_sorted = ids[order]
    first = np.flatnonzero((ids_sorted[:-1] == ids_sorted[1:]) & (ids_sorted[:-1] >= 0))
    a, b = divmod(order[first], 4), divmod(order[first + 1], 4)  # (square, corner) of each
    ra, rb = refined[a[0]], refined[b[0]]
    use = ra | rb
    first, a, b, ra, rb = first[use], (a[0][use], a[1][use]), (b[0][use], b[1][use]), ra[use], rb[use]
    if not len(first):
        return np.zeros(0, np.int64), np.zeros((0, 2))
    wa = ra / (ra.astype(np.float64) + rb)  # 1/2 each when both were refined
    c0 = wa[:, None] * quads[a[0], a[1]] + (1.0 - wa)[:, None] * quads[b[0], b[1]]  # the refined squares' corner
    # a square not refined lends, per corner, its predicted quad with the two sides from that
    # corner cut where they leave the image (beyond, profiles repeat the image's edge)
    size, k = gray.shape[::-1], len(quads)
    (sa, ia), (sb, ib) = (a[0][~ra], a[1][~ra]), (b[0][~rb], b[1][~rb])
    cut = np.concatenate([_cut_sides(quads[sa], ia, radius[sa], size), _cut_sides(quads[sb], ib, radius[sb], size)])
    a = (np.where(ra, a[0], k + np.cumsum(~ra) - 1), a[1])
    b = (np.where(rb, b[0], k + len(sa) + np.cumsum(~rb) - 1), b[1])
    quads, radius = np.concatenate([quads, cut]), np.concatenate([radius, radius[sa], radius[sb]])
    sides = np.linalg.norm(np.roll(quads[:k], -1, axis=1) - quads[:k], axis=2)
    count = int(np.clip(np.median(sides) * (1.0 - 2.0 * _JOINT_GAP), *_JOINT_COUNT))
    points, _, _, good = edge_points(gray, quads, radius=radius, count=count, end_gap=_JOINT_GAP,
                                     response=response, levels="side")
    tangents = [_tangent(points, good, quads, a, b, c0, along) for along in (_ALONG_X, _ALONG_Y)]
    (p, d), (q, e) = tangents
    den = d[:, 0] * e[:, 1] - d[:, 1] * e[:, 0]
    f = q - p
    u = (f[:, 0] * e[:, 1] - f[:, 1] * e[:, 0]) / np.where(np.abs(den) < 1e-9, np.nan, den)
    corner = p + u[:, None] * d
    keep = np.isfinite(corner).all(axis=1) & (np.linalg.norm(corner - c0, axis=1) < 1.0)
    return ids_sorted[first][keep], corner[keep]


def _cut_sides(quads: FloatArray, corner: NDArray[np.int64], radius: NDArray, size: tuple[int, int]) -> FloatArray:
    """Quads (V, 4, 2) with the two sides from ``corner`` (V,) ended where they come within
    ``radius + 2`` px of the image's edge (``size`` = (W, H)): their far corners moved toward
    ``corner`` along them."""
    out = quads.copy()
    rows = np.arange(len(quads))
    lo = (radius + 2.0)[:, None]
    hi = np.array(size, np.float64) - 1.0 - lo
    p0 = quads[rows, corner]
    for far in ((corner + 1) % 4, (corner + 3) % 4):
        p1 = quads[rows, far]
        d = p1 - p0
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(p1 > hi, (hi - p0) / d, np.where(p1 < lo, (lo - p0) / d, 1.0))
        t = np.clip(np.nan_to_num(t.min(axis=1), nan=0.0), 0.0, 1.0)
        out[rows, far] = p0 + t[:, None] * d
    return out


def _tangent(points: FloatArray, good: NDArray[np.bool_], quads: FloatArray, a: tuple, b: tuple, c0: FloatArray,
             along: NDArray[np.int64]) -> tuple[FloatArray, FloatArray]:
    """One line of :func:`_joint_corners` per corner: its point next to the corner ``c0``
    (N, 2) and its direction there (N, 2)."""
    sa, sb = along[a[1]], along[b[1]]
    pts = np.concatenate([points[a[0], sa], points[b[0], sb]], axis=1)  # (N, 2M, 2)
    w = np.concatenate([good[a[0], sa], good[b[0], sb]], axis=1).astype(np.float64)
    d = quads[a[0], (sa + 1) % 4] - quads[a[0], sa]
    length = np.maximum(np.linalg.norm(d, axis=1), 1e-9)
    d = d / length[:, None]
    n = np.stack([-d[:, 1], d[:, 0]], axis=1)
    rel = pts - c0[:, None, :]
    u = (rel * d[:, None, :]).sum(axis=2) / length[:, None]  # along the line, in sides
    v = (rel * n[:, None, :]).sum(axis=2)  # across it, px
    basis = np.stack([np.ones_like(u), u, u * u], axis=2)  # (N, 2M, 3)
    few = w.sum(axis=1) < 6
    for last in (False, True):  # fit, then refit without the first fit's outliers
        weighted = np.swapaxes(basis * w[..., None], 1, 2)  # (N, 3, 2M)
        gram = weighted @ basis + 1e-9 * np.eye(3)
        rhs = weighted @ v[..., None]  # (N, 3, 1)
        coef = np.linalg.solve(gram, rhs)[..., 0]
        res = np.abs(v - (basis @ coef[..., None])[..., 0])
        rms = np.sqrt((w * res * res).sum(axis=1) / np.maximum(w.sum(axis=1) - 3, 1))
        if not last:
            w = w * (res < 2.5 * rms[:, None] + 0.05)
    straight = np.abs(coef[:, 2]) < 3.0 * rms * np.sqrt(np.linalg.inv(gram)[:, 2, 2])
    if straight.any():  # a curvature within the noise only adds noise to the corner
        line = np.linalg.solve(gram[straight][:, :2, :2], rhs[straight][:, :2])[..., 0]
        coef[straight] = np.concatenate([line, np.zeros((len(line), 1))], axis=1)
    coef[few] = np.nan  # too few points: no line
    return c0 + coef[:, :1] * n, d + (coef[:, 1:2] / length[:, None]) * n


def _predict(board: CharucoBoard, found: dict[int, FloatArray]) -> tuple[NDArray[np.int64], FloatArray, FloatArray]:
    """Chessboard corners predicted by the homographies of the found markers next to each (the
    mean of their predictions): ids (N,), positions (N, 2) px, and the local size of a square
    (N,) px."""
    H, have = _marker_homographies(board, found)
    c = board.chessboard_corners[:, :2]
    near = _padded(board.adjacent_markers)
    pred, ok = _mean_prediction(H, have, near, c[:, None, :])  # (C, 1, 2)
    s = board.square_length
    square = c[:, None, :] + np.array([[0.0, 0.0], [s, 0.0], [s, s], [0.0, s]])  # (C, 4, 2)
    sq, _ = _mean_prediction(H, have, near, square)
    x, y = sq[..., 0], sq[..., 1]
    scale = np.sqrt(np.abs(0.5 * ((x * np.roll(y, -1, axis=1)).sum(1) - (np.roll(x, -1, axis=1) * y).sum(1))))
    ok &= np.isfinite(scale)
    ids = np.flatnonzero(ok)
    return ids.astype(np.int64), pred[ids, 0], scale[ids]


def _padded(groups: list[NDArray[np.int64]]) -> NDArray[np.int64]:
    """Lists of marker indices as a (G, W) array padded with -1."""
    width = max((len(g) for g in groups), default=0)
    out = np.full((len(groups), max(width, 1)), -1, np.int64)
    for i, g in enumerate(groups):
        out[i, : len(g)] = g
    return out


def _marker_homographies(board: CharucoBoard, found: dict[int, FloatArray]) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Board plane -> image homographies (M, 3, 3) of the board's markers from their four found
    corners, and which were found."""
    H = np.full((len(board.marker_ids), 3, 3), np.nan)
    for k, corners in found.items():
        H[k] = cv2.getPerspectiveTransform(board.marker_corners[k, :, :2].astype(np.float32),
                                           np.asarray(corners, np.float32))
    return H, np.isfinite(H).all(axis=(1, 2))


def _mean_prediction(H: FloatArray, have: NDArray[np.bool_], near: NDArray[np.int64],
                     points: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Per group g, its points (G, P, 2) mapped by each found marker of ``near[g]`` (G, W) and
    averaged; and whether a group had any (points in front of the camera)."""
    idx = np.where(near >= 0, near, 0)
    use = (near >= 0) & have[idx]  # (G, W)
    Hs = H[idx]  # (G, W, 3, 3)
    hom = np.concatenate([points, np.ones(points.shape[:2] + (1,))], axis=2)  # (G, P, 3)
    p = np.einsum("gwij,gpj->gwpi", np.nan_to_num(Hs), hom)  # (G, W, P, 3)
    front = (p[..., 2] > 0).all(axis=2) & use  # (G, W)
    xy = p[..., :2] / np.where(p[..., 2:3] > 0, p[..., 2:3], 1.0)
    n = front.sum(axis=1)
    mean = (xy * front[..., None, None]).sum(axis=1) / np.maximum(n, 1)[:, None, None]
    return mean, n > 0


def refine_saddles(light: NDArray, points: NDArray, *, radius: int | NDArray = 4, iterations: int = 4,
                   max_shift: float | NDArray = np.inf) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Chessboard corners moved to the saddle point of the light around them.

    Each point's neighbourhood (``2 radius + 1`` pixels on a side, Gaussian weights of sigma
    ``radius / 2``) of the image blurred by a Gaussian of sigma 1 px is fitted by a quadratic
    ``a x^2 + b x y + c y^2 + d x + e y + f`` (weighted least squares); the point moves to its
    stationary point, and again from there, ``iterations`` times or until it moves less than
    0.001 px.

    Parameters
    ----------
    light : ndarray (H, W)
        Grey levels, best linear in light (:func:`visloc.markers.response.response_lut`).
    points : ndarray (K, 2)
        Starting positions, px (pixel centres at integer coordinates).
    radius : int or ndarray (K,) of int
        Half-size of each neighbourhood, px (>= 2); keep it inside the squares next to the
        corner (a fifth of a square is safe on a ChArUco board with markers half a square wide).
    iterations : int
        Most fits per point (>= 1).
    max_shift : float or ndarray (K,)
        A point that moves further than this from its start, px, is not trusted.

    Returns
    -------
    (ndarray (K, 2), ndarray (K,) bool)
        The refined positions, px, and whether each is a saddle (the quadratic's Hessian has a
        negative determinant) that stayed within ``max_shift`` and inside the image.
    """
    img = np.asarray(light, np.float64)
    if img.ndim != 2:
        raise ValueError(f"light must be a (H, W) image, got shape {img.shape}")
    start = np.asarray(points, np.float64).reshape(-1, 2)
    k = len(start)
    radii = np.broadcast_to(np.asarray(radius, np.int64), (k,))
    if k and (radii.min() < 2 or radii.max() > 64):
        raise ValueError(f"radius must be in [2, 64] px, got {radii.min()}..{radii.max()}")
    if isinstance(iterations, bool) or int(iterations) != iterations or iterations < 1:
        raise ValueError(f"iterations must be an integer >= 1, got {iterations!r}")
    limit = np.broadcast_to(np.asarray(max_shift, np.float64), (k,))
    img = cv2.GaussianBlur(img, (0, 0), 1.0)
    h, w = img.shape
    p = start.copy()
    ok = np.isfinite(p).all(axis=1)
    for r in np.unique(radii).tolist():
        rows = np.flatnonzero((radii == r) & ok)
        if len(rows):
            p[rows], ok[rows] = _saddle_steps(img, p[rows], int(r), int(iterations))
    inside = (p[:, 0] >= 0) & (p[:, 0] <= w - 1) & (p[:, 1] >= 0) & (p[:, 1] <= h - 1)
    ok &= inside & (np.linalg.norm(p - start, axis=1) <= limit)
    return p, ok


def _saddle_steps(img: FloatArray, p: FloatArray, r: int, iterations: int) -> tuple[FloatArray, NDArray[np.bool_]]:
    """:func:`refine_saddles` for points (K, 2) of one radius."""
    h, w = img.shape
    d = np.arange(-r, r + 1)
    dy, dx = np.meshgrid(d, d, indexing="ij")
    dx, dy = dx.ravel(), dy.ravel()
    ok = np.ones(len(p), bool)
    for _ in range(iterations):
        base = np.rint(p).astype(np.int64)
        xs = np.clip(base[:, :1] + dx, 0, w - 1)
        ys = np.clip(base[:, 1:] + dy, 0, h - 1)
        v = img[ys, xs]  # (K, N)
        u = base[:, :1] + dx - p[:, :1]  # coordinates about the current estimate
        t = base[:, 1:] + dy - p[:, 1:]
        wt = np.exp(-(u * u + t * t) / (2.0 * (0.5 * r) ** 2))
        A = np.stack([u * u, u * t, t * t, u, t, np.ones_like(u)], axis=2)  # (K, N, 6)
        Aw = A * wt[:, :, None]
        coef = np.linalg.solve(np.einsum("kni,knj->kij", Aw, A) + 1e-9 * np.eye(6),
                               np.einsum("kni,kn->ki", Aw, v)[:, :, None])[:, :, 0]
        a, b, c, dd, e = coef[:, 0], coef[:, 1], coef[:, 2], coef[:, 3], coef[:, 4]
        det = 4.0 * a * c - b * b
        ok &= det < 0  # a saddle
        safe = np.where(det < 0, det, -1.0)
        step = np.stack([(-2.0 * c * dd + b * e) / safe, (b * dd - 2.0 * a * e) / safe], axis=1)
        step = np.where(np.isfinite(step), step, 0.0)
        step = np.clip(step, -r, r)
        p = p + step
        if np.abs(step).max(initial=0.0) < 1e-3:
            break
    return p, ok
