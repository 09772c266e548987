"""Metric ground velocity of a downward camera from the image motion (report §3.2.2, eq. H.7).

Conventions
-----------
``v`` is the camera's velocity relative to the ground in m/s, a (2,) array in the camera axes
of the *first* frame of the pair: x right and y down as in the image. A camera moving toward
+x makes the image content move toward -x. ``yaw_rate`` is the camera's rotation rate in
rad/s about its +z axis (the optical axis, pointing at the ground), right-handed: positive
turns camera +x toward camera +y; the content then turns the other way.

Pinhole model over flat ground at distance ``height`` along the optical axis: a ground
displacement ``D`` (m) moves the content at the principal point by ``-f D / height`` px
(report eq. H.7), ``height`` being the distance when the *second* frame of the pair was taken
(the content's motion is seen at that depth: a camera at ``h1`` that rises to ``h2`` while it
moves by ``D`` shifts the centre by ``-f D / h2``). Streaming, that is the height read with the
newest frame; the height at the first frame reads a climb of 1 % per frame as a velocity 1 %
too low. Roll and pitch rotations also move the content (by ``f`` times the angle,
whatever the height); with gyro rates they are subtracted first, as PX4 subtracts body rates
from flow rates.
"""

from __future__ import annotations

import math
from dataclasses import KW_ONLY, dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from visloc.flow.block import block_flow, check_pair
from visloc.flow.direct import blurred, direct_options, refine_blurred
from visloc.flow.motion import global_motion
from visloc.pose.camera import Camera
from visloc.types import FlowField, GlobalMotion, GroundVelocity

__all__ = ["EgoMotion", "estimate_ground_velocity", "ground_velocity"]


def _positive(value: float, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a number, got {type(value).__name__}") from None
    if not (0.0 < v < float("inf")):
        raise ValueError(f"{name} must be positive and finite, got {value!r}")
    return v


def ground_velocity(
    motion: GlobalMotion,
    camera: Camera,
    height: float,
    dt: float,
    *,
    gyro: NDArray | None = None,
    field: FlowField | None = None,
) -> GroundVelocity:
    """Camera velocity over flat ground from the image motion between two frames.

    Parameters
    ----------
    motion : GlobalMotion
        Content motion from the first frame to the second.
    camera : Camera
        Intrinsics of the frames (distortion is ignored near the principal point).
    height : float
        Distance from the camera to the ground along the optical axis when the second frame
        was taken, m (> 0; module docstring).
    dt : float
        Time between the frames, s (> 0).
    gyro : array_like (3,), optional
        Body rates (wx, wy, wz) in rad/s about the camera axes during the interval; wx and wy
        are removed from the flow (wz is measured by the flow itself).
    field : FlowField, optional
        The flow the motion came from, for the quality figure.

    Returns
    -------
    GroundVelocity
        ``quality`` 0 (and zero velocity) with a reason when the motion had no support.
    """
    if not isinstance(motion, GlobalMotion):
        raise TypeError(f"motion must be a GlobalMotion, got {type(motion).__name__}")
    if not isinstance(camera, Camera):
        raise TypeError(f"camera must be a Camera, got {type(camera).__name__}")
    h = _positive(height, "height")
    dt = _positive(dt, "dt")
    tx, ty = (float(v) for v in motion.translation)
    if motion.inliers < 3 or not (math.isfinite(tx) and math.isfinite(ty)):
        return GroundVelocity(np.zeros(2), 0.0, 0.0, "too few textured blocks to measure motion", motion)
    w, hgt = camera.size if camera.size is not None else (None, None)
    if field is not None:
        w, hgt = field.image_size
    if w is None:
        raise ValueError("camera.size is unknown: pass the FlowField (field=...) or a camera with a size")
    # content displacement at the principal point, px
    dx, dy = motion.displacement_at((camera.cx, camera.cy), ((w - 1) / 2.0, (hgt - 1) / 2.0)).tolist()
    if gyro is not None:
        g = np.asarray(gyro, np.float64).reshape(-1)
        if g.shape != (3,) or not np.isfinite(g).all():
            raise ValueError(f"gyro must be three finite rates (wx, wy, wz) in rad/s, got {gyro!r}")
        # a rotation by (ax, ay) about camera x, y moves the content at the principal point by
        # (-f ay, +f ax); remove it (PX4: compensated flow = flow rate - body rate)
        dx += camera.fx * float(g[1]) * dt
        dy -= camera.fy * float(g[0]) * dt
    yaw = -motion.rotation  # the camera turns opposite to its image content
    # ground displacement in the second frame's axes, then turned back into the first frame's
    X2, Y2 = -dx / camera.fx * h, -dy / camera.fy * h  # report eq. (H.7)
    c, s = math.cos(yaw), math.sin(yaw)
    quality, reason = _quality(motion, field)
    return GroundVelocity(np.array([(c * X2 - s * Y2) / dt, (s * X2 + c * Y2) / dt]), yaw / dt, quality, reason, motion)


def _quality(motion: GlobalMotion, field: FlowField | None) -> tuple[float, str]:
    """In [0, 1]: the share of confident blocks used, reduced by a large fit residual."""
    n = 0 if field is None else len(field.confidence)
    if n == 0:
        support = 1.0
    else:
        support = min(1.0, motion.inliers / max(0.5 * n, 1.0))
        support *= min(max(float(field.confidence.sum()) / n / 0.5, 0.0), 1.0)  # type: ignore[union-attr]
    rms = motion.residual_rms
    fit = 1.0 / (1.0 + (rms / 0.5) ** 2) if math.isfinite(rms) else 0.0
    q = min(max(support * fit, 0.0), 1.0)
    reason = "" if q >= 0.3 else ("little texture or few confident blocks" if support < 0.5 else "flow disagrees with a rigid motion")
    return q, reason


def estimate_ground_velocity(
    prev: NDArray[np.uint8],
    curr: NDArray[np.uint8],
    camera: Camera,
    height: float,
    dt: float,
    *,
    gyro: NDArray | None = None,
    method: str = "similarity",
    direct: bool = False,
    **flow_options: object,
) -> GroundVelocity:
    """Camera ground velocity from two consecutive downward frames: :func:`block_flow`, then
    :func:`global_motion`, then (``direct=True``) the sub-pixel stage
    :func:`visloc.flow.direct.refine_motion`, then :func:`ground_velocity` (conventions in the
    module docstring).

    Parameters
    ----------
    prev, curr : ndarray (H, W) or (H, W, 3) uint8
        Consecutive frames of a downward camera.
    camera : Camera
        Its intrinsics.
    height : float
        Height above the ground when ``curr`` was taken, m (> 0; module docstring).
    dt : float
        Time between the frames, s (> 0).
    gyro : array_like (3,), optional
        Body rates (wx, wy, wz), rad/s, about the camera axes (:func:`ground_velocity`).
    method : {"similarity", "cir"}
        Global-motion solver (:func:`global_motion`).
    direct : bool
        Add the sub-pixel stage.
    **flow_options
        Passed to :func:`block_flow`.

    Returns
    -------
    GroundVelocity
        Velocity in the first frame's camera axes, m/s; a texture-less pair gives ``quality``
        0 with a reason, never NaN.

    Raises
    ------
    ValueError
        A bad frame pair, height or ``dt``.
    """
    _positive(height, "height")
    _positive(dt, "dt")
    a, b = check_pair(prev, curr)
    fld = block_flow(a, b, **flow_options)  # type: ignore[arg-type]
    return _velocity(a, b, fld, method, direct, camera, height, dt, gyro)[0]


#: the quality of a pair whose direct alignment (``direct=True``) failed or moved too far is
#: scaled by this, with :data:`UNREFINED` as the reason: the block-sum motion stands, unrefined
UNREFINED_QUALITY = 0.5
UNREFINED = "the direct alignment did not converge near the block-sum motion"


def _velocity(a: NDArray[np.uint8], b: NDArray[np.uint8], fld: FlowField, method: str, direct: bool,
              camera: Camera, height: float, dt: float, gyro: NDArray | None, prior: GlobalMotion | None = None,
              frames: tuple[NDArray[np.float32], NDArray[np.float32]] | None = None) -> tuple[GroundVelocity, float]:
    """The ground velocity of a frame pair's flow field: its global motion, refined by the
    direct alignment (from it and from ``prior``; on ``frames``, the pair blurred, when given)
    when ``direct`` (and the field gave a motion); a refinement that failed lowers the
    quality (:data:`UNREFINED_QUALITY`) and says why. Also the alignment's residual spread
    (inf without one)."""
    motion = global_motion(fld, method=method)
    refine = direct and motion.inliers >= 3
    spread = math.inf
    if refine:
        if frames is None:
            frames = (blurred(a), blurred(b))
        refined, spread = refine_blurred(frames, motion, prior, direct_options(a.shape))
        failed = refined is None
        motion = motion if failed else refined
    gv = ground_velocity(motion, camera, height, dt, gyro=gyro, field=fld)
    if refine and failed and gv.quality > 0:
        gv = replace(gv, quality=UNREFINED_QUALITY * gv.quality, reason=gv.reason or UNREFINED)
    return gv, spread


#: The least quality of a pair whose motion :class:`EgoMotion` passes on as the next pair's prior
PRIOR_QUALITY = 0.3
#: Tracking (:class:`EgoMotion`, ``direct``): every this many pairs the block sums run again
TRACK_FRAMES = 30
#: Tracking: a pair whose alignment residuals exceed this many times the last block-sum pair's
#: goes through the block sums instead
TRACK_SPREAD = 2.0


def _prior(last: tuple[GlobalMotion, float] | None, dt: float) -> GlobalMotion | None:
    """The previous pair's image motion carried over ``dt`` (constant rates): the second
    start of the direct alignment (:func:`refine_motion`'s ``prior``)."""
    if last is None:
        return None
    motion, last_dt = last
    k = dt / last_dt
    return replace(motion, translation=motion.translation * k, rotation=motion.rotation * k,
                   scale=motion.scale**k, center_of_rotation=None)


def _pair_timing(dt: float | None, height: float | None, fps: float | None,
                 default_height: float | None) -> tuple[float, float]:
    """:meth:`EgoMotion.update`'s ``dt`` (s) and height (m) of a pair, the stream's defaults
    filled in (``1 / fps``, ``default_height``) and checked (its Raises)."""
    if dt is None:
        if fps is None:
            raise ValueError("dt is required when EgoMotion has no fps")
        dt = 1.0 / fps
    h = height if height is not None else default_height
    if h is None:
        raise ValueError("height is required when EgoMotion has no default height")
    _positive(h, "height")
    _positive(dt, "dt")
    return dt, h


def _split_options(options: dict) -> tuple[dict, str, bool, bool, bool]:
    """:class:`EgoMotion`'s ``options`` split into those for :func:`block_flow` (a copy) and
    its own: ``method``, ``direct``, ``track`` and ``shadows``, defaults filled in."""
    opts = dict(options)
    method = opts.pop("method", "similarity")
    direct = bool(opts.pop("direct", False))
    track = bool(opts.pop("track", True))
    local = bool(opts.pop("shadows", False))
    return opts, method, direct, track, local


@dataclass
class EgoMotion:
    """Streaming ground velocity and dead-reckoned track (report Figure 3.8, drift included).

    Call :meth:`update` with every new frame; the first frame only primes the stream. The
    track is in the first frame's camera axes (x right, y down in that image), in metres,
    with the accumulated yaw; ``last_field`` is the last block flow. Each pair of quality at
    least :data:`PRIOR_QUALITY` passes its image motion on as the next pair's prior (carried
    over the next ``dt``): the whole-image block match searches near it (``block_flow``'s
    ``prior``) and the direct alignment starts from it too (``refine_motion``'s ``prior``),
    so that over periodic textures the stream does not lock onto a neighbouring period.

    Parameters
    ----------
    camera : Camera
        Intrinsics of the frames; its ``size`` may be unknown (the frames' own size is used).
    height : float, optional
        Default height (m) when :meth:`update` gets none.
    fps : float, optional
        Default frame rate when :meth:`update` gets no ``dt`` or times.
    options : dict
        Passed to :func:`block_flow` (``method`` to :func:`global_motion`; ``direct=True`` adds
        the sub-pixel stage :func:`visloc.flow.direct.refine_motion`; ``track=False`` turns
        tracking off; ``shadows=True`` has the sub-pixel stage read each frame divided by its
        local mean, :func:`visloc.flow.direct.blurred`: moving shadows and uneven light).

    With ``direct=True`` the stream tracks: a pair after a good one is aligned from the prior
    alone, without the block sums (its motion's ``method`` ends in ``"+tracked"`` and
    ``last_field`` is None), as long as its residuals stay within :data:`TRACK_SPREAD` times
    those of the last pair that went through the block sums (the anchor), and at least every
    :data:`TRACK_FRAMES` pairs the block sums run again. Tracking costs a third of the full
    path per pair at 320 x 240.
    """

    camera: Camera
    _: KW_ONLY
    height: float | None = None
    fps: float | None = None
    options: dict = field(default_factory=dict)
    track: list[tuple[float, float, float, float]] = field(default_factory=list, init=False)
    last_field: FlowField | None = field(default=None, init=False)
    _prev: NDArray[np.uint8] | None = field(default=None, init=False, repr=False)
    _time: float = field(default=0.0, init=False, repr=False)
    _pos: NDArray = field(default_factory=lambda: np.zeros(2), init=False, repr=False)
    _yaw: float = field(default=0.0, init=False, repr=False)
    _last: tuple[GlobalMotion, float] | None = field(default=None, init=False, repr=False)  # motion, dt
    _blurred: NDArray[np.float32] | None = field(default=None, init=False, repr=False)  # the last frame's
    _anchor: tuple[float, float, int] | None = field(default=None, init=False, repr=False)  # spread, quality, age
    _sized: Camera | None = field(default=None, init=False, repr=False)  # the camera at the frames' size

    def __post_init__(self) -> None:
        for name in ("height", "fps"):
            v = getattr(self, name)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float, np.number))
                                  or not np.isfinite(v) or v <= 0):
                raise ValueError(f"EgoMotion: {name} must be a finite number > 0 or None, got {v!r}")

    def update(
        self,
        image: NDArray[np.uint8],
        *,
        dt: float | None = None,
        height: float | None = None,
        gyro: NDArray | None = None,
    ) -> GroundVelocity | None:
        """Add a frame; returns the velocity since the previous frame (None for the first).

        ``height`` is the height when ``image`` was taken (module docstring). The first frame
        only primes the stream: ``dt``, ``height`` and ``gyro`` are not used (nor checked) then.

        Parameters
        ----------
        image : ndarray (H, W) or (H, W, 3) uint8
            The new frame, the same size as the previous one (BGR turned grey; any image
            :func:`visloc.images.as_gray` takes).
        dt : float, optional
            Time since the previous frame, s (> 0); default ``1 / fps``.
        height : float, optional
            Distance from the camera to the ground along the optical axis when ``image`` was
            taken, m (> 0); default the stream's ``height``.
        gyro : array_like (3,), optional
            Body rates (wx, wy, wz), rad/s, about the camera axes since the previous frame; wx
            and wy are removed from the flow (:func:`ground_velocity`).

        Returns
        -------
        GroundVelocity or None
            Velocity (m/s) in the previous frame's camera axes and yaw rate (rad/s) over the
            pair, with its quality (0 and zero velocity when the motion had no support); None
            for the first frame. Its displacement ``v dt`` (turned into the first frame's axes)
            and yaw ``yaw_rate dt`` are integrated into :attr:`track`.

        Raises
        ------
        TypeError
            ``image`` is not a numpy array or has an unsupported pixel type
            (:func:`visloc.images.as_gray`), or ``dt`` or the height is not a number.
        ValueError
            ``image`` of an unsupported shape or with non-finite pixels; a frame of another size
            than the previous one or smaller than 16 x 16 px; ``dt`` missing when no ``fps`` was
            set, or a height missing when no default was set; ``dt`` or the height not finite
            and > 0; ``gyro`` not three finite rates (checked when the pair's motion has
            support); an unknown ``method`` in ``options``.
        """
        from visloc.images import as_gray

        img = as_gray(image, name="image")
        if min(img.shape) < 16:  # as block_flow would refuse it, before it becomes the stream's first frame
            raise ValueError(f"image must be at least 16 x 16 pixels, got {img.shape[::-1]} (W, H)")
        if self._prev is None:
            self._prev = img
            self.track.append((0.0, 0.0, 0.0, 0.0))
            return None
        dt, h = _pair_timing(dt, height, self.fps, self.height)
        a, b = check_pair(self._prev, img)
        opts, method, direct, track, local = _split_options(self.options)
        prior = _prior(self._last, dt)
        frames = None
        if direct:  # each frame is blurred once: as the second of one pair, the first of the next
            if self._blurred is None or self._blurred.shape != a.shape:
                self._blurred = blurred(a, local=local)
            frames = (self._blurred, blurred(b, local=local))
        gv, lost = self._tracked(frames, prior, method, h, dt, gyro) if direct and track else (None, False)
        if gv is None:
            if prior is not None and not lost:  # the previous pair's motion steers the whole-image match
                opts.setdefault("prior", tuple(prior.translation))
            self.last_field = block_flow(a, b, **opts)
            gv, spread = _velocity(a, b, self.last_field, method, direct, self.camera, h, dt, gyro, prior, frames)
            good = math.isfinite(spread) and gv.quality >= PRIOR_QUALITY
            self._anchor = (spread, gv.quality, 0) if good else None
        else:
            self.last_field = None
        self._advance(gv, dt, frames, img)
        return gv

    def _advance(self, gv: GroundVelocity, dt: float, frames: tuple[NDArray[np.float32], NDArray[np.float32]] | None,
                 img: NDArray[np.uint8]) -> None:
        """Move the stream past a measured pair: keep its motion as the next prior (if good
        enough) and its blurred second frame, integrate ``gv`` over ``dt`` (s) into the pose
        and :attr:`track`, and make ``img`` the previous frame."""
        # a pair of low quality passes no prior on: the next match searches the whole range again
        self._last = (gv.motion, dt) if gv.motion is not None and gv.quality >= PRIOR_QUALITY else None
        if frames is not None:
            self._blurred = frames[1]
        # integrate: the displacement is in the previous frame's axes
        c, s = np.cos(self._yaw), np.sin(self._yaw)
        step = gv.v * dt
        self._pos = self._pos + np.array([c * step[0] - s * step[1], s * step[0] + c * step[1]])
        self._yaw += gv.yaw_rate * dt
        self._time += dt
        self.track.append((self._time, float(self._pos[0]), float(self._pos[1]), self._yaw))
        self._prev = img

    def _tracked(self, frames: tuple[NDArray[np.float32], NDArray[np.float32]] | None, prior: GlobalMotion | None,
                 method: str, height: float, dt: float, gyro: NDArray | None) -> tuple[GroundVelocity | None, bool]:
        """Tracking (``direct``, ``track``): the pair's velocity from the direct alignment
        started at the prior alone, without the block sums, and whether the track was lost.
        None when the last block-sum pair (the anchor) is :data:`TRACK_FRAMES` pairs old or
        more or there is no prior (not lost), or the alignment failed, moved an image corner
        more than 3 px from the prior or left residuals more than :data:`TRACK_SPREAD` times
        the anchor's (lost: the block sums then search the whole range, not near the prior).
        Its quality is the anchor's, times the anchor's spread over the pair's (at most 1)."""
        if frames is None or prior is None or self._anchor is None or self._anchor[2] >= TRACK_FRAMES - 1:
            return None, False
        anchor, quality, age = self._anchor
        found, spread = refine_blurred(frames, prior, None, direct_options(frames[0].shape))
        if found is None or not spread <= TRACK_SPREAD * anchor:
            return None, True
        self._anchor = (anchor, quality, age + 1)
        motion = replace(found, method=method + "+tracked")
        gv = ground_velocity(motion, self._camera_at(frames[0].shape), height, dt, gyro=gyro)
        return replace(gv, quality=quality * min(1.0, anchor / spread), reason=""), False

    def _camera_at(self, shape: tuple[int, ...]) -> Camera:
        """The camera with the frames' own size ``(H, W)`` (no FlowField on the tracked path:
        the size the block-sum path takes from it), made once per size."""
        size = (shape[1], shape[0])
        if self.camera.size == size:
            return self.camera
        if self._sized is None or self._sized.size != size:
            self._sized = replace(self.camera, size=size)
        return self._sized

    @property
    def frame_shape(self) -> tuple[int, ...] | None:
        """(H, W) of the frames in the stream, None before the first."""
        return None if self._prev is None else self._prev.shape

    @property
    def position(self) -> NDArray[np.float64]:
        """Integrated (x, y) position, m, in the first frame's camera axes."""
        return self._pos.copy()

    @property
    def yaw(self) -> float:
        """Integrated yaw, rad."""
        return self._yaw
