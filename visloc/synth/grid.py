"""Views of a marker map (e.g. a grid on the floor) with exact ground truth of the camera pose."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from visloc.pose.maps import MarkerMap
from visloc.synth.camera import CameraEffects
from visloc.synth.markers import MarkerRender, render_markers
from visloc.types import Pose

__all__ = ["MapFlight", "MapView", "random_map_view", "render_map_flight", "render_map_view"]

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
    """Render every marker of ``marker_map`` seen from ``T_cam_map``.

    Parameters
    ----------
    marker_map : MarkerMap
        The markers: corners in the map frame, m.
    K : ndarray (3, 3)
        Camera matrix, px (pixel centres at integer coordinates).
    size : (int, int)
        ``(width, height)`` of the image, px.
    T_cam_map : Pose
        Map-to-camera transform, ``p_cam = R @ p_map + t`` (t in m).
    dictionary : str or Dictionary
        The markers' dictionary.
    **render_options
        Keyword arguments of :func:`visloc.synth.render_markers` (``background``,
        ``blur_sigma``, ``rng``, ``camera``, ...).

    Returns
    -------
    MapView
        The render (one ground-truth entry per marker, in id order) and ``T_cam_map``.

    Raises
    ------
    TypeError, ValueError
        On a malformed argument (:func:`visloc.synth.render_markers`); the message names it.
    """
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
    """A random view of the map from above: a camera over the map's centre, any yaw, tilted
    up to ``max_tilt_deg`` from looking straight down.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the camera pose and of the render's randomness.
    marker_map : MarkerMap
        The markers, in a map frame with z up (e.g. a grid on the floor), corners in m.
    K : ndarray (3, 3)
        Camera matrix, px (pixel centres at integer coordinates).
    size : (int, int)
        ``(width, height)`` of the image, px.
    dictionary : str or Dictionary
        The markers' dictionary.
    height : (float, float)
        Range of the camera's height above the mean of the marker corners, m.
    max_tilt_deg : float
        Largest tilt away from looking straight down (map -z), degrees.
    offset : float
        Largest horizontal distance of the camera from the mean of the corners along map x
        and along map y, m.
    **render_options
        Keyword arguments of :func:`visloc.synth.render_markers` other than ``rng``.

    Returns
    -------
    MapView
        The render and the camera pose ``T_cam_map``.

    Raises
    ------
    TypeError, ValueError
        On a malformed argument (:func:`visloc.synth.render_markers`); the message names it.
    """
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


#: The camera of the flights ``visloc render localize`` and the demo render: a webcam's optics
#: blur, sensor noise, vignetting and sRGB encoding, no JPEG, and no lens distortion (their
#: camera file has none).
FLIGHT_CAMERA = CameraEffects(blur_sigma=0.5, k1=0.0, jpeg_quality=None)


@dataclass(frozen=True, eq=False)
class MapFlight:
    """A downward camera's flight over a marker map on the ground, with exact truth.

    Attributes
    ----------
    frames : ndarray (N, H, W) uint8
    track : visloc.synth.flight.FlightTrack
        Truth; ``position`` is the camera centre in the map frame (z = height).
    K : ndarray (3, 3)
    marker_map : MarkerMap
    imu : ndarray (M, 7) or None
        IMU samples ``t, gx, gy, gz, fx, fy, fz`` from the same trajectory, in the *camera*
        axes: body rates (rad/s) and specific force ``R_world_cam^T (a - g)`` (m/s^2, with
        ``g = (0, 0, -9.81)`` in the z-up world: at rest looking down it reads (0, 0, -9.81)).
    """

    frames: NDArray[np.uint8]
    track: object
    K: NDArray[np.float64]
    marker_map: MarkerMap
    imu: NDArray[np.float64] | None = None


def render_map_flight(seconds: float, fps: float, marker_map: MarkerMap, *, size: tuple[int, int] = (320, 240),
                      seed: int = 1, dictionary: str = "DICT_4X4_50", max_speed: float = 0.4,
                      height: tuple[float, float] = (0.8, 1.3), roll_pitch: float = 0.1,
                      imu_rate: float | None = 200.0, accel_noise: float = 0.05, gyro_noise: float = 0.005,
                      **render_options: object) -> MapFlight:
    """Fly the bottom camera (AR.Drone 2.0 intrinsics scaled to ``size``) over ``marker_map``:
    a smooth random trajectory from :func:`visloc.synth.flight.flight_trajectory`, centred
    over the map, rendered frame by frame with exact marker ground truth, and (``imu_rate``)
    IMU samples of the same flight with white noise.

    Parameters
    ----------
    seconds, fps : float
        Duration, s, and frame rate, Hz (> 0): ``max(1, round(seconds * fps))`` frames.
    marker_map : MarkerMap
        The markers, lying in the ground plane ``z = 0`` of a z-up map frame, corners in m.
    size : (int, int)
        ``(width, height)`` of the frames, px.
    seed : int
        Seeds the trajectory, the render noise (``default_rng([seed, 3])``) and the IMU noise
        (``[seed, 4]``).
    dictionary : str
        The markers' dictionary.
    max_speed : float
        Bound of the camera's speed, m/s.
    height : (float, float)
        Range of the camera's height above the ground, m.
    roll_pitch : float
        Amplitude of roll and pitch, rad.
    imu_rate : float or None
        IMU sample rate, Hz; ``None`` (or 0): no IMU.
    accel_noise : float
        Standard deviation of the accelerometer's white noise per sample and axis, m/s^2.
    gyro_noise : float
        Standard deviation of the gyro's white noise per sample and axis, rad/s.
    **render_options
        Keyword arguments of :func:`visloc.synth.render_markers` other than ``rng``.

    Returns
    -------
    MapFlight
        Frames (N, height, width) uint8, the track (camera centre in the map frame), ``K``,
        the map and the IMU samples (M, 7) or ``None``.

    Raises
    ------
    TypeError, ValueError
        On a malformed argument; the message names it.
    """
    from dataclasses import replace

    from visloc.synth.flight import default_bottom_camera, flight_trajectory

    track = flight_trajectory(seed, seconds, fps, max_speed=max_speed, height=height, roll_pitch=roll_pitch)
    pts = np.concatenate([marker_map.corners_of(int(i)) for i in marker_map.ids])
    shift = pts[:, :2].mean(axis=0) - track.position[:, :2].mean(axis=0)
    position = track.position + np.array([shift[0], shift[1], 0.0])
    track = replace(track, position=position)
    K = default_bottom_camera(size)
    rng = np.random.default_rng([seed, 3])
    frames = np.empty((len(track.t), size[1], size[0]), np.uint8)
    for k in range(len(track.t)):
        R_world_cam, C = track.pose(k)
        T_cam_map = Pose(R_world_cam.T, -R_world_cam.T @ C)
        view = render_map_view(marker_map, K, size, T_cam_map, dictionary, rng=rng, **render_options)
        frames[k] = view.render.image
    imu = None
    if imu_rate:
        imu = _imu_samples(seed, seconds, imu_rate, max_speed, height, roll_pitch, accel_noise, gyro_noise)
    return MapFlight(frames, track, K, marker_map, imu)


def _imu_samples(seed, seconds, rate, max_speed, height, roll_pitch, accel_noise, gyro_noise) -> NDArray:
    """IMU of the same trajectory (it depends on the seed only) sampled at ``rate``: body rates
    and specific force in camera axes; accelerations by central differences of the analytic
    velocity (error O(h^2) with h = 1e-4 s)."""
    from visloc.synth.flight import flight_trajectory

    opts = {"max_speed": max_speed, "height": height, "roll_pitch": roll_pitch}
    tr = flight_trajectory(seed, seconds, rate, **opts)
    h = 1e-4
    up = flight_trajectory(seed, seconds, rate, t0=h, **opts)
    down = flight_trajectory(seed, seconds, rate, t0=-h, **opts)
    accel = (up.velocity - down.velocity) / (2 * h)
    R = tr.R_world_cam  # (M, 3, 3)
    f = np.einsum("mji,mj->mi", R, accel - np.array([0.0, 0.0, -9.81]))  # R^T (a - g)
    gyro = np.column_stack([tr.roll_rate, tr.pitch_rate, tr.yaw_rate])
    rng = np.random.default_rng([seed, 4])
    f = f + rng.normal(0.0, accel_noise, f.shape)
    gyro = gyro + rng.normal(0.0, gyro_noise, gyro.shape)
    return np.column_stack([tr.t, gyro, f])
