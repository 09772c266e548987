"""draw_markers: outlines, corner 0, ids and projected pose axes."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from visloc.io import draw_markers
from visloc.io.draw import AXIS_COLORS, CORNER0_COLOR, OUTLINE_COLOR
from visloc.types import MarkerDetection, Pose

SQUARE = np.array([[50, 50], [150, 50], [150, 150], [50, 150]], float)
CAMERA = SimpleNamespace(
    K=np.array([[200.0, 0, 100], [0, 200.0, 100], [0, 0, 1]]), dist=np.zeros(5)
)
# Marker 1 m in front of the camera, facing it: marker x -> camera x, y -> -y, z -> -z.
FACING = Pose(np.diag([1.0, -1.0, -1.0]), np.array([0.0, 0.0, 1.0]))


def _close(pixel: np.ndarray, bgr: tuple[int, int, int], tol: int = 40) -> bool:
    return bool(np.all(np.abs(pixel.astype(int) - np.array(bgr)) <= tol))


def test_outline_corner_and_id_are_drawn_on_a_copy() -> None:
    image = np.full((200, 200), 128, np.uint8)
    out = draw_markers(image, [MarkerDetection(7, SQUARE)])

    assert out.shape == (200, 200, 3) and out.dtype == np.uint8
    assert np.all(image == 128)  # input untouched
    for x, y in [(100, 50), (150, 100), (100, 150), (50, 100)]:  # edge midpoints
        assert _close(out[y, x], OUTLINE_COLOR), (x, y, out[y, x])
    assert _close(out[50, 50], CORNER0_COLOR)
    assert not _close(out[150, 150], CORNER0_COLOR)  # only corner 0 is marked
    assert np.all(out[10, 10] == 128) and np.all(out[75, 75] == 128)  # background
    centre = out[90:110, 90:110]
    assert np.any(centre.min(axis=2) > 200)  # white id text near the centre
    assert np.any(centre.max(axis=2) < 100)  # with its dark outline


def test_outline_is_sub_pixel() -> None:
    image = np.zeros((200, 200, 3), np.uint8)
    a = draw_markers(image, [MarkerDetection(1, SQUARE)])
    b = draw_markers(image, [MarkerDetection(1, SQUARE + [0.25, 0.0])])
    column_a = a[100, 145:156, 1].astype(int)  # right edge, green channel
    column_b = b[100, 145:156, 1].astype(int)
    assert not np.array_equal(column_a, column_b)
    xs = np.arange(145, 156)
    shift = (column_b * xs).sum() / column_b.sum() - (column_a * xs).sum() / column_a.sum()
    assert shift == pytest.approx(0.25, abs=0.1)


def test_pose_axes_are_projected() -> None:
    image = np.zeros((200, 200, 3), np.uint8)
    out = draw_markers(image, [MarkerDetection(7, SQUARE)], poses=[FACING], camera=CAMERA, marker_length=0.5)
    # x axis: (0.25, 0, 0) -> pixel (150, 100); y axis: (0, 0.25, 0) -> pixel (100, 50).
    assert _close(out[100, 135], AXIS_COLORS[0])
    assert _close(out[65, 100], AXIS_COLORS[1])
    plain = draw_markers(image, [MarkerDetection(7, SQUARE)])
    assert np.all(plain[100, 135] == 0)


def test_pose_behind_camera_and_missing_pose_are_skipped() -> None:
    behind = Pose(np.eye(3), np.array([0.0, 0.0, -1.0]))
    dets = [MarkerDetection(1, SQUARE), MarkerDetection(2, SQUARE + 10)]
    out = draw_markers(np.zeros((200, 200), np.uint8), dets, poses=[behind, None], camera=CAMERA, marker_length=0.5)
    assert out.shape == (200, 200, 3)
    assert not np.any(np.all(out == AXIS_COLORS[0], axis=2))


def test_bad_arguments_name_the_argument() -> None:
    image = np.zeros((50, 50), np.uint8)
    det = [MarkerDetection(1, SQUARE / 4)]
    with pytest.raises(ValueError, match="camera is required"):
        draw_markers(image, det, poses=[FACING])
    with pytest.raises(ValueError, match="marker_length is required"):
        draw_markers(image, det, poses=[FACING], camera=CAMERA)
    with pytest.raises(ValueError, match="poses must have one entry"):
        draw_markers(image, det, poses=[FACING, FACING], camera=CAMERA, marker_length=0.1)
    with pytest.raises(ValueError, match=r"camera\.K"):
        draw_markers(image, det, poses=[FACING], camera=SimpleNamespace(K=np.eye(2), dist=None), marker_length=0.1)
    with pytest.raises(TypeError, match="image"):
        draw_markers(image.astype(np.int32), det)  # type: ignore[arg-type]
    bad = MarkerDetection(1, np.zeros((3, 2)))
    with pytest.raises(ValueError, match=r"detections\[0\]\.corners"):
        draw_markers(image, [bad])
