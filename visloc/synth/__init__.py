"""Renderers with exact ground truth (markers; later grids, ground textures, IMU).

Marker renders: :func:`render_markers` draws given marker poses, :func:`random_scene` draws
random scenes of graded difficulty, :func:`render_dataset` and :func:`render_video` write
them to disk with ``ground_truth.json`` and an OpenCV ``camera.yml``.
"""

from visloc.synth.datasets import render_dataset, render_video, write_camera_yml
from visloc.synth.markers import (
    MarkerRender,
    RenderedMarker,
    marker_object_points,
    project_points,
    render_markers,
)
from visloc.synth.raster import polygon_coverage
from visloc.synth.scenes import DIFFICULTIES, MARKER_LENGTH, default_camera, random_scene
from visloc.synth.textures import TEXTURES

__all__ = [
    "DIFFICULTIES",
    "MARKER_LENGTH",
    "TEXTURES",
    "MarkerRender",
    "RenderedMarker",
    "default_camera",
    "marker_object_points",
    "polygon_coverage",
    "project_points",
    "random_scene",
    "render_dataset",
    "render_markers",
    "render_video",
    "write_camera_yml",
]
