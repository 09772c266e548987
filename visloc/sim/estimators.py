"""State estimators the simulated controller can fly on.

- :class:`TruthEstimator`: the true state (the report's linear-design setting).
- :class:`VisionEstimator`: visloc's own pipeline. Each bottom-camera image goes through
  :class:`visloc.markers.MarkerTracker` (the markers of the previous frames followed, and the
  map's markers in the last fix's view, :func:`visloc.pose.markers_in_view`; the detector's
  full search when following fails) and :func:`visloc.pose.estimate_camera_pose` (the
  report's marker grid, §3.2.2); the camera-centre fix corrects the Kalman filter of
  :class:`visloc.estimation.fusion.MapFixFusion` (filterpy inside) that integrates the
  accelerometer, rotated into the inertial frame, at the IMU rate. The attitude integrates the gyro (report eq. 2.3)
  and is pulled towards the map pose's attitude at each fix, the complementary filter of
  report eq. (3.4) with the vision angles in place of the accelerometer's (in flight the
  accelerometer of a drag-free quadrotor only sees the thrust axis). The body rates are the
  gyro's. The ultrasound (report §3.2.1) corrects the height between camera fixes.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from visloc.control._checks import as_array, check_real
from visloc.control.controller import wrap_angle
from visloc.estimation._checks import as_float_array
from visloc.estimation.fusion import MapFixFusion
from visloc.estimation.height import ultrasound_height
from visloc.markers.detector import MarkerDetector
from visloc.markers.tracker import MarkerTracker
from visloc.model.rigid_body import euler_rate_values, rotation_values
from visloc.pose.camera import Camera
from visloc.pose.map_pose import estimate_camera_pose, markers_in_view
from visloc.pose.rotations import matrix_to_euler_list
from visloc.sim.sensors import MAP_FROM_NED, BottomCamera
from visloc.types import FloatArray, Pose

__all__ = ["TruthEstimator", "VisionEstimator"]


class TruthEstimator:
    """Hands the controller the true state."""

    name = "truth"

    def __init__(self) -> None:
        self.state = np.zeros(12)

    def observe(self, state: FloatArray) -> None:
        """Take the true state as the estimate.

        Parameters
        ----------
        state : ndarray (12,)
            The vehicle's state in the model's order (:data:`visloc.model.STATE_NAMES`: position
            m and velocity m/s in A (NED), roll, pitch, yaw rad, body rates rad/s); copied.
        """
        self.state = state.copy()


class VisionEstimator:
    """Marker-map vision fused with the IMU (module docstring).

    Parameters
    ----------
    camera : BottomCamera
        The camera whose images :meth:`image` receives (map, intrinsics, frame conventions).
    initial_state : array_like (12,)
        The state the drone starts in (it is sitting still, known, before take-off).
    g : float
        Gravity, m/s^2.
    attitude_gain : float
        Crossover ``c`` (1/s) of the gyro / vision attitude complementary filter.
    accel_std : float
        Standard deviation of the accelerometer input per IMU sample, m/s^2 (the KF's ``Q``).
    min_fix_std : float
        Floor on the standard deviation of a vision position fix, m.
    localizer : callable, optional
        ``localizer(image) -> (T_cam_map, covariance) or None``: another vision front end
        (e.g. OpenCV's ArUco route, for benchmarks); ``covariance`` (3, 3) of the camera
        centre in the map frame, m^2, or None for ``fix_std``. Default: visloc's detector and
        :func:`visloc.pose.estimate_camera_pose` with its propagated covariance.
    fix_std : float
        Standard deviation of a fix without covariance, m.
    redetect_every : int
        visloc's front end (:class:`visloc.markers.MarkerTracker`): above 1 the markers are
        followed from frame to frame, the map's markers in the last fix's view joining at once
        (:func:`visloc.pose.markers_in_view`), with a full marker detection only when following
        fails; 1: the full detection on every frame.

    Attributes
    ----------
    fixes, misses : int
        Images that gave a map pose, and images that did not.
    last_fix_time : float
        Time of the last fix, s.
    """

    name = "vision"

    def __init__(self, camera: BottomCamera, initial_state: FloatArray, *, g: float = 9.81,
                 attitude_gain: float = 5.0, accel_std: float = 0.3,
                 min_fix_std: float = 0.002,
                 localizer: Callable[[NDArray[np.uint8]], tuple[Pose, FloatArray | None] | None]
                 | None = None, fix_std: float = 0.005, redetect_every: int = 10) -> None:
        if not isinstance(camera, BottomCamera):
            raise TypeError(f"camera: expected BottomCamera, got {type(camera).__name__}")
        s = as_array(initial_state, "initial_state", (12,))
        self.camera = camera
        # the floor renders are linear; the pose uses the ids and corners, not the confidence
        self.detector = MarkerDetector(camera.dictionary, response="linear", confidence=False)
        self.tracker = MarkerTracker(self.detector, redetect_every=redetect_every)
        self._last_pose: Pose | None = None
        self.intrinsics = Camera(camera.K)
        self.g = check_real(g, "g", positive=True)
        self.attitude_gain = check_real(attitude_gain, "attitude_gain", positive=True)
        self.accel_std = check_real(accel_std, "accel_std", positive=True)
        self.min_fix_std = check_real(min_fix_std, "min_fix_std", positive=True)
        self.fix_std = check_real(fix_std, "fix_std", positive=True)
        if localizer is not None and not callable(localizer):
            raise TypeError(f"localizer: expected a callable, got {type(localizer).__name__}")
        self.localizer = self._visloc_fix if localizer is None else localizer
        self.fusion = MapFixFusion(initial_position=s[:3], initial_velocity=s[3:6], initial_std=(0.01, 0.05),
                                   keep_history=False, min_fix_std=self.min_fix_std, fix_std=self.fix_std)
        self.kf = self.fusion.kf  # the ultrasound corrects z in it directly
        self.lam = s[6:9].copy()
        self.omega = s[9:12].copy()
        self.fixes = 0
        self.misses = 0
        self.last_fix_time = 0.0
        self._t = 0.0

    @property
    def state(self) -> FloatArray:
        """The estimate (12,) in the model's state order."""
        return np.concatenate([self.kf.position, self.kf.velocity, self.lam, self.omega])

    def imu(self, t: float, gyro: FloatArray, accel: FloatArray) -> None:
        """Propagate to time ``t`` with one IMU sample.

        The attitude integrates the gyro (report eq. 2.3), the body rates become the gyro's, and
        the Kalman filter predicts with the specific force rotated into A plus gravity.

        Parameters
        ----------
        t : float
            Time of the sample, s (not earlier than the previous one).
        gyro : ndarray (3,)
            Body rates, rad/s, body axes.
        accel : ndarray (3,)
            Specific force, m/s^2, body axes (level at rest: ``(0, 0, -g)``).

        Raises
        ------
        TypeError
            ``t`` or a sample not real numbers.
        ValueError
            ``t`` not finite or earlier than the last sample's, ``gyro`` not 3 finite values,
            ``accel`` not 3 values (a NaN in it drops the sample from the filter's prediction,
            :meth:`visloc.estimation.PositionVelocityKF.predict`). Nothing changes then.
        """
        t = check_real(t, "t")
        rates = as_array(gyro, "gyro", (3,))  # a NaN rate would spoil the attitude for good
        f = as_float_array(accel, "accel", (3,))
        if self.kf.t is not None and (t < self._t or t < self.kf.t):
            raise ValueError(f"out-of-order timestamp: t={t!r} is earlier than the last sample's {self._t!r}")
        dt = t - self._t
        self._t = t
        lam = self.lam.tolist()
        if dt > 0.0:  # report eq. (2.3), on floats (several times faster than on small arrays)
            lam = [a + b * dt for a, b in zip(lam, euler_rate_values(lam, rates.tolist()), strict=True)]
            self.lam = np.array(lam)
        self.omega = rates.copy()
        # x = F x + B a with a = R f + g, inertial NED (visloc.estimation.fusion)
        self.fusion.predict(t, f, np.array(rotation_values(*lam)), gravity=(0.0, 0.0, self.g), accel_std=self.accel_std)

    def _visloc_fix(self, image: NDArray[np.uint8]) -> tuple[Pose, FloatArray | None] | None:
        expected = None if self._last_pose is None else markers_in_view(  # the map's markers in the last view
            self.camera.marker_map, self.intrinsics, self._last_pose, size=self.camera.size)
        fix = estimate_camera_pose(self.tracker.detect(image, expected=expected), self.camera.marker_map,
                                   self.intrinsics, start=self._last_pose)  # from the last frame's pose
        self._last_pose = None if fix is None else fix.pose
        return None if fix is None else (fix.pose, fix.position_covariance)

    def ultrasound(self, t: float, reading: float, *, std: float = 0.01) -> bool:
        """Correct the height with one ultrasound reading (report §3.2.1).

        The reading becomes a distance along the beam by report eq. (3.13)
        (:func:`visloc.estimation.ultrasound_height`), a height by the estimated tilt, and an
        update of the filter's ``z`` alone (``H`` picks it from the state). Readings in a blind
        zone, and those more than 3 sigma from the prediction, are skipped.

        Parameters
        ----------
        t : float
            Time of the reading, s (the filter is predicted to it first).
        reading : float
            The sensor's reading, its own units (:func:`visloc.estimation.ultrasound_height`).
        std : float
            Standard deviation of the height it gives, m.

        Returns
        -------
        bool
            Whether the reading was used.
        """
        est = ultrasound_height(reading)
        if not bool(est.valid):
            return False
        self.kf.predict(t)
        phi, theta = self.lam[0], self.lam[1]
        z = -float(est.height) * math.cos(phi) * math.cos(theta)  # NED: down is +
        H = np.zeros((1, self.kf.dim_x))
        H[0, 2 * self.kf.order] = 1.0  # the z position (order_by_dim layout)
        y = z - float(self.kf.x[2 * self.kf.order])
        S = float(self.kf.P[2 * self.kf.order, 2 * self.kf.order]) + std**2
        if y * y > 9.0 * S:
            return False
        self.kf.kf.update(np.array([[z]]), R=np.array([[std**2]]), H=H)
        self.kf.kf.P = 0.5 * (self.kf.kf.P + self.kf.kf.P.T)
        return True

    def image(self, t: float, image: NDArray[np.uint8], dt: float) -> bool:
        """Correct with one bottom-camera image: its map fix corrects the position (Kalman
        update, gated) and pulls the attitude towards the fix's (report eq. 3.4).

        Parameters
        ----------
        t : float
            Time the image was taken, s.
        image : ndarray (H, W) uint8
            The bottom camera's grey frame.
        dt : float
            Seconds since the previous image (sets the attitude filter's pull, ``1 - exp(-c dt)``).

        Returns
        -------
        bool
            Whether the image gave a map pose that the filter accepted.
        """
        fix = self.localizer(image)
        if fix is None:
            self.misses += 1
            return False
        T_cam_map, cov = fix
        position, R = self.camera.body_from_map(T_cam_map)
        gain = 1.0 - math.exp(-self.attitude_gain * dt)
        self.lam = np.array([a + gain * wrap_angle(b - a)  # report eq. (3.4), the error wrapped
                             for a, b in zip(self.lam.tolist(), matrix_to_euler_list(R[None])[0], strict=True)])
        used = self.fusion.fix(position, None if cov is None else MAP_FROM_NED @ cov @ MAP_FROM_NED)
        if used:
            self.fixes += 1
            self.last_fix_time = t
        else:
            self.misses += 1
        return used
