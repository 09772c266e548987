"""Square fiducial markers: the report's staged detector (Appendix G) and dictionaries."""

from visloc.markers.detector import DetectionTrace, DetectorParams, MarkerDetector
from visloc.markers.dictionary import Dictionary, load_dictionary

__all__ = ["DetectionTrace", "DetectorParams", "Dictionary", "MarkerDetector", "load_dictionary"]
