"""Views of a marker map (e.g. a grid on the floor) with exact ground truth of the camera pose."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from visloc.pose.maps import MarkerMap
from visloc.synth.markers import MarkerRender, render_markers
from visloc.types import Pose

__all__ = ["MapView", "random_map_view", "render_map_view"]

#: Camera axes of a camera looking straight down at the map (z = up) with yaw 0:
#: image x along map +x, image y along map -y, optical axis along map -z.
LOOKING_DOWN = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True, eq=False)
class MapView:
    """A rendered view of a marker map and the camera pose that produced it.

    Attributes
    ----------
    render : MarkerRender
        Image and per-marker ground truth.
    T_cam_map : Pose
        ``p_cam = R @ p_map + t``.
    """

    render: MarkerRender
    T_cam_map: Pose

    @property
    def position(self) -> NDArray[np.float64]:
        """Camera centre in the map, m."""
        return -self.T_cam_map.R.T @ self.T_cam_map.t


def render_map_view(marker_map: MarkerMap, K: NDArray, size: tuple[int, int], T_cam_map: Pose,
                    dictionary: str, **render_options: object) -> MapView:
    """Render every marker of ``marker_map`` seen from ``T_cam_map`` (options as
    :func:`visloc.synth.render_markers`)."""
    placements = []
    for i in marker_map.ids:
        corners = marker_map.corners_of(int(i))
        length = float(np.linalg.norm(corners[1] - corners[0]))
        placements.append((int(i), T_cam_map.compose(marker_map.marker_pose(int(i))), length))
    render = render_markers(K, size, placements, dictionary, **render_options)  # type: ignore[arg-type]
    return MapView(render, T_cam_map)


def random_map_view(rng: np.random.Generator, marker_map: MarkerMap, K: NDArray, size: tuple[int, int],
                    dictionary: str, *, height: tuple[float, float] = (0.6, 1.6), max_tilt_deg: float = 20.0,
                    offset: float = 0.2, **render_options: object) -> MapView:
    """A camera above the map's centre (within ``offset`` m), at a height in ``height`` (m),
    any yaw, tilted up to ``max_tilt_deg`` from looking straight down."""
    pts = np.concatenate([marker_map.corners_of(int(i)) for i in marker_map.ids])
    centre = pts.mean(axis=0)
    pos = centre + np.array([rng.uniform(-offset, offset), rng.uniform(-offset, offset), rng.uniform(*height)])
    yaw = rng.uniform(-np.pi, np.pi)
    tilt = np.radians(rng.uniform(0.0, max_tilt_deg))
    az = rng.uniform(-np.pi, np.pi)
    R_tilt = Rotation.from_rotvec(tilt * np.array([np.cos(az), np.sin(az), 0.0])).as_matrix()
    R_map_cam = R_tilt @ Rotation.from_euler("z", yaw).as_matrix() @ LOOKING_DOWN
    T_cam_map = Pose(R_map_cam.T, -R_map_cam.T @ pos)
    return render_map_view(marker_map, K, size, T_cam_map, dictionary, rng=rng, **render_options)
