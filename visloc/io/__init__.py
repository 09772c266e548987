"""Input and output: frame sources, result writers, annotated images and rerun recordings.

Sources
    :func:`open_source` (image, folder, glob, video, camera) -> :class:`FrameSource` of
    :class:`visloc.types.Frame`; :class:`SourceError` when a source cannot be opened.
Writers
    :class:`JsonlWriter`, :class:`CsvWriter` (flushed per record), :class:`AnnotationSink`
    (video or PNG folder), :func:`draw_markers`.
Visualisation
    :class:`RerunLogger` writes a rerun ``.rrd`` recording.
Recordings
    :class:`BagSource`: the images of a ROS 1 / ROS 2 bag or an MCAP file (``visloc.io.bags``;
    rosbags, the extra ``visloc[ros]``); :func:`visloc.io.bags.read_bag_imu` its IMU.
Drone links
    :class:`MavlinkSink` sends estimates to PX4 / ArduPilot as MAVLink messages
    (``visloc.io.mavlink``; pymavlink, the extra ``visloc[mavlink]``).
"""

from visloc.io.bags import BagSource
from visloc.io.draw import draw_markers
from visloc.io.mavlink import MavlinkSink
from visloc.io.rerun_log import RerunLogger
from visloc.io.sources import (
    IMAGE_EXTENSIONS,
    VIDEO_EXTENSIONS,
    CameraSource,
    FrameSource,
    ImageListSource,
    SourceError,
    VideoSource,
    open_source,
    read_image,
)
from visloc.io.writers import AnnotationSink, CsvWriter, JsonlWriter, to_jsonable

__all__ = [
    "IMAGE_EXTENSIONS",
    "VIDEO_EXTENSIONS",
    "AnnotationSink",
    "BagSource",
    "CameraSource",
    "CsvWriter",
    "FrameSource",
    "ImageListSource",
    "JsonlWriter",
    "MavlinkSink",
    "RerunLogger",
    "SourceError",
    "VideoSource",
    "draw_markers",
    "open_source",
    "read_image",
    "to_jsonable",
]
