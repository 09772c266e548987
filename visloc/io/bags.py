"""Recorded flights in: ROS 1 bags (``.bag``), ROS 2 bags (a folder with ``metadata.yaml``,
SQLite or MCAP storage) and lone ``.mcap`` files, read with ``rosbags`` (the optional extra
``visloc[ros]``; no ROS installation needed).

Images
    ``sensor_msgs/Image`` in ``mono8``, ``bgr8``, ``rgb8``, ``bgra8``, ``rgba8`` or ``mono16``
    (scaled to 8 bits by its actual range, :func:`visloc.images.to_uint8`) and
    ``sensor_msgs/CompressedImage`` (JPEG, PNG: ``cv2.imdecode``). A message that cannot be
    turned into an image (unknown encoding, a wrong size) becomes a frame without an image
    and an ``error``; reading goes on.
Times
    Frame and IMU times are their messages' header stamps (the bag's log time where a stamp
    is zero), in seconds from the first image's stamp: images and IMU share that origin.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc.errors import UsageError
from visloc.images import to_uint8
from visloc.io.sources import FrameSource, SourceError
from visloc.types import Frame

__all__ = ["IMAGE_TYPES", "IMU_TYPE", "BagSource", "is_recording", "read_bag_imu", "recording_topics"]

#: Message types read as images.
IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
#: Message type read as IMU samples.
IMU_TYPE = "sensor_msgs/msg/Imu"

_CHANNELS = {"mono8": (1, None), "8UC1": (1, None), "mono16": (1, None), "16UC1": (1, None),
             "bgr8": (3, None), "rgb8": (3, cv2.COLOR_RGB2BGR), "bgra8": (4, cv2.COLOR_BGRA2BGR),
             "rgba8": (4, cv2.COLOR_RGBA2BGR), "8UC3": (3, None)}


def is_recording(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a ROS 1 bag, a lone MCAP file or a ROS 2 bag folder."""
    p = Path(path)
    if p.is_file():
        return p.suffix.lower() in (".bag", ".mcap")
    return p.is_dir() and (p / "metadata.yaml").is_file()


def _rosbags():
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise UsageError("ROS bags and MCAP need rosbags: pip install 'visloc[ros]'") from None
    return AnyReader, get_typestore(Stores.ROS2_HUMBLE)


def _open(path: str | os.PathLike[str]):
    """An open ``rosbags`` reader (a ``SourceError`` naming the file when it cannot be read)."""
    AnyReader, store = _rosbags()
    reader = AnyReader([Path(path)], default_typestore=store)
    try:
        reader.open()
    except Exception as exc:  # noqa: BLE001 - rosbags raises its own per-format errors
        raise SourceError(f"cannot read the recording {os.fspath(path)}: {exc}") from None
    return reader


def recording_topics(path: str | os.PathLike[str]) -> list[dict]:
    """The topics of a recording: ``topic``, ``type`` (ROS 2 style name), ``count`` and
    ``rate_hz`` (messages per second between the topic's first and last log times, ``None``
    for fewer than two; the whole recording is read once for them).

    Raises
    ------
    SourceError
        If the recording cannot be read.
    visloc.errors.UsageError
        If rosbags is not installed.
    """
    reader = _open(path)
    try:
        rows, span = {}, {}
        for c in reader.connections:
            row = rows.setdefault(c.topic, {"topic": c.topic, "type": c.msgtype, "count": 0})
            row["count"] += c.msgcount
        for conn, log_ns, _ in reader.messages():  # each topic's first and last log time
            first, _last = span.get(conn.topic, (log_ns, log_ns))
            span[conn.topic] = (min(first, log_ns), log_ns)
        for topic, row in rows.items():
            first, last = span.get(topic, (0, 0))
            row["rate_hz"] = (row["count"] - 1) / ((last - first) * 1e-9) if row["count"] > 1 and last > first else None
        return sorted(rows.values(), key=lambda r: r["topic"])
    finally:
        reader.close()


def _pick(reader, path, topic: str | None, types: tuple[str, ...], what: str, option: str):
    """The connections of ``topic`` (or of the only topic of ``types``)."""
    candidates = sorted({c.topic for c in reader.connections if c.msgtype in types})
    if topic is None:
        if len(candidates) != 1:
            listed = ", ".join(candidates) or "none"
            raise SourceError(f"{os.fspath(path)}: {len(candidates)} {what} topics ({listed}): choose one with {option}")
        topic = candidates[0]
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:
        raise SourceError(f"{os.fspath(path)} has no topic {topic!r} (its {what} topics: {', '.join(candidates) or 'none'})")
    if conns[0].msgtype not in types:
        raise SourceError(f"{os.fspath(path)}: topic {topic!r} holds {conns[0].msgtype}, not {' or '.join(types)}")
    return topic, conns


def _stamp(msg, log_ns: int) -> int:
    """The header stamp in ns, or the log time where the stamp is zero."""
    st = msg.header.stamp
    ns = int(st.sec) * 1_000_000_000 + int(st.nanosec)
    return ns if ns > 0 else int(log_ns)


def _image(msg, msgtype: str) -> NDArray[np.uint8]:
    """The pixels of an image message (grey or BGR, uint8); ``ValueError`` when they cannot be."""
    if msgtype.endswith("CompressedImage"):
        img = cv2.imdecode(np.frombuffer(msg.data, np.uint8), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise ValueError(f"compressed image ({msg.format}) could not be decoded")
        return to_uint8(img) if img.dtype != np.uint8 else img
    enc = msg.encoding
    if enc not in _CHANNELS:
        raise ValueError(f"unknown image encoding {enc!r} (read: {', '.join(_CHANNELS)})")
    channels, convert = _CHANNELS[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    wide = enc in ("mono16", "16UC1")
    dtype = np.dtype(">u2" if msg.is_bigendian else "<u2") if wide else np.dtype(np.uint8)
    row = w * channels * dtype.itemsize
    data = np.asarray(msg.data, np.uint8)
    if h < 1 or w < 1 or step < row or data.size < step * h:
        raise ValueError(f"{enc} image of {w} x {h} px with step {step} holds {data.size} bytes")
    rows = data[: step * h].reshape(h, step)[:, :row]
    img = np.ascontiguousarray(rows).view(dtype).reshape(h, w, channels) if channels > 1 or wide else rows
    if wide:
        return to_uint8(img.reshape(h, w).astype(np.uint16))
    img = img.reshape(h, w) if channels == 1 else img
    return cv2.cvtColor(img, convert) if convert is not None else np.ascontiguousarray(img)


class BagSource(FrameSource):
    """The images of one topic of a recording, in order, as :class:`visloc.types.Frame`.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.bag`` file, a ``.mcap`` file or a ROS 2 bag folder.
    topic : str, optional
        The image topic; needed when the recording has more than one.

    Attributes
    ----------
    topic : str
        The topic read.
    origin_ns : int
        The first image's stamp, ns: ``Frame.time`` counts from it (:func:`read_bag_imu` too).

    Raises
    ------
    SourceError
        If the recording cannot be read, or the topic is missing, ambiguous or not images.
    visloc.errors.UsageError
        If rosbags is not installed.
    """

    def __init__(self, path: str | os.PathLike[str], *, topic: str | None = None) -> None:
        self.path = os.fspath(path)
        self._reader = _open(path)
        try:
            self.topic, self._conns = _pick(self._reader, path, topic, IMAGE_TYPES, "image", "--topic")
            self.origin_ns = first_stamp(self._reader, self._conns)
        except Exception:
            self._reader.close()
            raise
        self._count = sum(c.msgcount for c in self._conns)
        super().__init__(f"{self.path} {self.topic} ({self._count} images)")

    def _length(self) -> int:
        return self._count

    def _frames(self) -> Iterator[Frame]:
        for index, (conn, log_ns, raw) in enumerate(self._reader.messages(connections=self._conns)):
            if self._closed:
                return
            name = f"{self.path}:{self.topic}#{index}"
            try:
                msg = self._reader.deserialize(raw, conn.msgtype)
                t = (_stamp(msg, log_ns) - self.origin_ns) * 1e-9
                yield Frame(index, t, _image(msg, conn.msgtype), name)
            except Exception as exc:  # noqa: BLE001 - one bad message costs its frame only
                yield Frame(index, (int(log_ns) - self.origin_ns) * 1e-9, None, name,
                            f"cannot read image message {name}: {exc}")

    def close(self) -> None:
        """Close the recording."""
        if not self._closed:
            self._reader.close()
        super().close()


def first_stamp(reader, conns) -> int:
    """The stamp (ns) of the first message of ``conns`` (0 when there is none)."""
    for conn, log_ns, raw in reader.messages(connections=conns):
        try:
            return _stamp(reader.deserialize(raw, conn.msgtype), log_ns)
        except Exception:  # noqa: BLE001 - a bad first message: its log time
            return int(log_ns)
    return 0


def read_bag_imu(path: str | os.PathLike[str], *, topic: str | None = None,
                 image_topic: str | None = None) -> NDArray[np.float64]:
    """The IMU samples of a recording: (M, 7) ``t, gx, gy, gz, fx, fy, fz`` (s from the first
    image's stamp, rad/s, m/s^2 specific force), in time order.

    Parameters
    ----------
    path : str or os.PathLike
        The recording.
    topic : str, optional
        The ``sensor_msgs/Imu`` topic (needed when there is more than one).
    image_topic : str, optional
        The image topic whose first stamp is the time origin (as :class:`BagSource`).

    Raises
    ------
    SourceError
        If the recording cannot be read or the topic is missing or ambiguous.
    """
    reader = _open(path)
    try:
        _, img_conns = _pick(reader, path, image_topic, IMAGE_TYPES, "image", "--topic")
        origin = first_stamp(reader, img_conns)
        _, conns = _pick(reader, path, topic, (IMU_TYPE,), "IMU", "--imu-topic")
        rows = []
        for conn, log_ns, raw in reader.messages(connections=conns):
            m = reader.deserialize(raw, conn.msgtype)
            w, a = m.angular_velocity, m.linear_acceleration
            rows.append(((_stamp(m, log_ns) - origin) * 1e-9, w.x, w.y, w.z, a.x, a.y, a.z))
    finally:
        reader.close()
    out = np.array(rows, float).reshape(-1, 7)
    return out[np.argsort(out[:, 0], kind="stable")]
