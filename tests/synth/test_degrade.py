"""The camera degradations of visloc.synth.textures.degrade, the fast-noise path of the
closed-loop simulation's camera against the float64 path the stored renders use."""

from __future__ import annotations

import numpy as np

from visloc.synth.textures import degrade


def _image() -> np.ndarray:
    y, x = np.mgrid[0:240, 0:320]
    img = 128.0 + 140.0 * np.sin(x / 17.0) * np.cos(y / 11.0)  # beyond 0-255 at the peaks: clipped
    img[::7, ::5] += 0.5  # exact halves: rounded to even on both paths
    return img.astype(np.float32)


def test_fast_noise_rounds_and_clips_as_the_float64_path():
    img = _image()
    slow, _ = degrade(img, np.random.default_rng(0))
    fast, _ = degrade(img, np.random.default_rng(0), fast_noise=True)
    assert slow.dtype == fast.dtype == np.uint8
    np.testing.assert_array_equal(fast, slow)  # no noise: the same grey levels
    gained, _ = degrade(img, np.random.default_rng(0), gain=0.7, fast_noise=True)
    want, _ = degrade(img, np.random.default_rng(0), gain=0.7)
    assert np.abs(gained.astype(int) - want).max() <= 1  # float32 against float64 products


def test_fast_noise_is_gaussian_seeded_and_new_each_frame():
    flat = np.full((240, 320), 100.0, np.float32)
    rng = np.random.default_rng(4)
    a, _ = degrade(flat, rng, noise_sigma=2.0, fast_noise=True)
    b, _ = degrade(flat, rng, noise_sigma=2.0, fast_noise=True)
    again, _ = degrade(flat, np.random.default_rng(4), noise_sigma=2.0, fast_noise=True)
    np.testing.assert_array_equal(a, again)  # the seed decides the draw
    assert (a != b).mean() > 0.5  # the next frame draws new noise
    d = a.astype(float) - 100.0
    assert abs(d.mean()) < 0.05 and abs(d.std() - np.sqrt(4.0 + 1.0 / 12.0)) < 0.05  # sigma 2, then rounded
