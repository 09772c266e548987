"""RerunLogger writes a .rrd recording that rerun reads back with the expected entities."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
import rerun as rr
from rerun.chunk import RrdReader

from visloc.io import RerunLogger
from visloc.types import MarkerDetection, Pose

SQUARE = np.array([[20, 10], [40, 10], [40, 30], [20, 30]], float)
CAMERA = SimpleNamespace(
    K=np.array([[80.0, 0, 31.5], [0, 80.0, 23.5], [0, 0, 1]]), dist=np.zeros(5)
)
POSE = Pose(np.diag([1.0, -1.0, -1.0]), np.array([0.0, 0.0, 1.0]))


@pytest.fixture(autouse=True)
def _strict_rerun() -> Iterator[None]:
    """Make rerun raise on bad log calls instead of only warning."""
    previous = rr.strict_mode()
    rr.set_strict_mode(True)
    yield
    rr.set_strict_mode(previous)


def _rows(path: Path) -> dict[tuple[str, str], list[tuple[int, object]]]:
    """(entity, column) -> [(frame, value)] for every temporal component in the file."""
    rows: dict[tuple[str, str], list[tuple[int, object]]] = {}
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        if "frame" not in batch.schema.names:
            continue
        frames = batch.column("frame").to_pylist()
        for name in batch.schema.names:
            if ":" in name:
                values = batch.column(name).to_pylist()
                rows.setdefault((chunk.entity_path, name), []).extend(zip(frames, values))
    return rows


def _log_three_frames(log: RerunLogger) -> None:
    grey = np.full((48, 64), 100, np.uint8)
    bgr = np.dstack([grey, grey + 20, grey + 40])
    log.log_frame(0, 0.0, grey, [MarkerDetection(7, SQUARE)], poses=[POSE], camera=CAMERA, marker_length=0.1)
    log.log_frame(
        1,
        0.04,
        bgr,
        [MarkerDetection(7, SQUARE), MarkerDetection(9, SQUARE + 5)],
        poses=[POSE, None],
        camera=CAMERA,
        marker_length=0.1,
    )
    log.log_frame(2, 0.08, None, [])  # an unreadable frame


def test_recording_is_written_and_loads_back(tmp_path: Path) -> None:
    path = tmp_path / "rec" / "run.rrd"
    with RerunLogger(path) as log:
        _log_three_frames(log)
    assert log.closed
    assert path.is_file() and path.stat().st_size > 1000

    reader = RrdReader(path)
    (entry,) = reader.recordings()
    assert entry.application_id == "visloc"
    entities = set(reader.store().schema().entity_paths())
    assert {
        "/camera",
        "/camera/image",
        "/camera/image/markers",
        "/camera/image/corner0",
        "/world/markers/7",
        "/world/markers/7/axes",
    } <= entities
    assert "/world/markers/9" not in entities  # no pose for marker 9

    rows = _rows(path)
    assert [f for f, _ in rows[("/camera/image", "Image:buffer")]] == [0, 1]
    assert [f for f, _ in rows[("/camera/image", "Clear:is_recursive")]] == [2]
    labels = dict(rows[("/camera/image/markers", "LineStrips2D:labels")])
    assert labels == {0: ["7"], 1: ["7", "9"], 2: []}
    strip = dict(rows[("/camera/image/markers", "LineStrips2D:strips")])[0][0]
    # closed outline, shifted to rerun's pixel-centre convention (+0.5)
    np.testing.assert_allclose(strip, np.vstack([SQUARE, SQUARE[:1]]) + 0.5)
    translation = dict(rows[("/world/markers/7", "Transform3D:translation")])
    np.testing.assert_allclose(translation[0], [[0.0, 0.0, 1.0]])
    assert [f for f, _ in rows[("/world/markers/7", "Clear:is_recursive")]] == [2]
    (pinhole,) = rows[("/camera", "Pinhole:image_from_camera")]  # logged once: unchanged K
    k = np.asarray(pinhole[1]).reshape(3, 3).T  # stored column-major
    np.testing.assert_allclose(k[:2, 2], [32.0, 24.0])


def test_time_timeline_is_in_seconds(tmp_path: Path) -> None:
    path = tmp_path / "t.rrd"
    with RerunLogger(path, app_id="visloc-test") as log:
        _log_three_frames(log)
    for chunk in RrdReader(path).stream():
        if chunk.entity_path == "/camera/image/markers":
            batch = chunk.to_record_batch()
            seconds = [d.total_seconds() for d in batch.column("time").to_pylist()]
            assert seconds == pytest.approx([0.0, 0.04, 0.08])
            break
    else:
        pytest.fail("no marker chunk in the recording")


def test_jpeg_option_makes_smaller_files(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    image = (rng.random((120, 160)) * 40 + 100).astype(np.uint8)
    sizes = {}
    for name, quality in [("raw", None), ("jpeg", 80)]:
        path = tmp_path / f"{name}.rrd"
        with RerunLogger(path, jpeg_quality=quality) as log:
            for i in range(5):
                log.log_frame(i, i / 10, image, [])
        sizes[name] = path.stat().st_size
    assert sizes["jpeg"] < sizes["raw"]


def test_bad_arguments(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="jpeg_quality"):
        RerunLogger(tmp_path / "x.rrd", jpeg_quality=0)
    with pytest.raises(ValueError, match="path is a directory"):
        RerunLogger(tmp_path)
    with RerunLogger(tmp_path / "y.rrd") as log:
        image = np.zeros((48, 64), np.uint8)
        det = [MarkerDetection(7, SQUARE)]
        with pytest.raises(ValueError, match="marker_length"):
            log.log_frame(0, 0.0, image, det, poses=[POSE], camera=CAMERA)
        with pytest.raises(ValueError, match="poses must have one entry"):
            log.log_frame(0, 0.0, image, det, poses=[], camera=CAMERA, marker_length=0.1)
        with pytest.raises(ValueError, match="time"):
            log.log_frame(0, float("nan"), image, det)
        with pytest.raises(TypeError, match="camera"):
            log.log_frame(0, 0.0, image, det, camera=object())
    with pytest.raises(ValueError, match="closed"):
        log.log_frame(1, 0.1, image, det)


def test_flow_and_localize_frames_are_checked_as_log_frame_checks_them(tmp_path: Path) -> None:
    with RerunLogger(tmp_path / "z.rrd") as log:
        with pytest.raises(ValueError, match="time"):
            log.log_localize(0, float("nan"), None, (0.0, 0.0, 1.0))
        with pytest.raises(ValueError, match="time"):
            log.log_flow(0, float("inf"), None, None, None)
        with pytest.raises(TypeError, match="index"):
            log.log_localize(0.5, 0.0, None, (0.0, 0.0, 1.0))
        log.log_localize(0, 0.0, None, (0.0, 0.0, 1.0))
    with pytest.raises(ValueError, match="closed"):
        log.log_localize(1, 0.1, None, (0.0, 0.0, 1.0))
    with pytest.raises(ValueError, match="closed"):
        log.log_flow(1, 0.1, None, None, None)


@pytest.mark.parametrize("bad, exc", [((1.0, 2.0), ValueError), ((1.0, 2.0, 3.0, 4.0), ValueError),
                                      ((0.0, float("nan"), 1.0), ValueError), ("abc", TypeError)])
def test_a_localize_position_that_is_not_three_finite_numbers_logs_nothing(tmp_path: Path, bad, exc) -> None:
    # a 2-element estimate used to be logged as x and y alone and a 2-point track segment
    path = tmp_path / "loc.rrd"
    with RerunLogger(path) as log:
        log.log_localize(0, 0.0, None, (0.0, 0.0, 1.0), truth=(0.0, 0.0, 1.0))
        with pytest.raises(exc, match="estimate"):
            log.log_localize(1, 0.1, None, bad)
        with pytest.raises(exc, match="truth"):
            log.log_localize(1, 0.1, None, (0.0, 0.0, 1.0), truth=bad)
        log.log_localize(2, 0.2, None, (0.1, 0.0, 1.0))
    rows = _rows(path)
    frames = {f for (entity, _), values in rows.items() if entity.startswith("/plots") for f, _ in values}
    assert frames == {0, 2}  # nothing of frame 1
    track = dict(rows[("/world/estimate", "LineStrips3D:strips")])[2][0]
    assert len(track) == 2 and all(len(p) == 3 for p in track)


def test_a_recording_not_named_rrd_is_refused_before_anything_is_written(tmp_path: Path) -> None:
    # it used to be written as x.txt, which the viewer would not open as a recording
    with pytest.raises(ValueError, match=r"\.rrd"):
        RerunLogger(tmp_path / "sub" / "x.txt")
    assert list(tmp_path.iterdir()) == []
    from visloc.cli import main

    image = tmp_path / "a.png"
    assert cv2.imwrite(str(image), np.full((64, 64), 200, np.uint8))
    assert main(["detect", str(image), "--rerun", str(tmp_path / "x.txt")]) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png"]
    with RerunLogger(tmp_path / "y.RRD") as log:  # the suffix in any case
        log.log_localize(0, 0.0, None, (0.0, 0.0, 1.0))
    assert (tmp_path / "y.RRD").is_file()
