import cv2
import numpy as np
import pytest

from visloc.markers.binarize import blur, default_window, threshold, to_gray


def test_to_gray_converts_bgr_and_keeps_gray():
    bgr = np.zeros((4, 5, 3), np.uint8)
    bgr[..., 2] = 255  # pure red
    g = to_gray(bgr)
    assert g.shape == (4, 5) and g.dtype == np.uint8
    assert abs(int(g[0, 0]) - 76) <= 1  # OpenCV luma weight of red: 0.299
    gray = np.arange(20, dtype=np.uint8).reshape(4, 5)
    assert to_gray(gray) is gray


@pytest.mark.parametrize(
    "bad, exc",
    [
        (np.zeros((0, 5), np.uint8), ValueError),
        (np.zeros((1, 1), np.uint8), ValueError),
        (np.zeros((4, 5), np.int32), TypeError),
        (np.full((4, 5), np.nan), ValueError),
        (np.zeros((4, 5, 2), np.uint8), ValueError),
        (np.zeros((2, 4, 5, 3), np.uint8), ValueError),
        ([[1, 2], [3, 4]], TypeError),
    ],
)
def test_to_gray_rejects_bad_images(bad, exc):
    with pytest.raises(exc, match="image"):
        to_gray(bad)


def test_blur_zero_is_identity_and_blur_smooths():
    img = np.zeros((21, 21), np.uint8)
    img[10, 10] = 255
    assert blur(img, sigma=0) is img
    b = blur(img, sigma=1.0)
    assert b[10, 10] < 255 and b[10, 11] > 0 and b.sum() > 0
    with pytest.raises(ValueError, match="sigma"):
        blur(img, sigma=-1)


def test_threshold_marks_dark_border_of_a_square_as_ink():
    img = np.full((60, 60), 200, np.uint8)
    img[20:40, 20:40] = 40
    b = threshold(img, window=7, offset=7)
    assert b.dtype == np.uint8 and set(np.unique(b)) <= {0, 255}
    assert b[20, 30] == 255 and b[39, 30] == 255  # dark pixels next to the edge are ink
    assert b[5, 5] == 0 and b[30, 30] == 0  # flat areas (bright or dark) are not
    with pytest.raises(ValueError, match="window"):
        threshold(img, window=4)


@pytest.mark.skipif(__import__("visloc.markers.binarize", fromlist=["_"])._threshold is None,
                    reason="built without a C compiler: OpenCV's threshold runs")
def test_compiled_threshold_is_opencvs_pixel_for_pixel():
    """visloc.markers._threshold against cv2.adaptiveThreshold (MEAN_C, BINARY_INV) on noise,
    binary and smooth images of odd sizes, every window from 3 to 51 and offsets that are
    negative, fractional (floored as OpenCV does) or beyond the grey range."""
    rng = np.random.default_rng(5)
    images = [rng.integers(0, 256, (1, 1), np.uint8), rng.integers(0, 256, (2, 37), np.uint8),
              rng.integers(0, 256, (53, 3), np.uint8), (rng.integers(0, 2, (40, 61)) * 255).astype(np.uint8),
              np.clip(rng.normal(128, 50, (97, 130)), 0, 255).astype(np.uint8),
              cv2.GaussianBlur(rng.integers(0, 256, (120, 90), np.uint8), (0, 0), 3)]
    for img in images:
        for window in range(3, 52, 2):
            for offset in (7, 4, 0, -3, 2.5, -0.5, 300, -300):
                ours = threshold(img, window=window, offset=offset, native=True)
                theirs = threshold(img, window=window, offset=offset, native=False)
                assert np.array_equal(ours, theirs), (img.shape, window, offset)


def test_default_window_is_odd_and_scales():
    assert default_window((480, 640)) % 2 == 1
    assert default_window((240, 320)) < default_window((1080, 1920))


def test_stage_defaults_are_the_detectors():
    import inspect

    from visloc.markers.detector import DetectorParams

    params = DetectorParams()
    assert inspect.signature(blur).parameters["sigma"].default == params.blur_sigma
    assert inspect.signature(threshold).parameters["window"].default == params.passes[0].window
    assert inspect.signature(threshold).parameters["offset"].default == params.offset


@pytest.mark.parametrize("native", [True, False])
@pytest.mark.parametrize("bad, exc, match", [
    (np.full((8, 8), 300, np.uint16), ValueError, "uint8"),  # compiled: wrapped to 44 before
    (np.full((8, 8), -1.0), ValueError, "uint8"),
    (np.zeros((8, 8, 3), np.uint8), ValueError, r"\(H, W\)"),
    (np.zeros((0, 8), np.uint8), ValueError, "non-empty"),
    ([[0, 255], [255, 0]], TypeError, "numpy array"),
])
def test_threshold_rejects_what_is_not_a_grey_uint8_image_either_way(native, bad, exc, match):
    with pytest.raises(exc, match=match):
        threshold(bad, native=native)


@pytest.mark.parametrize("kw, match", [({"window": 9.0}, "window"), ({"window": True}, "window"),
                                       ({"offset": float("nan")}, "offset")])
def test_threshold_rejects_a_fractional_window_or_a_nan_offset(kw, match):
    with pytest.raises(ValueError, match=match):
        threshold(np.zeros((8, 8), np.uint8), **kw)
