"""Frame sources: folders, globs, single images, videos, bad input."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from visloc.io import FrameSource, SourceError, open_source, read_image
from visloc.io.sources import ImageListSource
from visloc.types import Frame


def _grey(value: int, shape: tuple[int, int] = (24, 32)) -> np.ndarray:
    return np.full(shape, value, np.uint8)


def _write(path: Path, image: np.ndarray) -> Path:
    assert cv2.imwrite(str(path), image), path
    return path


def _write_video(path: Path, fourcc: str, n: int = 5, fps: float = 10.0) -> list[int]:
    """Write n frames of 64x48 with distinct uniform grey levels; return the levels."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, (64, 48))
    assert writer.isOpened(), f"codec {fourcc} cannot write {path.suffix} here"
    levels = [20 + 50 * i for i in range(n)]
    for v in levels:
        writer.write(np.full((48, 64, 3), v, np.uint8))
    writer.release()
    return levels


def test_folder_yields_images_in_sorted_order(tmp_path: Path) -> None:
    for name, value in [("b.png", 2), ("a.png", 1), ("c.jpg", 3), ("D.PNG", 4)]:
        _write(tmp_path / name, _grey(value * 40))
    (tmp_path / "notes.txt").write_text("not an image")
    (tmp_path / "sub").mkdir()
    _write(tmp_path / "sub" / "e.png", _grey(200))

    source = open_source(str(tmp_path))
    frames = list(source)

    names = [Path(f.name).name for f in frames]
    assert names == sorted(["a.png", "b.png", "c.jpg", "D.PNG"])
    assert len(source) == 4
    assert source.description == f"folder {tmp_path} (4 images)"
    assert [f.index for f in frames] == [0, 1, 2, 3]
    assert [f.time for f in frames] == [0.0, 1.0, 2.0, 3.0]  # no fps: one second per frame
    for f in frames:
        assert isinstance(f, Frame) and f.error is None
        assert f.image is not None and f.image.dtype == np.uint8 and f.image.shape == (24, 32)
    assert frames[1].image[0, 0] == 40  # a.png, lossless
    assert frames[0].image[0, 0] == 160  # D.PNG


def test_folder_times_use_fps_and_source_iterates_twice(tmp_path: Path) -> None:
    for i in range(3):
        _write(tmp_path / f"f{i}.png", _grey(i))
    source = open_source(tmp_path, fps=4.0)
    assert [f.time for f in source] == [0.0, 0.25, 0.5]
    assert [f.index for f in source] == [0, 1, 2]


def test_glob_keeps_matching_images_only(tmp_path: Path) -> None:
    _write(tmp_path / "x1.png", _grey(1))
    _write(tmp_path / "x2.png", _grey(2))
    _write(tmp_path / "y1.png", _grey(3))
    _write(tmp_path / "x3.jpg", _grey(4))
    pattern = str(tmp_path / "x?.png")
    source = open_source(pattern)
    assert [Path(f.name).name for f in source] == ["x1.png", "x2.png"]
    assert source.description == f"glob {pattern} (2 images)"
    with pytest.raises(SourceError, match="matches no image file"):
        open_source(str(tmp_path / "z*.png"))


def test_single_image(tmp_path: Path) -> None:
    path = _write(tmp_path / "one.jpg", np.zeros((10, 12, 3), np.uint8))
    source = open_source(str(path), fps=25)
    (frame,) = list(source)
    assert len(source) == 1
    assert frame.name == str(path) and frame.index == 0 and frame.time == 0.0
    assert frame.image.shape == (10, 12, 3) and frame.image.dtype == np.uint8


@pytest.mark.parametrize(("suffix", "fourcc"), [(".mp4", "mp4v"), (".avi", "MJPG")])
def test_video_frames_count_and_timestamps(tmp_path: Path, suffix: str, fourcc: str) -> None:
    path = tmp_path / f"clip{suffix}"
    levels = _write_video(path, fourcc, n=5, fps=10.0)

    with open_source(str(path)) as source:
        assert len(source) == 5
        assert source.description == f"video {path} (5 frames, 10 fps)"
        frames = list(source)
        again = list(source)  # a new iteration starts from the first frame
    assert source.closed

    assert [f.index for f in frames] == [0, 1, 2, 3, 4]
    assert [f.name for f in frames] == [f"{path}#{i}" for i in range(5)]
    np.testing.assert_allclose([f.time for f in frames], [0.0, 0.1, 0.2, 0.3, 0.4], atol=1e-6)
    for f, level in zip(frames, levels, strict=True):
        assert f.image.shape == (48, 64, 3) and f.image.dtype == np.uint8
        assert abs(float(f.image.mean()) - level) < 6  # lossy codec
    assert len(again) == 5 and np.array_equal(again[0].image, frames[0].image)
    with pytest.raises(ValueError, match="closed"):
        iter(source)


def test_video_fps_overrides_container_times(tmp_path: Path) -> None:
    path = tmp_path / "clip.mp4"
    _write_video(path, "mp4v", n=3, fps=10.0)
    with open_source(path, fps=2.0) as source:
        assert [f.time for f in source] == [0.0, 0.5, 1.0]


def test_corrupt_image_yields_error_frame_and_iteration_goes_on(tmp_path: Path) -> None:
    _write(tmp_path / "a.png", _grey(10))
    (tmp_path / "b.png").write_bytes(b"\x89PNG garbage, not an image" * 10)
    (tmp_path / "c.png").write_bytes(b"")
    _write(tmp_path / "d.png", _grey(30))

    frames = list(open_source(tmp_path))

    assert [f.index for f in frames] == [0, 1, 2, 3]
    assert frames[0].error is None and frames[3].error is None
    assert frames[3].image[0, 0] == 30
    for f in frames[1:3]:
        assert f.image is None
        assert f.error == f"cannot read image {f.name}"


def test_nonexistent_path_raises_source_error(tmp_path: Path) -> None:
    missing = tmp_path / "nowhere" / "x.png"
    with pytest.raises(SourceError, match="path does not exist") as info:
        open_source(str(missing))
    assert str(missing) in str(info.value)
    assert isinstance(info.value, ValueError)
    assert "\n" not in str(info.value)


def test_empty_folder_raises_source_error(tmp_path: Path) -> None:
    with pytest.raises(SourceError, match=r"folder .* contains no image file"):
        open_source(tmp_path)
    (tmp_path / "readme.txt").write_text("x")
    with pytest.raises(SourceError, match="contains no image file"):
        open_source(tmp_path)


def test_unreadable_video_and_camera_raise_source_error(tmp_path: Path) -> None:
    bad = tmp_path / "broken.mp4"
    bad.write_bytes(b"garbage" * 100)
    with pytest.raises(SourceError, match="cannot open video"):
        open_source(bad)
    other = tmp_path / "data.xyz"
    other.write_bytes(b"garbage")
    with pytest.raises(SourceError, match="not an image or a readable video"):
        open_source(other)
    with pytest.raises(SourceError, match="cannot open camera 97"):
        open_source(97)
    with pytest.raises(SourceError, match="cannot open camera 98"):
        open_source("98")
    with pytest.raises(SourceError, match="camera index"):
        open_source(-1)


def test_bad_arguments() -> None:
    with pytest.raises(TypeError, match="spec"):
        open_source(True)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="spec"):
        open_source(1.5)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="fps"):
        open_source(".", fps=0)
    with pytest.raises(ValueError, match="fps"):
        open_source(".", fps=float("nan"))


def test_16bit_png_is_scaled_to_uint8(tmp_path: Path) -> None:
    img16 = np.array([[0, 256 * 100, 65535], [1000, 40000, 255]], np.uint16)
    path = _write(tmp_path / "deep.png", img16)
    image, error = read_image(path)
    assert error is None
    assert image.dtype == np.uint8 and image.shape == (2, 3)
    np.testing.assert_array_equal(image, img16 >> 8)

    colour16 = np.zeros((4, 5, 3), np.uint16)
    colour16[..., 2] = 65535
    (frame,) = open_source(_write(tmp_path / "deep_bgr.png", colour16))
    assert frame.image.dtype == np.uint8 and frame.image.shape == (4, 5, 3)
    assert frame.image[0, 0].tolist() == [0, 0, 255]


def test_rgba_png_drops_alpha(tmp_path: Path) -> None:
    bgra = np.zeros((6, 7, 4), np.uint8)
    bgra[..., 0], bgra[..., 1], bgra[..., 2], bgra[..., 3] = 10, 20, 30, 0
    (frame,) = open_source(_write(tmp_path / "rgba.png", bgra))
    assert frame.image.shape == (6, 7, 3) and frame.image.dtype == np.uint8
    np.testing.assert_array_equal(frame.image, bgra[..., :3])


def test_len_of_unknown_length_source_raises_type_error() -> None:
    class Endless(FrameSource):
        def _frames(self):  # type: ignore[no-untyped-def]
            yield Frame(0, 0.0, None, "x", "none")

    source = Endless("endless")
    with pytest.raises(TypeError, match="has no len"):
        len(source)
    assert len(list(source)) == 1  # list() copes, as with a generator


def test_image_list_source_directly(tmp_path: Path) -> None:
    paths = [_write(tmp_path / f"{i}.png", _grey(i)) for i in range(2)]
    with ImageListSource([str(p) for p in paths], fps=10) as source:
        assert repr(source) == "<ImageListSource: 2 images>"
        assert [f.time for f in source] == [0.0, 0.1]


def test_12bit_data_in_a_16bit_png_is_read_by_its_depth_not_as_nearly_black(tmp_path: Path) -> None:
    img12 = np.array([[0, 4095, 2048], [16, 1000, 3000]], np.uint16)  # a 12-bit sensor's values
    image, error = read_image(_write(tmp_path / "d12.png", img12))
    assert error is None
    np.testing.assert_array_equal(image, img12 >> 4)  # its top 8 bits: 4095 -> 255
    img8 = np.array([[0, 200], [17, 255]], np.uint16)  # 8-bit values in a 16-bit file stay as they are
    np.testing.assert_array_equal(read_image(_write(tmp_path / "d8.png", img8))[0], img8)


def test_float_images_are_read_by_their_range(tmp_path: Path) -> None:
    from visloc.images import to_uint8

    np.testing.assert_array_equal(to_uint8(np.array([[0.0, 0.5, 1.0]], np.float32)), [[0, 128, 255]])
    np.testing.assert_array_equal(to_uint8(np.array([[0.0, 100.4, 255.0]], np.float32)), [[0, 100, 255]])
    np.testing.assert_array_equal(to_uint8(np.array([[np.nan, 2.0, 4095.0]])), [[0, 0, 255]])
    grey = np.arange(0, 250, 10, dtype=np.float32).reshape(5, 5)  # a float TIFF holding 0..255
    image, error = read_image(_write(tmp_path / "f.tiff", grey))
    assert error is None and np.array_equal(image, grey.astype(np.uint8))
    with pytest.raises(TypeError, match="unsupported pixel type"):
        to_uint8(np.zeros((2, 2), np.int32))


def test_an_image_too_small_to_use_is_an_unreadable_frame_and_the_folder_goes_on(tmp_path: Path) -> None:
    _write(tmp_path / "a.png", np.full((1, 1), 255, np.uint8))
    _write(tmp_path / "b.png", _grey(3))
    frames = list(open_source(str(tmp_path)))
    assert frames[0].image is None and "at least 2 x 2" in frames[0].error
    assert frames[1].image is not None


def _numbered_video(path: Path, fourcc: str) -> Path:
    """100 frames of 160 x 120 at 30 fps, each its number on its own grey; ``bad<ext>`` beside it
    with 3000 zero bytes in the middle of the file. Returns the bad file."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), 30, (160, 120))
    for i in range(100):
        img = np.full((120, 160, 3), (2 * i) % 255, np.uint8)
        cv2.putText(img, str(i), (20, 60), 0, 1, (255, 255, 255), 2)
        writer.write(img)
    writer.release()
    data = bytearray(path.read_bytes())
    data[len(data) // 2 : len(data) // 2 + 3000] = bytes(3000)  # zeros in the middle of the stream
    bad = path.with_name(f"bad{path.suffix}")
    bad.write_bytes(bytes(data))
    return bad


@pytest.mark.parametrize("ext, fourcc", [(".avi", "MJPG"), (".mp4", "mp4v")])
def test_a_video_with_corrupt_bytes_is_read_past_them_and_says_so(tmp_path: Path, ext: str, fourcc: str) -> None:
    path = tmp_path / f"v{ext}"
    bad = _numbered_video(path, fourcc)
    clean = list(open_source(path))
    assert len(clean) == 100 and all(f.error is None for f in clean)
    frames = list(open_source(bad))
    good = [f for f in frames if f.image is not None]
    assert len(good) > 60  # frames after the damage are read too (it used to stop there)
    lost = [f for f in frames if f.image is None and "could not be decoded" in f.error]
    assert lost  # each at its own place: the frames after keep their indices and times
    assert [f.index for f in frames] == list(range(len(frames)))
    assert [f.time for f in frames[:97]] == pytest.approx([k / 30 for k in range(97)], abs=1e-3)
    assert all(f.name.endswith(f"#{f.index}") for f in lost)
    after = [f for f in good if f.index > max(f.index for f in lost) + 12]  # past mp4v's next key frame

    def off(f, k):
        return float(np.abs(f.image.astype(int) - clean[k].image).mean())
    assert len(after) > 25 and all(off(f, f.index) < 1 < min(off(f, f.index - 1), off(f, f.index + 1))
                                   for f in after[:-1])  # each in its place
    end = [f for f in frames if f.name.endswith("#end")]
    if len(frames) - len(end) < 100:  # fewer than declared: one last row says so
        assert end == [frames[-1]] and "of 100 the container declares" in end[0].error
    else:
        assert not end
    truncated = tmp_path / f"cut{ext}"
    data = path.read_bytes()
    truncated.write_bytes(data[: len(data) * 2 // 3])
    if ext == ".mp4":  # its index is at the end: a cut file cannot be opened, and says so
        with pytest.raises(SourceError, match="cannot open video"):
            open_source(truncated)
        return
    cut = list(open_source(truncated))
    assert 0 < len(cut) - 1 < 100 and cut[-1].image is None
    assert "of 100 the container declares" in cut[-1].error and "ends early" in cut[-1].error


def test_frame_times_go_on_from_the_last_stamp_when_the_stamps_stop_being_usable() -> None:
    from visloc.io.sources import _FrameClock

    clock = _FrameClock(30.0, stamps=True)  # a stream starting at 10 s whose stamps repeat at frame 2
    times = [clock.time(k, s) for k, s in enumerate([10.0, 10.0 + 1 / 30, 10.0 + 1 / 30, 10.1, 10.0 + 4 / 30])]
    assert times == pytest.approx([10.0, 10.0 + 1 / 30, 10.0 + 2 / 30, 10.1, 10.0 + 4 / 30])
    none = _FrameClock(25.0, stamps=True)  # no usable stamp at all: index / rate from the start
    assert [none.time(k, math.nan) for k in range(3)] == pytest.approx([0.0, 0.04, 0.08])
    given = _FrameClock(10.0, stamps=False)  # --fps given: index / fps whatever the stamps
    assert [given.time(k, 5.0 + k) for k in range(3)] == pytest.approx([0.0, 0.1, 0.2])


def test_one_path_is_not_a_list_of_paths():
    # ImageListSource("a.png") was five one-letter paths
    with pytest.raises(TypeError, match=r"pass \['a.png'\]"):
        ImageListSource("a.png")
    assert len(ImageListSource(["a.png"])) == 1


def _avi(path: Path, n: int = 40) -> bytes:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30, (64, 48))
    for i in range(n):
        writer.write(np.full((48, 64, 3), 5 * i, np.uint8))
    writer.release()
    return path.read_bytes()


def test_the_avi_index_names_the_frames_whose_chunks_are_gone(tmp_path: Path) -> None:
    from visloc.io.avi_index import avi_unreadable_frames

    data = bytearray(_avi(tmp_path / "v.avi"))
    assert avi_unreadable_frames(tmp_path / "v.avi") == frozenset()
    movi = data.find(b"movi") + 4
    heads = [m for m in range(movi, len(data) - 4) if data[m : m + 4] == b"00dc"][:40]
    for k in (0, 7, 39):  # the first, one inside and the last frame's chunk headers zeroed
        data[heads[k] : heads[k] + 8] = bytes(8)
    (tmp_path / "bad.avi").write_bytes(bytes(data))
    assert avi_unreadable_frames(tmp_path / "bad.avi") == {0, 7, 39}
    frames = list(open_source(tmp_path / "bad.avi"))
    assert [f.index for f in frames] == list(range(40))  # no end row: every frame is accounted for
    assert [f.index for f in frames if f.image is None] == [0, 7, 39]
    assert all(f.error is None and abs(float(f.image.mean()) - 5 * f.index) < 2 for f in frames if f.image is not None)
    assert [f.time for f in frames] == pytest.approx([k / 30 for k in range(40)])
    (tmp_path / "cut.avi").write_bytes(bytes(data[: len(data) * 2 // 3]))  # the index is written last
    (tmp_path / "empty.avi").write_bytes(b"")
    for name in ("cut.avi", "empty.avi"):
        assert avi_unreadable_frames(tmp_path / name) is None
    assert avi_unreadable_frames(tmp_path / "missing.avi") is None
    (tmp_path / "riff.avi").write_bytes(b"RIFF\x04\x00\x00\x00AVI ")  # a header and nothing else
    assert avi_unreadable_frames(tmp_path / "riff.avi") is None


def test_frames_a_matroska_demuxer_drops_keep_their_places(tmp_path: Path) -> None:
    path = tmp_path / "v.mkv"
    bad = _numbered_video(path, "MJPG")  # the demuxer skips what it cannot parse
    clean = list(open_source(path))
    assert len(clean) == 100 and all(f.error is None for f in clean)
    frames = list(open_source(bad))
    assert [f.index for f in frames] == list(range(100))  # every slot accounted for, no end row
    lost = [f for f in frames if f.image is None]
    assert lost and all("timestamps skip it" in f.error or "could not be decoded" in f.error for f in lost)
    assert [f.time for f in frames] == pytest.approx([k / 30 for k in range(100)], abs=2e-3)
    after = [f for f in frames if f.image is not None and f.index > lost[-1].index]
    assert len(after) > 30 and all(np.array_equal(f.image, clean[f.index].image) for f in after)


def test_stamp_gaps_count_missing_periods_only_in_a_constant_rate_stream() -> None:
    from visloc.io.sources import _StampGaps

    gaps = _StampGaps(30.0)
    stamps = [0.0, 0.033, 0.067, 0.1, 0.233, 0.267]  # whole milliseconds, as Matroska stamps; 3 frames gone
    assert [gaps.missing(s) for s in stamps] == [0, 0, 0, 0, 3, 0]
    jitter = _StampGaps(30.0)  # a variable-rate stream: after its first uneven step, no gap is told
    assert [jitter.missing(s) for s in (0.0, 0.02, 0.1, 0.2)] == [0, 0, 0, 0]
    assert [_StampGaps(None).missing(s) for s in (0.0, 1.0)] == [0, 0]
    nan = _StampGaps(30.0)
    assert [nan.missing(s) for s in (0.0, math.nan, 0.1)] == [0, 0, 0]
