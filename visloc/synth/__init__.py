"""Renderers with exact ground truth (markers, bottom-camera flights; later grids, IMU).

Marker renders: :func:`render_markers` draws given marker poses, :func:`random_scene` draws
random scenes of graded difficulty, :func:`render_dataset` and :func:`render_video` write
them to disk with ``ground_truth.json`` and an OpenCV ``camera.yml``.

Flights: :func:`render_flight` renders a downward-looking camera flying a
:func:`flight_trajectory` (or :func:`straight_track`) over textured ground, with exact
velocity and yaw-rate ground truth (:class:`FlightTrack`); :func:`write_flight` writes it.

Boards: :func:`render_aprilgrid` draws a Kalibr-style AprilGrid (tags touching corner squares)
with one ground-truth entry per tag, :func:`random_board_scene` a random one.

Camera model: :class:`CameraEffects` and :func:`apply_camera` turn an ideal linear-light
render into a camera-like frame (lens distortion, blur, vignetting, shot and read noise, sRGB,
JPEG); ``render_markers(..., camera=...)`` and ``random_scene(..., camera=True)`` use it, with
ground truth from :func:`distort_points`.
"""

from visloc.synth.boards import (
    BOARD_DIFFICULTIES,
    BOARD_SPACING_RATIO,
    BOARD_TAG_LENGTH,
    aprilgrid_tag_corners,
    random_board_scene,
    render_aprilgrid,
)
from visloc.synth.camera import (
    CameraEffects,
    apply_camera,
    distort_points,
    ideal_window,
    srgb_decode,
    srgb_encode,
)
from visloc.synth.datasets import render_dataset, render_video, write_camera_yml
from visloc.synth.flight import (
    Flight,
    FlightTrack,
    flight_trajectory,
    render_flight,
    render_ground_view,
    straight_track,
    write_flight,
)
from visloc.synth.imu import ImuStream, imu_stream
from visloc.synth.markers import (
    MarkerRender,
    RenderedMarker,
    marker_object_points,
    project_points,
    render_markers,
)
from visloc.synth.raster import polygon_coverage
from visloc.synth.scenes import (
    DARK_EXPOSURE,
    DIFFICULTIES,
    MARKER_LENGTH,
    default_camera,
    random_scene,
)
from visloc.synth.textures import TEXTURES

__all__ = [
    "BOARD_DIFFICULTIES",
    "BOARD_SPACING_RATIO",
    "BOARD_TAG_LENGTH",
    "DARK_EXPOSURE",
    "DIFFICULTIES",
    "MARKER_LENGTH",
    "TEXTURES",
    "CameraEffects",
    "Flight",
    "FlightTrack",
    "ImuStream",
    "MarkerRender",
    "RenderedMarker",
    "apply_camera",
    "aprilgrid_tag_corners",
    "default_camera",
    "distort_points",
    "flight_trajectory",
    "ideal_window",
    "imu_stream",
    "marker_object_points",
    "polygon_coverage",
    "project_points",
    "random_board_scene",
    "random_scene",
    "render_aprilgrid",
    "render_dataset",
    "render_flight",
    "render_ground_view",
    "render_markers",
    "render_video",
    "srgb_decode",
    "srgb_encode",
    "straight_track",
    "write_camera_yml",
    "write_flight",
]
