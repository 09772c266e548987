"""Ground velocity from a downward camera: block-sum optical flow (report §3.2.2), the global
motion solvers (Appendix H and a robust similarity fit), an optional sub-pixel stage (direct
alignment of the similarity, :func:`refine_motion`), metric velocity and a streaming ego-motion
track."""

from visloc.flow.block import block_flow, default_block
from visloc.flow.direct import refine_motion
from visloc.flow.motion import global_motion, instantaneous_rotation, similarity_fit
from visloc.flow.velocity import EgoMotion, estimate_ground_velocity, ground_velocity

__all__ = [
    "EgoMotion",
    "block_flow",
    "default_block",
    "estimate_ground_velocity",
    "global_motion",
    "ground_velocity",
    "instantaneous_rotation",
    "refine_motion",
    "similarity_fit",
]
