"""Shared pytest fixtures and helpers."""

import os
import sys

# Bytecode is written for this run even where the environment says not to (this machine sets
# PYTHONDONTWRITEBYTECODE=1): the suite's processes (two xdist workers, Dask workers, CLI
# subprocesses) would otherwise each compile visloc's modules and assertion-rewrite the test
# modules from source. Measured on fresh clones on the 2-core host, runs interleaved: 75.5 and
# 72.6 s without this line, 72.6 and 70.1 s with it.
sys.dont_write_bytecode = False

# One thread each for OpenBLAS, OpenMP and OpenCV in the xdist workers (and the CLI and Dask
# subprocesses they start): one worker per core already fills the cores, and each library's own
# pool on top of that left threads waiting for each other (set before numpy and cv2 load, unless
# the environment chose). Whole suite on the 2-core host, 6 runs each, alternated: 57.5-74.6 s
# (mean 67.9) against 69.0-74.6 s (mean 72.9) without.
if os.environ.get("PYTEST_XDIST_WORKER"):
    for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "OPENCV_FOR_THREADS_NUM"):
        os.environ.setdefault(_name, "1")

import cv2
import numpy as np
import pytest


def render_square(size=(120, 100), corners=None, supersample=8, dark=30, bright=220, blur=0.0):
    """An anti-aliased dark quadrilateral on a bright background, exact to the pixel-centre
    convention (pixel (c, r) covers [c - 0.5, c + 0.5] x [r - 0.5, r + 0.5])."""
    w, h = size
    s = supersample
    q = np.asarray(corners, np.float64)
    # centres of the supersampled pixels, in image coordinates
    ys, xs = np.meshgrid((np.arange(h * s) + 0.5) / s - 0.5, (np.arange(w * s) + 0.5) / s - 0.5, indexing="ij")
    inside = np.ones(ys.shape, bool)
    e1, e2 = q[1] - q[0], q[2] - q[1]
    sign = np.sign(e1[0] * e2[1] - e1[1] * e2[0])
    for k in range(4):  # convex quad: inside every edge's half-plane
        a, b = q[k], q[(k + 1) % 4]
        inside &= sign * ((b[0] - a[0]) * (ys - a[1]) - (b[1] - a[1]) * (xs - a[0])) >= 0
    big = np.where(inside, float(dark), float(bright))
    img = big.reshape(h, s, w, s).mean(axis=(1, 3))
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def load_bench(name: str):
    """``bench/NAME.py`` as a module (its own imports of ``_timing``, ``_results``, ``_peers``
    found in bench/)."""
    import importlib.util
    from pathlib import Path

    bench = Path(__file__).resolve().parents[1] / "bench"
    sys.path.insert(0, str(bench))
    try:
        spec = importlib.util.spec_from_file_location(f"bench_{name}", bench / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module
    finally:
        sys.path.remove(str(bench))


def pytest_addoption(parser):
    parser.addoption("--runslow", action="store_true",
                     help="also run tests/sweeps: the issues' must-reach accuracy figures, measured by the benches "
                          "(about two minutes on two cores)")


def pytest_ignore_collect(collection_path, config):
    """tests/sweeps is collected only with ``--runslow``."""
    if "sweeps" in collection_path.parts and not config.getoption("--runslow"):
        return True
    return None


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
