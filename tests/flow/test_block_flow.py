import numpy as np
import pytest

from tests.flow.conftest import moved
from visloc.flow import block_flow, default_block


@pytest.mark.parametrize("dx, dy", [(3, 0), (0, -2), (7, 5), (-12, 9), (20, -15)])
def test_integer_shifts(dx, dy):
    a, b = moved(dx, dy)
    f = block_flow(a, b)
    good = f.confidence > 0.2
    assert good.sum() >= 0.5 * len(good)
    assert np.abs(np.median(f.vectors[good], axis=0) - (dx, dy)).max() < 0.02


@pytest.mark.parametrize("dx, dy", [(0.25, 0.0), (1.5, -0.5), (5.5, 2.25), (-3.75, 0.6)])
@pytest.mark.parametrize("mode", ["gradient", "intensity"])
def test_subpixel_shifts(dx, dy, mode):
    a, b = moved(dx, dy)
    f = block_flow(a, b, mode=mode)
    good = f.confidence > 0.2
    err = f.vectors[good] - (dx, dy)
    assert np.abs(np.median(err, axis=0)).max() < 0.08
    assert np.percentile(np.abs(err), 90) < 0.2


def test_layout_and_defaults():
    a, b = moved(2, 1)
    assert default_block(a.shape) == 40  # the report's 40 x 40 blocks at 320 x 240
    f = block_flow(a, b)
    assert f.block == 40 and f.image_size == (320, 240)
    assert f.centers.shape == (48, 2) and f.vectors.shape == (48, 2) and f.confidence.shape == (48,)
    assert np.allclose(f.centers[0], (19.5, 19.5))
    g = block_flow(a, b, step=20)  # overlapping blocks
    assert len(g.confidence) == 11 * 15


def test_identical_and_uniform_frames():
    a, _ = moved()
    f = block_flow(a, a)
    good = f.confidence > 0.2
    assert good.any() and np.abs(f.vectors[good]).max() < 1e-6
    flat = np.full((240, 320), 90, np.uint8)
    g = block_flow(flat, flat)
    assert (g.confidence == 0).all() and np.isfinite(g.vectors).all()


@pytest.mark.parametrize(
    "prev, curr, exc, word",
    [
        (np.zeros((240, 320), np.uint8), np.zeros((240, 321), np.uint8), ValueError, "same size"),
        (np.zeros((240, 320), np.int32), np.zeros((240, 320), np.uint8), TypeError, "prev"),
        (np.zeros((8, 8), np.uint8), np.zeros((8, 8), np.uint8), ValueError, "16 x 16"),
    ],
)
def test_bad_frames(prev, curr, exc, word):
    with pytest.raises(exc, match=word):
        block_flow(prev, curr)


def test_bad_options():
    a, b = moved(1, 1)
    with pytest.raises(ValueError, match="mode"):
        block_flow(a, b, mode="sobel")
    with pytest.raises(ValueError, match="step"):
        block_flow(a, b, block=40, step=30)
    with pytest.raises(ValueError, match="block"):
        block_flow(a, b, block=500)


def test_band_means_match_a_replicate_padded_reference():
    # the band sums come from a summed-area table; bands shifted past the frame repeat its
    # edge rows and columns, as cv2.BORDER_REPLICATE padding would
    import cv2

    from visloc.flow.block import _groups, _integral

    rng = np.random.default_rng(0)
    for _ in range(100):
        h, w = (int(v) for v in rng.integers(30, 200, 2))
        step = int(rng.integers(4, 20))
        rows, cols = (h // step) * step, (w // step) * step
        img = rng.integers(0, 256, (h, w), dtype=np.uint8)
        sx, sy = (int(v) for v in rng.integers(-2 * step, 2 * step, 2))
        m = max(abs(sx), abs(sy)) + 1
        pad = cv2.copyMakeBorder(img, m, m, m, m, cv2.BORDER_REPLICATE).astype(np.float64)
        gx = pad[m + sy : m + sy + rows, m : m + cols].reshape(rows // step, step, cols).mean(axis=1)
        gy = pad[m : m + rows, m + sx : m + sx + cols].reshape(rows, cols // step, step).mean(axis=2).T
        ax, ay = (v / step for v in _groups(_integral(img), img, step, rows, cols, sx, sy))
        assert np.abs(ax - gx).max() < 1e-3 and np.abs(ay - gy).max() < 1e-3


@pytest.mark.parametrize("step", [20, 10])
@pytest.mark.parametrize("mode", ["gradient", "intensity"])
def test_overlapping_blocks_measure_the_shift(step, mode):
    # overlapping blocks sum their costs over several step-long chunks of the profiles
    a, b = moved(4.5, -2.25)
    f = block_flow(a, b, block=40, step=step, mode=mode)
    good = f.confidence > 0.2
    assert good.sum() >= 0.5 * len(good)
    assert np.abs(np.median(f.vectors[good], axis=0) - (4.5, -2.25)).max() < 0.08


def test_global_shift_is_the_brute_force_best():
    from visloc.flow.block import _global_shift

    rng = np.random.default_rng(1)
    for _ in range(50):
        n = int(rng.integers(40, 400))
        search = int(rng.integers(1, 80))
        p = np.round(rng.normal(0, 500, n).cumsum())
        q = np.roll(p, int(rng.integers(-20, 20))) + np.round(rng.normal(0, 50, n))
        s = min(search, n // 3)
        cost = [((q[s + d : n - s + d] - p[s : n - s]) ** 2).sum() for d in range(-s, s + 1)]
        assert _global_shift(p, q, search) == int(np.argmin(cost)) - s


@pytest.mark.parametrize("block, step", [(40, 40), (40, 20), (40, 10), (40, 1), (9, 3), (12, 1)])
@pytest.mark.parametrize("seg_len_short", [0, 1])
def test_segment_sums_match_a_direct_sum(block, step, seg_len_short):
    # every segment [j step, j step + seg_len) summed: whole chunks plus a partial one
    from visloc.flow.block import _layout, _segment_sums

    rows, cols = 3 * block, 4 * block
    seg_len = block - seg_len_short  # gradient profiles are one sample shorter than the block
    lay = _layout(rows, cols, block, step, 2, cols - seg_len_short, rows - seg_len_short, seg_len)
    rng = np.random.default_rng(block * 100 + step)
    e = rng.normal(size=(5, 7, lay.length))
    got = _segment_sums(e, lay, block // step, seg_len)
    nseg = (lay.length - block) // step + 1
    want = np.stack([e[..., j * step : j * step + seg_len].sum(axis=-1) for j in range(nseg)], axis=-1)
    assert got.shape == want.shape
    assert np.allclose(got, want, rtol=1e-5, atol=1e-4)


def test_one_pixel_step_measures_the_shift():
    a, b = moved(2.5, -1.25)
    a, b = a[60:140, 80:200].copy(), b[60:140, 80:200].copy()
    f = block_flow(a, b, block=24, step=1)
    good = f.confidence > 0.2
    assert good.sum() >= 0.5 * len(good)
    assert np.abs(np.median(f.vectors[good], axis=0) - (2.5, -1.25)).max() < 0.08


def test_a_prior_narrows_the_whole_image_match():
    from visloc.flow.block import PRIOR_SEARCH, _global_shift

    a, b = moved(7, -5)
    free = block_flow(a, b)
    near = block_flow(a, b, prior=(6.4, -4.2))  # within PRIOR_SEARCH: the same match
    np.testing.assert_array_equal(free.vectors, near.vectors)
    far = block_flow(a, b, prior=(-12.0, 9.0))  # the true shift is out of its reach
    assert (far.confidence > 0.2).sum() < (free.confidence > 0.2).sum()
    # _global_shift keeps to the window around `near`
    rng = np.random.default_rng(2)
    p = np.round(rng.normal(0, 500, 200).cumsum())
    q = np.roll(p, 9)
    assert _global_shift(p, q, 40) == 9
    assert abs(_global_shift(p, q, 40, near=-10) + 10) <= PRIOR_SEARCH
    with pytest.raises(ValueError, match="prior"):
        block_flow(a, b, prior=(1.0, float("nan")))
