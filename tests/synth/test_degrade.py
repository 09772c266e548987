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


def test_whole_noise_on_uint8_frames_has_the_rounded_gaussians_distribution():
    """A uint8 frame with nothing else to do takes its noise as whole grey levels: each
    level's share is the rounded Gaussian's, clipped at 0 and 255 as the float path clips."""
    from math import erf, sqrt

    rng = np.random.default_rng(5)
    flat = np.full((240, 320), 100, np.uint8)
    a, _ = degrade(flat, rng, noise_sigma=2.0, fast_noise=True)
    b, _ = degrade(flat, rng, noise_sigma=2.0, fast_noise=True)
    again, _ = degrade(flat, np.random.default_rng(5), noise_sigma=2.0, fast_noise=True)
    assert a.dtype == np.uint8
    np.testing.assert_array_equal(a, again)
    assert (a != b).mean() > 0.5
    d = np.concatenate([a.ravel(), b.ravel()]).astype(int) - 100
    counts = np.bincount(d + 20, minlength=41)
    n = d.size
    for k in range(-5, 6):  # every level's share within 4 binomial sigma of its probability
        p = 0.5 * (erf((k + 0.5) / (2.0 * sqrt(2.0))) - erf((k - 0.5) / (2.0 * sqrt(2.0))))
        assert abs(counts[k + 20] - n * p) < 4.0 * sqrt(n * p * (1 - p)) + 1, k
    dark, _ = degrade(np.zeros((240, 320), np.uint8), rng, noise_sigma=2.0, fast_noise=True)
    want = 0.5 * (1 + erf(0.5 / (2.0 * sqrt(2.0))))  # P(noise rounds to <= 0): clipped to 0
    assert abs((dark == 0).mean() - want) < 0.01
    np.testing.assert_array_equal(degrade(flat, rng, fast_noise=True)[0], flat)  # no noise: unchanged
