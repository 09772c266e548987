import cv2
import numpy as np
import pytest

from tests.conftest import render_square
from visloc.markers.binarize import threshold
from visloc.markers.contours import find_contours
from visloc.markers.corners import (
    fit_line,
    fit_quad,
    intersect_lines,
    orient_clockwise,
    quad_from_lines,
    radial_peaks,
    radial_profile,
    split_sides,
)


def test_fit_line_handles_vertical_horizontal_and_oblique_lines():
    y = np.arange(10.0)
    a, b, c = fit_line(np.stack([np.full(10, 3.0), y], axis=1))  # x = 3
    assert abs(abs(a) - 1) < 1e-12 and abs(b) < 1e-12 and abs(c / a - 3) < 1e-12
    a, b, c = fit_line(np.stack([y, np.full(10, -2.0)], axis=1))  # y = -2
    assert abs(a) < 1e-12 and abs(c / b + 2) < 1e-12
    t = np.linspace(0, 5, 7)
    pts = np.stack([1 + 0.6 * t, 2 + 0.8 * t], axis=1)
    line = fit_line(pts)
    assert np.allclose(pts @ line[:2], line[2])
    with pytest.raises(ValueError):
        fit_line(np.zeros((1, 2)))


def test_fit_line_is_total_least_squares():
    # symmetric noise across a 45-degree line: TLS recovers it, OLS y(x) would tilt
    rng = np.random.default_rng(0)
    t = rng.uniform(-10, 10, 2000)
    n = rng.normal(0, 1.0, 2000)
    pts = np.stack([t - n / np.sqrt(2), t + n / np.sqrt(2)], axis=1)
    a, b, _ = fit_line(pts)
    assert abs(abs(a) - abs(b)) < 0.02


def test_intersections_and_parallel_lines():
    assert np.allclose(intersect_lines(np.array([1, 0, 2.0]), np.array([0, 1, 5.0])), [2, 5])
    assert np.isnan(intersect_lines(np.array([1, 0, 2.0]), np.array([1, 0, 3.0]))).all()
    square = np.array([[0, -1, 0.0], [1, 0, 4.0], [0, 1, 4.0], [-1, 0, 0.0]])  # top, right, bottom, left
    assert np.allclose(quad_from_lines(square), [[0, 0], [4, 0], [4, 4], [0, 4]])


def test_orient_clockwise():
    cw = np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]])
    assert np.array_equal(orient_clockwise(cw), cw)
    assert np.array_equal(orient_clockwise(cw[::-1]), cw[::-1][[0, 3, 2, 1]])


def test_radial_peaks_pick_the_four_corners_of_a_square_profile():
    corners = np.array([[10, 10], [50, 10], [50, 50], [10, 50]], float)
    pts = np.concatenate([np.linspace(corners[k], corners[(k + 1) % 4], 40, endpoint=False) for k in range(4)])
    center, _dist, smooth = radial_profile(pts)
    assert np.allclose(center, [30, 30])
    peaks = radial_peaks(smooth)
    assert np.array_equal(peaks, [0, 40, 80, 120])
    groups = split_sides(len(pts), peaks, padding=0.1)
    assert [len(g) for g in groups] == [31] * 4  # 40 points, 5 dropped next to each peak
    assert all(not set(g) & {0, 40, 80, 120} for g in groups)


def test_radial_peaks_none_for_a_circle():
    a = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    _, _, smooth = radial_profile(np.stack([50 + 30 * np.cos(a), 50 + 30 * np.sin(a)], axis=1))
    assert radial_peaks(smooth) is None


@pytest.mark.parametrize("angle", [0.0, 10.0, 33.0, 45.0, 80.0])
def test_fit_quad_finds_corners_of_a_rotated_square_within_half_a_pixel(angle):
    c = np.array([60.0, 50.0])
    a = np.deg2rad(angle)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    truth = c + np.array([[-25, -25], [25, -25], [25, 25], [-25, 25.0]]) @ rot.T
    img = render_square((120, 100), truth, blur=0.6)
    cs = find_contours(threshold(img, window=11, offset=7))
    contour = max(cs, key=len).reshape(-1, 2)
    quad, split = fit_quad(contour)
    # match up to a cyclic shift
    best = min(np.abs(np.roll(quad, k, axis=0) - truth).max() for k in range(4))
    assert best < 0.75  # the binary contour's accuracy; stage 8 does the sub-pixel work
    assert len(split.peaks) == 4 and len(split.groups) == 4


def test_fit_quad_uses_the_hint_when_a_peak_is_missing():
    # a strongly foreshortened quad whose obtuse corners barely peak
    truth = np.array([[20, 40], [100, 38], [104, 52], [16, 54.0]])
    img = render_square((120, 100), truth)
    contour = max(find_contours(threshold(img, window=11, offset=7)), key=len).reshape(-1, 2)
    hint = cv2.approxPolyDP(contour, 0.05 * len(contour), True).reshape(-1, 2)
    res = fit_quad(contour, hint=hint)
    assert res is not None
    quad = res[0]
    best = min(np.abs(np.roll(quad, k, axis=0) - truth).max() for k in range(4))
    assert best < 1.0


@pytest.mark.parametrize("angle", [7.0, 38.0])
def test_fit_quad_on_a_long_contour_profiled_at_a_stride(angle):
    # a 260-px square: its 800-1000-point contour is profiled at every 6th-8th point
    # (profile_stride); the peaks still split the sides and the corners stay within the
    # binary contour's accuracy
    from visloc.markers.corners import profile_stride

    c = np.array([200.0, 190.0])
    a = np.deg2rad(angle)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    truth = c + np.array([[-130, -130], [130, -130], [130, 130], [-130, 130.0]]) @ rot.T
    img = render_square((400, 380), truth, supersample=2, blur=0.6)
    contour = max(find_contours(threshold(img, window=11, offset=7)), key=len).reshape(-1, 2)
    assert profile_stride(len(contour)) >= 6
    quad, split = fit_quad(contour)
    best = min(np.abs(np.roll(quad, k, axis=0) - truth).max() for k in range(4))
    assert best < 0.75
    assert len(split.distance) == len(split.smoothed) == len(contour)
