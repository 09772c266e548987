"""Calibration boards: ChArUco boards (OpenCV's definition), their corners in images, and
camera calibration from them.

- :class:`CharucoBoard`: the board's geometry (from OpenCV's own ``cv2.aruco.CharucoBoard``, so
  boards printed by either tool match), read from and written to YAML board files.
- :func:`detect_charuco`: the chessboard corners of a board in an image: interpolated from the
  markers visloc's detector finds, then where the board's lines, fitted to the black squares'
  edges, cross (or by a saddle-point fit on the grey levels).
- :class:`MarkerBoard`, :func:`detect_marker_board`: visloc's own marker maps (a printed
  ``GridMap``) as boards, each marker's four corners the points.
- :func:`calibrate`: ``cv2.calibrateCamera`` on those corners, with per-view errors and the
  parameters' standard deviations (either kind of board).
"""

from visloc.boards.calibrate import CALIBRATION_MODELS, Calibration, calibrate
from visloc.boards.charuco import CharucoBoard, CharucoCorners, detect_charuco, refine_saddles
from visloc.boards.markers import MarkerBoard, detect_marker_board

__all__ = ["CALIBRATION_MODELS", "Calibration", "CharucoBoard", "CharucoCorners", "MarkerBoard", "calibrate",
           "detect_charuco", "detect_marker_board", "refine_saddles"]
