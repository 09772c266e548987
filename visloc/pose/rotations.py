"""Z-Y-X Euler angles (report §2) and rotation distances.

``R = Rz(psi) @ Ry(theta) @ Rx(phi)``; angle triplets are ordered ``[phi, theta, psi]`` as in
the report's parameter vector ``[x, y, z, phi, theta, psi]``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from visloc.types import FloatArray

Angle = float | FloatArray  # a cosine or sine: one value, or one per rotation


def euler_to_matrix(angles: ArrayLike) -> FloatArray:
    """Rotation matrices of Z-Y-X Euler angles.

    Parameters
    ----------
    angles : array_like (..., 3) or (..., 6)
        ``[phi, theta, psi]``, or full parameter vectors ``[x, y, z, phi, theta, psi]``
        (the last three entries are used).

    Returns
    -------
    ndarray (..., 3, 3)
        ``Rz(psi) @ Ry(theta) @ Rx(phi)``.
    """
    a = np.asarray(angles, dtype=np.float64)[..., -3:]
    c = np.cos(a)
    s = np.sin(a)
    if a.shape == (3,):  # one rotation: the products on Python floats (the same values), in a fifth of the time
        return np.array(_zyx_entries(*c.tolist(), *s.tolist())).reshape(3, 3)
    R = np.stack(_zyx_entries(c[..., 0], c[..., 1], c[..., 2], s[..., 0], s[..., 1], s[..., 2]), axis=-1)
    return R.reshape(a.shape[:-1] + (3, 3))


def _zyx_entries(cph: Angle, cth: Angle, cps: Angle, sph: Angle, sth: Angle, sps: Angle) -> list[Angle]:
    """The nine entries of ``Rz(psi) Ry(theta) Rx(phi)``, row by row, from the angles' cosines
    and sines, floats or arrays alike (report §2: R(lambda), multiplied out)."""
    # fmt: off
    return [cps * cth, cps * sth * sph - sps * cph, cps * sth * cph + sps * sph,
            sps * cth, sps * sth * sph + cps * cph, sps * sth * cph - cps * sph,
            -sth, cth * sph, cth * cph]
    # fmt: on


def matrix_to_euler(R: ArrayLike) -> FloatArray:
    """Z-Y-X Euler angles of rotation matrices.

    Parameters
    ----------
    R : array_like (..., 3, 3)
        Rotation matrices, ``R = Rz(psi) @ Ry(theta) @ Rx(phi)`` (not checked).

    Returns
    -------
    ndarray (..., 3)
        ``[phi, theta, psi]``, rad: ``theta`` in [-pi/2, pi/2] and ``phi, psi`` in (-pi, pi],
        the branch of ``Pose.euler_zyx`` (scipy's ``as_euler("ZYX")``); where ``cos(theta)``
        is exactly 0 (gimbal lock) only ``psi - phi`` or ``psi + phi`` is defined, and
        ``phi`` is 0, as scipy chooses.
    """
    R = np.asarray(R, dtype=np.float64)
    if R.shape == (3, 3):  # one matrix: the scalar code (the same values), in a fifth of the time
        return np.array(matrix_to_euler_list(R[None])[0])
    theta = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    phi = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    psi = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    lock = (R[..., 0, 0] == 0.0) & (R[..., 1, 0] == 0.0)  # cos(theta) exactly 0: phi and psi share one angle
    if np.any(lock):  # phi = 0 and psi the whole of it (scipy's choice)
        phi = np.where(lock, 0.0, phi)
        psi = np.where(lock, np.arctan2(-R[..., 0, 1], R[..., 1, 1]), psi)
    return np.stack([phi, theta, psi], axis=-1)


def matrix_to_euler_list(R: FloatArray) -> list[list[float]]:
    """:func:`matrix_to_euler` of a few matrices in scalar code, as lists.

    Parameters
    ----------
    R : array_like (S, 3, 3)
        Rotation matrices (not checked).

    Returns
    -------
    list of S lists of 3 float
        ``[phi, theta, psi]`` of each matrix, rad, on :func:`matrix_to_euler`'s branch.
    """
    out = []
    # numpy's arcsin and arctan2 on each value: the batched version's functions, so its values
    for (r00, r01, _), (r10, r11, _), (r20, r21, r22) in np.asarray(R, dtype=np.float64).tolist():
        theta = float(np.arcsin(min(max(-r20, -1.0), 1.0)))
        if r00 == 0.0 and r10 == 0.0:  # cos(theta) exactly 0: as matrix_to_euler
            out.append([0.0, theta, float(np.arctan2(-r01, r11))])
        else:
            out.append([float(np.arctan2(r21, r22)), theta, float(np.arctan2(r10, r00))])
    return out


def rotation_angle(R: ArrayLike) -> float:
    """Angle of a rotation matrix; accurate near 0 and pi (``atan2`` of the skew and
    symmetric parts rather than ``arccos`` of the trace).

    Parameters
    ----------
    R : array_like (3, 3)
        Rotation matrix.

    Returns
    -------
    float
        Rotation angle, rad, in [0, pi].

    Raises
    ------
    ValueError
        ``R`` is not (3, 3).
    """
    M = np.asarray(R, dtype=np.float64)
    if M.shape != (3, 3):
        raise ValueError(f"R must have shape (3, 3), got {M.shape}")
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = M.tolist()
    s = 0.5 * math.sqrt((m21 - m12) ** 2 + (m02 - m20) ** 2 + (m10 - m01) ** 2)
    c = 0.5 * (m00 + m11 + m22 - 1.0)
    return math.atan2(s, c)
