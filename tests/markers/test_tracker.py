"""MarkerTracker: markers followed between full detections give a full detection's corners."""

import numpy as np
import pytest

from visloc.markers import MarkerDetector, MarkerTracker
from visloc.model.rigid_body import rotation_matrix
from visloc.pose import Camera, markers_in_view
from visloc.pose.maps import GridMap
from visloc.sim import SIM_GRID, BottomCamera


def _poses():
    """The flight's body states and attitudes (state (12,), R (3, 3)) frame by frame."""
    out = []
    for k in range(40):
        s = np.zeros(12)
        s[0], s[1], s[2] = 0.05 * np.sin(k / 8), 0.004 * k, -1.0 - 0.1 * np.sin(k / 12)
        s[6], s[8] = 0.02 * np.sin(k / 8), 0.004 * k
        out.append((s, rotation_matrix(s[6:9])))
    return out


@pytest.fixture(scope="module")
def flight():
    """40 frames of the simulation's bottom camera over its marker grid, drifting, climbing,
    rocking and turning (up to about 2 px of marker motion per frame)."""
    cam = BottomCamera(GridMap(**SIM_GRID), "DICT_4X4_100", rng=np.random.default_rng(3))
    return cam, [cam.capture(s, R) for s, R in _poses()]


def _by_id(dets):
    return {d.id: d for d in dets}


def test_followed_markers_have_the_detectors_corners(flight):
    cam, frames = flight
    detector = MarkerDetector(cam.dictionary, response="linear")
    tracker = MarkerTracker(MarkerDetector(cam.dictionary, response="linear"), redetect_every=10)
    followed = 0
    for img in frames:
        full, got = _by_id(detector.detect(img)), _by_id(tracker.detect(img))
        assert set(got) <= set(full)  # nothing the detector would not find
        assert len(got) >= 0.75 * len(full)  # markers come into view at the next full detection
        for i, d in got.items():
            assert np.abs(d.corners - full[i].corners).max() < 0.02
            assert d.hamming == full[i].hamming
        followed += len(got)
    assert followed > 20 * len(frames)
    assert tracker.frames == len(frames)
    assert 4 <= tracker.full_detections <= 12  # every 10th frame, and when a quarter of the markers fail


def test_redetect_every_frame_is_the_detector(flight):
    cam, frames = flight
    detector = MarkerDetector(cam.dictionary, response="linear")
    tracker = MarkerTracker(detector, redetect_every=1)
    for img in frames[:5]:
        a, b = detector.detect(img), tracker.detect(img)
        assert [d.id for d in a] == [d.id for d in b]
        assert all(np.array_equal(x.corners, y.corners) for x, y in zip(a, b, strict=True))
    assert tracker.full_detections == 5


def _occlude(img, quads):
    out = img.copy()
    for q in quads:
        x0, y0 = np.floor(q.min(axis=0)).astype(int) - 4
        x1, y1 = np.ceil(q.max(axis=0)).astype(int) + 4
        out[max(y0, 0):y1, max(x0, 0):x1] = 128  # an occluder over the marker
    return out


def test_a_lost_marker_is_dropped_and_many_bring_back_the_full_detection(flight):
    cam, frames = flight
    detector = MarkerDetector(cam.dictionary, response="linear")
    tracker = MarkerTracker(detector, redetect_every=100)
    first = tracker.detect(frames[0])
    for f in frames[1:3]:
        tracker.detect(f)
    before = tracker.full_detections  # 1, or 2 if the zero-velocity guess of frame 1 was too far off
    assert before <= 2
    hidden = first[len(first) // 2]
    got = tracker.detect(_occlude(frames[3], [hidden.corners]))
    assert tracker.full_detections == before  # one marker lost: dropped, the others followed
    assert hidden.id not in {d.id for d in got} and len(got) >= len(first) - 3
    img = _occlude(frames[4], [d.corners for d in got[: len(got) // 2]])
    got = tracker.detect(img)  # half of them lost: the full search
    assert tracker.full_detections == before + 1
    assert [d.id for d in got] == [d.id for d in detector.detect(img)]


def test_confirm_wants_the_expected_id_and_orientation(flight):
    cam, frames = flight
    detector = MarkerDetector(cam.dictionary, response="linear")
    dets = detector.detect(frames[0])
    quads = np.array([d.corners for d in dets]) + 0.6  # a prediction half a pixel off
    ids = np.array([d.id for d in dets])
    got = detector.confirm(frames[0], quads, ids)
    assert all(g is not None and np.abs(g.corners - d.corners).max() < 0.02 for g, d in zip(got, dets, strict=True))
    assert all(g is None for g in detector.confirm(frames[0], quads, ids + 1))  # wrong ids
    turned = np.roll(quads, 1, axis=1)  # corner 0 not the marker's own top-left
    assert all(g is None for g in detector.confirm(frames[0], turned, ids))
    assert detector.confirm(frames[0], np.zeros((0, 4, 2)), []) == []
    # ids are whole numbers, as the tracker's: int() used to make 3.7 marker 3 and "3" too
    assert detector.confirm(frames[0], quads[:1], ids[:1].astype(float))[0] is not None
    with pytest.raises(ValueError, match="whole numbers"):
        detector.confirm(frames[0], quads[:1], ids[:1] + 0.7)
    with pytest.raises(TypeError, match="whole numbers"):
        detector.confirm(frames[0], quads[:1], [str(ids[0])])
    with pytest.raises(ValueError, match="2 x 2"):  # the image is checked with no quads too
        detector.confirm(np.zeros((0, 0), np.uint8), np.zeros((0, 4, 2)), [])


def test_bad_input_is_named():
    detector = MarkerDetector("DICT_4X4_50")
    with pytest.raises(TypeError, match="detector"):
        MarkerTracker("DICT_4X4_50")
    with pytest.raises(ValueError, match="redetect_every"):
        MarkerTracker(detector, redetect_every=0)
    with pytest.raises(ValueError, match="keep"):
        MarkerTracker(detector, keep=0.0)
    with pytest.raises(ValueError, match="refine"):
        MarkerTracker(MarkerDetector("DICT_4X4_50", refine=False))
    img = np.full((60, 80), 255, np.uint8)
    with pytest.raises(ValueError, match="quads"):
        detector.confirm(img, np.zeros((2, 3, 2)), [1, 2])
    with pytest.raises(ValueError, match="finite"):
        detector.confirm(img, np.full((1, 4, 2), np.nan), [1])
    with pytest.raises(ValueError):
        MarkerTracker(detector).detect(np.zeros((0, 5), np.uint8))


def test_white_on_black_markers_are_followed_too(flight):
    cam, frames = flight
    negatives = [255 - f for f in frames[:12]]
    detector = MarkerDetector(cam.dictionary, response="linear", inverted=True)
    tracker = MarkerTracker(detector, redetect_every=6)
    for img in negatives:
        full, got = _by_id(detector.detect(img)), _by_id(tracker.detect(img))
        assert got and set(got) <= set(full) and all(d.inverted for d in got.values())
        assert max(np.abs(d.corners - full[i].corners).max() for i, d in got.items()) < 0.02
    assert tracker.full_detections <= 4


def test_expected_markers_join_at_once_and_replace_the_periodic_search(flight):
    # each frame told the map's markers in the previous frame's true view: markers coming into
    # view are followed from their first whole frame, and no full search runs after the first
    cam, frames, poses = flight + (_poses(),)
    lens = Camera(cam.K, size=cam.size)
    detector = MarkerDetector(cam.dictionary, response="linear")
    guided = MarkerTracker(MarkerDetector(cam.dictionary, response="linear"), redetect_every=10)
    plain = MarkerTracker(MarkerDetector(cam.dictionary, response="linear"), redetect_every=10)
    n_guided = n_plain = 0
    for k, img in enumerate(frames):
        expected = None if k == 0 else markers_in_view(cam.marker_map, lens, cam.pose(*poses[k - 1]))
        full, got = _by_id(detector.detect(img)), _by_id(guided.detect(img, expected=expected))
        assert set(got) <= set(full)
        assert len(got) >= len(full) - 2  # at most those too near the edge to be followed
        assert max(np.abs(d.corners - full[i].corners).max() for i, d in got.items()) < 0.02
        n_guided += len(got)
        n_plain += len(plain.detect(img))
    # the first, and one on frame 1 if the zero-velocity guess was too far off (as without)
    assert guided.full_detections <= 2 and plain.full_detections >= 4
    assert n_guided > n_plain


def test_an_expected_marker_that_is_not_there_costs_no_full_search(flight):
    cam, frames = flight
    tracker = MarkerTracker(MarkerDetector(cam.dictionary, response="linear"), redetect_every=3)
    first = tracker.detect(frames[0])
    for img in frames[1:3]:
        tracker.detect(img)
    before = tracker.full_detections
    far = {99: first[0].corners + 40.0}  # an id printed nowhere near where it is said to be
    for img in frames[3:9]:
        got = tracker.detect(img, expected=far)
        assert 99 not in {d.id for d in got} and len(got) >= len(first) - 3
    assert tracker.full_detections == before  # 3 frames without, 6 with: no periodic search
    with pytest.raises(ValueError, match="expected"):
        tracker.detect(frames[9], expected={5: np.zeros((3, 2))})
    with pytest.raises(ValueError, match="expected"):
        tracker.detect(frames[9], expected={5: np.full((4, 2), np.nan)})


def test_redetect_every_frame_stays_the_detector_when_told_what_to_expect(flight):
    cam, frames = flight
    lens = Camera(cam.K, size=cam.size)
    tracker = MarkerTracker(MarkerDetector(cam.dictionary, response="linear"), redetect_every=1)
    poses = _poses()
    for k, img in enumerate(frames[:4]):
        tracker.detect(img, expected=markers_in_view(cam.marker_map, lens, cam.pose(*poses[max(k - 1, 0)])))
    assert tracker.full_detections == 4


def test_expected_must_map_whole_ids_and_keep_may_be_a_numpy_number():
    detector = MarkerDetector("DICT_4X4_50")
    tracker = MarkerTracker(detector)
    img = np.full((60, 80), 255, np.uint8)
    quad = np.array([[10.0, 10], [30, 10], [30, 30], [10, 30]])
    with pytest.raises(TypeError, match="expected must be a mapping of id to corners, got list"):
        tracker.detect(img, expected=[quad])
    with pytest.raises(TypeError, match="expected: marker ids must be whole numbers, got 'a'"):
        tracker.detect(img, expected={1: quad, "a": quad})
    with pytest.raises(TypeError, match="expected: marker ids must be whole numbers, got None"):
        tracker.detect(img, expected={None: quad})
    with pytest.raises(ValueError, match=r"expected: marker ids must be whole numbers, got 2\.7"):
        tracker.detect(img, expected={1: quad, 2.7: quad})
    with pytest.raises(ValueError, match="expected: marker ids must be whole numbers, got nan"):
        tracker.detect(img, expected={float("nan"): quad})
    assert tracker.frames == 0  # refused before the frame counts
    assert tracker.detect(img, expected={2.0: quad}) == [] and tracker.frames == 1
    assert MarkerTracker(detector, keep=np.float32(0.5)).keep == 0.5
    for keep in (True, np.nan, "0.5", np.float32(1.5)):
        with pytest.raises(ValueError, match="keep"):
            MarkerTracker(detector, keep=keep)


def test_editing_returned_corners_does_not_move_the_next_prediction(flight):
    cam, frames = flight
    clean = MarkerTracker(MarkerDetector(cam.dictionary, response="linear"), redetect_every=100)
    edited = MarkerTracker(MarkerDetector(cam.dictionary, response="linear"), redetect_every=100)
    for img in frames[:2]:
        clean.detect(img)
        for d in edited.detect(img):
            d.corners[:] += 30.0  # the caller's own use of the corners, in place
    a, b = clean.detect(frames[2]), edited.detect(frames[2])
    assert [d.id for d in a] == [d.id for d in b]
    assert all(np.array_equal(x.corners, y.corners) for x, y in zip(a, b, strict=True))
    assert clean.full_detections == edited.full_detections


def test_whole_float_and_numpy_ids_are_expected_as_ints(flight):
    cam, frames, poses = flight + (_poses(),)
    lens = Camera(cam.K, size=cam.size)
    plain = MarkerTracker(MarkerDetector(cam.dictionary, response="linear"))
    other = MarkerTracker(MarkerDetector(cam.dictionary, response="linear"))
    plain.detect(frames[0]), other.detect(frames[0])
    for k in (1, 2):
        expected = markers_in_view(cam.marker_map, lens, cam.pose(*poses[k - 1]))
        a = plain.detect(frames[k], expected=expected)
        b = other.detect(frames[k], expected={(float(i) if i % 2 else np.int64(i)): q for i, q in expected.items()})
        assert [(type(d.id), d.id) for d in a] == [(type(d.id), d.id) for d in b]
        assert all(np.array_equal(x.corners, y.corners) for x, y in zip(a, b, strict=True))
