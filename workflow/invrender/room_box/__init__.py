"""The `room_box` stage (mode `room`): the room as a box from one photo's depth, segmentation and
field of view; the coarse fit (coarse.py), its refinement by differentiable mask IoU and depth
L1 (refine.py, PSDR-Room Eq. 2), the box and its exact reference render (box.py), metrics."""

from .stage import run

__all__ = ["run"]
