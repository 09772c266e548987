"""Flights of a downward-looking camera over flat textured ground, with exact motion truth.

For testing and benchmarking optical-flow ground-velocity estimation (a drone's bottom camera,
e.g. the AR.Drone 2.0's 320 x 240 at 60 FPS, flying over grass).

Geometry. World frame: X, Y horizontal, Z up; the ground is the plane ``Z = 0``; ground point
``(X, Y)`` shows texel ``(u, v) = (X, Y) / metres_per_texel`` of a texture mirror-tiled without
end. Camera frame: OpenCV's (x right, y down in the image, z along the optical axis), centre
``C = (X, Y, h)``, height ``h > 0``. With no roll or pitch it looks straight down and its yaw
``psi`` turns x in the ground plane: ``x = (cos psi, sin psi, 0)``, ``y = (sin psi, -cos psi,
0)``, ``z = (0, 0, -1)``. Roll and pitch turn it about its own x and y axes::

    R_world_cam = Rz(psi) @ diag(1, -1, -1) @ Rx(roll) @ Ry(pitch)   # columns: camera axes

so at yaw 0, no tilt, ground point ``(C_x + dx, C_y + dy)`` lands on pixel
``(cx + f dx / h, cy - f dy / h)``.

Rates. ``(roll_rate, pitch_rate, yaw_rate)`` is the camera's angular velocity in its own x, y, z
axes (rad/s, right-handed). A positive ``yaw_rate`` turns camera +x towards camera +y, i.e.
about world -Z (clockwise seen from above): with no tilt ``yaw_rate = -dpsi/dt``, and the image
content turns the other way, by ``-yaw_rate * dt`` (from image x towards image y). ``v_cam`` is
the camera velocity along its own x, y axes (m/s): moving along +x, the camera sees the ground
move towards image -x by ``f * dx / h`` pixels.
"""

from __future__ import annotations

import numbers
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from visloc._checks import check_int
from visloc.synth._checks import check_camera, check_number, check_size
from visloc.synth.datasets import write_camera_yml
from visloc.synth.textures import _photo_texture, degrade, smooth_noise

FloatArray = NDArray[np.float64]

#: Texture names accepted by :func:`render_ground_view` and :func:`render_flight`.
GROUND_TEXTURES = ("grass", "gravel", "brick", "noise")
#: AR.Drone 2.0 bottom camera at 320 x 240 (calib/ardrone2_bottom_320x240.yml).
ARDRONE2_BOTTOM_F = 320.0669
_CSV_COLUMNS = ("frame,t,x,y,height,yaw,roll,pitch,vx,vy,yaw_rate,roll_rate,pitch_rate,"
                "pair_vx,pair_vy,pair_yaw_rate")


@dataclass(frozen=True, eq=False)
class FlightTrack:
    """Camera poses and exact motion ground truth at the frame times (module docstring).

    Attributes
    ----------
    t : ndarray (N,)
        Frame times, s.
    position, velocity : ndarray (N, 3)
        Camera centre ``(X, Y, h)`` (m) and its velocity (m/s), world frame.
    yaw, roll, pitch : ndarray (N,)
        Attitude, rad; ``yaw`` (``psi``) wrapped to ``[-pi, pi)``.
    v_cam : ndarray (N, 2)
        Instantaneous velocity along the camera's own x and y axes, m/s.
    yaw_rate, roll_rate, pitch_rate : ndarray (N,)
        Angular velocity about the camera's z, x and y axes, rad/s.
    pair_v : ndarray (N, 2)
        Row k >= 1: displacement from frame k-1 to k in frame k-1's camera x, y axes, / dt.
    pair_yaw_rate : ndarray (N,)
        Row k >= 1: ``-(psi_k - psi_{k-1}) / dt`` (unwrapped), the mean rate about camera +z
        (exact without roll and pitch). Row 0 of the ``pair_*`` arrays is NaN.
    """

    t: FloatArray
    position: FloatArray
    yaw: FloatArray
    roll: FloatArray
    pitch: FloatArray
    velocity: FloatArray
    v_cam: FloatArray
    yaw_rate: FloatArray
    roll_rate: FloatArray
    pitch_rate: FloatArray
    pair_v: FloatArray
    pair_yaw_rate: FloatArray

    def __len__(self) -> int:
        return len(self.t)

    @property
    def R_world_cam(self) -> FloatArray:
        """(N, 3, 3) camera axes in world coordinates, one rotation per frame."""
        return _rotations(self.yaw, self.roll, self.pitch)

    def pose(self, k: int) -> tuple[FloatArray, FloatArray]:
        """``(R_world_cam, C)`` of frame ``k``, as :func:`render_ground_view` takes it.

        Parameters
        ----------
        k : int
            Frame index; negative counts from the end, as for a sequence.

        Returns
        -------
        R_world_cam : ndarray (3, 3)
            Camera axes in world coordinates (columns), from the frame's yaw, roll and pitch
            (module docstring).
        C : ndarray (3,)
            Camera centre ``(X, Y, h)``, m, world frame (a copy of ``position[k]``).

        Raises
        ------
        IndexError
            If ``k`` is not in ``[-len(self), len(self) - 1]``.
        """
        k = range(len(self.t))[k]
        sl = slice(k, k + 1)
        return _rotations(self.yaw[sl], self.roll[sl], self.pitch[sl])[0], self.position[k].copy()


@dataclass(frozen=True, eq=False)
class Flight:
    """A rendered flight: ``frames`` (N, H, W) uint8, their ground truth ``track``, the
    camera matrix ``K`` (3, 3, no distortion) and the render settings ``params`` (``seconds``,
    ``fps``, ``size``, ``seed``, ``texture``, ``noise_sigma``, ``blur_sigma``,
    ``metres_per_texel`` and the trajectory options)."""

    frames: NDArray[np.uint8]
    track: FlightTrack
    K: FloatArray
    params: dict = field(default_factory=dict)


def _rotations(yaw: FloatArray, roll: FloatArray, pitch: FloatArray) -> FloatArray:
    """``Rz(yaw) @ Rx(pi) @ Rx(roll) @ Ry(pitch)`` per frame, (N, 3, 3)."""
    return Rotation.from_euler("ZXY", np.column_stack([yaw, np.pi + roll, pitch])).as_matrix()


def _frame_times(seconds: object, fps: object, t0: object = 0.0) -> FloatArray:
    seconds = check_number(seconds, "seconds", low=0.0, low_open=True)
    fps = check_number(fps, "fps", low=0.0, low_open=True)
    t0 = check_number(t0, "t0")
    return t0 + np.arange(max(1, round(seconds * fps))) / fps


def _make_track(t: FloatArray, pos: FloatArray, vel: FloatArray, angles: FloatArray,
                rates: FloatArray) -> FlightTrack:
    """Ground truth from the analytic values: angles/rates rows = psi, roll, pitch and d/dt."""
    psi, phi, theta = angles
    dpsi, dphi, dtheta = rates
    R = _rotations(psi, phi, theta)
    cp, sp, ct, st = np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta)
    # body rates from R^T dR/dt for R = Rz(psi) D Rx(phi) Ry(theta), D = diag(1, -1, -1)
    roll_rate = dphi * ct + dpsi * st * cp
    pitch_rate = dtheta - dpsi * sp
    yaw_rate = dphi * st - dpsi * ct * cp
    pair_v = np.full((len(t), 2), np.nan)
    pair_yaw = np.full(len(t), np.nan)
    if len(t) > 1:
        dt = np.diff(t)
        step = np.einsum("nji,nj->ni", R[:-1], np.diff(pos, axis=0))
        pair_v[1:] = step[:, :2] / dt[:, None]
        pair_yaw[1:] = -np.diff(psi) / dt
    wrapped = (psi + np.pi) % (2.0 * np.pi) - np.pi
    return FlightTrack(t=t, position=pos, yaw=wrapped, roll=phi, pitch=theta, velocity=vel,
                       v_cam=np.einsum("nji,nj->ni", R, vel)[:, :2], yaw_rate=yaw_rate,
                       roll_rate=roll_rate, pitch_rate=pitch_rate, pair_v=pair_v,
                       pair_yaw_rate=pair_yaw)


def _sines(rng: np.random.Generator, t: FloatArray, n: int, w_lo: float,
           w_hi: float) -> tuple[FloatArray, FloatArray, float]:
    """``s(t) = sum c_i sin(w_i t + p_i)`` with ``sum |c_i| = 1``: values, derivatives and
    the bound ``sum |c_i w_i|`` of ``|s'|``."""
    c = rng.uniform(0.2, 1.0, n)
    c /= c.sum()
    w, p = rng.uniform(w_lo, w_hi, n), rng.uniform(0.0, 2.0 * np.pi, n)
    arg = np.outer(t, w) + p
    return np.sin(arg) @ c, np.cos(arg) @ (c * w), float(c @ w)


def flight_trajectory(
    rng_or_seed: int | np.random.Generator,
    seconds: float,
    fps: float,
    *,
    max_speed: float = 2.0,
    height: float | tuple[float, float] = (0.5, 2.5),
    max_yaw_rate: float = 1.5,
    roll_pitch: float = 0.0,
    t0: float = 0.0,
) -> FlightTrack:
    """A smooth random flight, evaluated in closed form at ``t_k = t0 + k / fps``.

    Horizontal velocity is a sum of three vectors of fixed length turning at random rates (the
    path is a sum of circles); height, roll and pitch are sums of three sinusoids, yaw a drift
    plus three sinusoids. For all t: 3-D speed <= ``max_speed``, height within ``height``,
    ``|yaw_rate| <= max_yaw_rate``, ``|roll|, |pitch| <= roll_pitch``. The path depends on the
    generator only, not on ``seconds``, ``fps`` or ``t0``.

    Parameters
    ----------
    rng_or_seed : int or numpy.random.Generator
        Source of the random path.
    seconds, fps : float
        Duration and frame rate (> 0): ``max(1, round(seconds * fps))`` frames.
    max_speed, max_yaw_rate : float
        Bounds of the speed (m/s) and of the yaw rate (rad/s), >= 0.
    height : float or (float, float)
        Constant height or ``(low, high)`` range, m (> 0).
    roll_pitch : float
        Amplitude of roll and pitch, rad, in [0, 0.5].
    t0 : float
        Time of the first frame, s.

    Returns
    -------
    FlightTrack
        Poses and exact motion at the frame times (module docstring for the frames).

    Raises
    ------
    TypeError, ValueError
        On a malformed argument; the message names it.
    """
    if not isinstance(rng_or_seed, (np.random.Generator, numbers.Integral)) \
            or isinstance(rng_or_seed, bool):
        raise TypeError(f"rng_or_seed must be an int or a Generator, got {rng_or_seed!r}")
    rng = np.random.default_rng(rng_or_seed)
    t = _frame_times(seconds, fps, t0)
    vmax = check_number(max_speed, "max_speed", low=0.0)
    ymax = check_number(max_yaw_rate, "max_yaw_rate", low=0.0)
    amp = check_number(roll_pitch, "roll_pitch", low=0.0, high=0.5)
    lo, hi = _check_height(height)
    s, ds, bound = _sines(rng, t, 3, 0.1, 0.6)  # height mid + a_h s(t), |dh/dt| <= 0.4 vmax
    a_h = min(0.5 * (hi - lo), 0.4 * vmax / bound)
    v_h = np.sqrt(max(vmax**2 - (a_h * bound) ** 2, 0.0))  # bound of the horizontal speed
    a = rng.uniform(0.2, 1.0, 3)  # velocity sum a_i (cos th_i, sin th_i), sum a_i = v_h
    a *= v_h / a.sum()
    w = rng.uniform(0.15, 0.8, 3) * rng.choice([-1.0, 1.0], 3)
    th = np.outer(t, w) + rng.uniform(0.0, 2.0 * np.pi, 3)
    pos = np.column_stack([rng.uniform(0.0, 10.0, 2) + np.column_stack(
        [np.sin(th) @ (a / w), -np.cos(th) @ (a / w)]), 0.5 * (lo + hi) + a_h * s])
    vel = np.column_stack([np.cos(th) @ a, np.sin(th) @ a, a_h * ds])
    roll, droll, b_roll = _sines(rng, t, 3, 0.5, 3.0)
    pitch, dpitch, _ = _sines(rng, t, 3, 0.5, 3.0)
    # |yaw_rate| <= |droll| |sin pitch| + |dpsi|: keep |dpsi| <= max_yaw_rate - that margin
    y = max(ymax - amp * b_roll * np.sin(amp), 0.0)
    drift = y * rng.uniform(-0.3, 0.3)
    s, ds, bound = _sines(rng, t, 3, 0.1, 1.0)
    k = (y - abs(drift)) / bound
    psi = rng.uniform(-np.pi, np.pi) + drift * t + k * s
    return _make_track(t, pos, vel, np.stack([psi, amp * roll, amp * pitch]),
                       np.stack([drift + k * ds, amp * droll, amp * dpitch]))


def straight_track(
    seconds: float,
    fps: float,
    *,
    velocity: tuple[float, float] = (0.0, 0.0),
    yaw_rate: float = 0.0,
    height: float = 1.0,
    yaw: float = 0.0,
    start: tuple[float, float] = (0.0, 0.0),
) -> FlightTrack:
    """A level flight at constant height, ``v_cam`` and yaw rate, in closed form from t = 0.

    The path is straight when ``yaw_rate = 0``, otherwise a circle flown at constant speed.

    Parameters
    ----------
    seconds, fps : float
        Duration and frame rate (> 0): ``max(1, round(seconds * fps))`` frames.
    velocity : (float, float)
        ``v_cam``, velocity along the camera's own x and y axes, m/s.
    yaw_rate : float
        Rate about camera +z, rad/s: ``psi(t) = yaw - yaw_rate * t``.
    height : float
        Height, m (> 0).
    yaw : float
        ``psi`` at t = 0, rad.
    start : (float, float)
        Ground position ``(X, Y)`` at t = 0, m.

    Returns
    -------
    FlightTrack
        As for :func:`flight_trajectory`.

    Raises
    ------
    TypeError, ValueError
        On a malformed argument; the message names it.
    """
    t = _frame_times(seconds, fps)
    vx, vy = _check_pair(velocity, "velocity")
    x0, y0 = _check_pair(start, "start")
    r = check_number(yaw_rate, "yaw_rate")
    h = check_number(height, "height", low=0.0, low_open=True)
    psi0 = check_number(yaw, "yaw")
    # integral of the world velocity: the chord t sinc(r t / 2), turned to the mid-angle
    chord, mid = t * np.sinc(r * t / (2.0 * np.pi)), psi0 - 0.5 * r * t
    cm, sm, c, s = np.cos(mid), np.sin(mid), np.cos(psi0 - r * t), np.sin(psi0 - r * t)
    pos = np.column_stack([x0 + chord * (vx * cm + vy * sm), y0 + chord * (vx * sm - vy * cm),
                           np.full_like(t, h)])
    vel = np.column_stack([vx * c + vy * s, vx * s - vy * c, np.zeros_like(t)])
    zero = np.zeros_like(t)
    return _make_track(t, pos, vel, np.stack([psi0 - r * t, zero, zero]),
                       np.stack([np.full_like(t, -r), zero, zero]))


def _check_pair(value: object, name: str) -> tuple[float, float]:
    if not isinstance(value, (tuple, list, np.ndarray)) or len(value) != 2:
        raise TypeError(f"{name} must be a pair of numbers, got {value!r}")
    return check_number(value[0], name), check_number(value[1], name)


def _check_height(height: object) -> tuple[float, float]:
    if isinstance(height, numbers.Real):
        lo = hi = check_number(height, "height", low=0.0, low_open=True)
    else:
        lo, hi = _check_pair(height, "height")
        if not 0.0 < lo <= hi:
            raise ValueError(f"height must be (low, high) with 0 < low <= high, got {height!r}")
    return lo, hi


@lru_cache(maxsize=8)
def _named_mipmap(name: str) -> tuple[NDArray[np.float32], ...]:
    tex = smooth_noise((512, 512), np.random.default_rng(0)) if name == "noise" else \
        _photo_texture(name)
    return _mipmap(tex)


def _mipmap(texture: NDArray) -> tuple[NDArray[np.float32], ...]:
    """Levels 1x, 2x, 4x: Gaussian pre-blur, then 2 x 2 box means. Unlike ``cv2.pyrDown``,
    texel j of a level covers texels 2j, 2j+1 of the one above, so each level stays exactly
    mirror-symmetric at the tile edges: the tiling stays seamless."""
    levels = [np.ascontiguousarray(texture, dtype=np.float32)]
    while len(levels) < 3 and all(n % 2 == 0 and n >= 8 for n in levels[-1].shape):
        blurred = cv2.GaussianBlur(levels[-1], (0, 0), 0.7, borderType=cv2.BORDER_REFLECT)
        h, w = blurred.shape
        levels.append(cv2.resize(blurred, (w // 2, h // 2), interpolation=cv2.INTER_AREA))
    return tuple(levels)


def _ground_mipmap(texture: object) -> tuple[tuple[NDArray[np.float32], ...], str]:
    if isinstance(texture, str):
        if texture not in GROUND_TEXTURES:
            raise ValueError(f"texture must be one of {GROUND_TEXTURES} or an array, got "
                             f"{texture!r}")
        return _named_mipmap(texture), texture
    if not isinstance(texture, np.ndarray) or not np.issubdtype(texture.dtype, np.number):
        raise TypeError(f"texture must be a name or a numeric (H, W) array, got "
                        f"{type(texture).__name__}")
    if texture.ndim != 2 or min(texture.shape) < 2 or not np.all(np.isfinite(texture)):
        raise ValueError(f"texture must be a finite (H, W) array, at least 2 x 2, got shape "
                         f"{texture.shape}")
    return _mipmap(texture), "array"


@lru_cache(maxsize=8)
def _rays(k_bytes: bytes, w: int, h: int, s: int) -> NDArray[np.float32]:
    """(3, h*s * w*s) rays ``K^-1 [x, y, 1]`` through the supersample centres, row-major."""
    ys, xs = np.meshgrid((np.arange(h * s) + 0.5) / s - 0.5, (np.arange(w * s) + 0.5) / s - 0.5,
                         indexing="ij")
    pix = np.stack([xs.ravel(), ys.ravel(), np.ones(xs.size)])
    return np.ascontiguousarray(np.linalg.inv(np.frombuffer(k_bytes).reshape(3, 3)) @ pix,
                                dtype=np.float32)


def _check_pose(pose: object) -> tuple[FloatArray, FloatArray]:
    if not isinstance(pose, (tuple, list)) or len(pose) != 2:
        raise TypeError(f"pose_world_from_cam must be a pair (R, C), got {type(pose).__name__}")
    R, C = (np.asarray(v, dtype=np.float64) for v in pose)
    if R.shape != (3, 3) or C.shape != (3,) or not np.isfinite(np.r_[R.ravel(), C]).all():
        raise ValueError(f"pose_world_from_cam must be finite R (3, 3), C (3,), got {R.shape}, "
                         f"{C.shape}")
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ValueError("pose_world_from_cam: R must be a rotation matrix")
    if C[2] <= 0:
        raise ValueError(f"pose_world_from_cam: the camera must be above the ground, C_z = {C[2]}")
    return R, C


def _texture_level(levels: tuple[NDArray[np.float32], ...], K: FloatArray, size: tuple[int, int],
                   R: FloatArray, C: FloatArray, mpt: float, k_inv: FloatArray | None = None
                   ) -> tuple[NDArray[np.float32], float]:
    """The texture level a view samples (a pixel spans at most 1.5 of its texels at the
    principal point) and its scale ``2^level``; ``ValueError`` when part of the view misses
    the ground. ``k_inv``: ``K``'s inverse, if the caller has it."""
    w, h = size
    k_inv = np.linalg.inv(K) if k_inv is None else k_inv
    corners = k_inv @ np.array([[-0.5, w - 0.5, -0.5, w - 0.5], [-0.5, -0.5, h - 0.5, h - 0.5],
                                [1.0, 1.0, 1.0, 1.0]])
    if np.max((R @ corners)[2]) >= -1e-9:  # ray z is linear in the pixel: corners suffice
        raise ValueError("pose_world_from_cam: part of the view misses the ground (horizon)")
    depth = -C[2] / float(R[2] @ k_inv @ np.array([K[0, 2], K[1, 2], 1.0]))
    texels = depth / (np.sqrt(K[0, 0] * K[1, 1]) * mpt)  # texels per pixel at the centre
    level = min(int(np.ceil(np.log2(max(texels / 1.5, 1.0)))), len(levels) - 1)
    return levels[level], 2.0**level


def _render(levels: tuple[NDArray[np.float32], ...], K: FloatArray, size: tuple[int, int],
            R: FloatArray, C: FloatArray, mpt: float, s: int) -> NDArray[np.float32]:
    """The noiseless ground view, float32 (H, W); arguments already checked."""
    w, h = size
    tex, scale = _texture_level(levels, K, size, R, C, mpt)
    d = R.astype(np.float32) @ _rays(np.asarray(K, np.float64).tobytes(), w, h, s)
    lam = np.float32(-C[2] / (mpt * scale)) / d[2]  # ray length to the ground, in texels
    maps = []
    for axis, n in ((0, tex.shape[1]), (1, tex.shape[0])):
        # level coordinate (u0 + 0.5) / 2^L - 0.5; mirror-tile: period 2n, fold about n - 0.5
        u = d[axis] * lam
        u += np.float32((C[axis] / (mpt * scale) + 0.5 / scale - 0.5) % (2 * n))
        u -= np.float32(2 * n) * np.floor(u * np.float32(0.5 / n))
        u -= np.float32(n - 0.5)
        maps.append((np.float32(n - 0.5) - np.abs(u, out=u)).reshape(h * s, w * s))
    img = cv2.remap(tex, maps[0], maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    return img if s == 1 else cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)  # S x S mean


def render_ground_view(
    K: object,
    size: tuple[int, int],
    pose_world_from_cam: tuple[object, object],
    *,
    texture: str | NDArray = "grass",
    metres_per_texel: float = 0.002,
    supersample: int = 2,
    rng: np.random.Generator | None = None,
    noise_sigma: float = 0.0,
    blur_sigma: float = 0.0,
) -> NDArray[np.uint8]:
    """Render the textured ground plane ``Z = 0`` seen by a pinhole camera.

    Each pixel is the mean of ``supersample**2`` bilinear texture samples (``cv2.remap``) at
    ``((c + 0.5) / S - 0.5, (r + 0.5) / S - 0.5)``, where the rays ``R K^-1 [x, y, 1]`` from
    ``C`` hit the ground. When a pixel spans more than 1.5 texels at the principal point, a
    pre-blurred 2x or 4x smaller level of the texture is sampled instead (anti-aliasing).

    Parameters
    ----------
    K : array_like (3, 3)
        Pinhole camera matrix, px (pixel centres at integer coordinates).
    size : (int, int)
        Image ``(width, height)``, px.
    pose_world_from_cam : (ndarray (3, 3), ndarray (3,))
        ``(R_world_cam, C)``: camera axes in world coordinates (columns), and the camera
        centre in the world frame (module docstring), m, with ``C_z > 0``.
    texture : str or ndarray (H, W)
        A name from :data:`GROUND_TEXTURES` or a grey image (uint8 or float, finite, at
        least 2 x 2), mirror-tiled over the ground.
    metres_per_texel : float
        Ground size of a texel, m (> 0).
    supersample : int
        Samples per pixel along each axis (1 to 8).
    rng : numpy.random.Generator or None
        Noise source (None: a fresh unseeded one).
    noise_sigma : float
        Gaussian sensor noise, grey levels (>= 0).
    blur_sigma : float
        Optical blur, px (>= 0); noise and blur are applied by
        :func:`~visloc.synth.textures.degrade`.

    Returns
    -------
    ndarray (height, width) uint8
        The rendered view.

    Raises
    ------
    TypeError
        If an argument has the wrong type; the message names it.
    ValueError
        If part of the view misses the ground (horizon), or an argument is out of range.
    """
    levels, _ = _ground_mipmap(texture)
    K = check_camera(K)
    w, h = check_size(size)
    R, C = _check_pose(pose_world_from_cam)
    mpt = check_number(metres_per_texel, "metres_per_texel", low=0.0, low_open=True)
    s = check_int(supersample, "supersample", low=1, high=8)
    noise = check_number(noise_sigma, "noise_sigma", low=0.0)
    blur = check_number(blur_sigma, "blur_sigma", low=0.0)
    img = _render(levels, K, (w, h), R, C, mpt, s)
    return degrade(img, rng if rng is not None else np.random.default_rng(), blur_sigma=blur,
                   noise_sigma=noise)[0]


def default_bottom_camera(size: tuple[int, int] = (320, 240)) -> FloatArray:
    """AR.Drone 2.0 bottom camera matrix (calib/ardrone2_bottom_320x240.yml) scaled to ``size``.

    Parameters
    ----------
    size : (int, int)
        ``(width, height)`` of the images, px.

    Returns
    -------
    ndarray (3, 3) float64
        ``[[f, 0, cx], [0, f, cy], [0, 0, 1]]`` with ``f = 320.0669 w / 320`` px and the
        principal point ``((w - 1) / 2, (h - 1) / 2)`` (pixel centres at integer coordinates).

    Raises
    ------
    TypeError, ValueError
        If ``size`` is not a pair of ints >= 8.
    """
    w, h = check_size(size)
    f = ARDRONE2_BOTTOM_F * w / 320.0
    return np.array([[f, 0.0, 0.5 * (w - 1)], [0.0, f, 0.5 * (h - 1)], [0.0, 0.0, 1.0]])


def _given_track(track: object, fps: object, options: dict) -> FlightTrack:
    if not isinstance(track, FlightTrack):
        raise TypeError(f"track must be a FlightTrack or None, got {type(track).__name__}")
    if options:
        raise ValueError(f"track cannot be combined with trajectory options {sorted(options)}")
    fps = check_number(fps, "fps", low=0.0, low_open=True)
    if len(track.t) > 1 and not np.allclose(np.diff(track.t), 1.0 / fps, rtol=1e-6):
        raise ValueError(f"track: the frame spacing does not match fps = {fps}")
    return track


def render_flight(
    seconds: float,
    fps: float,
    *,
    size: tuple[int, int] = (320, 240),
    K: object = None,
    seed: int = 1,
    texture: str | NDArray = "grass",
    noise_sigma: float = 1.0,
    blur_sigma: float = 0.0,
    metres_per_texel: float = 0.002,
    track: FlightTrack | None = None,
    progress: Callable[[int], object] | None = None,
    **trajectory_options: object,
) -> Flight:
    """Render a flight of the bottom camera over textured ground.

    Parameters
    ----------
    seconds, fps : float
        Duration and frame rate (> 0); with ``track``, ``fps`` must match its frame spacing.
    size : (int, int)
        ``(width, height)``, px.
    K : array_like (3, 3) or None
        Camera matrix, px; default :func:`default_bottom_camera` for ``size``.
    seed : int
        Seeds the trajectory (``default_rng([seed, 1])``) and the noise (``[seed, 2]``).
    texture : str or ndarray (H, W)
        Ground texture, as in :func:`render_ground_view` (which renders each frame,
        supersample 2).
    noise_sigma : float
        Gaussian sensor noise, grey levels (>= 0).
    blur_sigma : float
        Optical blur, px (>= 0).
    metres_per_texel : float
        Ground size of a texel, m (> 0).
    track : FlightTrack or None
        Fly this track instead of a random :func:`flight_trajectory`.
    progress : callable or None
        Called as ``progress(k)`` after frame ``k``.
    **trajectory_options
        Keyword arguments of :func:`flight_trajectory` (``max_speed``, ``height``, ...).

    Returns
    -------
    Flight
        ``frames`` (N, H, W) uint8, their ``track``, ``K`` and the settings.

    Raises
    ------
    TypeError, ValueError
        On a malformed argument (the message names it), ``track`` combined with trajectory
        options or with a frame spacing other than ``1 / fps``, or a view that misses the
        ground.
    """
    w, h = check_size(size)
    K = default_bottom_camera((w, h)) if K is None else check_camera(K)
    seed = check_int(seed, "seed", low=0)
    levels, tex_name = _ground_mipmap(texture)
    noise = check_number(noise_sigma, "noise_sigma", low=0.0)
    blur = check_number(blur_sigma, "blur_sigma", low=0.0)
    mpt = check_number(metres_per_texel, "metres_per_texel", low=0.0, low_open=True)
    if progress is not None and not callable(progress):
        raise TypeError(f"progress must be a callable or None, got {type(progress).__name__}")
    track = flight_trajectory(np.random.default_rng([seed, 1]), seconds, fps,
                              **trajectory_options) if track is None else \
        _given_track(track, fps, trajectory_options)
    rng = np.random.default_rng([seed, 2])
    frames = np.empty((len(track.t), h, w), np.uint8)
    for k, R in enumerate(track.R_world_cam):
        img = _render(levels, K, (w, h), R, track.position[k], mpt, 2)
        frames[k] = degrade(img, rng, blur_sigma=blur, noise_sigma=noise)[0]
        if progress is not None:
            progress(k)
    params = {"seconds": float(seconds), "fps": float(fps), "size": (w, h), "seed": seed,
              "texture": tex_name, "noise_sigma": noise, "blur_sigma": blur,
              "metres_per_texel": mpt} | dict(trajectory_options)
    return Flight(frames=frames, track=track, K=K, params=params)


def write_flight(outdir: str | Path, flight: Flight, *, video: bool = False) -> Path:
    """Write a flight to a folder.

    Files: ``frame_00000.png``, ... or, with ``video``, ``flight.mp4`` (codec mp4v, lossy);
    ``ground_truth.csv``, a row per frame with the columns ``frame,t,x,y,height,yaw,roll,pitch,
    vx,vy,yaw_rate,roll_rate,pitch_rate,pair_vx,pair_vy,pair_yaw_rate`` (``vx, vy`` =
    ``v_cam``; ``pair_*`` of frame 0 are nan); ``heights.csv`` (``frame,t,height``); and
    ``camera.yml`` (OpenCV FileStorage, zero distortion).

    Parameters
    ----------
    outdir : str or Path
        Output folder, created if missing; files already there are overwritten.
    flight : Flight
        The flight (:func:`render_flight`).
    video : bool
        Write the frames as ``flight.mp4`` at ``flight.params["fps"]`` (default 30) instead
        of PNG files.

    Returns
    -------
    Path
        ``outdir``.

    Raises
    ------
    TypeError
        If ``flight`` is not a Flight.
    OSError
        If the video or a frame cannot be written.
    """
    if not isinstance(flight, Flight):
        raise TypeError(f"flight must be a Flight, got {type(flight).__name__}")
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    n, h, w = flight.frames.shape
    if video:
        writer = cv2.VideoWriter(str(out / "flight.mp4"), cv2.VideoWriter_fourcc(*"mp4v"),
                                 float(flight.params.get("fps", 30.0)), (w, h), isColor=False)
        if not writer.isOpened():
            raise OSError(f"could not open {out / 'flight.mp4'} for writing an mp4v video")
        try:
            for img in flight.frames:
                writer.write(img)
        finally:
            writer.release()
    else:
        for k, img in enumerate(flight.frames):
            if not cv2.imwrite(str(out / f"frame_{k:05d}.png"), img):
                raise OSError(f"could not write {out / f'frame_{k:05d}.png'}")
    tr = flight.track
    rows = np.column_stack([np.arange(n), tr.t, tr.position, tr.yaw, tr.roll, tr.pitch,
                            tr.v_cam, tr.yaw_rate, tr.roll_rate, tr.pitch_rate, tr.pair_v,
                            tr.pair_yaw_rate])
    fmt = ["%d"] + ["%.10g"] * (rows.shape[1] - 1)
    np.savetxt(out / "ground_truth.csv", rows, fmt=fmt, delimiter=",", header=_CSV_COLUMNS,
               comments="")
    np.savetxt(out / "heights.csv", rows[:, [0, 1, 4]], fmt=fmt[:3], delimiter=",",
               header="frame,t,height", comments="")
    write_camera_yml(out / "camera.yml", flight.K, (w, h))
    return out
