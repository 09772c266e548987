"""MarkerDetector on renders with exact ground truth, and its error handling."""

import json

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from visloc.markers import MarkerDetector
from visloc.markers.explain import write_explain
from visloc.synth import default_camera, random_board_scene, random_scene, render_markers
from visloc.synth.camera import CameraEffects, srgb_encode
from visloc.types import Pose


def _match(dets, scene):
    truth = {m.id: m for m in scene.markers if m.visible}
    pairs = [(d, truth[d.id]) for d in dets if d.id in truth]
    false = [d for d in dets if d.id not in truth]
    return pairs, false, truth


@pytest.fixture(scope="module")
def detector():
    """The detector for visloc's linear renders (their grey levels are linear in light)."""
    return MarkerDetector("DICT_4X4_50", response="linear")


def test_clean_renders_are_found_with_hundredth_pixel_corners(detector):
    errs, n_truth, n_found = [], 0, 0
    for seed in range(6):
        scene = random_scene(seed, size=(640, 480), difficulty="easy")
        dets = detector.detect(scene.image)
        pairs, false, truth = _match(dets, scene)
        assert not false
        n_truth += len(truth)
        n_found += len(pairs)
        for d, t in pairs:
            errs.append(np.linalg.norm(d.corners - t.corners, axis=1))
            assert d.hamming == 0 and d.margin > 0.5 and d.refined
    assert n_found == n_truth
    rms = float(np.sqrt(np.mean(np.concatenate(errs) ** 2)))
    assert rms < 0.05, rms


def test_hard_renders_keep_recall_and_subpixel_corners(detector):
    errs, n_truth, n_found = [], 0, 0
    for seed in range(100, 112):
        scene = random_scene(seed, size=(640, 480), difficulty="hard")
        pairs, false, truth = _match(detector.detect(scene.image), scene)
        assert not false
        n_truth += len(truth)
        n_found += len(pairs)
        errs += [np.linalg.norm(d.corners - t.corners, axis=1) for d, t in pairs]
    assert n_found >= 0.95 * n_truth
    assert float(np.median(np.concatenate(errs))) < 0.3


def test_small_markers_are_found(detector):
    n_truth = n_found = 0
    for seed in range(200, 208):
        scene = random_scene(seed, size=(640, 480), difficulty="small")
        pairs, false, truth = _match(detector.detect(scene.image), scene)
        assert not false
        n_truth += len(truth)
        n_found += len(pairs)
    assert n_found == n_truth


def test_tiny_markers_in_a_large_frame_as_often_as_opencv(detector, monkeypatch):
    # 10-23 px markers in 1280 x 720 frames: the frame is searched shrunk, and the candidate
    # perimeter bound must not drop what OpenCV's detector finds at full size
    import cv2

    from visloc.synth import scenes

    monkeypatch.setitem(scenes._SIZE, "small", (0.014, 0.03))
    peer = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50),
                                   cv2.aruco.DetectorParameters())
    ours = theirs = total = 0
    for i in range(12):
        sc = random_scene(np.random.default_rng([7, i]), size=(1280, 720), difficulty="small")
        truth = {m.id for m in sc.markers if m.visible}
        total += len(truth)
        ours += len(truth & {d.id for d in detector.detect(sc.image)})
        ids = peer.detectMarkers(sc.image)[1]
        theirs += len(truth & set(() if ids is None else ids.ravel().tolist()))
    assert total >= 30 and ours >= theirs and ours >= 0.8 * total, (ours, theirs, total)


def test_empty_textured_frames_give_no_detection(detector):
    for seed in range(300, 306):
        scene = random_scene(seed, size=(640, 480), difficulty="empty")
        assert detector.detect(scene.image) == []


@pytest.mark.parametrize("yaw_quarters", [0, 1, 2, 3])
def test_marker_at_any_of_four_rotations_decodes_with_corners_rotated(detector, yaw_quarters):
    K = default_camera((320, 240))
    yaw = yaw_quarters * np.pi / 2 + 0.2
    R = Rotation.from_euler("zx", [yaw, 0.3]).as_matrix() @ np.diag([1.0, -1.0, -1.0])
    pose = Pose(R, np.array([0.02, -0.01, 0.6]))
    scene = render_markers(K, (320, 240), [(11, pose, 0.15)], "DICT_4X4_50", background="flat")
    (d,) = detector.detect(scene.image)
    assert d.id == 11
    assert np.abs(d.corners - scene.markers[0].corners).max() < 0.05


def test_rotating_the_image_rotates_the_corners(detector):
    scene = random_scene(3, size=(640, 480), difficulty="easy")
    img = scene.image
    base = {d.id: d.corners for d in detector.detect(img)}
    w = img.shape[1]
    rotated = np.ascontiguousarray(np.rot90(img))  # counter-clockwise: (x, y) -> (y, w - 1 - x)
    turned = {d.id: d.corners for d in detector.detect(rotated)}
    assert set(turned) == set(base)
    for i, c in base.items():
        expected = np.stack([c[:, 1], w - 1 - c[:, 0]], axis=1)
        assert np.abs(turned[i] - expected).max() < 0.05


@pytest.mark.parametrize("name", ["DICT_6X6_250", "DICT_APRILTAG_36h11", "DICT_ARUCO_ORIGINAL", "DICT_5X5_100"])
def test_other_dictionaries(name):
    det = MarkerDetector(name)
    for seed in range(2):
        scene = random_scene(seed, size=(640, 480), dictionary=name, difficulty="easy")
        pairs, false, truth = _match(det.detect(scene.image), scene)
        assert not false and len(pairs) == len(truth)


def test_marker_cut_by_the_image_border_is_not_reported(detector):
    K = default_camera((320, 240))
    R = np.diag([1.0, -1.0, -1.0])  # facing the camera, upright
    pose = Pose(R, np.array([-0.33, 0.0, 0.6]))  # centre near the left border: partly outside
    scene = render_markers(K, (320, 240), [(5, pose, 0.15)], "DICT_4X4_50", background="flat")
    assert not scene.markers[0].visible
    assert detector.detect(scene.image) == []


def test_trace_and_explain_pictures(tmp_path, detector):
    scene = random_scene(1, size=(320, 240), difficulty="easy")
    trace = detector.trace(scene.image)
    assert {d.id for d in trace.detections} == {d.id for d in detector.detect(scene.image)}
    # every pass that runs is traced: at 320 x 240 the one on the image shrunk 4 times (60 px
    # high) is below min_pass_size and skipped
    ran = [sp for sp in detector.params.passes if 240 / sp.scale >= detector.params.min_pass_size]
    assert trace.binary.shape == (240, 320) and len(trace.passes) == len(ran) == len(detector.params.passes) - 1
    stages = {c.stage for c in trace.candidates}
    assert "accepted" in stages
    for ps in trace.passes:  # every outer border is kept for the picture, flagged by its hole
        assert len(ps.enclosing) == len(ps.contours) > ps.enclosing.sum() > 0
    paths = write_explain(trace, tmp_path, stem="f0")
    names = {p.name for p in paths}
    assert {"f0_C_contours.png", "f0_D_radial.png", "f0_I_detections.png", "f0_candidates.json"} <= names
    assert all(p.stat().st_size > 0 for p in paths)
    summary = json.loads((tmp_path / "f0_candidates.json").read_text())
    assert [p["enclosing_a_hole"] for p in summary["passes"]] == [int(ps.enclosing.sum()) for ps in trace.passes]


def test_the_coarse_pass_does_not_fit_markers_the_fine_pass_proposed(detector, monkeypatch):
    import visloc.markers.detector as det_mod

    fitted = []
    original = det_mod.fit_quads

    def counting(contours, **kw):
        fitted.append(len(contours))
        return original(contours, **kw)

    monkeypatch.setattr(det_mod, "fit_quads", counting)
    trace = detector.trace(random_scene(3, size=(320, 240), difficulty="easy").image)
    enclosing = [int(ps.enclosing.sum()) for ps in trace.passes]
    assert len(trace.detections) > 0 and enclosing[1] > 0
    # every marker is fitted once, by the fine pass; the coarse pass's copies stop before stage 6
    assert sum(fitted) == len(trace.candidates) - sum(c.stage == "bits" for c in trace.candidates)
    assert {c.scale for c in trace.candidates if c.stage == "accepted"} == {1.0}
    assert len([c for c in trace.candidates if c.stage == "accepted"]) == len(trace.detections)


def test_bgr_input_gives_the_same_result(detector):
    scene = random_scene(2, size=(320, 240), difficulty="easy")
    bgr = np.repeat(scene.image[:, :, None], 3, axis=2)
    a = detector.detect(scene.image)
    b = detector.detect(bgr)
    assert [d.id for d in a] == [d.id for d in b]
    assert all(np.allclose(x.corners, y.corners) for x, y in zip(a, b, strict=True))


@pytest.mark.parametrize(
    "bad, exc",
    [
        (np.zeros((0, 0), np.uint8), ValueError),
        (np.zeros((1, 1), np.uint8), ValueError),
        (np.zeros((40, 40), np.int32), TypeError),
        (np.full((40, 40), np.nan), ValueError),
        (np.zeros((40, 40, 2), np.uint8), ValueError),
        ("image.png", TypeError),
    ],
)
def test_bad_images_raise_naming_the_argument(detector, bad, exc):
    with pytest.raises(exc, match="image"):
        detector.detect(bad)


def test_tiny_and_flat_images_give_nothing(detector):
    assert detector.detect(np.zeros((2, 2), np.uint8)) == []
    assert detector.detect(np.full((480, 640), 128, np.uint8)) == []


def test_constructor_errors():
    with pytest.raises(TypeError, match="unknown detector parameter"):
        MarkerDetector("DICT_4X4_50", windw=3)
    with pytest.raises(ValueError, match="unknown dictionary"):
        MarkerDetector("DICT_NOPE")
    with pytest.raises(ValueError, match="scale"):
        MarkerDetector("DICT_4X4_50", passes=[(0.5, 9)])
    with pytest.raises(ValueError, match="at least one search pass"):
        MarkerDetector("DICT_4X4_50", passes=[])
    with pytest.raises(ValueError, match="border_bits"):
        MarkerDetector("DICT_4X4_50", border_bits=4)
    with pytest.raises(ValueError, match="inverted"):
        MarkerDetector("DICT_4X4_50", inverted="yes")
    with pytest.raises(ValueError, match="response"):
        MarkerDetector("DICT_4X4_50", response="log")
    with pytest.raises(ValueError, match="refine_max_iterations"):
        MarkerDetector("DICT_4X4_50", refine_max_iterations=0)
    with pytest.raises(ValueError, match="refine_tolerance"):
        MarkerDetector("DICT_4X4_50", refine_tolerance=-0.1)
    with pytest.raises(ValueError, match="small_side"):
        MarkerDetector("DICT_4X4_50", small_side=float("nan"))


@pytest.mark.parametrize("key, bad", [
    ("dark_mean", -1.0), ("dark_mean", float("nan")), ("min_pass_size", -1), ("min_pass_size", 2.5),
    ("erode", 1.5), ("board_retry", "yes"), ("base_height", 0), ("blur_sigma", -0.5), ("blur_sigma", "x"),
    ("offset", float("inf")), ("corner_sigma", 0.0), ("corner_sigma", "x"), ("corner_padding", 0.5),
    ("refine", None), ("refine_radius", 0), ("refine_radius", 2.5), ("refine_iterations", 0),
    ("refine_iterations", 7), ("refine_max_radius", 0), ("refine_profiles", 1), ("refine_profiles", True),
    ("bend", 1), ("border_error_rate", 1.5), ("min_quiet_zone", -0.1), ("cell_margin", 0.5),
    ("bit_threshold", 2.0), ("error_correction_rate", float("nan")), ("error_correction_rate", True),
])
def test_every_parameter_is_checked_when_the_detector_is_made(key, bad):
    # before, these were taken and failed (or ran on nonsense) only at the first frame
    switch = key in ("board_retry", "refine", "bend")
    with pytest.raises(TypeError if switch else ValueError, match=key):
        MarkerDetector("DICT_4X4_50", **{key: bad})


def test_parameters_at_their_bounds_are_taken():
    det = MarkerDetector("DICT_4X4_50", dark_mean=0, min_pass_size=0, erode=5, blur_sigma=0.0, offset=-3,
                         corner_sigma=2.0, corner_padding=0.0, refine_radius=3, refine_iterations=6,
                         refine_profiles=2, border_error_rate=1.0, min_quiet_zone=0.0, cell_margin=0.0,
                         bit_threshold=0.0, error_correction_rate=0.0, refine=np.True_)
    assert det.params.refine_iterations == 6 and det.params.bit_threshold == 0.0
    with pytest.raises(TypeError, match="candidates"):
        MarkerDetector("DICT_4X4_50", candidates={"min_side": 3})
    with pytest.raises(ValueError, match="scale"):
        MarkerDetector("DICT_4X4_50", passes=[(float("inf"), 9)])


def _sheet(ids, border_bits=1, cell=12, invert=False):
    """Markers drawn by OpenCV side by side on white, 2 cells apart, a 3-cell margin, blurred in
    linear light and sRGB-encoded as a camera writes them; returns the image and each marker's
    geometric corners (pixel (c, r) covers c - 0.5 .. c + 0.5)."""
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    side = (4 + 2 * border_bits) * cell
    img = np.full((side + 6 * cell, len(ids) * (side + 2 * cell) + 4 * cell), 255, np.uint8)
    corners = {}
    for k, i in enumerate(ids):
        x0, y0 = 3 * cell + k * (side + 2 * cell), 3 * cell
        img[y0 : y0 + side, x0 : x0 + side] = cv2.aruco.generateImageMarker(d, i, side, borderBits=border_bits)
        corners[i] = np.array([[x0, y0], [x0 + side, y0], [x0 + side, y0 + side], [x0, y0 + side]]) - 0.5
    light = cv2.GaussianBlur((255 - img if invert else img).astype(np.float64) / 255, (0, 0), 0.7)
    return np.round(255 * srgb_encode(light)).astype(np.uint8), corners


@pytest.mark.parametrize("border_bits", [2, 3])
def test_thick_borders_need_border_bits(border_bits):
    img, truth = _sheet([3, 17, 40], border_bits)
    assert MarkerDetector("DICT_4X4_50", border_bits=1).detect(img) == []
    dets = MarkerDetector("DICT_4X4_50", border_bits=border_bits).detect(img)
    assert [d.id for d in dets] == [3, 17, 40]
    for d in dets:
        assert np.abs(d.corners - truth[d.id]).max() < 0.1


def test_inverted_markers_by_polarity():
    normal, truth = _sheet([5, 9])
    white_on_black, _ = _sheet([21, 33], invert=True)
    img = np.hstack([normal, white_on_black])
    shifted = {i: c + [normal.shape[1], 0] for i, c in _sheet([21, 33])[1].items()}
    assert [d.id for d in MarkerDetector("DICT_4X4_50").detect(img)] == [5, 9]
    inv = MarkerDetector("DICT_4X4_50", inverted=True).detect(img)
    assert [d.id for d in inv] == [21, 33] and all(d.inverted for d in inv)
    both = MarkerDetector("DICT_4X4_50", inverted="both").detect(img)
    assert [(d.id, d.inverted) for d in both] == [(5, False), (9, False), (21, True), (33, True)]
    for d in both:
        assert np.abs(d.corners - (shifted if d.inverted else truth)[d.id]).max() < 0.1
        assert d.to_dict().get("inverted", False) == d.inverted


def test_confidence_falls_with_damaged_cells():
    img, truth = _sheet([7])
    (clean,) = MarkerDetector("DICT_4X4_50").detect(img)
    assert clean.confidence > 0.95 and clean.to_dict()["confidence"] == round(clean.confidence, 4)
    bits = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50).generateImageMarker(7, 6)
    r, c = np.argwhere(bits[1:5, 1:5] == 0)[0] + 1  # a black cell of the code: paint half of it white
    x0, y0 = truth[7][0] + 0.5
    damaged = img.copy()
    damaged[int(y0 + r * 12) : int(y0 + r * 12 + 12), int(x0 + c * 12) : int(x0 + c * 12 + 5)] = 255
    (hurt,) = MarkerDetector("DICT_4X4_50").detect(damaged)
    assert hurt.id == 7 and hurt.hamming == 0  # under half the cell: the majority still reads black
    # OpenCV's confidence: 1 - wrong share of the read area (each of the 36 cells less 13 %
    # on every side); the white stripe covers 5 - 1.56 of the cell's 8.88 px wide read area
    assert hurt.confidence == pytest.approx(1 - (5 - 0.13 * 12) / (0.74 * 12) / 36, abs=0.003)


def test_confidence_off_skips_only_the_area_read(monkeypatch):
    import json

    import visloc.markers.detector as det_mod

    img, _ = _sheet([7, 12])
    on = MarkerDetector("DICT_4X4_50").detect(img)
    reads = []
    monkeypatch.setattr(det_mod.MarkerDetector, "_area_check",
                        lambda self, *a: reads.append(1) or pytest.fail("area read with confidence=False"))
    off = MarkerDetector("DICT_4X4_50", confidence=False).detect(img)
    assert len(on) == 2 and _same(on, off) and not reads
    assert all(np.isnan(d.confidence) for d in off)
    assert json.loads(json.dumps(off[0].to_dict()))["confidence"] is None  # strict JSON: null, not NaN
    monkeypatch.undo()
    # a bit threshold needs the area read, so the confidence comes with it
    (d,) = MarkerDetector("DICT_4X4_50", confidence=False, bit_threshold=0.49).detect(_sheet([7])[0])
    assert d.confidence > 0.95
    with pytest.raises(TypeError, match="confidence must be True or False"):
        MarkerDetector("DICT_4X4_50", confidence="no")


def _same(a, b):
    return [d.id for d in a] == [d.id for d in b] and all(np.array_equal(x.corners, y.corners) for x, y in zip(a, b))


def test_the_worker_thread_changes_no_detection(detector, monkeypatch):
    import visloc.markers.detector as det_mod

    images = [random_scene(np.random.default_rng(s), size=(320, 240), difficulty=d).image
              for s, d in ((1, "easy"), (2, "hard"), (3, "small"), (4, "empty"))]
    monkeypatch.setattr(det_mod, "_THREAD_MAX_PIXELS", 0)  # every pass on the calling thread
    alone = [detector.detect(im) for im in images]
    monkeypatch.setattr(det_mod, "_THREAD_MAX_PIXELS", 10**9)  # later passes on the worker
    threaded = [detector.detect(im) for im in images]
    assert sum(map(len, alone)) > 5
    assert all(_same(a, b) for a, b in zip(alone, threaded, strict=True))


def _detect_in_child(queue):
    image = random_scene(np.random.default_rng(1), size=(320, 240), difficulty="easy").image
    queue.put([d.id for d in MarkerDetector("DICT_4X4_50").detect(image)])


def test_detection_works_in_a_forked_child(detector):
    import multiprocessing

    image = random_scene(np.random.default_rng(1), size=(320, 240), difficulty="easy").image
    ids = [d.id for d in detector.detect(image)]  # the parent's worker thread exists now
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_detect_in_child, args=(queue,))
    child.start()
    try:
        assert queue.get(timeout=20) == ids and ids
    finally:
        child.join(timeout=10)
        if child.is_alive():
            child.kill()


@pytest.mark.parametrize("k1", [-0.15, 0.0])
def test_curved_sides_give_the_corners_under_lens_distortion(k1):
    # stage 8b: a webcam's barrel distortion bends the sides; lines fitted to them miss the
    # corners, curves do not (and straight sides stay as accurate as before)
    eff = CameraEffects(k1=k1, full_well=None, read_noise=0.0, jpeg_quality=None, vignetting=0.0)
    errs = {True: [], False: []}
    for seed in range(3):
        scene = random_scene(np.random.default_rng([3, seed]), size=(640, 480), difficulty="easy", camera=eff)
        truth = {m.id: m.corners for m in scene.markers if m.visible}
        for bend in (True, False):
            dets = MarkerDetector("DICT_4X4_50", bend=bend).detect(scene.image)
            assert sorted(d.id for d in dets) == sorted(truth)
            errs[bend].extend(np.linalg.norm(d.corners - truth[d.id], axis=1).max() for d in dets)
    assert max(errs[True]) < 0.1
    if k1:
        assert max(errs[False]) > 0.3  # what the straight sides miss by
    else:
        assert max(errs[True]) <= max(errs[False]) + 0.002


def test_deeper_pixel_types_are_read_as_their_uint8_equivalent(detector):
    image = random_scene(2, size=(320, 240), difficulty="easy", camera=True).image
    base = detector.detect(image)
    for deep in (image.astype(np.uint16) << 4, image.astype(np.float32), image / 255.0):  # 12-bit, 0..255, 0..1
        dets = detector.detect(deep)
        assert [d.id for d in dets] == [d.id for d in base] and len(base) > 0
        assert all(np.abs(a.corners - b.corners).max() < 0.05 for a, b in zip(dets, base, strict=True))
    with pytest.raises(TypeError, match="uint8"):
        detector.detect(image.astype(np.int32))


def test_the_python_stages_give_the_compiled_detections():
    from visloc.markers.bits import NATIVE_CELLS
    from visloc.markers.contours import NATIVE_BORDERS
    from visloc.markers.corners_batch import NATIVE_QUADS
    from visloc.markers.refine import NATIVE_REFINE

    python = MarkerDetector("DICT_4X4_50", native=False)
    assert python.detect(random_scene(11, size=(320, 240), difficulty="easy", camera=True).image)
    if not (NATIVE_BORDERS and NATIVE_QUADS and NATIVE_REFINE and NATIVE_CELLS):
        pytest.skip("the compiled stages were not built (no C compiler at install)")
    compiled = MarkerDetector("DICT_4X4_50", native=True)
    for seed, difficulty in ((11, "easy"), (12, "hard"), (13, "small")):
        image = random_scene(seed, size=(320, 240), difficulty=difficulty, camera=True).image
        a, b = compiled.detect(image), python.detect(image)
        assert [d.id for d in a] == [d.id for d in b]
        # stage 8 interpolates in double precision compiled, through cv2.remap in numpy
        assert all(np.abs(x.corners - y.corners).max() < 0.05 for x, y in zip(a, b, strict=True))
    with pytest.raises(ValueError, match="native"):
        MarkerDetector("DICT_4X4_50", native="yes")


@pytest.mark.parametrize("seed", [0, 6])
def test_board_tags_touching_corner_squares_are_found_by_stage_3c(seed):
    # sharp linear renders of AprilGrid-style boards: each tag's border touches the corner
    # squares, so most tags' outlines are not closed squares until stage 3c erodes the ink
    scene = random_board_scene(np.random.default_rng([9, 2, seed]), camera=False, size=(320, 240))
    truth = {m.id: m.corners for m in scene.markers if m.visible}

    def found(pairs):
        return sum(1 for mid, c in pairs if mid in truth and np.abs(c - truth[mid]).max() < 3)

    def visloc(**kw):
        dets = MarkerDetector("DICT_APRILTAG_36h11", response="linear", **kw).detect(scene.image)
        return [(d.id, d.corners) for d in dets]

    cv_det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11))
    corners, ids, _ = cv_det.detectMarkers(scene.image)
    opencv = [] if ids is None else [(int(i), c.reshape(4, 2)) for c, i in zip(corners, ids.ravel())]
    with_retry, without = found(visloc()), found(visloc(board_retry=False))
    assert with_retry >= 0.9 * len(truth)
    assert with_retry > without and with_retry >= found(opencv)


def test_stage_3c_leaves_isolated_markers_alone(monkeypatch):
    scene = random_scene(np.random.default_rng(5), size=(320, 240), difficulty="easy")
    det = MarkerDetector("DICT_4X4_50")
    calls = []
    monkeypatch.setattr(det, "_eroded", lambda *a: calls.append(a))
    assert det.detect(scene.image) and not calls


@pytest.mark.parametrize("native", [None, False])
def test_coarse_pass_quads_on_dark_frames_are_refined_from_a_wide_refinement_too(native):
    # Dark, noisy 1280 x 720 camera-like frames: these markers are found only by the coarse
    # search passes, whose contours put one side of each quad 10-34 px off at one end. Stage 8
    # (0.4 cell, at most 5 px) cannot reach that; the refinement from a wide first one (0.4 cell
    # uncapped), kept where its sides sit on stronger edges, brings every corner within 2.5 px.
    # Without it (coarse_scale=None) corners stay 16-30 px off.
    scenes = [random_scene(np.random.default_rng([700, 1280, i, 4]), size=(1280, 720), difficulty="dark", camera=True)
              for i in (8, 11)]
    worst = {}
    for coarse_scale in (3.0, None):
        det = MarkerDetector("DICT_4X4_50", coarse_scale=coarse_scale, native=native)
        errors = []
        for sc in scenes:
            truth = {m.id: m.corners for m in sc.markers if m.visible}
            got = {d.id: d.corners for d in det.detect(sc.image) if d.id in truth}
            assert len(got) == 4
            errors += [float(np.linalg.norm(c - truth[i], axis=1).max()) for i, c in got.items()]
        worst[coarse_scale] = max(errors)
    assert worst[3.0] < 2.5
    assert worst[None] > 10.0


def test_coarse_refinement_settings_are_checked():
    assert MarkerDetector("DICT_4X4_50").params.coarse_scale == 3.0
    with pytest.raises(ValueError, match="coarse_scale"):
        MarkerDetector("DICT_4X4_50", coarse_scale=0.5)
    with pytest.raises(ValueError, match="coarse_iterations"):
        MarkerDetector("DICT_4X4_50", coarse_iterations=0)


def test_the_detectors_fast_detection_is_the_dataclasss_own() -> None:
    # the detector sets a MarkerDetection's fields at once (_detection): the same object as the
    # dataclass's __init__ makes, every field included (a new field must be added there too)
    import dataclasses

    from visloc.markers.detector import _detection
    from visloc.types import MarkerDetection

    corners = np.arange(8.0).reshape(4, 2)
    values = (7, corners, 1, 0.25, 3, 80.5, False, 0.75, True)
    fast, slow = _detection(*values), MarkerDetection(*values)
    assert type(fast) is MarkerDetection and vars(fast) == vars(slow)
    assert [f.name for f in dataclasses.fields(MarkerDetection)] == list(vars(fast))
    with pytest.raises(dataclasses.FrozenInstanceError):
        fast.id = 2  # type: ignore[misc]
