import cv2
import numpy as np
import pytest

from tests.conftest import render_square
from visloc.markers.refine import (
    NATIVE_REFINE,
    edge_contrast,
    edge_offsets,
    edge_points,
    refine_quads,
    sample_edge_profiles,
)
from visloc.synth.camera import srgb_encode

ENGINES = [False, True] if NATIVE_REFINE else [False]  # numpy, and the compiled one when built


def _turned_square(rng):
    """The corners (4, 2) of a square 30-50 px wide near (50, 50), turned by up to 90 degrees."""
    c = rng.uniform(45, 55, 2)
    a = rng.uniform(0, np.pi / 2)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    return c + np.array([[-1, -1], [1, -1], [1, 1], [-1, 1.0]]) * rng.uniform(15, 25) @ rot.T


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


def test_edge_contrast_is_largest_on_the_edges():
    truth = np.array([[30, 30], [70, 30], [70, 70], [30, 70.0]])
    img = render_square((100, 100), truth, blur=1.0)
    c = np.array([[50.0, 50.0]])
    grown = lambda d: c + (truth - c) * (20 + d) / 20  # each side d px outward
    quads = np.array([grown(d) for d in (-4, -2, 0, 2, 4)] + [truth + [3.0, 0.0]])
    got = edge_contrast(img, quads)
    assert got.shape == (6,) and int(np.argmax(got)) == 2
    assert got[2] > 0.6 * (float(img.max()) - float(img.min()))  # 1-2 px either side of a 1 px blur
    assert np.all(got[[0, 1, 3, 4, 5]] < got[2] - 10)
    assert edge_contrast(img, truth).shape == (1,)
    assert edge_contrast(255 - img, truth)[0] < 0  # bright on dark: the sides read inside out
    with pytest.raises(ValueError, match="count"):
        edge_contrast(img, truth, count=0)
    with pytest.raises(ValueError, match="finite"):
        edge_contrast(img, truth * np.nan)


def test_edge_points_lie_on_the_sides_of_a_blurred_square():
    truth = np.array([[30.3, 28.6], [71.2, 31.1], [69.4, 72.5], [28.8, 69.7]])
    img = render_square((100, 100), truth, blur=1.0)
    start = truth + [[0.3, -0.2], [-0.25, 0.3], [0.2, 0.2], [-0.3, -0.1]]  # a quad off by 0.4 px
    pts, normals, offsets, good = edge_points(img, start, radius=4, count=20, response="linear")
    assert pts.shape == (1, 4, 20, 2) and offsets.shape == good.shape == (1, 4, 20) and good.all()
    assert np.allclose(np.linalg.norm(normals[0], axis=1), 1.0)
    for s in range(4):
        a, b = truth[s], truth[(s + 1) % 4]
        n = np.array([b[1] - a[1], a[0] - b[0]]) / np.linalg.norm(b - a)
        assert np.abs((pts[0, s] - a) @ n).max() < 0.03  # on the true side
        assert np.abs(offsets[0, s]).max() > 0.05  # found off the quad given


@pytest.mark.parametrize("native", ENGINES)
@pytest.mark.parametrize("blur", [0.0, 0.8, 1.5])
def test_refine_recovers_subpixel_corners(blur, native, rng):
    for _ in range(5):
        truth = _turned_square(rng) + rng.normal(0, 1.0, (4, 2))  # perspective-like irregular quad
        img = render_square((100, 100), truth, blur=blur)
        start = truth + rng.uniform(-0.8, 0.8, (4, 2))
        out, ok = refine_quads(img, start[None], radius=3, iterations=3, response="linear", native=native)
        assert ok[0]
        err = np.sqrt(((out[0] - truth) ** 2).sum(axis=1)).max()
        assert err < 0.06, err


@pytest.mark.parametrize("native", ENGINES)
def test_more_passes_follow_blur_wider_than_the_profiles(native):
    # blur (sigma 2 px) spreads each edge beyond the 7 px profiles: a pass moves a side only
    # part of the way, two passes from 1.5 px off stop short; passing on until the corners
    # settle (max_iterations) reaches the edges
    rng = np.random.default_rng(3)
    two, more = [], []
    for _ in range(6):
        truth = _turned_square(rng)
        img = render_square((100, 100), truth, blur=2.0)
        start = truth + rng.uniform(-1.5, 1.5, (4, 2))
        for max_iterations, errs in ((None, two), (8, more)):
            out, ok = refine_quads(img, start[None], radius=3, max_iterations=max_iterations, response="linear",
                                   native=native)
            assert ok[0]
            errs.append(np.abs(out[0] - truth).max())
    assert max(two) > 0.2, two
    assert max(more) < 0.15, more


def test_refine_rejects_bad_iteration_limits():
    img = render_square((60, 60), [[20, 20], [40, 20], [40, 40], [20, 40]])
    quad = np.array([[20, 20], [40, 20], [40, 40], [20, 40.0]])
    with pytest.raises(ValueError, match="max_iterations"):
        refine_quads(img, quad, max_iterations=101)
    with pytest.raises(ValueError, match="tolerance"):
        refine_quads(img, quad, max_iterations=4, tolerance=-1.0)


@pytest.mark.parametrize("native", ENGINES)
@pytest.mark.parametrize("blur", [0.8, 1.5])
def test_refine_measures_edges_in_linear_light_on_srgb_images(blur, native, rng):
    # a camera blurs light, then encodes it with the sRGB curve: read through the sRGB
    # response the corners are as accurate as on a linear image; read as linear they are not
    srgb_err, linear_err = [], []
    for _ in range(5):
        truth = _turned_square(rng)
        linear = render_square((100, 100), truth, dark=3, bright=200, blur=0).astype(np.float64)
        linear = cv2.GaussianBlur(linear, (0, 0), blur)
        img = np.round(255 * srgb_encode(linear / 255)).astype(np.uint8)
        start = truth + rng.uniform(-0.8, 0.8, (4, 2))
        for response, errs in (("srgb", srgb_err), ("linear", linear_err)):
            out, ok = refine_quads(img, start[None], radius=3, iterations=3, response=response, native=native)
            assert ok[0]
            errs.append(np.sqrt(((out[0] - truth) ** 2).sum(axis=1)).max())
    assert max(srgb_err) < 0.06, srgb_err
    assert min(linear_err) > 0.15, linear_err  # the bias the response removes


@pytest.mark.parametrize("native", ENGINES)
def test_dark_low_contrast_squares_refine_through_the_srgb_response(native):
    # a dim camera frame, about 8 vs 33 grey levels: about 3 levels apart in linear light,
    # but the contrast test counts grey levels, so the square still refines
    cover = render_square((80, 80), [[20, 20], [60, 20], [60, 60], [20, 60]], dark=0, bright=255) / 255.0
    linear = cv2.GaussianBlur(0.6 + (3.8 - 0.6) * cover, (0, 0), 0.8)
    img = np.round(255 * srgb_encode(linear / 255)).astype(np.uint8)
    assert 6 <= img.min() and img.max() <= 35
    out, ok = refine_quads(img, np.array([[[20.6, 19.5], [59.5, 20.4], [60.3, 60.5], [19.6, 59.6]]]), radius=3,
                           native=native)
    assert ok[0]
    assert np.abs(out[0] - [[20, 20], [60, 20], [60, 60], [20, 60]]).max() < 0.2


def test_unknown_response_is_refused():
    img = render_square((60, 60), [[20, 20], [40, 20], [40, 40], [20, 40]])
    with pytest.raises(ValueError, match="response"):
        refine_quads(img, np.array([[[20, 20], [40, 20], [40, 40], [20, 40.0]]]), response="gamma")


@pytest.mark.parametrize("native", ENGINES)
def test_refine_fails_cleanly_without_contrast(native):
    img = np.full((60, 60), 128, np.uint8)
    out, ok = refine_quads(img, np.array([[[10, 10], [40, 10], [40, 40], [10, 40.0]]]), radius=2, native=native)
    assert not ok[0]
    assert np.allclose(out[0], [[10, 10], [40, 10], [40, 40], [10, 40]])


@pytest.mark.skipif(not NATIVE_REFINE, reason="compares the compiled stage 8 with the numpy one")
@pytest.mark.parametrize("bend", [False, True])
def test_compiled_and_numpy_refinement_agree_on_rendered_markers(bend):
    from visloc.markers import MarkerDetector
    from visloc.markers.binarize import to_gray
    from visloc.synth import random_scene

    det = MarkerDetector("DICT_4X4_50", refine=False)
    diffs, n_quads = [], 0
    for seed, difficulty in ((1, "easy"), (2, "hard"), (3, "small"), (4, "easy")):
        scene = random_scene(np.random.default_rng(seed), size=(320, 240), difficulty=difficulty)
        gray = to_gray(scene.image)
        quads = np.array([d.corners for d in det.detect(gray)])
        if not len(quads):
            continue
        a, ok_a = refine_quads(gray, quads, radius=2, bend=bend, native=False)
        b, ok_b = refine_quads(gray, quads, radius=2, bend=bend, native=True)
        assert (ok_a == ok_b).all()
        diffs.append(np.abs(a - b)[ok_a].ravel())
        n_quads += len(quads)
    d = np.concatenate(diffs)
    assert n_quads >= 8
    assert np.median(d) < 0.01 and d.max() < 0.15  # interpolation differs (module docstring)


def test_refine_rejects_bad_input():
    img = np.zeros((20, 20), np.uint8)
    quad = np.array([[[5, 5], [15, 5], [15, 15], [5, 15.0]]])
    with pytest.raises(ValueError, match="gray"):
        refine_quads(np.zeros((20, 20, 3), np.uint8), quad)
    with pytest.raises(ValueError, match="radius"):
        refine_quads(img, quad, radius=0)
    with pytest.raises(ValueError, match="count"):
        refine_quads(img, quad, count=1)


@pytest.mark.parametrize("native", ENGINES)
def test_corners_or_radii_it_cannot_use_are_refused(native):
    gray = np.zeros((100, 100), np.uint8)
    gray[30:70, 30:70] = 255
    quad = np.array([[[29.5, 29.5], [69.5, 29.5], [69.5, 69.5], [29.5, 69.5]]])
    bad = quad.copy()
    bad[0, 1, 1] = np.nan
    with pytest.raises(ValueError, match="finite"):
        refine_quads(gray, bad, native=native)
    with pytest.raises(ValueError, match="radius"):
        refine_quads(gray, quad, radius=10**9, native=native)  # the work grows with it


@pytest.mark.skipif(not NATIVE_REFINE, reason="calls the compiled stage 8 directly")
def test_the_compiled_stage_checks_its_own_arguments_and_far_corners_read_the_border():
    from visloc.markers import _refine
    from visloc.markers.response import response_lut

    gray = np.zeros((100, 100), np.uint8)
    lut = response_lut("srgb")
    for quad, r, word in ((np.full((1, 4, 2), np.nan), 2, "finite"), (np.full((1, 4, 2), 50.0), 10**9, "radius")):
        with pytest.raises(ValueError, match=word):
            _refine.refine_quads(gray, 100, 100, quad, np.array([r], np.int64), 2, 24, 0.15, lut, True, False)
    far = np.array([[[1e300, -1e300], [2e300, -1e300], [2e300, 1e300], [1e300, 1e300]]])  # finite, far outside
    _, ok = _refine.refine_quads(gray, 100, 100, far, np.array([2], np.int64), 2, 24, 0.15, lut, True, False)
    assert not np.frombuffer(ok, np.uint8).any()  # no contrast there: not refined, and no crash


@pytest.mark.parametrize("native", ENGINES)
def test_a_large_square_under_a_light_gradient_keeps_its_corners(native):
    # a 70 px square under a light gradient (25 % across the image, as vignetting): the corners
    # stay within 0.05 px (about 0.015 px without the gradient)
    truth = np.array([[20.3, 15.6], [90.1, 16.2], [89.4, 85.7], [19.8, 84.9]])
    flat = render_square((110, 110), truth, blur=0.8).astype(np.float64)
    light = np.linspace(1.0, 0.75, 110)[None, :]
    img = np.clip(np.round(flat * light), 0, 255).astype(np.uint8)
    start = truth + 0.5
    errs = {}
    for levels in ("auto", "side"):
        out, ok = refine_quads(img, start[None], radius=3, iterations=3, response="linear", levels=levels,
                               native=native)
        assert ok[0]
        errs[levels] = np.sqrt(((out[0] - truth) ** 2).sum(axis=1)).max()
    assert errs["side"] < 0.05 and errs["auto"] < 0.05
    with pytest.raises(ValueError, match="levels"):
        refine_quads(img, start[None], levels="quad")


def test_edge_stages_refuse_what_they_cannot_read_instead_of_crashing():
    # quads off the image cropped it to nothing, and OpenCV then read memory it does not own
    # (a segmentation fault); an empty image gave uninitialised profiles
    from visloc.markers.refine import bend_corners

    img = np.full((240, 320), 200, np.uint8)
    far = np.array([[1100.0, 1100.0], [1150.0, 1100.0], [1150.0, 1150.0], [1100.0, 1150.0]])
    np.testing.assert_array_equal(bend_corners(img, far)[0], far)  # nothing to bend: kept
    for q in (far, far * 1e300):
        with pytest.raises(ValueError, match="none reaches"):
            edge_points(img, q, radius=2)
    with pytest.raises(ValueError, match="finite"):
        bend_corners(img, far * np.nan)
    with pytest.raises(ValueError, match="non-empty"):
        sample_edge_profiles(np.zeros((0, 0), np.uint8), far, 2)
    inside = far - 1000.0  # still refined
    assert bend_corners(img, inside).shape == (1, 4, 2)


@pytest.mark.parametrize("native", ENGINES)
def test_stage_8b_profiles_are_capped_by_bend_radius(native):
    # stage 8b starts from refined sides: refine_quads' bend is stage 8 at the quad's radius,
    # then bend_corners at that radius capped by bend_radius (the detector's default: 3 px)
    from visloc.markers import DetectorParams
    from visloc.markers.refine import bend_corners

    rng = np.random.default_rng(7)
    quad = np.array([[[40.3, 52.1], [151.7, 47.6], [156.2, 160.4], [44.8, 163.9]]])
    img = render_square((200, 210), quad[0], supersample=8)
    img = np.clip(img.astype(np.float64) * 0.2 + rng.normal(0, 3, img.shape), 0, 255).astype(np.uint8)  # dark
    start = quad + rng.normal(0, 0.6, quad.shape)
    straight, ok = refine_quads(img, start, radius=5, max_iterations=6, native=native)
    capped, ok_c = refine_quads(img, start, radius=5, max_iterations=6, bend=True, bend_radius=3, native=native)
    wide, ok_w = refine_quads(img, start, radius=5, max_iterations=6, bend=True, native=native)
    assert ok[0] and ok_c[0] and ok_w[0]
    tol = 1e-9 if not native else 0.05  # the compiled interpolation differs a little (module docstring)
    assert np.abs(capped - bend_corners(img, straight, radius=3)).max() <= tol
    assert np.abs(wide - bend_corners(img, straight, radius=5)).max() <= tol
    assert np.abs(capped - wide).max() > tol  # the cap changes something here
    assert np.array_equal(refine_quads(img, start, radius=2, bend=True, bend_radius=3, native=native)[0],
                          refine_quads(img, start, radius=2, bend=True, native=native)[0])  # under the cap
    assert DetectorParams().bend_radius == 3
    with pytest.raises(ValueError, match="bend_radius"):
        refine_quads(img, start, bend=True, bend_radius=0, native=native)


@pytest.mark.parametrize("native", ENGINES)
def test_stage_8b_reads_a_noisy_quad_through_a_narrower_window(native):
    # noisy_bend_radius: where the noise of a quad's end samples is a tenth of its contrast or
    # more, stage 8b reads it at that half-width (less noise summed); without noise it keeps
    # bend_radius (a narrower window would only lose a blurred edge's tails)
    from visloc.markers import DetectorParams
    from visloc.markers.refine import bend_corners

    quad = np.array([[[40.3, 52.1], [151.7, 47.6], [156.2, 160.4], [44.8, 163.9]]])
    clean = cv2.GaussianBlur(render_square((200, 210), quad[0], supersample=8, dark=20, bright=60), (0, 0), 0.8)
    noisy = np.clip(clean + np.random.default_rng(5).normal(0, 8, clean.shape), 0, 255).astype(np.uint8)
    tol = 1e-9 if not native else 0.01  # the compiled interpolation differs a little (module docstring)
    for img, expect in ((noisy, 2), (clean, 3)):
        start = quad + np.random.default_rng(3).normal(0, 0.4, quad.shape)
        straight = refine_quads(img, start, radius=5, max_iterations=6, native=native)[0]
        got, ok = refine_quads(img, start, radius=5, max_iterations=6, bend=True, bend_radius=3, noisy_bend_radius=2,
                               native=native)
        assert ok[0]
        assert np.abs(got - bend_corners(img, straight, radius=expect)).max() <= tol
        assert np.abs(got - bend_corners(img, straight, radius=5 - expect)).max() > 2 * tol  # not the other
    assert DetectorParams().noisy_bend_radius == 2
    with pytest.raises(ValueError, match="noisy_bend_radius"):
        refine_quads(clean, quad, bend=True, noisy_bend_radius=0, native=native)


def test_corners_on_dark_camera_like_frames_are_not_pushed_outward_by_clipped_noise():
    # dark frames (mean grey under 30): the white margin is the noisier side (shot noise), and
    # each profile's samples are clipped to [0, 1] of the black-white span, so the far white
    # samples lose more than the black ones gain and the edges move out; stage 8b's narrower
    # windows (3 px, 2 on noisy quads) cut the outward bias (median along the corner's diagonal)
    # on these 8 frames from +0.26 to +0.21 px and the median corner error from 0.355 to 0.295 px
    from visloc.markers import MarkerDetector
    from visloc.synth import random_scene

    det = MarkerDetector("DICT_4X4_50")
    errs, out = [], []
    for s in range(8):
        scene = random_scene(s, size=(640, 480), difficulty="dark", camera=True)
        assert scene.image.mean() < 30
        for d in det.detect(scene.image):
            t = next(m.corners for m in scene.markers if m.id == d.id)
            e = d.corners - t
            u = (t - t.mean(axis=0)) / np.linalg.norm(t - t.mean(axis=0), axis=1, keepdims=True)
            errs += np.linalg.norm(e, axis=1).tolist()
            out += (e * u).sum(axis=1).tolist()
    assert len(errs) >= 80
    assert np.median(errs) < 0.33 and np.median(out) < 0.24
