import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from visloc.markers.dictionary import PREDEFINED, load_dictionary, pack_bits

TUTORIAL_DICT = "datasets/real/tutorial_dict.yml"


@pytest.mark.parametrize("name", ["DICT_4X4_50", "DICT_6X6_250", "DICT_APRILTAG_36h11", "DICT_ARUCO_ORIGINAL"])
def test_marker_images_match_opencv(name):
    d = load_dictionary(name)
    cv_dict = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))
    for marker_id in (0, 1, len(d) - 1):
        ours = d.marker_image(marker_id, cell_px=5)
        theirs = cv2.aruco.generateImageMarker(cv_dict, marker_id, ours.shape[0])
        assert np.array_equal(ours, theirs)


def test_names_are_case_tolerant_and_unknown_names_fail():
    assert len(load_dictionary("DICT_APRILTAG_36H11")) == 587
    assert load_dictionary("4X4_50").marker_size == 4
    assert "DICT_ARUCO_MIP_36h12" in PREDEFINED
    with pytest.raises(ValueError, match="unknown dictionary"):
        load_dictionary("DICT_9X9_1")


def test_yaml_dictionary_matches_opencv_reader():
    d = load_dictionary(TUTORIAL_DICT)
    fs = cv2.FileStorage(TUTORIAL_DICT, cv2.FILE_STORAGE_READ)
    ref = cv2.aruco.Dictionary()
    ref.readDictionary(fs.root())
    assert len(d) == 35 and d.marker_size == 6
    for i in range(len(d)):
        bits = cv2.aruco.Dictionary.getBitsFromByteList(ref.bytesList[i : i + 1], 6)
        assert np.array_equal(d.bits[i], bits)
    assert d.max_correction >= 1


def test_malformed_yaml_is_rejected(tmp_path):
    p = tmp_path / "bad.yml"
    p.write_text('%YAML:1.0\nnmarkers: 1\nmarkersize: 4\nmarker_0: "0101"\n')
    with pytest.raises(ValueError, match="marker_0"):
        load_dictionary(str(p))


@pytest.mark.parametrize("text", ["", "garbage {{{ not yaml\x00\x01", "%YAML:1.0\n[1, 2"])
def test_empty_or_garbage_yaml_is_a_clear_error(tmp_path, text):
    p = tmp_path / "dict.yml"
    p.write_bytes(text.encode("latin-1"))
    with pytest.raises(ValueError, match=r"dictionary file .* (is empty|is not OpenCV FileStorage|lacks)"):
        load_dictionary(str(p))


def test_correction_bits_beyond_the_dictionarys_distance_are_refused(tmp_path):
    d = load_dictionary("DICT_4X4_50")
    rows = "".join(f'marker_{i}: "{"".join(map(str, d.bits[i].ravel()))}"\n' for i in range(len(d)))
    head = f"%YAML:1.0\nnmarkers: {len(d)}\nmarkersize: 4\n"
    ok, bad = tmp_path / "ok.yml", tmp_path / "bad.yml"
    ok.write_text(head + rows + f"maxCorrectionBits: {d.max_correction}\n")
    bad.write_text(head + rows + "maxCorrectionBits: 99\n")
    assert load_dictionary(str(ok)).max_correction == d.max_correction
    with pytest.raises(ValueError, match="maxCorrectionBits 99 exceeds"):
        load_dictionary(str(bad))


@settings(max_examples=40, deadline=None)
@given(marker_id=st.integers(0, 249), rot=st.integers(0, 3), flips=st.integers(0, 2))
def test_match_finds_any_rotation_with_errors(marker_id, rot, flips):
    d = load_dictionary("DICT_6X6_250")
    bits = np.rot90(d.bits[marker_id], rot).copy()
    for k in range(flips):
        bits.flat[7 * k + 3] ^= 1
    hit = d.match(bits, d.max_correction)
    assert hit == (marker_id, rot, flips)


def test_match_refuses_grids_of_the_wrong_shape_or_values():
    d = load_dictionary("DICT_4X4_50")
    with pytest.raises(ValueError, match=r"bits must be \(4, 4\).*got shape \(5, 5\)"):
        d.match(np.zeros((5, 5), np.uint8), 10)
    with pytest.raises(ValueError, match="bits must hold only 0 and 1, got 2"):
        d.match(np.full((4, 4), 2), 16)
    assert d.match(d.bits[3].astype(bool), 0) == (3, 0, 0)  # bool grids are 0/1


def test_pack_bits_refuses_more_than_64_values_or_values_other_than_0_and_1():
    with pytest.raises(ValueError, match="at most 64 values, got 65"):
        pack_bits(np.ones(65))
    with pytest.raises(ValueError, match="bits must hold only 0 and 1, got -1.0"):
        pack_bits([-1.0])
    with pytest.raises(ValueError, match="bits must hold only 0 and 1, got nan"):
        pack_bits([1.0, np.nan])
    assert pack_bits(np.ones(64)) == np.uint64(2**64 - 1)
    assert pack_bits([True, False, 1.0]) == np.uint64(5)


def test_loaded_dictionaries_are_read_only(tmp_path):
    # _predefined is cached: every load hands out the same arrays, an edit would spoil them all
    d = load_dictionary("DICT_4X4_50")
    rows = "".join(f'marker_{i}: "{"".join(map(str, d.bits[i].ravel()))}"\n' for i in range(3))
    path = tmp_path / "three.yml"
    path.write_text(f"%YAML:1.0\nnmarkers: 3\nmarkersize: 4\n{rows}")
    for dic in (d, load_dictionary(str(path))):
        for arr in (dic.bits, dic.codes):
            assert not arr.flags.writeable
            with pytest.raises(ValueError, match="read-only"):
                arr[0, 0] = 0
    assert load_dictionary("4x4_50") is d


@pytest.mark.parametrize(("kwargs", "error", "message"), [
    ({"marker_id": True}, TypeError, "marker_id must be an integer, got bool"),
    ({"marker_id": 1.5}, TypeError, "marker_id must be an integer, got float"),
    ({"marker_id": "a"}, TypeError, "marker_id must be an integer, got str"),
    ({"marker_id": 50}, ValueError, r"marker_id must be in \[0, 49\], got 50"),
    ({"marker_id": -1}, ValueError, r"marker_id must be in \[0, 49\], got -1"),
    ({"marker_id": 1, "cell_px": 2.5}, TypeError, "cell_px must be an integer, got float"),
    ({"marker_id": 1, "cell_px": 0}, ValueError, "cell_px must be >= 1, got 0"),
    ({"marker_id": 1, "border_bits": -1}, ValueError, "border_bits must be >= 0, got -1"),
    ({"marker_id": 1, "border_bits": False}, TypeError, "border_bits must be an integer, got bool"),
])
def test_marker_image_refuses_arguments_that_are_not_integers_in_range(kwargs, error, message):
    with pytest.raises(error, match=message):
        load_dictionary("DICT_4X4_50").marker_image(**kwargs)


def test_marker_image_takes_numpy_integers():
    d = load_dictionary("DICT_4X4_50")
    want = d.marker_image(7, cell_px=3, border_bits=2)
    assert want.shape == (24, 24)
    assert np.array_equal(d.marker_image(np.int64(7), cell_px=np.uint8(3), border_bits=np.int32(2)), want)
