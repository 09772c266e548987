"""External-camera tracking: a rigid body carrying markers, relative to reference markers.

Report §3.2.2 "External top camera" and Appendix G (Figures G.2-G.3): "we have a transformation
from quadrotor-markers to camera frame and a transformation from cube-markers to camera frame.
The transformations can be combined to estimate the location of the quadrotor with respect to
the cube (inertia frame)."

Both maps are seen by one fixed camera in the same image: ``T_cam_body`` and ``T_cam_ref`` come
from :func:`visloc.pose.estimate_camera_pose` on each map's markers, and the body's pose in the
reference frame is ``T_ref_body = T_cam_ref^-1 T_cam_body``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from visloc.pose.camera import Camera
from visloc.pose.map_pose import MapPose, estimate_camera_pose
from visloc.pose.maps import MarkerMap
from visloc.pose.rotations import matrix_to_euler
from visloc.types import MarkerDetection, Pose

__all__ = ["BodyPose", "relative_pose", "track_body"]


@dataclass(frozen=True, eq=False)
class BodyPose:
    """A body's pose in a reference frame, from one camera image.

    Attributes
    ----------
    T_ref_body : Pose
        ``p_ref = R @ p_body + t``.
    body : MapPose
        The camera's pose relative to the body's markers.
    reference : MapPose
        The camera's pose relative to the reference markers.
    """

    T_ref_body: Pose
    body: MapPose
    reference: MapPose

    @property
    def position(self) -> NDArray[np.float64]:
        """Body origin in the reference frame, m."""
        return self.T_ref_body.t

    @property
    def euler_zyx(self) -> NDArray[np.float64]:
        """``[phi, theta, psi]`` of ``R_ref_body`` (``Rz(psi) Ry(theta) Rx(phi)``), rad."""
        return matrix_to_euler(self.T_ref_body.R)

    @property
    def yaw(self) -> float:
        """Rotation of the body about the reference frame's z axis, rad."""
        return float(self.euler_zyx[2])

    def to_dict(self) -> dict:
        """JSON-ready: ``x, y, z, yaw`` (m, rad), the full ``R``/``t``, Euler angles, the rvec
        and both fits' reprojection errors and marker ids."""
        x, y, z = (float(v) for v in self.position)
        return {
            "x": x, "y": y, "z": z, "yaw": self.yaw,
            "euler_zyx_rad": [float(v) for v in self.euler_zyx],
            "rvec": [float(v) for v in self.T_ref_body.rvec],
            "R": [[float(v) for v in row] for row in self.T_ref_body.R],
            "body_rms_px": float(self.body.pose.reprojection_rms),
            "reference_rms_px": float(self.reference.pose.reprojection_rms),
            "body_markers": self.body.used, "reference_markers": self.reference.used,
        }


def relative_pose(T_cam_body: Pose, T_cam_ref: Pose) -> Pose:
    """``T_ref_body = T_cam_ref^-1 T_cam_body``: the body frame in the reference frame.

    Parameters
    ----------
    T_cam_body : Pose
        Body frame into camera frame, ``p_cam = R @ p_body + t`` (m).
    T_cam_ref : Pose
        Reference frame into the same camera frame (m).

    Returns
    -------
    Pose
        ``T_ref_body``: ``p_ref = R @ p_body + t``, m.

    Raises
    ------
    TypeError
        ``T_cam_body`` or ``T_cam_ref`` not a :class:`~visloc.types.Pose`.
    """
    for name, value in (("T_cam_body", T_cam_body), ("T_cam_ref", T_cam_ref)):
        if not isinstance(value, Pose):
            raise TypeError(f"{name} must be a Pose, got {type(value).__name__}")
    return T_cam_ref.inverse().compose(T_cam_body)


def track_body(
    detections: list[MarkerDetection],
    body_map: MarkerMap,
    reference_map: MarkerMap,
    camera: Camera,
    **pose_options: object,
) -> BodyPose | None:
    """Pose of the body (``body_map``'s markers) in the reference frame (``reference_map``'s),
    both seen in one image by ``camera``.

    Parameters
    ----------
    detections : list of MarkerDetection
        Markers found in the image, corners in pixels (ids of neither map are ignored).
    body_map : MarkerMap
        The body's markers in the body frame, m.
    reference_map : MarkerMap
        The reference markers in the reference frame, m.
    camera : Camera
        Intrinsics of the image.
    **pose_options
        Passed to both calls of :func:`visloc.pose.estimate_camera_pose` (``pixel_sigma``,
        ``max_residual``, ``max_iter``, ``n_starts``).

    Returns
    -------
    BodyPose or None
        ``T_ref_body`` (m) with the two camera fits; None when the body's or the reference's
        markers are not seen.

    Raises
    ------
    ValueError
        When the two maps share marker ids (a detection could not be told apart), or a
        pose option is out of range.
    TypeError
        ``camera`` is not a :class:`Camera`, or an unknown pose option.
    """
    shared = sorted(set(body_map.ids.tolist()) & set(reference_map.ids.tolist()))
    if shared:
        raise ValueError(f"body and reference maps must not share marker ids, both have {shared}")
    body = estimate_camera_pose([d for d in detections if d.id in body_map], body_map, camera, **pose_options)
    ref = estimate_camera_pose([d for d in detections if d.id in reference_map], reference_map, camera,
                               **pose_options)
    if body is None or ref is None:
        return None
    return BodyPose(relative_pose(body.pose, ref.pose), body, ref)
