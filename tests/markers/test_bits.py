import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from visloc.markers.bits import (
    CellSample,
    decode,
    otsu_threshold,
    read_bits,
    sample_cells,
    square_to_quad,
)
from visloc.markers.dictionary import load_dictionary


def test_square_to_quad_maps_the_unit_square_onto_the_corners(rng):
    quads = rng.uniform(0, 100, (5, 4, 2))
    H = square_to_quad(quads)
    unit = np.array([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1.0]])
    mapped = np.einsum("kij,nj->kni", H, unit)
    assert np.allclose(mapped[..., :2] / mapped[..., 2:], quads, atol=1e-9)


def test_sample_cells_reads_a_drawn_marker():
    d = load_dictionary("DICT_4X4_50")
    cell = 8
    img = np.full((80, 80), 255, np.uint8)
    img[16:64, 16:64] = d.marker_image(7, cell_px=cell)  # 6 cells of 8 px, white margin of 2 cells
    # the marker's black square spans pixels 16..63: its outer corners are at 15.5 and 63.5
    quad = np.array([[15.5, 15.5], [63.5, 15.5], [63.5, 63.5], [15.5, 63.5]])
    sample = sample_cells(img, quad, 6)
    assert sample.cells.shape == (1, 6, 6) and sample.ring.shape == (1, 28)
    assert np.allclose(sample.ring, 255)
    valid, bits, margin, contrast, _ = read_bits(sample)
    assert valid[0] and np.array_equal(bits[0], d.bits[7])
    assert margin[0] > 0.95 and contrast[0] > 250
    ids, shift, hamming, ok = decode(bits, d)
    assert (ids[0], shift[0], hamming[0], ok[0]) == (7, 0, 0, True)


def test_sample_cells_empty_batch():
    s = sample_cells(np.zeros((10, 10), np.uint8), np.zeros((0, 4, 2)), 6)
    assert s.cells.shape == (0, 6, 6)


def test_otsu_splits_two_clusters():
    thr, dark, bright = otsu_threshold(np.array([[10, 12, 11, 200, 205, 199, 198.0]]))
    assert 12 < thr[0] < 198 and abs(dark[0] - 11) < 1 and abs(bright[0] - 200.5) < 1


def test_read_bits_rejects_white_border_and_low_contrast():
    n = 6
    cells = np.zeros((2, n, n))
    cells[0, 0, :] = 255  # a whole white border row: more than 35 % of 16 bits = 5 cells
    cells[0, :, 0] = 255
    cells[1] = 100 + np.random.default_rng(0).uniform(0, 4, (n, n))  # no contrast
    ring = np.full((2, 4 * n + 4), 255.0)
    ring[1] = 102
    valid = read_bits(CellSample(cells, ring))[0]
    assert not valid.any()


@settings(max_examples=30, deadline=None)
@given(marker_id=st.integers(0, 249), rot=st.integers(0, 3))
def test_decode_returns_the_corner_that_is_the_marker_top_left(marker_id, rot):
    d = load_dictionary("DICT_6X6_250")
    # a candidate whose first corner is the marker's corner `k` sees the grid rotated
    observed = np.rot90(d.bits[marker_id], rot)[None]
    ids, shift, hamming, ok = decode(observed, d)
    assert ok[0] and ids[0] == marker_id and hamming[0] == 0
    assert shift[0] == (4 - rot) % 4


def test_decode_rejects_bad_shapes():
    with pytest.raises(ValueError, match="bits"):
        decode(np.zeros((1, 4, 4), np.uint8), load_dictionary("DICT_6X6_250"))


def _engines():
    from visloc.markers.bits import NATIVE_CELLS

    return [False, True] if NATIVE_CELLS else [False]


def test_compiled_and_numpy_cell_reads_are_the_same():
    from visloc.markers.bits import NATIVE_CELLS, read_cells
    from visloc.synth import random_scene

    if not NATIVE_CELLS:
        pytest.skip("visloc.markers._cells was not built (no C compiler at install)")
    rng = np.random.default_rng(7)
    for i, difficulty in enumerate(("easy", "hard", "dark")):
        scene = random_scene(np.random.default_rng([4, i]), size=(320, 240), difficulty=difficulty, camera=True)
        quads = np.array([m.corners for m in scene.markers] + list(rng.uniform(-30, 350, (10, 4, 2))))
        for n, per_side, border in ((6, 3, 1), (6, 4, 1), (8, 4, 2)):  # 8 x 8 with 2 border cells: no marker
            (sa, ra), (sb, rb) = (read_cells(scene.image, quads, n, per_side=per_side, border=border,
                                             min_quiet_zone=0.25, native=e) for e in (True, False))
            for x, y in zip((sa.cells, sa.ring, sa.samples, *ra), (sb.cells, sb.ring, sb.samples, *rb), strict=True):
                assert np.array_equal(x, y)
            assert ra.valid.any() or border == 2  # the markers themselves read (through their own grid)


@pytest.mark.parametrize("native", _engines())
def test_cell_reads_refuse_corners_that_are_not_finite(native):
    from visloc.markers.bits import read_cells

    quad = np.array([[[10.0, 10.0], [50.0, 10.0], [50.0, np.nan], [10.0, 50.0]]])
    with pytest.raises(ValueError, match="finite"):
        read_cells(np.zeros((60, 60), np.uint8), quad, 6, native=native)


def test_compiled_sampling_maps_are_the_numpy_maps():
    # the compiled maps (SSE four points at a time where there is SSE) are bits._map_points'
    # single-precision operations: the same maps, so the same samples, degenerate quads too
    from visloc.markers.bits import NATIVE_CELLS, _area_grid, _map_points, cell_white_fractions

    if not NATIVE_CELLS:
        pytest.skip("visloc.markers._cells was not built (no C compiler at install)")
    from visloc.markers import _cells

    rng = np.random.default_rng(11)
    quads = rng.uniform(-40, 360, (40, 4, 2))
    quads[0] = [[5, 5], [5, 5], [5, 5], [5, 5]]  # all corners at one point
    quads[1] = quads[1][[0, 2, 1, 3]]  # self-intersecting
    for uv1 in (_area_grid(6, 4, 0.13), _area_grid(7, 5, 0.0)):  # 576 and 1225 points (a scalar tail)
        mx, my = (np.frombuffer(a, np.float32).reshape(len(quads), -1) for a in _cells.quad_maps(
            np.ascontiguousarray(quads), len(quads), np.ascontiguousarray(uv1[:2]), uv1.shape[1]))
        want_x, want_y = _map_points(quads, uv1)
        assert np.array_equal(mx, want_x, equal_nan=True) and np.array_equal(my, want_y, equal_nan=True)
    image = rng.integers(0, 256, (240, 320), dtype=np.uint8)
    thr = rng.uniform(60, 200, len(quads))
    for n, per_side in ((6, 4), (10, 32)):  # 102400 points a marker: OpenCV's maps in pieces
        a, b = (cell_white_fractions(image, quads[2:6], n, thr[2:6], per_side=per_side, native=e) for e in (True, False))
        assert a.shape == (4, n, n) and np.array_equal(a, b)
