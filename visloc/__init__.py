"""visloc: visual localisation for small drones and robots.

Square fiducial markers (the report's staged detector, Appendix G), Gauss-Newton marker pose,
synthetic renders with exact ground truth, and a command-line tool (``visloc``).
"""

__version__ = "0.1.0"
