"""``MarkerTracker``: markers through a video, full detection only now and then.

Between two frames of a video a marker moves little, so the search of stages 2-7 (blur,
threshold, contours, corner fits) need not run on every frame: each marker of the previous
frame is predicted to move on as it moved between the two frames before (each corner at
constant velocity in the image; a marker first found in the previous frame by the affine
motion of the others' last step), and its predicted quad goes straight to stages 8-10
(:meth:`visloc.markers.MarkerDetector.confirm`). Stage 8 converges onto the marker's edges
from anywhere within its profile half-width (about 0.4 cell), so the corners come out as a
full detection's do; the cell read and dictionary match then vouch for the marker as they
vouch for any candidate. A marker that fails (occluded, or its guess too far off: a marker
that has just come into view) is dropped until a full detection finds it again. A full
detection runs every ``redetect_every`` frames (markers that came into view are found there),
and on any frame on which fewer than ``keep`` of the followed markers whose predicted quads lie
inside the image confirm (a jerk that outran the prediction): that frame's markers are then
exactly :meth:`~visloc.markers.MarkerDetector.detect`'s. A followed marker is known by its id
(and polarity): an id printed twice in view is followed once between full detections.

With a marker map, the markers the last camera pose puts in view can be handed to
:meth:`MarkerTracker.detect` (``expected=``, :func:`visloc.pose.markers_in_view`): those not
followed yet are tried at once, as markers first found in the previous frame, and the periodic
full detection is no longer needed (``visloc localize`` and the simulation's vision do this).
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from visloc._checks import marker_id
from visloc.markers.binarize import to_gray
from visloc.markers.detector import MarkerDetector
from visloc.types import MarkerDetection

__all__ = ["MarkerTracker"]


class MarkerTracker:
    """Follow the markers of a video from frame to frame (module docstring).

    Parameters
    ----------
    detector : MarkerDetector
        The detector of the full detections and of the confirmations (its stage 8 must be on,
        ``refine=True``).
    redetect_every : int
        A full detection at least every this many frames (>= 1; 1: every frame, the
        detector alone).
    keep : float
        Least share of the followed markers inside the image that must confirm, in (0, 1];
        below it the frame runs a full detection (1: any failure does).

    Attributes
    ----------
    frames, full_detections : int
        Frames seen, and those of them that ran a full detection.
    """

    def __init__(self, detector: MarkerDetector, *, redetect_every: int = 10, keep: float = 0.75) -> None:
        if not isinstance(detector, MarkerDetector):
            raise TypeError(f"detector: expected a MarkerDetector, got {type(detector).__name__}")
        if not detector.params.refine:
            raise ValueError("detector: a tracker needs stage 8 (refine=True) to follow markers")
        if isinstance(redetect_every, bool) or not isinstance(redetect_every, numbers.Integral) or redetect_every < 1:
            raise ValueError(f"redetect_every must be an integer >= 1, got {redetect_every!r}")
        if isinstance(keep, bool) or not isinstance(keep, numbers.Real) or not 0.0 < keep <= 1.0:
            raise ValueError(f"keep must be a number in (0, 1], got {keep!r}")
        self.detector = detector
        self.redetect_every = int(redetect_every)
        self.keep = float(keep)
        self.frames = 0
        self.full_detections = 0
        self._since = 0  # frames since the last full detection
        self._last: dict[tuple[int, bool], NDArray] = {}  # (id, inverted) -> corners (4, 2)
        self._before: dict[tuple[int, bool], NDArray] = {}

    def __repr__(self) -> str:
        return f"MarkerTracker({self.detector!r}, redetect_every={self.redetect_every}, keep={self.keep})"

    def reset(self) -> None:
        """Forget the markers followed so far: the next frame runs a full detection."""
        self._last, self._before, self._since = {}, {}, 0

    def detect(self, image: NDArray[np.uint8], *, expected: Mapping[int, ArrayLike] | None = None
               ) -> list[MarkerDetection]:
        """The markers of the next frame of the video.

        Parameters
        ----------
        image : ndarray (H, W) or (H, W, 3) uint8
            The frame, grey or BGR; frames come in the video's order.
        expected : mapping of int to array_like (4, 2), optional
            Markers known to be in view from elsewhere: id -> corners (px, clockwise from the
            marker's own top-left corner) *in the previous frame*, e.g. a marker map's
            markers projected through the previous frame's camera pose
            (:func:`visloc.pose.markers_in_view`). Those not followed yet are tried as if
            found in the previous frame (moved by the affine motion of the followed markers'
            last step), of the polarity the detector looks for (white on black only for
            ``inverted=True``). With ``expected`` given, markers coming into view come from it
            and no periodic full detection runs: one runs only when nothing is followed or
            fewer than ``keep`` of the followed markers confirm (or on every frame with
            ``redetect_every=1``, the detector alone). A failed expected marker costs nothing
            else.

        Returns
        -------
        list of MarkerDetection
            Sorted by id: a full detection's, or the followed and expected markers that
            confirmed.

        Raises
        ------
        TypeError
            ``expected`` not a mapping, or one of its ids a bool or not a number.
        ValueError
            An image that is not uint8 grey or BGR; ``expected`` corners that are not (4, 2)
            finite numbers, or an id with a fraction (2.0 is marker 2; 2.7 no marker).
        """
        gray = to_gray(image)
        new = self._new_expected(expected)
        self.frames += 1
        periodic = self._since >= self.redetect_every - 1 if expected is None else self.redetect_every == 1
        dets = self._follow(gray, new) if self._last and not periodic else None
        if dets is None:
            dets = self.detector.detect(gray)
            self.full_detections += 1
            self._since = 0
        else:
            self._since += 1
        # copies: a caller editing a returned detection's corners must not move the next prediction
        now = {(d.id, d.inverted): d.corners.copy() for d in dets}
        self._before, self._last = self._last, now
        return dets

    def _new_expected(self, expected: Mapping[int, ArrayLike] | None) -> dict[tuple[int, bool], NDArray]:
        """The expected markers not followed yet, keyed as the followed ones (all the corners
        checked at once)."""
        if expected is None:
            return {}
        if not isinstance(expected, Mapping):
            raise TypeError(f"expected must be a mapping of id to corners, got {type(expected).__name__}")
        if not expected:
            return {}
        try:
            q = np.asarray(list(expected.values()), dtype=np.float64)
        except (TypeError, ValueError):  # ragged or not numbers
            q = np.zeros(0)
        if q.shape[1:] != (4, 2) or not np.isfinite(q).all():
            raise ValueError("expected: each marker's corners must be (4, 2) finite numbers")
        polarity = self.detector.params.inverted is True
        ids = [marker_id(i, "expected") for i in expected]
        return {(i, polarity): q[k] for k, i in enumerate(ids) if (i, polarity) not in self._last}

    def _follow(self, gray: NDArray[np.uint8], new: dict[tuple[int, bool], NDArray]) -> list[MarkerDetection] | None:
        """The followed markers (and the ``new`` expected ones) confirmed in ``gray``; None if
        fewer than ``keep`` of the followed markers inside the image confirmed, or none of all."""
        h, w = gray.shape[:2]
        margin = self.detector.params.candidates.border_distance + 1.0
        last = {**new, **self._last}
        dets: list[MarkerDetection] = []
        tried = confirmed = 0
        for inverted in (False, True):
            keys = [k for k in last if k[1] is inverted]
            if not keys:
                continue
            quads = self._predicted(keys, last)
            inside = ((quads >= margin) & (quads <= np.array([w - 1, h - 1]) - margin)).all(axis=(1, 2))
            if not inside.any():
                continue
            got = self.detector.confirm(gray, quads[inside], np.array([k[0] for k in keys])[inside],
                                        inverted=inverted)
            for key, d in zip([k for k, i in zip(keys, inside.tolist(), strict=True) if i], got, strict=True):
                followed = key in self._last
                tried += followed
                confirmed += followed and d is not None
                if d is not None:
                    dets.append(d)
        if not dets or confirmed < self.keep * tried:
            return None
        return sorted(dets, key=lambda d: (d.id, d.corners[0, 1], d.corners[0, 0]))

    def _predicted(self, keys: list[tuple[int, bool]], last: dict[tuple[int, bool], NDArray]) -> NDArray:
        """Where the markers ``keys`` (corners in the last frame: ``last``) should be now (K, 4,
        2): on at the velocity of their last step; a marker found only in the last frame moves
        by the affine motion that took the others' corners through their last step (least
        squares; fewer than two others: it stays)."""
        now = np.array([last[k] for k in keys])
        seen_list = [k in self._before for k in keys]
        if not any(seen_list):
            return now
        before = np.array([self._before[k] for k, s in zip(keys, seen_list, strict=True) if s])
        if all(seen_list):  # (the usual frame: every marker was seen twice)
            return 2.0 * now - before
        seen = np.array(seen_list)
        pred = now.copy()
        pred[seen] = 2.0 * now[seen] - before
        if not seen.all() and seen.sum() >= 2:
            a = before.reshape(-1, 2)
            affine = np.linalg.lstsq(np.hstack([a, np.ones((len(a), 1))]), now[seen].reshape(-1, 2), rcond=None)[0]
            new = now[~seen].reshape(-1, 2)
            pred[~seen] = (np.hstack([new, np.ones((len(new), 1))]) @ affine).reshape(-1, 4, 2)
        return pred
