import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from visloc.markers.bits import (
    CellSample,
    cell_white_fractions,
    decode,
    otsu_threshold,
    read_bits,
    read_cells,
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
    thr[3:9] = [128.0, -3.0, 255.0, 300.0, np.nan, 254.5]  # whole, out of range and NaN thresholds
    for n, per_side in ((6, 4), (10, 32)):  # 102400 points a marker: OpenCV's maps in pieces
        a, b = (cell_white_fractions(image, quads[2:10], n, thr[2:10], per_side=per_side, native=e) for e in (True, False))
        assert a.shape == (8, n, n) and np.array_equal(a, b)
    # the compiled cell means (whole sums over the samples) are the numpy ones
    a, b = (sample_cells(image, quads[2:], 6, per_side=4, native=e) for e in (True, False))
    assert np.array_equal(a.cells, b.cells) and np.array_equal(a.ring, b.ring)
    assert np.array_equal(a.samples, b.samples)


def _quad(x0=10.0, x1=50.0):
    return np.array([[x0, x0], [x1, x0], [x1, x1], [x0, x1]])


def test_square_to_quad_takes_one_quad_and_refuses_other_shapes(rng):
    quads = rng.uniform(0, 100, (3, 4, 2))
    assert np.array_equal(square_to_quad(quads[1]), square_to_quad(quads)[1])
    assert square_to_quad(quads[1]).shape == (3, 3)
    with pytest.raises(ValueError, match=r"quads must be \(K, 4, 2\) or \(4, 2\), got shape \(3, 2\)"):
        square_to_quad(np.zeros((3, 2)))


def test_decode_refuses_values_other_than_0_and_1():
    d = load_dictionary("DICT_4X4_50")
    with pytest.raises(ValueError, match="bits must hold only 0 and 1, got 3"):
        decode(np.full((2, 4, 4), 3, np.uint8), d)
    with pytest.raises(ValueError, match="bits must hold only 0 and 1, got -1"):
        decode(-np.ones((1, 4, 4), np.int64), d)
    with pytest.raises(ValueError, match="bits must hold only 0 and 1, got 0.5"):
        decode(np.full((1, 4, 4), 0.5), d)
    grids = np.rot90(d.bits[[3, 9]], 1, axes=(1, 2))
    want = decode(grids, d)
    for other in (grids.astype(bool), grids.astype(np.int64), grids.astype(np.float64)):
        for a, b in zip(decode(other, d), want, strict=True):
            assert np.array_equal(a, b) and a.dtype == b.dtype


@pytest.mark.parametrize("name", ["DICT_4X4_50", "DICT_6X6_250", "DICT_7X7_1000", "DICT_APRILTAG_36h11"])
def test_compiled_and_numpy_decodes_are_the_same(name):
    """The compiled match (``_cells.match_codes``) gives numpy's ids, shifts, distances and
    verdicts: on the markers themselves in all four turns, on them with bits flipped (ties
    between codes included: the first closest wins in both) and on random grids."""
    from visloc.markers.bits import NATIVE_CELLS

    if not NATIVE_CELLS:
        pytest.skip("visloc.markers._cells was not built (no C compiler at install)")
    d = load_dictionary(name)
    rng = np.random.default_rng(7)
    s = d.marker_size
    turned = np.concatenate([np.rot90(d.bits[:40], r, axes=(1, 2)) for r in range(4)])
    flipped = turned ^ (rng.random(turned.shape) < 0.12)
    grids = np.concatenate([turned, flipped, rng.integers(0, 2, (500, s, s))]).astype(np.uint8)
    for bits in (grids, grids.astype(bool)):
        native, numpy_ = decode(bits, d, native=True), decode(bits, d, native=False)
        for a, b in zip(native, numpy_, strict=True):
            assert a.dtype == b.dtype and np.array_equal(a, b)
    assert native[3][:160].all() and np.array_equal(native[1][:160], np.repeat([0, 3, 2, 1], 40))
    with pytest.raises(ValueError, match="bits must hold only 0 and 1, got 2"):
        decode(np.full((2, s, s), 2, np.uint8), d, native=True)


def test_decode_of_no_candidates_is_empty():
    d = load_dictionary("DICT_4X4_50")
    ids, shift, hamming, ok = decode(np.zeros((0, 4, 4), np.uint8), d)
    for a, dtype in ((ids, np.intp), (shift, np.intp), (hamming, np.intp), (ok, np.bool_)):
        assert a.shape == (0,) and a.dtype == dtype
    with pytest.raises(ValueError, match=r"bits must be \(K, 4, 4\)"):
        decode(np.zeros((0, 5, 5), np.uint8), d)


@pytest.mark.filterwarnings("ignore:(invalid value|overflow) encountered in accumulate:RuntimeWarning")
def test_otsu_threshold_refuses_fewer_than_two_or_non_finite_values():
    with pytest.raises(ValueError, match=r"values must be .* m >= 2, got shape \(1, 1\)"):
        otsu_threshold(np.array([[5.0]]))
    for bad in ([1, np.nan, 3], [[1, 2, 3], [4, -np.inf, 6]], [np.inf, 1.0], [np.inf, -np.inf], [1e308, 1e308]):
        with pytest.raises(ValueError, match="values must be finite"):
            otsu_threshold(bad)
    thr, dark, bright = otsu_threshold(np.zeros((0, 5)))  # no rows: no splits
    assert thr.shape == dark.shape == bright.shape == (0,)


@pytest.mark.parametrize("native", _engines())
def test_cell_reads_refuse_a_border_that_leaves_no_bits(native):
    gray = np.full((60, 60), 128, np.uint8)
    with pytest.raises(ValueError, match="border must be >= 1, got 0"):
        read_cells(gray, _quad(), 6, border=0, native=native)
    with pytest.raises(ValueError, match=r"n must be more than 2 border \(4\), got 4"):
        read_cells(gray, _quad(), 4, border=2, native=native)
    sample = sample_cells(gray, _quad(), 6)
    with pytest.raises(ValueError, match="border must be >= 1, got 0"):
        read_bits(sample, border=0)


@pytest.mark.parametrize("native", _engines())
def test_cell_sampling_refuses_bad_counts_and_images(native):
    gray, quad = np.full((60, 60), 128, np.uint8), _quad()
    for read in (lambda **kw: sample_cells(gray, quad, native=native, **kw),
                 lambda **kw: cell_white_fractions(gray, quad, threshold=[100.0], native=native, **kw)):
        with pytest.raises(ValueError, match="n must be >= 1, got 0"):
            read(n=0)
        with pytest.raises(TypeError, match="n must be an integer, got float"):
            read(n=6.5)
        with pytest.raises(ValueError, match="per_side must be >= 1, got 0"):
            read(n=6, per_side=0)
    for image, error, message in ((np.zeros((0, 0), np.uint8), ValueError, r"non-empty \(H, W\).*\(0, 0\)"),
                                  (np.zeros((60, 60, 3), np.uint8), ValueError, r"\(H, W\).*\(60, 60, 3\)"),
                                  (np.zeros((60, 60)), TypeError, "gray must be a uint8 array, got float64")):
        with pytest.raises(error, match="gray"):
            sample_cells(image, quad, 6, native=native)
        with pytest.raises(error, match=message):
            cell_white_fractions(image, quad, 6, [100.0], native=native)
    with pytest.raises(ValueError, match=r"quads must be \(K, 4, 2\) or \(4, 2\), got shape \(3, 2\)"):
        sample_cells(gray, quad[:3], 6, native=native)


@pytest.mark.parametrize("native", _engines())
def test_cell_white_fractions_checks_corners_and_thresholds(native):
    gray = np.full((60, 60), 128, np.uint8)
    bad = _quad()
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match="finite"):
        cell_white_fractions(gray, bad, 6, [100.0], native=native)
    quads = np.stack([_quad(), _quad(5.0, 40.0), _quad(20.0, 55.0)])
    with pytest.raises(ValueError, match=r"threshold must hold one value per quad \(3\), got shape \(2,\)"):
        cell_white_fractions(gray, quads, 6, [100.0, 120.0], native=native)
    white = cell_white_fractions(gray, quads, 6, [100.0, 120.0, 200.0], native=native)
    assert np.array_equal(white, np.repeat([1.0, 1.0, 0.0], 36).reshape(3, 6, 6))
    assert cell_white_fractions(gray, np.zeros((0, 4, 2)), 6, [], native=native).shape == (0, 6, 6)


@pytest.mark.parametrize("native", [None, False])
def test_no_candidates_read_as_no_reads(native):
    # read_cells of an empty batch used to fail on a reshape (it has a branch for exactly this)
    img = np.zeros((50, 50), np.uint8)
    sample, read = read_cells(img, np.zeros((0, 4, 2)), 6, native=native)
    assert sample.cells.shape == (0, 6, 6) and read.bits.shape == (0, 4, 4) and read.valid.shape == (0,)
    assert read_bits(sample).threshold.shape == (0,)
