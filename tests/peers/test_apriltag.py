"""Ports of AprilTag 3's own tests (AprilRobotics/apriltag, test/) that need no data files, or
only the photo visloc already carries, on OpenCV's ``DICT_APRILTAG_*`` dictionaries.

Not ported: test_detection.c (regression against AprilTag 3's own detections of its photos:
tests/markers/test_real_photos.py holds visloc to those), test_tag_pose_estimation (pose, no
detection). The Circle / Standard / Custom families of test_quick_decode.c have no OpenCV
dictionary and are left out.
"""

from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.peers.conftest import (
    REPO,
    aruco_dict,
    opencv_detector,
    opencv_found,
    place,
    visloc_found,
)
from visloc.markers import MarkerDetector
from visloc.markers.bits import decode
from visloc.markers.dictionary import load_dictionary

#: Family -> its minimum Hamming distance h (the number in the family's name).
FAMILIES = {"DICT_APRILTAG_16h5": 5, "DICT_APRILTAG_25h9": 9, "DICT_APRILTAG_36h10": 10, "DICT_APRILTAG_36h11": 11}


def _limit(h):
    """test_quick_decode.c's correction tested: (h - 1) / 2, at most 3."""
    return min((h - 1) // 2, 3)


def _rate(dictionary, limit):
    """The error-correction rate that corrects exactly ``limit`` bits under OpenCV's (and
    visloc's) rule ``int(maxCorrectionBits * rate)``."""
    rate = limit / dictionary.maxCorrectionBits
    assert int(dictionary.maxCorrectionBits * rate) == limit
    return rate


def _error_patterns(nbits, limit, rng, per_order=40):
    """Bit sets to flip: none, every single bit, and up to ``per_order`` random sets of each
    size 2 .. ``limit`` (the original enumerates them all: millions of decodes)."""
    patterns = [()] + [(b,) for b in range(nbits)]
    for k in range(2, limit + 1):
        seen = set()
        while len(seen) < per_order:
            seen.add(tuple(sorted(rng.choice(nbits, size=k, replace=False).tolist())))
        patterns += sorted(seen)
    return patterns


@pytest.mark.parametrize("family", list(FAMILIES))
def test_quick_decode_corrects_up_to_the_family_limit(family):
    """test_quick_decode.c: every code word of the family decodes to its own id with hamming 0;
    with 1, 2, 3 flipped bits (up to min((h - 1) / 2, 3)) to its own id with hamming equal to
    the flips. All code words of 16h5 and 25h9, 24 of 36h10 and 36h11, and 40 random flip sets of
    sizes 2 and 3
    (fixed seed) stand in for the original's exhaustive loops. visloc's stage 10
    (:func:`visloc.markers.bits.decode`) with the rate that corrects exactly that many bits;
    OpenCV's ``Dictionary.identify`` / ``getDistanceToId`` as the check."""
    rng = np.random.default_rng(36)
    d = aruco_dict(family)
    ours = load_dictionary(family)
    s = d.markerSize
    limit = _limit(FAMILIES[family])
    rate = _rate(d, limit)
    n = d.bytesList.shape[0]
    code_ids = np.arange(n) if n <= 40 else np.sort(rng.choice(n, size=24, replace=False))
    patterns = _error_patterns(s * s, limit, rng)
    grids, want_id, want_ham = [], [], []
    for i in code_ids.tolist():
        bits = cv2.aruco.Dictionary.getBitsFromByteList(d.bytesList[i : i + 1], s).astype(np.uint8)
        for flips in patterns:
            g = bits.copy().reshape(-1)
            g[list(flips)] ^= 1
            grids.append(g.reshape(s, s))
            want_id.append(i)
            want_ham.append(len(flips))
    grids = np.array(grids)
    for k in range(0, len(grids), max(1, len(grids) // 50)):  # OpenCV's check on ~50 (ms each)
        ok, idx, _ = d.identify(grids[k], rate)
        assert ok and idx == want_id[k] and d.getDistanceToId(grids[k], idx) == want_ham[k]
    got_id, got_ham, got_ok = [], [], []
    for start in range(0, len(grids), 256):  # stage 10 compares each grid with every code
        ids, _, ham, ok = decode(grids[start : start + 256], ours, error_correction_rate=rate)
        got_id.append(ids)
        got_ham.append(ham)
        got_ok.append(ok)
    got_id, got_ham, got_ok = (np.concatenate(a) for a in (got_id, got_ham, got_ok))
    bad = np.flatnonzero(~got_ok | (got_id != np.array(want_id)) | (got_ham != np.array(want_ham)))
    assert not len(bad), (
        f"{len(bad)} of {len(grids)} code words misdecoded, e.g. code {want_id[bad[0]]} with "
        f"{want_ham[bad[0]]} flips -> id {got_id[bad[0]]}, hamming {got_ham[bad[0]]}, ok {got_ok[bad[0]]}"
    )


@pytest.mark.parametrize("family", list(FAMILIES))
def test_generated_tags_with_bit_errors_decode_through_the_detector(family):
    """test_quick_decode.c through the image path: tags of the family drawn (10 px cells, white
    margins) with 0 .. min((h - 1) / 2, 3) flipped bits, 3 ids per error count in one image, are
    each found once with their id and, for visloc, hamming equal to the flips; OpenCV
    (``errorCorrectionRate`` correcting exactly that many bits) finds the same ids."""
    rng = np.random.default_rng(7)
    d = aruco_dict(family)
    s = d.markerSize
    limit = _limit(FAMILIES[family])
    rate = _rate(d, limit)
    side = (s + 2) * 10
    pitch = side + 40
    ids = rng.choice(d.bytesList.shape[0], size=3 * (limit + 1), replace=False).tolist()
    img = np.full((3 * pitch + 40, (limit + 1) * pitch + 40), 255, np.uint8)
    truth = {}
    for j, mid in enumerate(ids):
        errors, row = divmod(j, 3)
        bits = cv2.aruco.Dictionary.getBitsFromByteList(d.bytesList[mid : mid + 1], s).astype(np.uint8)
        flat = bits.reshape(-1)
        flat[rng.choice(s * s, size=errors, replace=False)] ^= 1
        one = cv2.aruco.Dictionary(cv2.aruco.Dictionary.getByteListFromBits(bits), s, 0)
        place(img, cv2.aruco.generateImageMarker(one, 0, side), (40 + errors * pitch, 40 + row * pitch))
        truth[mid] = errors
    found, _ = opencv_found(opencv_detector(d, errorCorrectionRate=rate), img)
    assert sorted(found) == sorted(truth)
    dets = MarkerDetector(family, error_correction_rate=rate).detect(img)
    got = {m.id: m.hamming for m in dets}
    assert len(dets) == len(got) and got == truth, f"visloc (id: hamming) {got}, expected {truth}"


def test_multiple_sizes_on_one_detector():
    """test_multiple_sizes.c: one detector runs on images of different sizes in turn
    (AprilTag: quad_decimate 2, 1, 2 on one handle) without stale cached state. visloc picks its
    search scale from the image size, so the same photo goes in at full, half, double and full
    size again; the original only requires the runs to complete, and the first and last runs
    must agree (OpenCV's as well)."""
    path = Path(REPO) / "datasets" / "real" / "33369213973_9d9bb4cc96_c.jpg"
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    sizes = [img, cv2.resize(img, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA),
             cv2.resize(img, None, fx=2.0, fy=2.0, interpolation=cv2.INTER_LINEAR), img]
    ref = opencv_detector("DICT_APRILTAG_36h11")
    runs = [opencv_found(ref, im) for im in sizes]
    assert runs[0][0] == runs[-1][0] and np.array_equal(runs[0][1], runs[-1][1])
    det = MarkerDetector("DICT_APRILTAG_36h11")
    runs = [visloc_found(det, im) for im in sizes]
    assert len(runs[0][0]) > 0
    assert runs[0][0] == runs[-1][0] and np.array_equal(runs[0][1], runs[-1][1])
