import cv2
import numpy as np
import pytest

GRASS = cv2.imread(str(__import__("pathlib").Path(__file__).resolve().parents[2] / "visloc/synth/data/grass.png"),
                   cv2.IMREAD_GRAYSCALE)


def moved(dx=0.0, dy=0.0, angle=0.0, center=None, size=(320, 240), origin=(350, 350)):
    """A view of the grass texture and the same view after the content moved: rotated by
    ``angle`` (rad, +x toward +y) about ``center`` (view pixels; default the view centre),
    then shifted by (dx, dy) px."""
    # optics-like blur first, so the bilinear warp below barely changes the texture's sharpness
    big = cv2.GaussianBlur(cv2.resize(GRASS, (1024, 1024), interpolation=cv2.INTER_LINEAR), (0, 0), 1.0)
    w, h = size
    ox, oy = origin
    c = np.array([(w - 1) / 2.0, (h - 1) / 2.0]) if center is None else np.asarray(center, float)
    cg, sg = np.cos(angle), np.sin(angle)
    # x' = R (x - c) + c + d, in big-image coordinates
    cb = c + (ox, oy)
    M = np.array([[cg, -sg, cb[0] - cg * cb[0] + sg * cb[1] + dx],
                  [sg, cg, cb[1] - sg * cb[0] - cg * cb[1] + dy]])
    after = cv2.warpAffine(big, M, (1024, 1024), flags=cv2.INTER_LINEAR)
    return big[oy : oy + h, ox : ox + w].copy(), after[oy : oy + h, ox : ox + w].copy()


@pytest.fixture
def pair():
    return moved
