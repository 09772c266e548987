"""Fixtures for the pose tests: marker poses with known truth."""

from __future__ import annotations

import types

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

# a marker seen face-on: marker x right, y up in the image, its face towards the camera
FACE_ON = np.diag([1.0, -1.0, -1.0])


def marker_pose(
    tilt: float, tilt_dir: float, yaw: float, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """R (marker into camera) tilted by ``tilt`` (rad) about an in-image-plane axis at angle
    ``tilt_dir``, turned by ``yaw`` about the marker's normal; ``t`` as given."""
    axis = np.array([np.cos(tilt_dir), np.sin(tilt_dir), 0.0])
    R = Rotation.from_rotvec(axis * tilt).as_matrix() @ FACE_ON
    R = R @ Rotation.from_euler("z", yaw).as_matrix()
    return R, np.asarray(t, dtype=float)


def random_marker_pose(
    rng: np.random.Generator, *, max_tilt_deg: float = 60.0, dist: tuple[float, float] = (0.3, 3.0)
) -> tuple[np.ndarray, np.ndarray]:
    """Marker in front of the camera: distance in ``dist`` m, centre within about 17 deg of
    the optical axis, tilt below ``max_tilt_deg``, any yaw."""
    ray = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.25, 0.25), 1.0])
    t = rng.uniform(*dist) * ray / np.linalg.norm(ray)
    return marker_pose(
        rng.uniform(0.0, np.radians(max_tilt_deg)),
        rng.uniform(0.0, 2 * np.pi),
        rng.uniform(0.0, 2 * np.pi),
        t,
    )


@pytest.fixture(scope="session")
def poses() -> types.SimpleNamespace:
    """``poses.marker_pose(...)`` and ``poses.random_marker_pose(...)`` (pytest runs with
    ``--import-mode=importlib``, so test modules cannot import a helper module)."""
    return types.SimpleNamespace(marker_pose=marker_pose, random_marker_pose=random_marker_pose)
