"""The batched corner split and line fits give what the single-contour stages give."""

import cv2
import numpy as np
import pytest

from visloc.markers import MarkerDetector
from visloc.markers.corners import fit_quad
from visloc.markers.corners_batch import NATIVE_QUADS, fit_quads
from visloc.synth import random_scene


@pytest.fixture(scope="module")
def contours_and_hints():
    det = MarkerDetector("DICT_4X4_50")
    contours = []
    for seed, difficulty in ((1, "easy"), (2, "hard"), (3, "small")):
        scene = random_scene(np.random.default_rng(seed), size=(320, 240), difficulty=difficulty)
        trace = det.trace(scene.image)
        contours += [c.contour for c in trace.candidates]
        # and raw borders of texture blobs: most are no quadrilateral
        contours += [c.reshape(-1, 2) for c in trace.passes[0].contours if 20 <= len(c) <= 300][:40]
    rng = np.random.default_rng(0)
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)  # circles: no four peaks, no hint either
    contours += [np.round(np.c_[30 + 12 * np.cos(t), 30 + 12 * np.sin(t)]).astype(np.int32)]
    hints = []
    for c in contours:
        a = cv2.approxPolyDP(c.reshape(-1, 1, 2).astype(np.int32), 0.05 * len(c), True).reshape(-1, 2)
        if len(a) != 4:
            a = cv2.boxPoints(cv2.minAreaRect(c.reshape(-1, 1, 2).astype(np.int32)))
        hints.append(a + rng.normal(0, 0.3, (4, 2)))
    return contours, np.array(hints)


ENGINES = [False, True] if NATIVE_QUADS else [False]  # numpy, and the compiled one when built


@pytest.mark.parametrize("native", ENGINES)
def test_batch_equals_single(contours_and_hints, native):
    contours, hints = contours_and_hints
    assert len(contours) > 50
    corners, ok, splits = fit_quads(contours, hints=hints, splits=True, native=native)
    found = 0
    for i, c in enumerate(contours):
        single = fit_quad(c, hint=hints[i])
        assert (single is not None) == bool(ok[i])
        if single is not None:
            found += 1
            np.testing.assert_allclose(corners[i], single[0], atol=1e-9)
            np.testing.assert_array_equal(splits[i].peaks, single[1].peaks)
            for g1, g2 in zip(splits[i].groups, single[1].groups, strict=True):
                np.testing.assert_array_equal(g1, g2)
        else:
            assert np.isnan(corners[i]).all() and splits[i] is None
    assert found > 30


@pytest.mark.parametrize("native", ENGINES)
def test_without_hints_and_empty(contours_and_hints, native):
    contours, _ = contours_and_hints
    corners, ok, splits = fit_quads(contours[:20], native=native)
    for i in range(20):
        single = fit_quad(contours[i])
        assert (single is not None) == bool(ok[i])
        if single is not None:
            np.testing.assert_allclose(corners[i], single[0], atol=1e-9)
    assert splits is None
    corners, ok, splits = fit_quads([], splits=True, native=native)
    assert corners.shape == (0, 4, 2) and ok.shape == (0,) and splits == []


@pytest.mark.parametrize("native", ENGINES)
def test_a_given_smoothing_width_is_used(contours_and_hints, native):
    contours, hints = contours_and_hints
    corners, ok, _ = fit_quads(contours[:30], hints=hints[:30], sigma=2.5, native=native)
    for i in range(30):
        single = fit_quad(contours[i], sigma=2.5, hint=hints[i])
        assert (single is not None) == bool(ok[i])
        if single is not None:
            np.testing.assert_allclose(corners[i], single[0], atol=1e-9)


def test_bad_input_is_named():
    square = np.array([[0, 0], [5, 0], [5, 5], [0, 5]], np.int32)
    with pytest.raises(ValueError, match="sigma"):
        fit_quads([square], sigma=0.0)
    if NATIVE_QUADS:
        with pytest.raises(ValueError, match="at least 4 points"):
            fit_quads([square[:3]], native=True)
