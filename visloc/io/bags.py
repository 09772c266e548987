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

import functools
import os
import struct
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc.errors import UsageError
from visloc.images import to_uint8
from visloc.io.sources import FrameSource, SourceError
from visloc.types import Frame

__all__ = ["IMAGE_TYPES", "IMU_TYPE", "BagSource", "is_recording", "read_bag_imu", "recording_topics", "write_bag"]

#: Message types read as images.
IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
#: Message type read as IMU samples.
IMU_TYPE = "sensor_msgs/msg/Imu"

_CHANNELS = {"mono8": (1, None), "8UC1": (1, None), "mono16": (1, None), "16UC1": (1, None),
             "bgr8": (3, None), "rgb8": (3, cv2.COLOR_RGB2BGR), "bgra8": (4, cv2.COLOR_BGRA2BGR),
             "rgba8": (4, cv2.COLOR_RGBA2BGR), "8UC3": (3, None)}


def is_recording(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a ROS 1 bag, a lone MCAP file or a ROS 2 bag folder.

    Only the name is looked at, not the contents: a file counts when its suffix is ``.bag``
    or ``.mcap`` (any case), a folder when it holds a ``metadata.yaml`` file.

    Parameters
    ----------
    path : str or os.PathLike
        The file or folder to look at.

    Returns
    -------
    bool
        True for a ``.bag`` or ``.mcap`` file or a folder with ``metadata.yaml``; False
        otherwise, and for a path that does not exist.
    """
    p = Path(path)
    if p.is_file():
        return p.suffix.lower() in (".bag", ".mcap")
    return p.is_dir() and (p / "metadata.yaml").is_file()


@functools.cache
def _rosbags():
    """rosbags' reader class and the default type store (made once: building its ~150 message
    classes costs about 0.1 s)."""
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise UsageError("ROS bags and MCAP need rosbags: pip install 'visloc[ros]'") from None
    return AnyReader, get_typestore(Stores.ROS2_HUMBLE)


def _open(path: str | os.PathLike[str]):
    """An open ``rosbags`` reader (a ``SourceError`` naming the file when it cannot be read)."""
    AnyReader, store = _rosbags()
    if not Path(path).exists():
        raise SourceError(f"cannot read the recording {os.fspath(path)}: no such file or folder")
    try:
        reader = AnyReader([Path(path)], default_typestore=store)
        reader.open()
    except Exception as exc:  # noqa: BLE001 - rosbags raises its own per-format errors
        raise SourceError(f"cannot read the recording {os.fspath(path)}: {exc}") from None
    return reader


def recording_topics(path: str | os.PathLike[str]) -> list[dict]:
    """The topics of a recording, with their message types, counts and rates.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.bag`` file, a ``.mcap`` file or a ROS 2 bag folder.

    Returns
    -------
    list of dict
        One dict per topic, sorted by topic name: ``topic`` (str), ``type`` (str, ROS 2
        style name such as ``"sensor_msgs/msg/Image"``), ``count`` (int, messages over all
        the topic's connections) and ``rate_hz`` (float, messages per second between the
        topic's first and last log times, ``(count - 1) / span``; ``None`` for fewer than two
        messages or no time between them). The whole recording is read once for the rates.

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


def _decoded(data, fmt: str = "") -> NDArray[np.uint8]:
    """A compressed image's pixels (grey or BGR, uint8); ``ValueError`` when they cannot be."""
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"compressed image{f' ({fmt})' if fmt else ''} could not be decoded")
    return to_uint8(img) if img.dtype != np.uint8 else img


def _image(msg, msgtype: str) -> NDArray[np.uint8]:
    """The pixels of an image message (grey or BGR, uint8); ``ValueError`` when they cannot be."""
    if msgtype.endswith("CompressedImage"):
        return _decoded(msg.data, msg.format)
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


def _compressed_payload(raw: bytes, ros2: bool) -> tuple[int, memoryview] | None:
    """A ``sensor_msgs/CompressedImage`` message's header stamp (ns) and its ``data`` bytes,
    read in place from the serialised message (ROS 1, or little-endian CDR for ROS 2) without
    building the message object; None when the bytes are not laid out as expected (then the
    caller deserialises them with rosbags)."""
    view = memoryview(raw)
    n = len(view)
    stamp = _raw_stamp(view, ros2)
    if stamp is None or n < 20:
        return None
    pos = 12
    for _ in range(2):  # the strings frame_id and format: a length, the bytes (CDR: a NUL, then aligned to 4)
        if pos + 4 > n:
            return None
        pos += 4 + struct.unpack_from("<I", view, pos)[0]
        if ros2:
            pos = 4 + -(-(pos - 4) // 4) * 4  # aligned from the end of the encapsulation header
    if pos + 4 > n:
        return None
    size = struct.unpack_from("<I", view, pos)[0]
    if pos + 4 + size != n:
        return None
    return stamp, view[pos + 4 :]


def _raw_stamp(view: memoryview, ros2: bool) -> int | None:
    """The header stamp (ns) of a serialised image message, read in place: ``(sec, nanosec)``
    follows ROS 1's ``seq`` or CDR's encapsulation header alike; None when the bytes are too
    short or not little-endian CDR."""
    if len(view) < 12 or (ros2 and (view[0] != 0 or view[1] != 1)):
        return None
    sec, nsec = struct.unpack_from("<II", view, 4)
    return sec * 1_000_000_000 + nsec


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
            self.origin_ns = _first_stamp(self._reader, self._conns)
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
                fast = _compressed_payload(raw, self._reader.is2) if conn.msgtype.endswith("CompressedImage") else None
                if fast is not None:  # the pixels straight from the message's bytes
                    t = ((fast[0] or int(log_ns)) - self.origin_ns) * 1e-9
                    yield Frame(index, t, _decoded(fast[1]), name)
                    continue
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


def _first_stamp(reader, conns) -> int:
    """The stamp (ns) of the first message of ``conns`` (0 when there is none), its log time
    where the stamp is zero. Read in place from the message's bytes (the image messages begin
    with their header): building a message object first costs the reader its (de)serialisers'
    code generation, about 10 ms."""
    for conn, log_ns, raw in reader.messages(connections=conns):
        ns = _raw_stamp(memoryview(raw), reader.is2)
        if ns is not None:
            return ns if ns > 0 else int(log_ns)
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
        origin = _first_stamp(reader, img_conns)
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


def _header(store, ns: int, ros1: bool, frame_id: str):
    Time, Header = store.types["builtin_interfaces/msg/Time"], store.types["std_msgs/msg/Header"]
    stamp = Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
    return Header(seq=0, stamp=stamp, frame_id=frame_id) if ros1 else Header(stamp=stamp, frame_id=frame_id)


def _image_message(store, img: NDArray[np.uint8], header, encoding: str):
    if encoding in ("png", "jpeg"):
        ok, buf = cv2.imencode(".png" if encoding == "png" else ".jpg", img)
        if not ok:
            raise ValueError(f"cannot encode a {img.shape} image as {encoding}")
        return store.types["sensor_msgs/msg/CompressedImage"](header=header, format=encoding,
                                                               data=np.frombuffer(buf.tobytes(), np.uint8))
    if encoding == "rgb8":
        img = cv2.cvtColor(img if img.ndim == 3 else cv2.cvtColor(img, cv2.COLOR_GRAY2BGR), cv2.COLOR_BGR2RGB)
    elif encoding == "bgr8":
        img = img if img.ndim == 3 else cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    elif encoding == "mono8":
        img = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    else:
        raise ValueError(f"encoding must be mono8, bgr8, rgb8, png or jpeg, got {encoding!r}")
    img = np.ascontiguousarray(img)  # the step below is the written rows' (a slice's own strides are not)
    h, w = img.shape[:2]
    return store.types["sensor_msgs/msg/Image"](header=header, height=h, width=w, encoding=encoding, is_bigendian=0,
                                                 step=img.strides[0], data=img.reshape(-1))


def _imu_message(store, row: NDArray, header):
    Vec, Quat = store.types["geometry_msgs/msg/Vector3"], store.types["geometry_msgs/msg/Quaternion"]
    return store.types["sensor_msgs/msg/Imu"](
        header=header, orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=np.zeros(9),
        angular_velocity=Vec(x=float(row[1]), y=float(row[2]), z=float(row[3])),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=Vec(x=float(row[4]), y=float(row[5]), z=float(row[6])),
        linear_acceleration_covariance=np.zeros(9))


def write_bag(path: str | os.PathLike[str], frames: list[NDArray[np.uint8]], times: list[float], *,
              imu: NDArray | None = None, fmt: str = "ros1", encoding: str = "mono8",
              topic: str = "/camera/image", imu_topic: str = "/imu", t0_ns: int = 1_700_000_000 * 10**9,
              log_delay: float = 0.003) -> Path:
    """Write frames (and IMU samples) as a recording, with rosbags' writers.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.bag`` file (``fmt="ros1"``) or a new ROS 2 bag folder (``"ros2"``: SQLite,
        ``"mcap"``: MCAP storage).
    frames : list of ndarray (H, W) or (H, W, 3) uint8
        Grey or BGR images.
    times : list of float
        Each frame's time, s (its header stamp is ``t0_ns`` plus it).
    imu : ndarray (M, 7), optional
        ``t, gx, gy, gz, fx, fy, fz`` rows (as ``visloc render localize``'s ``imu.csv``).
    fmt : str
        ``"ros1"``, ``"ros2"`` or ``"mcap"``.
    encoding : str
        ``"mono8"``, ``"bgr8"``, ``"rgb8"`` (``sensor_msgs/Image``) or ``"png"``, ``"jpeg"``
        (``sensor_msgs/CompressedImage``).
    topic, imu_topic : str
        The topics.
    t0_ns : int
        The stamp of time 0, ns since the epoch.
    log_delay : float
        Seconds between a message's stamp and its log time (a recorder's delay).

    Returns
    -------
    Path
        ``path``, the recording written.

    Raises
    ------
    ValueError
        ``fmt`` or ``encoding`` unknown, as many times as frames not given, or a frame that is
        not a uint8 grey or BGR image (checked before the file is begun).
    """
    from rosbags.rosbag1 import Writer as Ros1Writer
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Ros2Writer
    from rosbags.typesys import Stores, get_typestore

    if fmt not in ("ros1", "ros2", "mcap"):
        raise ValueError(f"fmt must be ros1, ros2 or mcap, got {fmt!r}")
    if len(frames) != len(times):
        raise ValueError(f"{len(frames)} frames but {len(times)} times")
    for k, f in enumerate(frames):  # all checked before the file is begun: no half-written bag
        if not (isinstance(f, np.ndarray) and f.dtype == np.uint8 and f.size
                and (f.ndim == 2 or f.ndim == 3 and f.shape[2] == 3)):
            raise ValueError(f"frames[{k}]: expected a uint8 (H, W) or (H, W, 3) image, got "
                             f"{getattr(f, 'dtype', type(f).__name__)} {getattr(f, 'shape', '')}")
    ros1 = fmt == "ros1"
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    img_type = "sensor_msgs/msg/CompressedImage" if encoding in ("png", "jpeg") else "sensor_msgs/msg/Image"
    serialize = store.serialize_ros1 if ros1 else store.serialize_cdr
    plugin = StoragePlugin.MCAP if fmt == "mcap" else StoragePlugin.SQLITE3
    writer = Ros1Writer(Path(path)) if ros1 else Ros2Writer(Path(path), version=9, storage_plugin=plugin)
    rows = np.zeros((0, 7)) if imu is None else np.asarray(imu, float).reshape(-1, 7)
    events = sorted([(float(t), 0, k) for k, t in enumerate(times)] + [(float(r[0]), 1, i) for i, r in enumerate(rows)])
    with writer as w:
        cam = w.add_connection(topic, img_type, typestore=store)
        imu_conn = w.add_connection(imu_topic, IMU_TYPE, typestore=store) if len(rows) else None
        for t, what, i in events:
            ns = t0_ns + round(t * 1e9)  # integer ns: t0 + t in floats would lose 0.2 us
            log = ns + round(log_delay * 1e9)
            if what == 0:
                msg = _image_message(store, frames[i], _header(store, ns, ros1, "camera"), encoding)
                w.write(cam, log, serialize(msg, img_type))
            else:
                w.write(imu_conn, log, serialize(_imu_message(store, rows[i], _header(store, ns, ros1, "imu")), IMU_TYPE))
    return Path(path)
