"""Square fiducial markers: the report's staged detector (Appendix G) and dictionaries."""

from visloc.markers.detector import (
    FAST_PASSES,
    DetectionTrace,
    DetectorParams,
    MarkerDetector,
    SearchPass,
)
from visloc.markers.dictionary import Dictionary, load_dictionary
from visloc.markers.tracker import MarkerTracker

__all__ = [
    "FAST_PASSES",
    "DetectionTrace",
    "DetectorParams",
    "Dictionary",
    "MarkerDetector",
    "MarkerTracker",
    "SearchPass",
    "load_dictionary",
]
