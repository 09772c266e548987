import numpy as np
import pytest

from tests.conftest import render_square
from visloc.markers.refine import edge_offsets, refine_quads, sample_edge_profiles


def test_edge_offsets_exact_for_an_area_sampled_step():
    # pixel k covers [k - 0.5, k + 0.5]; an edge at e inside the window -> exact recovery
    for e in (-1.3, -0.5, 0.0, 0.21, 0.77, 1.4):
        s = np.arange(-3, 4, dtype=np.float64)
        v = np.clip(s + 0.5 - e, 0, 1)  # fraction of each pixel beyond the edge (bright)
        prof = 20 + 200 * v
        assert abs(edge_offsets(prof, 20.0, 220.0) - e) < 1e-9


def test_sample_edge_profiles_shapes_and_outward_normals():
    img = render_square((100, 100), [[30, 30], [70, 30], [70, 70], [30, 70]])
    quad = np.array([[[30, 30], [70, 30], [70, 70], [30, 70.0]]])
    base, normals, prof = sample_edge_profiles(img, quad, radius=2, count=10)
    assert base.shape == (1, 4, 10, 2) and normals.shape == (1, 4, 2) and prof.shape == (1, 4, 10, 5)
    assert np.allclose(normals[0], [[0, -1], [1, 0], [0, 1], [-1, 0]])
    assert (prof[..., 0] < prof[..., -1]).all()  # dark inside, bright outside


@pytest.mark.parametrize("blur", [0.0, 0.8, 1.5])
def test_refine_recovers_subpixel_corners(blur, rng):
    for _ in range(5):
        c = rng.uniform(45, 55, 2)
        a = rng.uniform(0, np.pi / 2)
        rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        half = rng.uniform(15, 25)
        truth = c + np.array([[-1, -1], [1, -1], [1, 1], [-1, 1.0]]) * half @ rot.T
        truth = truth + rng.normal(0, 1.0, (4, 2))  # perspective-like irregular quad
        img = render_square((100, 100), truth, blur=blur)
        start = truth + rng.uniform(-0.8, 0.8, (4, 2))
        out, ok = refine_quads(img, start[None], radius=3, iterations=3)
        assert ok[0]
        err = np.sqrt(((out[0] - truth) ** 2).sum(axis=1)).max()
        assert err < 0.06, err


def test_refine_fails_cleanly_without_contrast():
    img = np.full((60, 60), 128, np.uint8)
    out, ok = refine_quads(img, np.array([[[10, 10], [40, 10], [40, 40], [10, 40.0]]]), radius=2)
    assert not ok[0]
    assert np.allclose(out[0], [[10, 10], [40, 10], [40, 40], [10, 40]])
