"""Helpers for the ports of the peers' own test suites (OpenCV's ArUco tests, AprilTag's tests).

Each ported case rebuilds its images the way the original does (``cv2.aruco.generateImageMarker``,
``warpPerspective`` with nearest-neighbour sampling, boards, ...), runs OpenCV's
``cv2.aruco.ArucoDetector`` on them as a check that the port is right (the originals assert that
OpenCV passes), then visloc's :class:`~visloc.markers.MarkerDetector` against the same criteria.

Pixel conventions
-----------------
OpenCV's unrefined corners are contour pixels: a marker covering pixels 100..199 gets corners at
100 and 199. visloc's corners are geometric: 99.5 and 199.5. Where an original checks corners
against contour-pixel positions, the visloc half of the port checks the geometric corners
(:func:`contour_to_geometric`). Markers drawn with ``warpPerspective`` (nearest neighbour) from a
``N``-pixel marker image whose corners ``(0, 0) .. (N, N)`` were mapped to the projected corners
have their geometric edges where the source coordinates -0.5 and N - 0.5 land
(:func:`warp_truth`); the originals' ground truth is the projection of 0 and N.

visloc's names for OpenCV's parameters
--------------------------------------
:data:`PLANNED` maps the OpenCV ``DetectorParameters`` fields the cases set to the
:class:`~visloc.markers.MarkerDetector` keywords that do the same.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

#: OpenCV ``DetectorParameters`` fields -> visloc ``MarkerDetector`` keywords (OpenCV's
#: ``detectInvertedMarker=True`` finds both polarities: visloc's ``inverted="both"``).
PLANNED = {
    "markerBorderBits": "border_bits",
    "detectInvertedMarker": "inverted",
    "perspectiveRemoveIgnoredMarginPerCell": "cell_margin",
    "validBitIdThreshold": "bit_threshold",
}

#: ``DetectorParameters().minDistanceToBorder`` (OpenCV's default image-border margin, px).
OPENCV_MIN_DISTANCE_TO_BORDER = 3

REPO = Path(__file__).resolve().parents[2]


def aruco_dict(name):
    """OpenCV predefined dictionary by name (``"DICT_6X6_250"``)."""
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))


def opencv_params(**fields):
    """``cv2.aruco.DetectorParameters`` with the given fields set (OpenCV names)."""
    p = cv2.aruco.DetectorParameters()
    for k, v in fields.items():
        if not hasattr(p, k):
            raise AttributeError(f"DetectorParameters has no field {k}")
        setattr(p, k, v)
    return p


def opencv_detector(dictionary, **fields):
    """``cv2.aruco.ArucoDetector`` for a dictionary (name or object) and parameter fields."""
    d = aruco_dict(dictionary) if isinstance(dictionary, str) else dictionary
    return cv2.aruco.ArucoDetector(d, opencv_params(**fields))


def opencv_found(detector, image):
    """OpenCV detections as ``(ids, corners)``: a list of ints and an (N, 4, 2) float array."""
    corners, ids, _ = detector.detectMarkers(image)
    if ids is None:
        return [], np.zeros((0, 4, 2))
    return ids.ravel().tolist(), np.array(corners, np.float64).reshape(-1, 4, 2)


def visloc_found(detector, image):
    """visloc detections as ``(ids, corners)`` like :func:`opencv_found`."""
    dets = detector.detect(image)
    return [d.id for d in dets], np.array([d.corners for d in dets], np.float64).reshape(-1, 4, 2)


def corner_distances(found, truth):
    """Euclidean distance of each of the 4 corners (OpenCV's ``cv::norm`` per corner)."""
    return np.linalg.norm(np.asarray(found, np.float64) - np.asarray(truth, np.float64), axis=-1)


def contour_to_geometric(quad, d=0.5):
    """Move each corner of a quad (4, 2) given in OpenCV's contour-pixel convention out to the
    geometric corner: both adjacent sides move ``d`` px outwards and the corner goes to their
    new intersection (exactly -0.5 / +0.5 per axis for an axis-aligned square)."""
    q = np.asarray(quad, np.float64)
    x, y = q[:, 0], q[:, 1]
    sign = 1.0 if 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) > 0 else -1.0
    e = np.roll(q, -1, axis=0) - q  # side k runs from corner k to corner k + 1
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    n = sign * np.stack([e[:, 1], -e[:, 0]], axis=1)  # outward normals (y down)
    n_in, n_out = np.roll(n, 1, axis=0), n  # the sides ending and starting at each corner
    miter = (n_in + n_out) / (1.0 + np.sum(n_in * n_out, axis=1, keepdims=True))
    return q + d * miter


def warp_truth(H, x0, y0, size):
    """Geometric corners in the destination of a marker drawn by ``warpPerspective(H)`` from an
    image whose marker covers source pixels ``x0 .. x0 + size - 1`` (and ``y0 ..``)."""
    a, b = x0 - 0.5, x0 + size - 0.5
    c, e = y0 - 0.5, y0 + size - 0.5
    src = np.array([[[a, c], [b, c], [b, e], [a, e]]], np.float64)
    return cv2.perspectiveTransform(src, np.asarray(H, np.float64))[0]


def paste_warped(img, src, H):
    """Warp ``src`` into ``img`` (in place) with nearest-neighbour sampling and copy every pixel
    that is not the 127 fill, the way the originals' ``projectMarker`` draws a marker.

    Only the bounding box of the warped source is computed (the same mapping of each pixel,
    translated; the originals warp the whole image, which costs ~1 ms a marker at 750 px)."""
    h, w = src.shape[:2]
    box = np.array([[[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]]])
    ends = cv2.perspectiveTransform(box, np.asarray(H, np.float64))[0]
    x0, y0 = np.maximum(np.floor(ends.min(axis=0)).astype(int) - 2, 0)
    x1 = min(int(np.ceil(ends[:, 0].max())) + 3, img.shape[1])
    y1 = min(int(np.ceil(ends[:, 1].max())) + 3, img.shape[0])
    if x1 <= x0 or y1 <= y0:
        return img
    shift = np.array([[1.0, 0.0, -x0], [0.0, 1.0, -y0], [0.0, 0.0, 1.0]])
    aux = cv2.warpPerspective(src, shift @ np.asarray(H, np.float64), (x1 - x0, y1 - y0), flags=cv2.INTER_NEAREST,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=127)
    roi = img[y0:y1, x0:x1]
    keep = aux != 127
    roi[keep] = aux[keep]
    return img


def camera(f, size):
    """Pinhole matrix with focal ``f`` and the principal point at ``size / 2`` (integer halves,
    as the originals compute it)."""
    K = np.eye(3)
    K[0, 0] = K[1, 1] = f
    K[0, 2], K[1, 2] = size[0] // 2, size[1] // 2
    return K


def compose(r1, r2):
    """Rotation vector of rotation ``r1`` followed by ``r2`` (``cv2.composeRT`` with zero
    translations)."""
    z = np.zeros((3, 1))
    return cv2.composeRT(np.asarray(r1, np.float64).reshape(3, 1), z, np.asarray(r2, np.float64).reshape(3, 1), z)[0]


def board_synthetic_rt(yaw, pitch, distance):
    """``getSyntheticRT`` of OpenCV's test_aruco_utils.cpp: the scene pitched about x, then
    yawed about y, ``distance`` along the optical axis."""
    rvec = compose([-pitch, 0, 0], [0, yaw, 0])
    return rvec, np.array([[0.0], [0.0], [distance]])


def project_board_marker(img, board, index, K, rvec, tvec, border_bits):
    """``projectMarker`` of test_aruco_utils.cpp: marker ``index`` of ``board`` drawn at 100 px,
    warped to its projected corners (board centred on the origin). Returns the projected corners
    (the original's truth) and the geometric corners of the drawn marker."""
    side = 100
    marker = cv2.aruco.generateImageMarker(board.getDictionary(), int(board.getIds()[index]), side,
                                           borderBits=border_bits)
    centre = np.array(board.getRightBottomCorner(), np.float32) / np.float32(2)
    obj = np.asarray(board.getObjPoints()[index], np.float32).reshape(4, 3) - centre
    proj = cv2.projectPoints(obj, rvec, tvec, K, np.zeros(5))[0].reshape(4, 2).astype(np.float32)
    src = np.array([[0, 0], [side, 0], [side, side], [0, side]], np.float32)
    H = cv2.getPerspectiveTransform(src, proj)
    paste_warped(img, marker, H)
    return proj.astype(np.float64), warp_truth(H, 0, 0, side)


def project_board(board, K, yaw, pitch, distance, size, border_bits):
    """``projectBoard`` of test_aruco_utils.cpp: every marker of a grid board in perspective on
    white. Returns the image and the pose used."""
    rvec, tvec = board_synthetic_rt(yaw, pitch, distance)
    img = np.full((size[1], size[0]), 255, np.uint8)
    for i in range(len(board.getIds())):
        project_board_marker(img, board, i, K, rvec, tvec, border_bits)
    return img, rvec, tvec


def get_axis(K, dist, rvec, tvec, length, offset=(0.0, 0.0)):
    """``getAxis`` of test_aruco_utils: the projected origin (at ``offset``) and x, y, z axis ends."""
    ox, oy = offset
    pts = np.array([[ox, oy, 0], [length + ox, oy, 0], [ox, length + oy, 0], [ox, oy, length]], np.float32)
    return cv2.projectPoints(pts, rvec, tvec, K, dist)[0].reshape(4, 2)


def rotate_marker(marker, quarter_turns):
    """``rotateMarker``: 1 = ROT_90 (transpose, flip rows), 2 = ROT_180, 3 = ROT_270."""
    return np.ascontiguousarray(np.rot90(marker, quarter_turns))


def place(img, marker, top_left):
    """Copy ``marker`` into ``img`` with its first pixel at ``top_left`` (x, y)."""
    x, y = int(top_left[0]), int(top_left[1])
    img[y : y + marker.shape[0], x : x + marker.shape[1]] = marker


def write_dictionary(dictionary, path):
    """Write an OpenCV dictionary as OpenCV YAML (visloc reads that file) and return the path."""
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    dictionary.writeDictionary(fs)
    fs.release()
    return str(path)
