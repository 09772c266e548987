"""Recordings as sources (``visloc.io.bags``): ROS 1 bags, ROS 2 bags (SQLite and MCAP) and lone
MCAP files written here with rosbags' own writers from a rendered flight and its IMU."""

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.typesys import Stores, get_typestore

from visloc.cli import main
from visloc.io import open_source
from visloc.io.bags import (
    BagSource,
    _compressed_payload,
    _header,
    _image_message,
    read_bag_imu,
    recording_topics,
    write_bag,
)
from visloc.io.sources import SourceError
from visloc.markers import MarkerDetector

FPS = 10.0
T0 = 1_700_000_000  # header stamps in epoch seconds, as a robot writes them


def write_recording(path: Path, frames: list[np.ndarray], imu: np.ndarray, *, fmt: str, kind: str) -> Path:
    """A recording of ``frames`` (at FPS) on /camera/image and ``imu`` rows on /imu."""
    return write_bag(path, frames, [k / FPS for k in range(len(frames))], imu=imu, fmt=fmt, encoding=kind,
                     t0_ns=T0 * 1_000_000_000)


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    root = tmp_path_factory.mktemp("bags")
    src = root / "flight"
    assert main(["render", "localize", str(src), "--seconds", "1.0", "--fps", str(FPS), "--seed", "6"]) == 0
    frames = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in sorted(src.glob("frame_*.png"))]
    imu = np.loadtxt(src / "imu.csv", delimiter=",", skiprows=1)
    return root, src, frames, imu


@pytest.mark.parametrize(("fmt", "kind"), [("ros1", "mono8"), ("ros2", "rgb8"), ("mcap", "png")])
def test_every_frame_and_imu_sample_comes_back_in_order_with_its_stamp(flight, fmt, kind):
    root, _, frames, imu = flight
    path = write_recording(root / f"rec_{fmt}_{kind}{'.bag' if fmt == 'ros1' else ''}", frames, imu, fmt=fmt,
                           kind=kind)
    with open_source(path) as source:  # the only image topic: no --topic needed
        got = list(source)
        assert isinstance(source, BagSource) and len(source) == len(frames)
    assert [f.index for f in got] == list(range(len(frames)))
    assert [f.time for f in got] == pytest.approx([k / FPS for k in range(len(frames))], abs=1e-9)
    for f, img in zip(got, frames, strict=True):
        grey = f.image if f.image.ndim == 2 else cv2.cvtColor(f.image, cv2.COLOR_BGR2GRAY)
        assert np.array_equal(grey, img)  # raw and PNG are lossless: the same pixels
    back = read_bag_imu(path)
    assert back[:, 1:] == pytest.approx(imu[:, 1:])
    assert back[:, 0] == pytest.approx(imu[:, 0], abs=1e-9)  # the same origin as the frames


def test_lone_mcap_file_and_topics_listing(flight):
    root, _, frames, imu = flight
    folder = write_recording(root / "lone", frames, imu, fmt="mcap", kind="mono8")
    mcap = next(folder.glob("*.mcap"))
    topics = {t["topic"]: t for t in recording_topics(mcap)}
    assert topics["/camera/image"]["count"] == len(frames) and topics["/imu"]["type"] == "sensor_msgs/msg/Imu"
    assert topics["/camera/image"]["rate_hz"] == pytest.approx(FPS, rel=1e-6)
    with open_source(mcap, topic="/camera/image") as source:
        assert sum(f.image is not None for f in source) == len(frames)
    assert main(["info", str(mcap)]) == 0


def test_compressed_and_raw_give_the_same_detections(flight):
    root, _, frames, imu = flight
    raw = write_recording(root / "raw.bag", frames, imu, fmt="ros1", kind="mono8")
    png = write_recording(root / "png.bag", frames, imu, fmt="ros1", kind="png")
    det = MarkerDetector("DICT_4X4_100")
    with open_source(raw) as a, open_source(png) as b:
        for fa, fb in zip(a, b, strict=True):
            da, db = det.detect(fa.image), det.detect(fb.image)
            assert [d.id for d in da] == [d.id for d in db] and len(da) > 0
            assert all(np.array_equal(x.corners, y.corners) for x, y in zip(da, db, strict=True))


def test_localize_on_a_bag_with_its_imu_matches_the_folder_and_csv(flight, tmp_path):
    root, src, frames, imu = flight
    bag = write_recording(root / "loc.bag", frames, imu, fmt="ros1", kind="mono8")
    common = ["--camera", str(src / "camera.yml"), "--map", str(src / "map.yml"), "--quiet"]
    assert main(["localize", str(bag), "--imu-topic", "/imu", "--out", str(tmp_path / "bag.csv"), *common]) == 0
    assert main(["localize", str(src), "--fps", str(FPS), "--imu", str(src / "imu.csv"),
                 "--out", str(tmp_path / "folder.csv"), *common]) == 0
    a = list(csv.DictReader((tmp_path / "bag.csv").open()))
    b = list(csv.DictReader((tmp_path / "folder.csv").open()))
    assert len(a) == len(b) == len(frames)
    for ra, rb in zip(a, b, strict=True):
        assert float(ra["time"]) == pytest.approx(float(rb["time"]), abs=1e-9) and ra["fix"] == rb["fix"]
        for k in ("x", "y", "z", "vx", "vy", "vz"):
            assert float(ra[k]) == pytest.approx(float(rb[k]), abs=1e-9)


def test_bad_recordings_are_one_clear_line(flight, tmp_path, capsys):
    root, src, frames, imu = flight
    bag = write_recording(root / "bad.bag", frames, imu, fmt="ros1", kind="mono8")
    assert main(["detect", str(bag), "--topic", "/nope", "--quiet"]) == 2
    assert "no topic '/nope'" in capsys.readouterr().err
    assert main(["detect", str(bag), "--topic", "/imu", "--quiet"]) == 2
    assert "holds sensor_msgs/msg/Imu" in capsys.readouterr().err
    cut = tmp_path / "cut.bag"
    cut.write_bytes(bag.read_bytes()[: bag.stat().st_size // 2])
    code = main(["detect", str(cut), "--quiet"])
    err = capsys.readouterr().err
    assert code in (1, 2) and "Traceback" not in err and err.strip().splitlines()[-1].startswith("visloc detect")
    with pytest.raises(SourceError, match="topic"):
        open_source(src, topic="/camera/image")  # a topic for a folder


def test_an_unknown_encoding_costs_its_frame_only(flight, tmp_path):
    frames = flight[2]
    store = get_typestore(Stores.ROS1_NOETIC)
    path = tmp_path / "mixed.bag"
    with Ros1Writer(path) as w:
        cam = w.add_connection("/camera/image", "sensor_msgs/msg/Image", typestore=store)
        for k, img in enumerate(frames[:3]):
            msg = _image_message(store, img, _header(store, T0 * 1_000_000_000 + k * 100_000_000, True, "c"), "mono8")
            if k == 1:
                msg = type(msg)(header=msg.header, height=msg.height, width=msg.width, encoding="yuv422",
                                is_bigendian=0, step=msg.step, data=msg.data)
            w.write(cam, T0 * 1_000_000_000 + round(k / FPS * 1e9), store.serialize_ros1(msg, "sensor_msgs/msg/Image"))
    out = tmp_path / "d.jsonl"
    assert main(["detect", str(path), "--dict", "DICT_4X4_100", "--out", str(out), "--quiet"]) == 1
    lines = out.read_text().splitlines()
    assert len(lines) == 3 and "yuv422" in lines[1] and '"markers"' in lines[0] and '"markers"' in lines[2]


@pytest.mark.parametrize("ros2", [False, True])
def test_compressed_images_are_read_in_place_as_rosbags_reads_them(flight, ros2):
    # the header stamp and the image bytes straight from the serialised message, for frame
    # ids and formats of every length modulo 4 (CDR aligns the fields after each string)
    store = get_typestore(Stores.ROS2_HUMBLE if ros2 else Stores.ROS1_NOETIC)
    ok, png = cv2.imencode(".png", flight[2][0])
    assert ok
    typ = "sensor_msgs/msg/CompressedImage"
    for frame_id in ("", "c", "cam", "camera", "camera_1"):
        for fmt, data in (("png", png.ravel()), ("jpeg", png.ravel()[:101]), ("mono8; png compressed ", png.ravel())):
            header = _header(store, T0 * 1_000_000_000 + 123_456_789, not ros2, frame_id)
            msg = store.types[typ](header=header, format=fmt, data=data)
            raw = bytes(store.serialize_cdr(msg, typ) if ros2 else store.serialize_ros1(msg, typ))
            stamp, got = _compressed_payload(raw, ros2)
            assert stamp == T0 * 1_000_000_000 + 123_456_789
            assert bytes(got) == data.tobytes()
            assert _compressed_payload(raw[:-1], ros2) is None  # cut short: left to rosbags
            assert _compressed_payload(raw + b"\0", ros2) is None
            if ros2:  # big-endian CDR: left to rosbags too
                assert _compressed_payload(bytes(store.serialize_cdr(msg, typ, little_endian=False)), ros2) is None


def test_a_frame_stamped_before_the_last_is_recorded_and_the_run_goes_on(flight, tmp_path):
    _, src, frames, _ = flight
    store = get_typestore(Stores.ROS1_NOETIC)
    stamps = [k / FPS for k in range(len(frames))]
    stamps[3] = stamps[1]  # the camera's clock jumped back on frame 3; the recorder's log time did not
    bag = tmp_path / "back.bag"
    with Ros1Writer(bag) as w:
        conn = w.add_connection("/camera/image", "sensor_msgs/msg/Image", typestore=store)
        for k, (img, t) in enumerate(zip(frames, stamps, strict=True)):
            msg = _image_message(store, img, _header(store, T0 * 10**9 + round(t * 1e9), True, "camera"), "mono8")
            w.write(conn, T0 * 10**9 + round(k / FPS * 1e9), store.serialize_ros1(msg, "sensor_msgs/msg/Image"))
    cam = ["--camera", str(src / "camera.yml"), "--quiet"]
    assert main(["localize", str(bag), "--map", str(src / "map.yml"), "--out", str(tmp_path / "l.csv"), *cam]) == 1
    rows = list(csv.DictReader((tmp_path / "l.csv").open()))
    assert len(rows) == len(frames) and rows[3]["fix"] == "time went back"
    assert rows[2]["fix"] == rows[4]["fix"] == "used"  # the frames around it localised as usual
    assert main(["flow", str(bag), "--height", "1.0", "--out", str(tmp_path / "f.csv"), *cam]) == 1
    rows = list(csv.DictReader((tmp_path / "f.csv").open()))
    assert len(rows) == len(frames) and "not after the previous frame's" in rows[3]["reason"]
    assert float(rows[4]["quality"]) > 0  # the next pair spans frames 2 and 4


def test_strided_frames_are_written_whole_and_a_bad_frame_starts_no_file(tmp_path):
    # the message's step came from a slice's own strides (its data from the contiguous copy):
    # the bag could not be read back; a bad later frame left a half-written, unindexed bag
    img = (np.arange(240 * 320) % 251).astype(np.uint8).reshape(240, 320)
    for name, frame in (("strided", img[::2, ::2]), ("fortran", np.asfortranarray(img)), ("flipped", img[::-1]),
                        ("bgr", np.dstack([img, img, img])[:, ::2])):
        for fmt in ("ros1", "ros2"):
            path = write_bag(tmp_path / f"{name}_{fmt}{'.bag' if fmt == 'ros1' else ''}", [frame], [0.0], fmt=fmt,
                             encoding="bgr8" if frame.ndim == 3 else "mono8")
            (got,) = list(open_source(path))
            assert got.error is None and np.array_equal(got.image, frame)
    with pytest.raises(ValueError, match=r"frames\[1\]"):
        write_bag(tmp_path / "bad.bag", [img, np.zeros((4, 4, 5), np.uint8)], [0.0, 0.1])
    assert not (tmp_path / "bad.bag").exists()
    with pytest.raises(SourceError, match="no such file"):
        BagSource(tmp_path / "missing.bag")  # FileNotFoundError before
