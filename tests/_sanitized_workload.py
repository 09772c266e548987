"""visloc's compiled stages, built with AddressSanitizer and UBSan into the folder given as the
first argument, on hostile but valid inputs (run by tests/test_compiled.py in a child process
with the sanitizers' runtime preloaded; a memory error or undefined behaviour aborts it)."""
import importlib.util
import sys

import numpy as np

d = sys.argv[1]


def load(name):
    spec = importlib.util.spec_from_file_location(name, f"{d}/{name}.so")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


import visloc.flow.direct as D
import visloc.markers.binarize as T
import visloc.markers.bits as B
import visloc.markers.contours as C
import visloc.markers.corners_batch as Q
import visloc.markers.refine as R
import visloc.pose.gauss_newton as G

C._borders, C._filter, Q._quads, R._refine = load("_borders"), load("_filter"), load("_quads"), load("_refine")
B._cells, G._lm, D._direct, T._threshold = load("_cells"), load("_lm"), load("_direct"), load("_threshold")
import visloc.control.controller as K
import visloc.model.rigid_body as RB

RB._rigid, K._feedback = load("_rigid"), load("_feedback")

from visloc.flow import block_flow, global_motion
from visloc.markers import MarkerDetector
from visloc.markers.refine import refine_quads
from visloc.pose import Camera, estimate_marker_pose
from visloc.synth import default_camera, random_scene
from visloc.types import GlobalMotion

rng = np.random.default_rng(0)
images = [rng.integers(0, 256, (h, w), dtype=np.uint8) for h, w in ((17, 23), (48, 64), (241, 321))]
images += [np.zeros((60, 80), np.uint8), np.full((60, 80), 255, np.uint8),
           (np.indices((120, 160)).sum(axis=0) % 2 * 255).astype(np.uint8),  # one-pixel checkerboard
           np.kron((np.indices((12, 16)).sum(axis=0) % 2), np.ones((10, 10))).astype(np.uint8) * 255]
for k in range(2):
    images.append(random_scene(np.random.default_rng(k), size=(320, 240), difficulty=("easy", "dark")[k]).image)
for det in (MarkerDetector("DICT_4X4_50", native=True), MarkerDetector("DICT_APRILTAG_36h11", inverted="both"),
            MarkerDetector("DICT_4X4_50", border_bits=2, erode=2)):
    for img in images:
        det.detect(img)
gray = images[-1]
h, w = gray.shape
for _ in range(30):  # quads anywhere: inside, across the border, tiny, thin
    c = rng.uniform(-20, max(h, w) + 20, 2)
    s = rng.uniform(0.5, 150)
    a = rng.uniform(0, 2 * np.pi)
    sq = c + s * np.array([[np.cos(a + t), np.sin(a + t)] for t in np.arange(4) * np.pi / 2]) * rng.uniform(0.2, 1.0, (4, 1))
    refine_quads(gray, sq[None], radius=int(rng.integers(1, 12)), response="srgb", bend=bool(rng.integers(2)))
cam = Camera(default_camera((320, 240)))
for _ in range(20):
    c = rng.uniform(20, 300, 2)
    s = rng.uniform(2, 200)
    sq = c + s * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * rng.uniform(0.05, 1.0, (4, 1))
    try:
        estimate_marker_pose(sq, 0.1, cam, start=("auto", "all", "yaw")[_ % 3])
    except ValueError:
        pass
a = images[-4]
for motion in (GlobalMotion(np.array([1e4, -1e4]), 0.0, 1.0, None, 0.0, 10, "similarity"),
               GlobalMotion(np.zeros(2), 3.0, 50.0, None, 0.0, 10, "similarity"),
               GlobalMotion(np.array([0.3, -0.2]), 0.01, 1.0, None, 0.0, 10, "similarity")):
    for stride in (2, 7):
        D.refine_motion(a, np.roll(a, 3, axis=1), motion, stride=stride, prior=motion)
f = block_flow(a, np.roll(a, 2, axis=0))
global_motion(f)
inertia = [0.0022, 0.0029, 0.0048]
for _ in range(50):  # the rigid body and the controller on wild, non-finite and wrongly sized values
    s = (rng.normal(0, 1e3, 12) * rng.choice([1.0, np.inf, np.nan], 12, p=[0.8, 0.1, 0.1])).tolist()
    RB.rk4_values(s, rng.normal(0, 10, 4).tolist(), 0.01, 0.42, 9.81, inertia, gyroscopic=bool(_ % 2),
                  force=None if _ % 3 else rng.normal(size=3).tolist(), native=True)
    RB.rhs_values(s, [1.0, 0.0, 0.0, 0.0], 0.42, 9.81, inertia, native=True)
    ctrl = K.Controller(native=True)
    ctrl.pwm(np.r_[rng.normal(0, 10, 12)], np.zeros(4), 0.005)
for bad in ([0.0] * 11, [0.0] * 13, "abcdefghijkl"):
    try:
        RB.rk4_values(bad, [1.0, 0, 0, 0], 0.01, 0.42, 9.81, inertia, native=True)
    except (ValueError, TypeError):
        pass
    try:
        K._feedback.feedback(bad, [0.0] * 4, 0.005, b"\0" * 512, b"\0" * 160, [1.0, 1.0], 1.0, [0.0] * 4,
                             [1.0] * 4, [1.0] * 4)
    except (ValueError, TypeError):
        pass
try:
    K._feedback.feedback([0.0] * 12, [0.0] * 4, 0.005, b"\0" * 8, b"\0" * 160, [1.0, 1.0], 1.0, [0.0] * 4,
                         [1.0] * 4, [1.0] * 4)
except ValueError:
    pass
print("fuzz ok")
