import cv2
import numpy as np

from visloc.markers.contours import CandidateFilter, filter_candidates, find_contours


def _ink(shape=(100, 120)):
    return np.zeros(shape, np.uint8)


def test_find_contours_returns_outer_borders_only():
    b = _ink()
    b[18:63, 18:63] = 255  # a ring 5 px wide: an outer border and a hole
    b[23:58, 23:58] = 0
    cs = find_contours(b)
    assert len(cs) == 1
    c = cs[0]
    c = c.reshape(-1, 2)
    assert c[:, 0].min() == 18 and c[:, 0].max() == 62  # the outer border, not the hole


def test_find_contours_keeps_a_component_inside_a_hole():
    b = _ink()
    cv2.rectangle(b, (5, 5), (110, 90), 255, thickness=2)
    cv2.rectangle(b, (40, 30), (70, 60), 255, thickness=-1)
    assert len(find_contours(b)) == 2


def test_find_contours_enclosing_keeps_only_regions_with_a_hole():
    b = _ink()
    b[10:40, 10:40] = 255  # a ring with a hole: kept
    b[15:35, 15:35] = 0
    b[60:90, 10:40] = 255  # a solid square: no hole
    b[60:90, 60:90] = 255  # a ring whose "hole" opens to the outside: no hole
    b[65:85, 65:95] = 0
    b[45:47, 100:102] = 255  # a speck
    assert len(find_contours(b)) == 4
    cs = find_contours(b, enclosing=True)
    assert len(cs) == 1
    c = cs[0].reshape(-1, 2)
    assert (c.min(axis=0) == [10, 10]).all() and (c.max(axis=0) == [39, 39]).all()


def test_filter_keeps_squares_and_rejects_other_shapes():
    b = _ink((200, 300))
    cv2.fillPoly(b, [np.array([[30, 30], [80, 35], [75, 85], [28, 80]])], 255)  # quad
    cv2.circle(b, (150, 60), 25, 255, -1)  # circle
    cv2.fillPoly(b, [np.array([[200, 30], [260, 40], [220, 90]])], 255)  # triangle
    cv2.rectangle(b, (30, 150), (33, 153), 255, -1)  # too small
    cv2.rectangle(b, (250, 150), (299, 199), 255, -1)  # touches the image border
    cv2.fillPoly(b, [np.array([[120, 120], [200, 120], [200, 190], [160, 150], [120, 190]])], 255)
    cands = filter_candidates(find_contours(b), b.shape)
    assert len(cands) == 1
    _contour, quad = cands[0]
    assert quad.shape == (4, 2)
    assert quad[:, 0].min() < 35 and quad[:, 1].max() > 75


def test_filter_perimeter_bounds_follow_the_image_size():
    b = _ink((200, 300))
    cv2.rectangle(b, (100, 100), (120, 120), 255, -1)
    cs = find_contours(b)
    assert len(filter_candidates(cs, b.shape)) == 1
    assert filter_candidates(cs, b.shape, CandidateFilter(min_perimeter_rate=0.5)) == []
