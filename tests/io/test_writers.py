"""JSONL/CSV writers (flushed per record) and the annotation sink (PNG folder, video)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from visloc.io import AnnotationSink, CsvWriter, JsonlWriter, to_jsonable
from visloc.io.closing import staged_path
from visloc.types import MarkerDetection, Pose


def test_jsonl_lines_are_on_disk_while_the_writer_is_open(tmp_path: Path) -> None:
    path = tmp_path / "out" / "results.jsonl"  # parent folder is created
    det = MarkerDetection(3, np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float))
    staged = staged_path(path)  # where the lines are until the writer closes
    with JsonlWriter(path) as out:
        out.write({"frame": np.int64(0), "t": np.float32(0.5), "v": np.arange(3)})
        assert staged.read_text().splitlines() == ['{"frame":0,"t":0.5,"v":[0,1,2]}']
        out.write({"frame": 1, "rms": float("nan"), "markers": [det], "ok": np.bool_(True)})
        lines = staged.read_text().splitlines()
        assert len(lines) == 2 and out.count == 2
        second = json.loads(lines[1])
        assert second["rms"] is None  # strict JSON: NaN -> null
        assert second["ok"] is True
        assert second["markers"][0]["id"] == 3
        assert second["markers"][0]["corners"][2] == [1.0, 1.0]
        assert " " not in lines[1]  # compact
    assert out.closed
    assert path.read_text().splitlines() == lines and not staged.exists()
    with pytest.raises(ValueError, match="closed"):
        out.write({"frame": 2})


def test_jsonl_rejects_non_dict_and_unserialisable_values(tmp_path: Path) -> None:
    with JsonlWriter(tmp_path / "r.jsonl") as out:
        with pytest.raises(TypeError, match="obj must be a dict"):
            out.write([1, 2])  # type: ignore[arg-type]
        with pytest.raises(TypeError, match=r"obj\['x'\] has type object"):
            out.write({"x": object()})
        assert out.count == 0
    assert not (tmp_path / "r.jsonl").exists() and not staged_path(tmp_path / "r.jsonl").exists()


def test_to_jsonable_handles_numpy_pose_and_keys() -> None:
    pose = Pose(np.eye(3), np.array([0.0, 0.0, 2.0]), reprojection_rms=0.1)
    out = to_jsonable({np.int32(5): pose, "m": np.eye(2, dtype=np.float32), "s": (1, np.inf)})
    assert out["5"]["tvec"] == [0.0, 0.0, 2.0]
    assert out["m"] == [[1.0, 0.0], [0.0, 1.0]]
    assert out["s"] == [1, None]
    json.dumps(out, allow_nan=False)


def test_csv_rows_are_flushed_and_readable(tmp_path: Path) -> None:
    path = tmp_path / "poses.csv"
    with CsvWriter(path, ["frame", "x", "ok", "corners"]) as out:
        assert staged_path(path).read_text().strip() == "frame,x,ok,corners"
        out.write({"frame": np.int64(0), "x": np.float64(0.25), "corners": np.array([1, 2])})
        out.write({"frame": 1, "x": float("nan")})
        rows = list(csv.DictReader(staged_path(path).open(newline="")))
        assert rows == [
            {"frame": "0", "x": "0.25", "ok": "", "corners": "[1,2]"},
            {"frame": "1", "x": "", "ok": "", "corners": ""},
        ]
        with pytest.raises(ValueError, match=r"not in fieldnames: \['y'\]"):
            out.write({"frame": 2, "y": 1})
    with pytest.raises(ValueError, match="fieldnames"):
        CsvWriter(tmp_path / "bad.csv", [])
    with pytest.raises(TypeError, match="fieldnames"):
        CsvWriter(tmp_path / "bad.csv", "frame,x")


def test_annotation_sink_writes_pngs_named_after_frames(tmp_path: Path) -> None:
    target = tmp_path / "annotated"
    images = [np.full((20, 30, 3), 40 * i, np.uint8) for i in range(4)]
    images[1][5, 7] = (1, 2, 3)
    names = ["in/img_01.jpg", "clip.mp4#12", "other/img_01.jpg", None]
    with AnnotationSink(target) as sink:
        written = [sink.write(img, name) for img, name in zip(images, names, strict=True)]
        sink.write(np.zeros((20, 30), np.uint8), "grey.png")
    assert not sink.is_video and sink.count == 5
    assert [p.name for p in written] == [
        "img_01.png",
        "clip_000012.png",
        "img_01_1.png",
        "000003.png",
    ]
    for path, img in zip(written, images, strict=True):
        np.testing.assert_array_equal(cv2.imread(str(path), cv2.IMREAD_UNCHANGED), img)
    assert cv2.imread(str(target / "grey.png"), cv2.IMREAD_UNCHANGED).shape == (20, 30)
    with pytest.raises(ValueError, match="closed"):
        sink.write(images[0], "late.png")


@pytest.mark.parametrize("suffix", [".mp4", ".avi"])
def test_annotation_sink_writes_a_readable_video(tmp_path: Path, suffix: str) -> None:
    target = tmp_path / "videos" / f"annotated{suffix}"
    with AnnotationSink(target, fps=12) as sink:
        assert sink.is_video
        for i in range(4):
            sink.write(np.full((48, 64, 3), 30 + 50 * i, np.uint8), f"f{i}")
        sink.write(np.full((96, 128), 200, np.uint8))  # another size, grey: resized
    capture = cv2.VideoCapture(str(target))
    assert capture.isOpened()
    assert capture.get(cv2.CAP_PROP_FRAME_COUNT) == 5
    assert capture.get(cv2.CAP_PROP_FPS) == pytest.approx(12)
    means = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        assert frame.shape == (48, 64, 3)
        means.append(float(frame.mean()))
    capture.release()
    np.testing.assert_allclose(means, [30, 80, 130, 180, 200], atol=6)


def test_annotation_sink_bad_arguments(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="fps"):
        AnnotationSink(tmp_path / "a.mp4", fps=0)
    existing = tmp_path / "file.txt"
    existing.write_text("x")
    with pytest.raises(ValueError, match="target"):
        AnnotationSink(existing)
    with AnnotationSink(tmp_path / "out") as sink, pytest.raises(TypeError, match="image"):
        sink.write(np.zeros((4, 4), np.int32))  # type: ignore[arg-type]


def test_an_earlier_result_survives_a_run_that_fails_before_its_first_record(tmp_path: Path) -> None:
    path = tmp_path / "det.jsonl"
    path.write_text('{"frame":0}\n')
    with pytest.raises(RuntimeError), JsonlWriter(path):
        raise RuntimeError("the run failed before any frame")
    assert path.read_text() == '{"frame":0}\n' and not staged_path(path).exists()
    with pytest.raises(KeyboardInterrupt), JsonlWriter(path) as out:  # interrupted after a frame
        out.write({"frame": 7})
        raise KeyboardInterrupt
    assert path.read_text() == '{"frame":7}\n'  # what was computed is kept
    csv_path = tmp_path / "v.csv"
    csv_path.write_text("frame\n1\n")
    CsvWriter(csv_path, ["frame"]).close()
    assert csv_path.read_text() == "frame\n1\n"


def test_keys_with_one_json_form_and_a_video_target_that_is_a_folder_are_refused(tmp_path: Path) -> None:
    with pytest.raises(TypeError, match=r"obj\['a'\]: the keys 1 and '1' both become '1'"):
        to_jsonable({"a": {1: 2, "1": 3}})
    assert to_jsonable({1: 2, "2": 3}) == {"1": 2, "2": 3}
    (tmp_path / "ann.mp4").mkdir()
    with pytest.raises(ValueError, match="is a folder"):
        AnnotationSink(tmp_path / "ann.mp4")


def test_long_doubles_are_floats_in_json():
    # item() of np.longdouble is an np.longdouble again: to_jsonable recursed for ever
    assert to_jsonable(np.longdouble(1.5)) == 1.5
    assert to_jsonable(np.array([1.5, np.nan], np.longdouble)) == [1.5, None]
    with pytest.raises(TypeError, match="clongdouble"):
        to_jsonable(np.clongdouble(1 + 2j))
