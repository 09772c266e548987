"""Calibration boards: ChArUco boards (OpenCV's definition), their corners in images, and
camera calibration from them.

- :class:`CharucoBoard`: the board's geometry (from OpenCV's own ``cv2.aruco.CharucoBoard``, so
  boards printed by either tool match), read from and written to YAML board files.
- :func:`detect_charuco`: the chessboard corners of a board in an image: interpolated from the
  markers visloc's detector finds, then refined by a saddle-point fit on the grey levels.
- :func:`calibrate`: ``cv2.calibrateCamera`` on those corners, with per-view errors and the
  parameters' standard deviations.
"""

from visloc.boards.calibrate import CALIBRATION_MODELS, Calibration, calibrate
from visloc.boards.charuco import CharucoBoard, CharucoCorners, detect_charuco, refine_saddles

__all__ = ["CALIBRATION_MODELS", "Calibration", "CharucoBoard", "CharucoCorners", "calibrate", "detect_charuco",
           "refine_saddles"]
