"""MAVLink out: visloc's estimates as the messages PX4 and ArduPilot take from a companion
computer (``pymavlink``, the optional extra ``visloc[mavlink]``).

Frames
    A marker map has its z axis up (``visloc.pose.maps``). The flight stack's local frame is
    NED (x north, y east, z down). :data:`MAP_FRAMES` names how the map's axes lie::

        "nwu" (default)          "enu"
          x: north (forward)       x: east
          y: west  (left)          y: north
          z: up                    z: up

              x (N)                    y (N)
              ^                        ^
              |                        |
        y <---o z (up, toward you)     o---> x (E)    z up, toward you

    A position ``p_map`` becomes ``p_ned = MAP_FRAMES[name] @ p_map``; a rotation
    ``R_map_x`` becomes ``MAP_FRAMES[name] @ R_map_x``.
Camera mounting
    The body's attitude comes from the camera's with :data:`DOWN_CAMERA` (the camera looks
    down, the top of the image toward the nose: camera x = body right, camera y = body back,
    camera z = body down; the AR.Drone 2.0's bottom camera and visloc's simulator).
Sending
    Messages are packed in the caller's thread and written at once on UDP (a datagram never
    blocks: a flight stack that is not listening costs nothing); on other links (serial, TCP)
    a writer thread sends them from a bounded queue, dropping the oldest when the link cannot
    keep up (``dropped`` counts them). Timestamps are the frames' times in microseconds.
"""

from __future__ import annotations

import math
import queue
import threading
from collections.abc import Sequence
from typing import Self

import numpy as np
from numpy.typing import ArrayLike, NDArray

from visloc.errors import UsageError

__all__ = ["DOWN_CAMERA", "MAP_FRAMES", "MavlinkSink", "body_attitude_ned", "load_pymavlink"]

#: ``R_ned_map`` of each map-frame name (module docstring).
MAP_FRAMES: dict[str, NDArray[np.float64]] = {
    "nwu": np.diag([1.0, -1.0, -1.0]),
    "enu": np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]),
}

#: ``R_body_cam`` of a downward camera with the image's top toward the nose (camera x = body
#: y, camera y = -body x, camera z = body z), as ``visloc.sim.BODY_TO_CAMERA.T``.
DOWN_CAMERA: NDArray[np.float64] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])

_QUEUE = 256  # messages waiting on a slow (non-UDP) link before the oldest are dropped


def load_pymavlink():
    """``(mavutil, common dialect)`` from pymavlink, or a :class:`visloc.errors.UsageError`
    naming the extra to install."""
    try:
        from pymavlink import mavutil
        from pymavlink.dialects.v20 import common
    except ImportError:
        raise UsageError("MAVLink needs pymavlink: pip install 'visloc[mavlink]'") from None
    return mavutil, common


def body_attitude_ned(R_map_cam: ArrayLike, *, map_frame: str = "nwu",
                      R_body_cam: ArrayLike = DOWN_CAMERA) -> NDArray[np.float64]:
    """The body's attitude in NED from the camera's in the map.

    Parameters
    ----------
    R_map_cam : array_like (3, 3)
        Camera axes to map axes (``MapPose.R_map_cam``).
    map_frame : str
        A key of :data:`MAP_FRAMES`.
    R_body_cam : array_like (3, 3)
        Camera axes to body axes (default :data:`DOWN_CAMERA`).

    Returns
    -------
    ndarray (3, 3)
        ``R_ned_body`` (body FRD axes to NED).
    """
    return _map_frame(map_frame) @ np.asarray(R_map_cam, float) @ np.asarray(R_body_cam, float).T


def _map_frame(name: str) -> NDArray[np.float64]:
    if name not in MAP_FRAMES:
        raise ValueError(f"map_frame must be one of {', '.join(MAP_FRAMES)}, got {name!r}")
    return MAP_FRAMES[name]


def _quaternion(R: NDArray) -> list[float]:
    """``[w, x, y, z]`` of a rotation matrix (MAVLink's order; Shepperd's method, the largest
    of the four squares first for accuracy)."""
    m = np.asarray(R, float).tolist()
    tr = m[0][0] + m[1][1] + m[2][2]
    if tr > max(m[0][0], m[1][1], m[2][2]):
        s = 2.0 * math.sqrt(1.0 + tr)
        q = [0.25 * s, (m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s]
    elif m[0][0] >= m[1][1] and m[0][0] >= m[2][2]:
        s = 2.0 * math.sqrt(1.0 + m[0][0] - m[1][1] - m[2][2])
        q = [(m[2][1] - m[1][2]) / s, 0.25 * s, (m[0][1] + m[1][0]) / s, (m[0][2] + m[2][0]) / s]
    elif m[1][1] >= m[2][2]:
        s = 2.0 * math.sqrt(1.0 + m[1][1] - m[0][0] - m[2][2])
        q = [(m[0][2] - m[2][0]) / s, (m[0][1] + m[1][0]) / s, 0.25 * s, (m[1][2] + m[2][1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m[2][2] - m[0][0] - m[1][1])
        q = [(m[1][0] - m[0][1]) / s, (m[0][2] + m[2][0]) / s, (m[1][2] + m[2][1]) / s, 0.25 * s]
    return q if q[0] >= 0 else [-v for v in q]


_TRIU6 = np.ravel_multi_index(np.triu_indices(6), (6, 6))  # flat: one gather, half the time of two index arrays


def _upper_triangle(cov: ArrayLike | None) -> list[float]:
    """MAVLink's row-major upper triangle (21 values) of a 6 x 6 covariance (NaN first: unknown)."""
    if cov is None:
        return [math.nan] * 21
    c = np.asarray(cov, float)
    if c.shape != (6, 6):
        raise ValueError(f"covariance must be (6, 6), got shape {c.shape}")
    return c.ravel()[_TRIU6].tolist()


class MavlinkSink:
    """Send estimates to a flight stack over MAVLink 2.

    Parameters
    ----------
    url : str
        A pymavlink connection string: ``udpout:HOST:PORT`` (default loopback
        ``udpout:127.0.0.1:14550``), ``udpin:HOST:PORT``, ``tcp:HOST:PORT`` or a serial device
        (``/dev/ttyUSB0,921600``).
    system_id, component_id : int
        The sender's ids (default 1 and 197, ``MAV_COMP_ID_VISUAL_INERTIAL_ODOMETRY``).
    heartbeat_period : float
        Seconds of frame time between ``HEARTBEAT`` messages (an onboard controller's), > 0.

    Attributes
    ----------
    sent : dict
        Messages sent, per name.
    dropped : int
        Messages the link could not take (a full queue, or an error from the socket).

    Raises
    ------
    visloc.errors.UsageError
        If pymavlink is not installed, or the link cannot be opened.

    Examples
    --------
    >>> with MavlinkSink("udpout:127.0.0.1:14550") as link:          # doctest: +SKIP
    ...     link.send_vision_position(t, position_ned, rpy, covariance)
    """

    def __init__(self, url: str = "udpout:127.0.0.1:14550", *, system_id: int = 1, component_id: int = 197,
                 heartbeat_period: float = 1.0) -> None:
        mavutil, common = load_pymavlink()
        self._mav = common
        for name, v in (("system_id", system_id), ("component_id", component_id)):
            if not isinstance(v, int) or not 0 < v < 256:
                raise ValueError(f"{name} must be an integer in 1..255, got {v!r}")
        if not heartbeat_period > 0 or not math.isfinite(heartbeat_period):
            raise ValueError(f"heartbeat_period must be a positive number of seconds, got {heartbeat_period!r}")
        self.url = url
        try:
            self._conn = mavutil.mavlink_connection(url, source_system=system_id, source_component=component_id,
                                                    dialect="common", autoreconnect=True)
        except Exception as exc:  # noqa: BLE001 - pymavlink raises whatever its link raises (serial, socket)
            raise UsageError(f"--mavlink {url}: cannot open the link: {exc}") from None
        self._period = float(heartbeat_period)
        self._next_beat: float | None = None
        self.sent: dict[str, int] = {}
        self.dropped = 0
        self._queue: queue.Queue[bytes | None] | None = None
        self._thread: threading.Thread | None = None
        if not url.startswith("udp"):
            self._queue = queue.Queue(_QUEUE)
            self._thread = threading.Thread(target=self._writer, name="visloc-mavlink", daemon=True)
            self._thread.start()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _writer(self) -> None:
        assert self._queue is not None
        while (buf := self._queue.get()) is not None:
            self._write(buf)

    def _write(self, buf: bytes) -> None:
        try:
            self._conn.write(buf)
        except OSError:  # nobody listening (ECONNREFUSED on a connected socket), a link gone
            self.dropped += 1

    def _send(self, msg) -> None:
        buf = msg.pack(self._conn.mav)  # packed here, in order: the sequence numbers stay in order
        name = msg.get_type()
        self.sent[name] = self.sent.get(name, 0) + 1
        if self._queue is None:
            self._write(buf)
            return
        try:
            self._queue.put_nowait(buf)
        except queue.Full:  # the link cannot keep up: the oldest message goes
            try:
                self._queue.get_nowait()
                self.dropped += 1
            except queue.Empty:
                pass
            self._queue.put_nowait(buf)

    def heartbeat(self, time_s: float) -> None:
        """Send a ``HEARTBEAT`` (onboard controller, no autopilot) when one is due.

        Beats are due at the first call's time plus whole multiples of ``heartbeat_period``
        (frame time): a call sends one when a due time has been reached since the last beat,
        and after a gap in the frames the next is due at the first of those times after
        ``time_s`` (one beat, not a burst of the missed ones). A time before the last beat's
        (the frame clock started again: a new recording) sends one at once and counts the
        beats from there. The ``send_*`` methods call it before each message.

        Parameters
        ----------
        time_s : float
            The frame's time, s (the same clock as the ``send_*`` methods' ``time_s``).

        Raises
        ------
        ValueError
            ``time_s`` not a finite time >= 0 (nothing is sent).
        """
        _usec(time_s)  # checked before anything goes out
        due = self._next_beat
        if due is not None and due - self._period <= time_s < due:
            return
        m = self._mav
        self._send(m.MAVLink_heartbeat_message(m.MAV_TYPE_ONBOARD_CONTROLLER, m.MAV_AUTOPILOT_INVALID, 0, 0,
                                               m.MAV_STATE_ACTIVE, 3))
        if due is None or time_s < due - self._period:  # the first beat, or the clock went back
            self._next_beat = time_s + self._period
            return
        nxt = due + self._period
        if nxt <= time_s:  # a gap in the frames: the next beat of the same schedule after now
            nxt = due + self._period * (math.floor((time_s - due) / self._period) + 1)  # not a loop per beat missed
            if not nxt > time_s:  # a time beyond float's resolution of the schedule
                nxt = time_s + self._period
        self._next_beat = nxt

    def send_vision_position(self, time_s: float, position_ned: ArrayLike, rpy: Sequence[float], *,
                             covariance: ArrayLike | None = None, reset_counter: int = 0) -> None:
        """``VISION_POSITION_ESTIMATE``: the body's position and attitude in the local NED frame.

        Parameters
        ----------
        time_s : float
            The frame's time, s (sent as microseconds).
        position_ned : array_like (3,)
            Position, m, NED.
        rpy : sequence of 3 floats
            Roll, pitch, yaw (Z-Y-X), rad.
        covariance : array_like (6, 6), optional
            Of ``x, y, z, roll, pitch, yaw`` (m^2, rad^2); ``None``: unknown (NaN, as MAVLink
            asks).
        reset_counter : int
            Bumped by the caller each time the estimate jumps (the filter re-initialised).
        """
        x, y, z = np.asarray(position_ned, float).reshape(3).tolist()
        self.heartbeat(time_s)
        self._send(self._mav.MAVLink_vision_position_estimate_message(
            _usec(time_s), x, y, z, float(rpy[0]), float(rpy[1]), float(rpy[2]), _upper_triangle(covariance),
            int(reset_counter) % 256))

    def send_odometry(self, time_s: float, position_ned: ArrayLike, R_ned_body: ArrayLike, velocity_ned: ArrayLike,
                      *, pose_covariance: ArrayLike | None = None, velocity_covariance: ArrayLike | None = None,
                      reset_counter: int = 0, quality: int = 100) -> None:
        """``ODOMETRY``: position and attitude in local NED, velocity in NED (``MAV_FRAME_LOCAL_NED``
        for both), estimator type vision.

        Parameters
        ----------
        time_s : float
            The frame's time, s.
        position_ned, velocity_ned : array_like (3,)
            m and m/s, NED.
        R_ned_body : array_like (3, 3)
            The body's attitude (:func:`body_attitude_ned`).
        pose_covariance, velocity_covariance : array_like (6, 6), optional
            Of ``x, y, z, roll, pitch, yaw`` and of ``vx, vy, vz`` and the body rates; None: unknown.
        reset_counter : int
            As :meth:`send_vision_position`.
        quality : int
            0 (invalid) .. 100 (best); clipped to that range, NaN sent as 0.
        """
        m = self._mav
        p = np.asarray(position_ned, float).reshape(3).tolist()
        v = np.asarray(velocity_ned, float).reshape(3).tolist()
        q = float(quality)
        message = m.MAVLink_odometry_message(  # built, with its arguments' checks, before anything goes out
            _usec(time_s), m.MAV_FRAME_LOCAL_NED, m.MAV_FRAME_LOCAL_NED, *p, _quaternion(np.asarray(R_ned_body, float)),
            *v, math.nan, math.nan, math.nan, _upper_triangle(pose_covariance),
            _upper_triangle(velocity_covariance), int(reset_counter) % 256, m.MAV_ESTIMATOR_TYPE_VISION,
            int(max(0.0, min(100.0, q))) if math.isfinite(q) else 0)  # min(100, nan) would be 100
        self.heartbeat(time_s)
        self._send(message)

    def send_landing_target(self, time_s: float, position_cam: ArrayLike, size_m: float, *, target_num: int = 0,
                            R_body_cam: ArrayLike = DOWN_CAMERA) -> None:
        """``LANDING_TARGET``: a marker pad seen by the camera, for precision landing.

        Parameters
        ----------
        time_s : float
            The frame's time, s.
        position_cam : array_like (3,)
            The marker's centre in the camera frame (x right, y down, z along the optical
            axis), m (``Pose.t`` of its pose).
        size_m : float
            The marker's side, m (sent as its angular size).
        target_num : int
            The target's number (0-255; visloc sends the marker id's low byte).
        R_body_cam : array_like (3, 3)
            Camera axes to body FRD axes (default :data:`DOWN_CAMERA`).

        Notes
        -----
        ``angle_x``/``angle_y`` are the target's angles from the optical axis along the image's
        x and y (rad; what ArduPilot's precision landing reads), ``distance`` its range;
        ``x, y, z`` its position in the body FRD frame (``MAV_FRAME_BODY_FRD``, ``position_valid``
        1; what PX4's landing-target estimator reads).
        """
        p = np.asarray(position_cam, float).reshape(3)
        if not np.isfinite(p).all() or p[2] <= 0:
            raise ValueError(f"position_cam must be finite and in front of the camera, got {p.tolist()}")
        m = self._mav
        dist = float(np.linalg.norm(p))
        size = 2.0 * math.atan2(0.5 * float(size_m), dist)
        body = (np.asarray(R_body_cam, float) @ p).tolist()
        self.heartbeat(time_s)
        self._send(m.MAVLink_landing_target_message(
            _usec(time_s), int(target_num) % 256, m.MAV_FRAME_BODY_FRD, math.atan2(p[0], p[2]), math.atan2(p[1], p[2]),
            dist, size, size, *body, [1.0, 0.0, 0.0, 0.0], m.LANDING_TARGET_TYPE_VISION_FIDUCIAL, 1))

    def send_optical_flow(self, time_s: float, interval_s: float, velocity_cam: ArrayLike, distance_m: float,
                          quality: float, *, gyro: ArrayLike | None = None) -> None:
        """``OPTICAL_FLOW_RAD``: a downward camera's flow over one frame interval, as PX4's and
        ArduPilot's flow drivers expect it from a flow sensor.

        Parameters
        ----------
        time_s : float
            The frame's time, s (the end of the interval).
        interval_s : float
            The interval, s (> 0).
        velocity_cam : array_like (2,)
            The camera's velocity over the ground in its own x (image right) and y (image
            down) axes, m/s (``GroundVelocity.v``); non-finite: no flow (sent with quality 0).
        distance_m : float
            The height above the ground that scaled it, m.
        quality : float
            0-1 (``GroundVelocity.quality``), sent as 0-255.
        gyro : array_like (3,), optional
            The mean body rates over the interval in camera axes, rad/s, when ``velocity_cam``
            had them removed (``EgoMotion.update(gyro=...)``): they are added back to the flow
            and sent as the gyro integrals. None: the velocity still holds the rotation, and
            the gyro integrals are NaN (unknown).

        Notes
        -----
        The sensor axes are the camera's. Moving along +x gives ``integrated_y = vx dt / h``
        (positive), moving along +y gives ``integrated_x = -vy dt / h``; a right-handed turn
        about x or y adds ``wx dt`` or ``wy dt``: the angles the ground turned through as seen
        by the camera, rotation included, as a flow sensor reports them (the flight stack
        removes the rotation with the gyro integrals, or its own gyro).
        """
        dt = float(interval_s)
        if not dt > 0 or not math.isfinite(dt):
            raise ValueError(f"interval_s must be a positive number of seconds, got {interval_s!r}")
        v = np.asarray(velocity_cam, float).reshape(2)
        h = float(distance_m)
        ok = bool(np.isfinite(v).all() and h > 0 and math.isfinite(h))
        w = [math.nan] * 3 if gyro is None else [float(g) * dt for g in np.asarray(gyro, float).reshape(3)]
        fx, fy = (-float(v[1]) * dt / h, float(v[0]) * dt / h) if ok else (0.0, 0.0)
        if ok and gyro is not None:  # the rotation the velocity had removed, back in the flow
            fx, fy = fx + w[0], fy + w[1]
        q = round(255 * min(1.0, max(0.0, float(quality)))) if ok else 0
        self.heartbeat(time_s)
        self._send(self._mav.MAVLink_optical_flow_rad_message(
            _usec(time_s), 0, round(dt * 1e6), fx, fy, w[0], w[1], w[2], 0, q, 0,
            h if h > 0 and math.isfinite(h) else -1.0))

    def close(self) -> None:
        """Send what is queued and close the link."""
        if self._thread is not None and self._queue is not None:
            self._queue.put(None)
            self._thread.join(timeout=2.0)
            self._thread = None
        self._conn.close()


def _usec(time_s: float) -> int:
    if not math.isfinite(time_s) or time_s < 0:
        raise ValueError(f"time_s must be a finite time >= 0, got {time_s!r}")
    return round(time_s * 1e6)
