"""Camera model and marker pose.

:class:`Camera` (intrinsics, OpenCV distortion, FileStorage YAML), :func:`estimate_marker_pose`
(Gauss-Newton pose of a square marker from its corners, report Appendix G) and helpers.
"""

from visloc.pose.camera import Camera
from visloc.pose.gauss_newton import refine_params
from visloc.pose.map_pose import MapPose, estimate_camera_pose, markers_in_view
from visloc.pose.maps import GridMap, MarkerMap
from visloc.pose.marker_pose import estimate_marker_pose, is_flip, pose_error, yaw_seed_start
from visloc.pose.planar import marker_object_points, planar_solutions, yaw_seeds
from visloc.pose.rotations import euler_to_matrix, matrix_to_euler, rotation_angle

__all__ = [
    "Camera",
    "GridMap",
    "MapPose",
    "MarkerMap",
    "estimate_camera_pose",
    "estimate_marker_pose",
    "euler_to_matrix",
    "is_flip",
    "marker_object_points",
    "markers_in_view",
    "matrix_to_euler",
    "planar_solutions",
    "pose_error",
    "refine_params",
    "rotation_angle",
    "yaw_seed_start",
    "yaw_seeds",
]
