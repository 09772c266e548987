"""Ports of the marker-detection parts of OpenCV's modules/objdetect/test/test_boarddetection.cpp.

Not ported: CV_ArucoRefine / CV_Aruco3Refine (``refineDetectedMarkers``, a board-guided second
look visloc's detector does not have), CV_ArucoBoardPose.CheckNegativeZ (solvePnP on fixed
points, no detection), CV_ArucoGenerateBoard.regression_1226 and CV_ArucoDictionary
(board drawing and dictionary extension, no detection), the CV_Aruco3BoardPose variant (OpenCV's
internal ArUco3 search).
"""

import cv2
import numpy as np
import pytest

from tests.peers.conftest import (
    OPENCV_MIN_DISTANCE_TO_BORDER,
    PLANNED,
    aruco_dict,
    camera,
    get_axis,
    opencv_detector,
    opencv_found,
    project_board,
    visloc_found,
)
from visloc.markers import MarkerDetector
from visloc.markers.contours import CandidateFilter

#: Views of this port where the installed OpenCV (5.0.0 and 5.1.0, opencv-python-headless) itself fails the
#: original's criteria: (distance, yaw, pitch) -> what it does. The OpenCV check skips them;
#: visloc is held to every view.
OPENCV_MISSES = {(0.35, 45, -55): "finds 8 of the 9 markers (misses id 51, 2 border bits, ~2 px cells)"}


def _board_pose_check(board, ids, corners, K):
    """The original's checks after detection; returns a list of failure strings."""
    dist = np.zeros(5)
    board_ids = [int(i) for i in board.getIds()]
    if sorted(ids) != sorted(board_ids):
        return [f"found {sorted(ids)} instead of the board's {len(board_ids)} markers"]
    obj, imgp = board.matchImagePoints([c.reshape(1, 4, 2).astype(np.float32) for c in corners],
                                       np.array(ids, np.int32).reshape(-1, 1))
    _, rvec, tvec = cv2.solvePnP(obj, imgp, K, dist)
    axes = get_axis(K, dist, rvec, tvec, board.getRightBottomCorner()[0])
    by_id = dict(zip(ids, corners, strict=True))
    bad = []
    for marker, corner, axis in ((board_ids[0], 0, 0), (board_ids[2], 1, 1), (board_ids[6], 3, 2)):
        off = np.abs(by_id[marker][corner] - axes[axis]).max()
        if off > 2.0:
            bad.append(f"axis {axis}: marker {marker} corner {corner} off by {off:.2f} px > 2")
    for mid, c in by_id.items():
        obj_pts = np.asarray(board.getObjPoints()[board_ids.index(mid)], np.float32)
        proj = cv2.projectPoints(obj_pts, rvec, tvec, K, dist)[0].reshape(4, 2)
        err = np.linalg.norm(proj - c, axis=1).max()
        if err > 5.0:
            bad.append(f"marker {mid}: reprojection error {err:.2f} px > 5")
    return bad


def _run_board_pose(border_bits):
    size = (500, 500)
    K = camera(650, size)
    d = aruco_dict("DICT_6X6_250")
    kwargs = {"candidates": CandidateFilter(border_distance=float(OPENCV_MIN_DISTANCE_TO_BORDER))}
    if border_bits != 1:
        kwargs[PLANNED["markerBorderBits"]] = border_bits
    det = MarkerDetector("DICT_6X6_250", **kwargs)
    ref = opencv_detector(d, minDistanceToBorder=OPENCV_MIN_DISTANCE_TO_BORDER, markerBorderBits=border_bits)
    it, failures, n = 0, [], 0
    for distance in (0.2, 0.35):
        for yaw in range(-55, 51, 25):
            for pitch in range(-55, 51, 25):
                board = cv2.aruco.GridBoard((3, 3), 0.02, 0.005, d, np.array([(it + i) % 250 for i in range(9)]))
                bb = it % 2 + 1
                it += 1
                if bb != border_bits:
                    continue
                n += 1
                img, _, _ = project_board(board, K, np.deg2rad(yaw), np.deg2rad(pitch), distance, size, bb)
                ids, corners = opencv_found(ref, img)
                if (distance, yaw, pitch) not in OPENCV_MISSES:
                    assert not _board_pose_check(board, ids, corners, K), ("OpenCV", distance, yaw, pitch)
                ids, corners = visloc_found(det, img)
                bad = _board_pose_check(board, ids, corners, K)
                if bad:
                    failures.append(((distance, yaw, pitch), bad[0]))
    assert not failures, f"visloc failed {len(failures)} of {n} views ((dist, yaw, pitch), first problem): {failures[:6]}"


BOARD_POSE_DOC = """CV_ArucoBoardPose.accuracy: 3 x 3 DICT_6X6_250 grid boards (ids rotate per view) seen
    from 0.2 / 0.35 m at yaw and pitch -55..45 deg (500 x 500 px, f = 650 px); exactly the 9
    markers are found, the board pose from ``solvePnP`` on their corners puts the board's origin
    and axis ends within 2 px of the matching marker corners and reprojects every marker corner
    within 5 px. The C++ loop alternates 1 and 2 border bits; this function takes {bits}. The
    drawn markers' geometric corners differ from the projected ones by <= 0.35 px here, inside
    these tolerances, so the original's truth is kept; ``minDistanceToBorder = 3`` ->
    ``border_distance=3``. The installed OpenCV fails one view itself (:data:`OPENCV_MISSES`)."""


def test_board_pose_one_border_bit():
    _run_board_pose(1)


def test_board_pose_two_border_bits():
    _run_board_pose(2)


test_board_pose_one_border_bit.__doc__ = BOARD_POSE_DOC.format(bits="the views with 1 border bit")
test_board_pose_two_border_bits.__doc__ = BOARD_POSE_DOC.format(
    bits="the views with 2 border bits (``border_bits``)")


@pytest.mark.parametrize("angle_deg", [0.0, 45.0, 90.0, 135.0])
def test_board_image_with_rotated_marker(angle_deg):
    """CV_ArucoBoardGenerateImage_RotationTest: a one-marker board whose DICT_4X4_50 marker is
    rotated by 0 / 45 / 90 / 135 deg in the board plane, drawn by ``Board.generateImage``
    (margin 20 px, 1 border bit); exactly one marker, id 0, is found."""
    a = np.float32(np.deg2rad(angle_deg))
    c, s = np.cos(a), np.sin(a)
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    rotated = np.stack([square[:, 0] * c - square[:, 1] * s, square[:, 0] * s + square[:, 1] * c], axis=1)
    obj = np.hstack([rotated, np.zeros((4, 1), np.float32)]).astype(np.float32)
    d = aruco_dict("DICT_4X4_50")
    board = cv2.aruco.Board([obj], d, np.array([0], np.int32))
    side = int((np.float32(np.sqrt(np.float32(2.0))) + np.float32(2.0)) * np.float32(500)) + 2 * 20
    img = board.generateImage((side, side), marginSize=20, borderBits=1)
    assert opencv_found(cv2.aruco.ArucoDetector(d, cv2.aruco.DetectorParameters()), img)[0] == [0]
    ids, _ = visloc_found(MarkerDetector("DICT_4X4_50"), img)
    assert ids == [0], f"visloc found {ids} at {angle_deg} deg"
