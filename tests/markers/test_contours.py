import cv2
import numpy as np
import pytest

from visloc.markers.contours import (
    CandidateFilter,
    filter_candidates,
    find_candidates,
    find_contours,
)


def _native():
    from visloc.markers.contours import NATIVE_BORDERS

    return NATIVE_BORDERS


def _engines():
    return [False, True] if _native() else [False]


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


@pytest.mark.parametrize("native", _engines())
def test_filter_keeps_squares_and_rejects_other_shapes(native):
    b = _ink((200, 300))
    cv2.fillPoly(b, [np.array([[30, 30], [80, 35], [75, 85], [28, 80]])], 255)  # quad
    cv2.circle(b, (150, 60), 25, 255, -1)  # circle
    cv2.fillPoly(b, [np.array([[200, 30], [260, 40], [220, 90]])], 255)  # triangle
    cv2.rectangle(b, (30, 150), (33, 153), 255, -1)  # too small
    cv2.rectangle(b, (250, 150), (299, 199), 255, -1)  # touches the image border
    cv2.fillPoly(b, [np.array([[120, 120], [200, 120], [200, 190], [160, 150], [120, 190]])], 255)
    cands = filter_candidates(find_contours(b), b.shape, native=native)
    assert len(cands) == 1
    _contour, quad = cands[0]
    assert quad.shape == (4, 2)
    assert quad[:, 0].min() < 35 and quad[:, 1].max() > 75


def test_filter_perimeter_bounds_follow_the_image_size():
    b = _ink((200, 300))
    cv2.rectangle(b, (100, 100), (120, 120), 255, -1)
    cs = find_contours(b)
    assert len(filter_candidates(cs, b.shape)) == 1
    assert filter_candidates(cs, b.shape, params=CandidateFilter(min_perimeter_rate=0.5)) == []


def _reference(binary, lo=1, hi=10**9):
    from visloc.markers.contours import outer_borders

    cs, holes = outer_borders(binary)
    return [cs[i].reshape(-1, 2) for i in np.flatnonzero(holes) if lo <= len(cs[i]) <= hi]


@pytest.mark.parametrize("native", _engines())
def test_enclosing_borders_match_opencv_point_for_point(native):
    from visloc.markers.binarize import blur, threshold, to_gray
    from visloc.markers.contours import enclosing_borders
    from visloc.synth import random_scene

    rng = np.random.default_rng(5)
    images = [((rng.random((rng.integers(1, 30), rng.integers(1, 30))) < p) * 255).astype(np.uint8)
              for p in (0.3, 0.5, 0.7) for _ in range(100)]
    for k, name in enumerate(["easy", "hard", "small", "empty"]):
        gray = to_gray(random_scene(k, size=(320, 240), difficulty=name).image)
        images.append(threshold(blur(gray, sigma=0.6), window=9, offset=7))
    images.append(np.full((7, 9), 255, np.uint8))  # ink everywhere, touching the image border
    images.append(np.zeros((5, 5), np.uint8))
    n_found = 0
    for b in images:
        got = enclosing_borders(b, native=native)
        want = _reference(b)
        assert len(got) == len(want)
        assert all(g.dtype == np.int32 and np.array_equal(g, w) for g, w in zip(got, want, strict=True))
        n_found += len(got)
        sub = enclosing_borders(b, min_len=8, max_len=40, native=native)
        assert all(np.array_equal(g, w) for g, w in zip(sub, _reference(b, 8, 40), strict=True))
    assert n_found > 100  # the comparison saw many borders


@pytest.mark.parametrize("native", _engines())
def test_enclosing_borders_nested_regions(native):
    from visloc.markers.contours import enclosing_borders

    b = _ink((60, 60))
    b[2:58, 2:58] = 255  # a ring ...
    b[6:54, 6:54] = 0
    b[12:48, 12:48] = 255  # ... with a ring in its hole ...
    b[16:44, 16:44] = 0
    b[25:35, 25:35] = 255  # ... with a solid square in that one's hole
    cs = enclosing_borders(b, native=native)
    assert sorted(int(c[:, 0].min()) for c in cs) == [2, 12]


def test_enclosing_borders_rejects_bad_input():
    from visloc.markers.contours import enclosing_borders

    with pytest.raises(ValueError, match="binary"):
        enclosing_borders(np.zeros((4, 4, 3), np.uint8))
    with pytest.raises(ValueError, match="binary"):
        enclosing_borders(np.zeros((4, 4), np.float32))


def test_the_compiled_follower_is_used_when_built():
    from visloc.markers import contours

    assert contours.NATIVE_BORDERS == (contours._borders is not None)
    if not contours.NATIVE_BORDERS:
        with pytest.raises(RuntimeError, match="not built"):
            contours.enclosing_borders(_ink(), native=True)


@pytest.mark.skipif(not _native(), reason="compares the compiled filter with the OpenCV calls")
def test_compiled_filter_keeps_what_opencv_keeps():
    from visloc.markers.binarize import blur, threshold, to_gray
    from visloc.markers.contours import outer_borders
    from visloc.synth import random_scene

    kept = 0
    for k, name in enumerate(["easy", "hard", "small", "empty", "easy"]):
        gray = to_gray(random_scene(k, size=(320, 240), difficulty=name).image)
        for window in (5, 9, 15):
            b = threshold(blur(gray, sigma=0.6), window=window, offset=7)
            cs = [c.reshape(-1, 2) for c in outer_borders(b)[0]]  # texture too: most are rejected
            for params in (CandidateFilter(), CandidateFilter(approx_rate=0.03, min_solidity=0.9)):
                want = filter_candidates(cs, b.shape, params=params, native=False)
                got = filter_candidates(cs, b.shape, params=params, native=True)
                assert len(got) == len(want)
                for (c1, q1), (c2, q2) in zip(got, want, strict=True):
                    assert np.array_equal(c1, c2) and np.array_equal(q1, q2)
                kept += len(want)
    assert kept > 20


@pytest.mark.parametrize("native", _engines())
def test_find_candidates_is_stages_4_and_5_in_one(native):
    from visloc.markers.binarize import threshold
    from visloc.markers.contours import enclosing_borders, perimeter_bounds
    from visloc.synth import random_scene

    binary = threshold(random_scene(5, size=(320, 240), difficulty="easy").image, window=9, offset=7)
    params = CandidateFilter()
    both = find_candidates(binary, params=params, native=native)
    lo, hi = perimeter_bounds(binary.shape, params=params)
    apart = filter_candidates(enclosing_borders(binary, min_len=lo, max_len=hi, native=native),
                              binary.shape, params=params, native=native)
    assert len(both) == len(apart) > 0
    for (c1, q1), (c2, q2) in zip(both, apart, strict=True):
        assert np.array_equal(c1, c2) and np.array_equal(q1, q2)
    assert find_candidates(np.zeros((50, 60), np.uint8), params=params, native=native) == []


@pytest.mark.parametrize("native", _engines())
def test_a_marker_seen_edge_on_is_a_candidate(native):
    from visloc.markers.contours import enclosing_borders

    b = _ink((120, 160))
    quad = np.array([[20, 40], [140, 52], [142, 64], [22, 52]], np.int32)  # 120 x 12 px
    cv2.fillConvexPoly(b, quad, 255)
    cv2.fillConvexPoly(b, np.array([[40, 46], [120, 54], [121, 58], [41, 50]], np.int32), 0)  # its cells
    contours = enclosing_borders(b, native=native)
    assert len(contours) == 1
    n = len(contours[0])
    assert len(cv2.approxPolyDP(contours[0], 0.05 * n, True)) < 4  # the usual tolerance spans its width
    found = filter_candidates(contours, b.shape, params=CandidateFilter(), native=native)
    assert len(found) == 1
    assert np.abs(np.sort(found[0][1], axis=0) - np.sort(quad, axis=0)).max() <= 2
    assert filter_candidates(contours, b.shape, params=CandidateFilter(min_compactness=0.45), native=native) == []
