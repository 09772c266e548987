"""Logging frames, detections and marker poses to a rerun ``.rrd`` recording.

Entity layout (the camera is the reference frame)::

    /                       ViewCoordinates RDF (static): the 3-D root is the camera frame,
                            x right, y down, z forward (OpenCV's axes)
    camera                  Pinhole (K, resolution), logged when it changes
    camera/image            Image (RGB or grey)
    camera/image/markers    LineStrips2D, one closed outline per marker, label = id
    camera/image/corner0    Points2D, each marker's corner 0 (its own top-left)
    world/markers/<id>      Transform3D (marker -> camera: R, t) + Boxes3D (the marker plate)
    world/markers/<id>/axes Arrows3D, x red, y green, z blue, marker_length / 2 long

``world`` carries no transform, so marker poses are expressed in the camera frame, exactly as
:class:`visloc.types.Pose` gives them. Markers not seen in a frame are cleared.

Timelines: ``frame`` (sequence = frame index) and ``time`` (duration, seconds).

Pixel convention: visloc (like OpenCV) puts pixel centres at integer coordinates, rerun at
``+0.5``; 2-D coordinates and the principal point of ``K`` are shifted by half a pixel when
logged so that overlays line up with the image in the viewer.
"""

from __future__ import annotations

import math
import os
import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc.images import check_image
from visloc.io.closing import Closing, commit_staged, staged_path
from visloc.types import MarkerDetection


def _rerun():
    """The rerun SDK, imported on first use (it takes about half a second to import)."""
    import rerun

    return rerun

__all__ = ["RerunLogger"]

_AXIS_RGB = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255]], dtype=np.uint8)
_PLATE_RGB = (200, 200, 200)
_CORNER0_RGB = (255, 0, 255)
_HALF_PIXEL = 0.5  # rerun: centre of pixel (0, 0) is at (0.5, 0.5)


def _rgb(image: object) -> NDArray[np.uint8]:
    img = check_image(image, name="image")
    if img.ndim == 3 and img.shape[2] == 1:
        return img[:, :, 0]
    if img.ndim == 3 and img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    if img.ndim == 3:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    return img


def _check_poses(poses: list[Any] | None, n_detections: int, marker_length: float | None) -> None:
    """Raise a ValueError unless ``poses`` (when given) has one entry per detection and comes
    with a positive, finite ``marker_length`` (m)."""
    if poses is None:
        return
    if len(poses) != n_detections:
        raise ValueError(
            f"poses must have one entry (or None) per detection: "
            f"got {len(poses)} poses for {n_detections} detections"
        )
    if marker_length is None or not math.isfinite(marker_length) or marker_length <= 0:
        raise ValueError(
            f"marker_length must be a positive length when poses are given, "
            f"got {marker_length!r}"
        )


def _image_archetype(rgb: NDArray[np.uint8] | None, jpeg_quality: int | None):
    """What ``camera/image`` is logged as: the RGB or grey image (JPEG-compressed with
    ``jpeg_quality``, 1-100, when given), or a non-recursive clear when ``rgb`` is None."""
    if rgb is None:
        return _rerun().Clear(recursive=False)
    img = _rerun().Image(rgb)
    return img if jpeg_quality is None else img.compress(jpeg_quality=int(jpeg_quality))


def _log_outlines(rec, ids: list[int], corners: list[NDArray[np.float64]]) -> None:
    """Log the markers' closed outlines (labelled with their ids) and their corner 0 points to
    the recording stream ``rec``; corners (4, 2) px, shifted to rerun's pixel centres."""
    strips = [np.vstack([c, c[:1]]) + _HALF_PIXEL for c in corners]
    rec.log(
        "camera/image/markers",
        _rerun().LineStrips2D(strips, labels=[str(i) for i in ids], class_ids=ids),
    )
    rec.log(
        "camera/image/corner0",
        _rerun().Points2D([c[0] + _HALF_PIXEL for c in corners], colors=_CORNER0_RGB, radii=-3.0),
    )


class RerunLogger(Closing):
    """Write a rerun recording (``.rrd`` file) of frames, marker detections and poses.

    Nothing is spawned or served: the recording goes straight to ``path`` and can be opened
    later with ``rerun path.rrd``. See the module docstring for the entity layout.

    Parameters
    ----------
    path : str or os.PathLike
        Output ``.rrd`` file; overwritten if it exists, parent folders are created.
    app_id : str, default "visloc"
        Application id shown in the viewer.
    jpeg_quality : int, optional
        When given (1-100), images are stored JPEG-compressed, which makes long recordings
        10-20 times smaller; default: raw pixels.

    Raises
    ------
    TypeError, ValueError
        ``path`` not a path, a folder or not named ``.rrd`` (the viewer opens a recording by
        its suffix); ``app_id`` empty; ``jpeg_quality`` outside 1-100. Nothing is created then.

    Examples
    --------
    >>> with RerunLogger("run.rrd") as log:  # doctest: +SKIP
    ...     for frame in source:
    ...         dets = detector.detect(frame.image)
    ...         log.log_frame(frame.index, frame.time, frame.image, dets)
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        app_id: str = "visloc",
        jpeg_quality: int | None = None,
    ) -> None:
        if not isinstance(path, (str, os.PathLike)):
            raise TypeError(f"path must be a str or os.PathLike, got {type(path).__name__}")
        if not isinstance(app_id, str) or not app_id:
            raise ValueError(f"app_id must be a non-empty str, got {app_id!r}")
        if jpeg_quality is not None and (
            isinstance(jpeg_quality, bool)
            or not isinstance(jpeg_quality, (int, np.integer))
            or not 1 <= jpeg_quality <= 100
        ):
            raise ValueError(f"jpeg_quality must be an int in 1..100 or None, got {jpeg_quality!r}")
        self.path = Path(path)
        if self.path.is_dir():
            raise ValueError(f"path is a directory, expected an .rrd file path: {self.path}")
        if self.path.suffix.lower() != ".rrd":  # the viewer opens a recording by its suffix
            raise ValueError(f"path: a rerun recording is an .rrd file, got {self.path}")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.jpeg_quality = jpeg_quality
        self.recording = _rerun().RecordingStream(app_id, recording_id=str(uuid.uuid4()))
        self.recording.save(staged_path(self.path))  # renamed over path by close()
        self.recording.log("/", _rerun().ViewCoordinates.RDF, static=True)
        self._pinhole: tuple[bytes, tuple[int, int]] | None = None
        self._marker_paths: set[str] = set()
        self._track: list[list[float]] = []
        self._tracks3d: dict[str, list[list[float]]] = {}
        self._closed = False

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` has been called."""
        return self._closed

    def log_frame(
        self,
        index: int,
        time: float,
        image: NDArray[np.uint8] | None,
        detections: Sequence[MarkerDetection],
        *,
        poses: Sequence[Any | None] | None = None,
        camera: Any | None = None,
        marker_length: float | None = None,
    ) -> None:
        """Log one frame with its detections and, optionally, marker poses.

        Parameters
        ----------
        index : int
            Frame index (``frame`` timeline).
        time : float
            Seconds since the start (``time`` timeline).
        image : ndarray (H, W) or (H, W, 3) uint8, or None
            Grey or BGR image (converted to RGB); ``None`` (unreadable frame) clears the image.
        detections : sequence of MarkerDetection
            Markers found in the frame (anything with ``id`` and ``corners`` (4, 2)).
        poses : sequence of Pose or None, optional
            One entry per detection (``None`` where no pose was found); anything with ``R``
            (3, 3) and ``t`` (3,) mapping marker points into the camera frame.
        camera : object, optional
            Anything with ``K`` (3, 3); logged as the ``camera`` pinhole when given (its
            resolution is the image size, so it needs ``image``).
        marker_length : float, optional
            Marker side (m); required with ``poses`` to size the plates and axes.

        Raises
        ------
        ValueError
            If the logger is closed, ``time`` is not finite, shapes are wrong or ``poses``
            does not match ``detections`` or comes without ``marker_length``.
        TypeError
            If ``image`` is not a uint8 array or ``camera`` has no ``K``.
        """
        self._check_frame(index, time)
        detections = list(detections)
        corners = [self._corners(d, i) for i, d in enumerate(detections)]
        poses = None if poses is None else list(poses)
        _check_poses(poses, len(detections), marker_length)
        rgb = None if image is None else _rgb(image)
        K = None if camera is None else self._camera_K(camera)

        rec = self.recording
        rec.set_time("frame", sequence=int(index))
        rec.set_time("time", duration=float(time))
        rec.log("camera/image", _image_archetype(rgb, self.jpeg_quality))
        if rgb is not None and K is not None:
            self._log_pinhole(K, (rgb.shape[1], rgb.shape[0]))

        ids = [int(d.id) for d in detections]
        _log_outlines(rec, ids, corners)
        self._log_poses(ids, poses, marker_length)

    def _check_frame(self, index: int, time: float) -> None:
        """Raise unless the logger is open, ``index`` an int and ``time`` a finite number."""
        if self._closed:
            raise ValueError(f"cannot log to closed RerunLogger({self.path})")
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
            raise TypeError(f"index must be an int, got {type(index).__name__}")
        if (
            isinstance(time, bool)
            or not isinstance(time, (int, float, np.integer, np.floating))
            or not math.isfinite(time)
        ):
            raise ValueError(f"time must be a finite number of seconds, got {time!r}")

    def _frame(self, index: int, time: float, image: NDArray[np.uint8] | None):
        """Check the frame (:meth:`_check_frame`), set both timelines and log the image (if
        any); returns the recording stream."""
        self._check_frame(index, time)
        rec = self.recording
        rec.set_time("frame", sequence=int(index))
        rec.set_time("time", duration=float(time))
        if image is not None:
            img = _rerun().Image(_rgb(image))
            rec.log("camera/image",
                    img if self.jpeg_quality is None else img.compress(jpeg_quality=int(self.jpeg_quality)))
        return rec

    def log_flow(
        self,
        index: int,
        time: float,
        image: NDArray[np.uint8] | None,
        field: Any | None,
        velocity: Any | None,
        position: Sequence[float] | None = None,
    ) -> None:
        """Log one frame of a ground-velocity run.

        Logs the image, the block flow vectors (``camera/image/flow``), the velocity, yaw rate
        and quality as scalar plots (``plots/vx``, ``plots/vy``, ``plots/yaw_rate``,
        ``plots/quality``) and the integrated position (``track/position``, a growing line in
        metres).

        Parameters
        ----------
        index, time : int, float
            As for :meth:`log_frame`: the ``frame`` and ``time`` (s) timelines.
        image : ndarray (H, W) or (H, W, 3) uint8, or None
            Grey or BGR image (converted to RGB); ``None``: no image is logged for this frame
            (the viewer keeps showing the last one).
        field : FlowField or None
            The block flow of the frame pair (:class:`visloc.types.FlowField`): the vectors of
            blocks with ``confidence > 0.2`` are drawn as arrows from their centres, px (pixel
            centres at integers, shifted by half a pixel for rerun); None: no arrows.
        velocity : GroundVelocity or None
            The ground velocity of the frame pair (:class:`visloc.types.GroundVelocity`): ``v``
            (m/s, camera x and y axes), ``yaw_rate`` (rad/s) and ``quality`` are plotted; None
            for the first frame (nothing plotted).
        position : sequence of float, optional
            Integrated ``(x, y)`` position, m (e.g. ``EgoMotion.position``, the first frame's
            camera axes), appended to the track; None: the track is not extended.

        Raises
        ------
        ValueError
            If the logger is closed or ``time`` is not finite.
        TypeError, ValueError
            If ``index`` is not an int, or ``image`` is not a usable image
            (:func:`visloc.images.check_image`).
        """
        rec = self._frame(index, time, image)
        if field is not None and len(field.centers):
            good = np.asarray(field.confidence) > 0.2
            rec.log("camera/image/flow", _rerun().Arrows2D(origins=field.centers[good] + _HALF_PIXEL,
                                                     vectors=field.vectors[good], colors=(0, 200, 255)))
        if velocity is not None:
            rec.log("plots/vx", _rerun().Scalars(float(velocity.v[0])))
            rec.log("plots/vy", _rerun().Scalars(float(velocity.v[1])))
            rec.log("plots/yaw_rate", _rerun().Scalars(float(velocity.yaw_rate)))
            rec.log("plots/quality", _rerun().Scalars(float(velocity.quality)))
        if position is not None:
            self._track.append([float(position[0]), float(position[1])])
            rec.log("track/position", _rerun().LineStrips2D([self._track]))

    def log_localize(self, index: int, time: float, image: NDArray[np.uint8] | None,
                     estimate: Sequence[float] | None, truth: Sequence[float] | None = None) -> None:
        """Log one frame of a localisation run.

        Logs the image, the estimated position (and the true one when known) as scalar plots
        (``plots/x/estimate``, ``plots/x/truth``, ... for x, y and z), and both tracks in 3-D
        (``world/estimate``, ``world/truth``, growing lines).

        Parameters
        ----------
        index, time, image
            As for :meth:`log_flow` (``None``: the viewer keeps showing the last image).
        estimate : sequence of float (3,) or None
            Estimated camera position ``(x, y, z)``, m, map frame; None (no estimate yet):
            nothing is logged for it.
        truth : sequence of float (3,), optional
            True position in the same frame and units; None (unknown): nothing is logged for it.

        Raises
        ------
        TypeError, ValueError
            As for :meth:`log_flow`: a closed logger, a ``time`` that is not finite, an
            ``index`` that is not an int or an unusable ``image``; an ``estimate`` or
            ``truth`` that is not three finite numbers (checked before anything is logged).
        """
        points = {name: _position(p, name) for name, p in (("estimate", estimate), ("truth", truth)) if p is not None}
        rec = self._frame(index, time, image)
        for name, p in points.items():
            for axis, v in zip("xyz", p, strict=True):
                rec.log(f"plots/{axis}/{name}", _rerun().Scalars(float(v)))
            track = self._tracks3d.setdefault(name, [])
            track.append([float(v) for v in p])
            rec.log(f"world/{name}", _rerun().LineStrips3D([track]))

    @staticmethod
    def _corners(det: MarkerDetection, i: int) -> NDArray[np.float64]:
        c = np.asarray(det.corners, dtype=np.float64)
        if c.shape != (4, 2):
            raise ValueError(f"detections[{i}].corners must have shape (4, 2), got {c.shape}")
        return c

    @staticmethod
    def _camera_K(camera: Any) -> NDArray[np.float64]:
        if not hasattr(camera, "K"):
            raise TypeError(f"camera must have an attribute K (3, 3), got {type(camera).__name__}")
        K = np.asarray(camera.K, dtype=np.float64)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            raise ValueError(f"camera.K must be a finite (3, 3) matrix, got shape {K.shape}")
        K = K.copy()
        K[:2, 2] += _HALF_PIXEL  # principal point in rerun's pixel convention
        return K

    def _log_pinhole(self, K: NDArray[np.float64], size: tuple[int, int]) -> None:
        key = (K.tobytes(), size)
        if key != self._pinhole:
            self.recording.log("camera", _rerun().Pinhole(image_from_camera=K, resolution=list(size)))
            self._pinhole = key

    def _log_poses(
        self, ids: list[int], poses: list[Any] | None, marker_length: float | None
    ) -> None:
        rec = self.recording
        logged: set[str] = set()
        if poses is not None and marker_length is not None:
            half = 0.5 * float(marker_length)
            for i, (marker_id, pose) in enumerate(zip(ids, poses, strict=True)):
                if pose is None:
                    continue
                R = np.asarray(getattr(pose, "R", None), dtype=np.float64)
                t = np.asarray(getattr(pose, "t", None), dtype=np.float64).ravel()
                if R.shape != (3, 3) or t.shape != (3,):
                    raise ValueError(
                        f"poses[{i}] must have R (3, 3) and t (3,), got R {R.shape} and t {t.shape}"
                    )
                path, k = f"world/markers/{marker_id}", 0
                while path in logged:  # the same id twice in one frame
                    k += 1
                    path = f"world/markers/{marker_id}_{k}"
                logged.add(path)
                rec.log(path, _rerun().Transform3D(translation=t, mat3x3=R))
                rec.log(
                    path,
                    _rerun().Boxes3D(
                        half_sizes=[[half, half, half / 50]],
                        colors=[_PLATE_RGB],
                        labels=[str(marker_id)],
                    ),
                )
                rec.log(
                    f"{path}/axes",
                    _rerun().Arrows3D(
                        origins=np.zeros((3, 3)), vectors=np.eye(3) * half, colors=_AXIS_RGB
                    ),
                )
        for path in sorted(self._marker_paths - logged):
            rec.log(path, _rerun().Clear(recursive=True))
        self._marker_paths = logged

    def close(self) -> None:
        """Flush everything and finish the ``.rrd`` file (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self.recording.flush()
        self.recording.disconnect()
        commit_staged(staged_path(self.path), self.path, keep=True)


def _position(p: object, name: str) -> list[float]:
    """``p`` as three finite floats (a position, m), or a TypeError/ValueError naming ``name``."""
    try:
        a = np.asarray(p, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name}: expected three numbers (x, y, z), got {type(p).__name__}") from exc
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: expected three finite numbers (x, y, z), got {a.tolist()!r}")
    return a.tolist()
