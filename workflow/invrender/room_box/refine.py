"""Room optimisation (PSDR-Room section 4.2, Eq. 2): the box refined by differentiable rendering.

    L_box = - sum_i IoU(M^r_i(theta), M^t_i) + L1(D^r(theta), D^t),   i in {wall, floor, ceiling}

M^r and D^r are render/silhouette.py's anti-aliased label coverages and pixel-averaged depth of
the box mesh (its faces labelled wall, floor, ceiling), so the IoU takes fractional pixels
(intersection sum(M^r M^t), union sum(M^r + M^t - M^r M^t)) and its gradient lives on the box's
edges. Depths are the normalised ones (median 1, the paper's "unit range").

Where the photo shows an object (or a window, a lamp, an unlabelled pixel) the room is hidden,
so neither term counts that pixel: the paper's masks are "much smaller than the rendered box
sides, as the room was not empty", and comparing the box's wall with a wall mask full of holes
would pull the box towards the holes. Targets are taken at a reduced resolution (whole blocks of
pixels averaged: fractional targets and weights), which is what the refinement can afford.

theta is the box's pose as the paper optimises it ("rotation, translation and scaling"): its
rotation as an axis-angle r, the renderer's own, and the positions of its six sides along its own
axes (the box is {R(r) q : low <= q <= high}), 9 numbers; the renderer's 9-vector per part is
[R(r) (low + high) / 2, r, log(high - low)]. The rotation is free, not only the yaw: a floor plane
that a distorted depth tilted is corrected by the masks. Sides rather than centre and size: a
side the photo does not show (the wall behind the camera) gets no gradient and stays where the
coarse fit put it, instead of drifting with the centre.
Adam with a learning rate decaying linearly to a tenth, keeping the iterate of the lowest loss
(the coarse box included); each step renders with a new seed; after
each step the sides are projected to keep the camera inside the box.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
import torch

from ..render.silhouette import rotation_matrix
from ..scene.cameras import binned_camera
from ..scene.images import block_mean
from ..scene.types import Camera
from .box import BOX_CLASSES, OrientedBox, RoomBox, box_mesh, rotation_y

__all__ = ["RefineSettings", "Targets", "reduced_targets", "box_loss", "refine_box", "theta_of", "box_of"]

logger = logging.getLogger(__name__)


@dataclass
class RefineSettings:
    iterations: int = 60
    learning_rate: float = 0.02
    spp: int = 4  # samples per pixel of each render (the edges get their own samples)
    max_width: int = 128  # the targets' width after block averaging, at most
    depth_weight: float = 1.0  # Eq. 2 weighs the two terms equally
    camera_margin: float = 0.05  # each side stays this far beyond the camera (normalised depth units)
    rotation_rate: float = 1.0  # the rotation's learning rate as a fraction of the sides'


@dataclass
class Targets:
    masks: np.ndarray  # (3, h, w) each class's share of a block's room pixels
    weight: np.ndarray  # (h, w) the share of a block's pixels that show the room
    depth: np.ndarray  # (h, w) mean normalised depth of a block's room pixels with a depth
    depth_weight: np.ndarray  # (h, w) the share of a block's pixels that have both
    camera: Camera  # the reduced camera


def reduced_targets(classes: np.ndarray, depth: np.ndarray, camera: Camera, max_width: int) -> Targets:
    """Block averages of the class image (BOX_CLASSES indices, -1 elsewhere) and of the
    normalised depth, at most ``max_width`` wide."""
    factor = max(1, int(np.ceil(camera.width / max_width)))
    room = classes >= 0
    weight = block_mean(room.astype(np.float64), factor)
    with np.errstate(invalid="ignore", divide="ignore"):
        masks = np.stack([block_mean((classes == c).astype(np.float64), factor) / weight for c in range(3)])
        has_depth = room & (depth > 0)
        depth_weight = block_mean(has_depth.astype(np.float64), factor)
        mean_depth = block_mean(np.where(has_depth, depth, 0.0), factor) / depth_weight
    return Targets(
        masks=np.nan_to_num(masks),
        weight=weight,
        depth=np.nan_to_num(mean_depth),
        depth_weight=depth_weight,
        camera=binned_camera(camera, factor),
    )


def box_loss(masks, depth, targets: Targets, depth_weight: float = 1.0):
    """Eq. 2 and its parts: (loss, {"iou": [per class], "depth_l1": ...}) of rendered (3, h, w)
    masks and (h, w) depth (torch), over the room's pixels. A class the photo does not show has
    no IoU to gain (0 / its union) and is left out."""
    weight = torch.as_tensor(targets.weight, dtype=masks.dtype)
    target = torch.as_tensor(targets.masks, dtype=masks.dtype)
    ious = []
    loss = masks.new_zeros(())
    for i in range(len(BOX_CLASSES)):
        if targets.masks[i].max() <= 0:
            ious.append(None)
            continue
        inter = (weight * masks[i] * target[i]).sum()
        union = (weight * (masks[i] + target[i] - masks[i] * target[i])).sum()
        iou = inter / union
        loss = loss - iou
        ious.append(float(iou.detach()))
    dw = torch.as_tensor(targets.depth_weight, dtype=depth.dtype)
    l1 = (dw * (depth - torch.as_tensor(targets.depth, dtype=depth.dtype)).abs()).sum() / dw.sum()
    loss = loss + depth_weight * l1
    return loss, {"iou": ious, "depth_l1": float(l1.detach())}


def _rodrigues(r: torch.Tensor) -> torch.Tensor:
    """render/silhouette.py's rotation_matrix in torch: the rotation by |r| about r / |r|."""
    theta2 = (r * r).sum()
    zero = r.new_zeros(())
    K = torch.stack(
        [torch.stack([zero, -r[2], r[1]]), torch.stack([r[2], zero, -r[0]]), torch.stack([-r[1], r[0], zero])]
    )
    small = theta2 < 1e-12  # the series, where sin(t) / t and (1 - cos t) / t^2 lose their digits
    theta = torch.sqrt(torch.where(small, torch.ones_like(theta2), theta2))
    a = torch.where(small, 1 - theta2 / 6, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24, (1 - torch.cos(theta)) / theta**2)
    return torch.eye(3, dtype=r.dtype) + a * K + b * (K @ K)


def theta_of(box: RoomBox) -> torch.Tensor:
    """[axis-angle (3), low sides (3), high sides (3)] of an upright box: the box is
    {R(r) q : low <= q <= high}, r = (0, yaw, 0)."""
    yaw = np.radians(box.yaw_deg)
    middle = rotation_y(-yaw) @ box.center
    return torch.tensor([0.0, yaw, 0.0, *(middle - box.size / 2), *(middle + box.size / 2)], dtype=torch.float64)


def box_of(theta: torch.Tensor) -> OrientedBox:
    r, low, high = (v.detach().cpu().numpy().astype(np.float64) for v in (theta[:3], theta[3:6], theta[6:9]))
    rotation = rotation_matrix(r)
    return OrientedBox(rotation, rotation @ ((low + high) / 2), high - low)


def _pose(theta: torch.Tensor) -> torch.Tensor:
    """The renderer's [t, axis-angle, log s] of the box."""
    r, low, high = theta[:3], theta[3:6], theta[6:9]
    return torch.cat([_rodrigues(r) @ ((low + high) / 2), r, torch.log(high - low)]).reshape(1, 9)


def _keep_camera_inside(rotation: torch.Tensor, sides: torch.Tensor, camera_center: np.ndarray, margin: float):
    """Project the sides back to at least ``margin`` beyond the camera: the room is seen from
    inside, and a side that crosses the camera (a wall beside or behind it, which the photo shows
    little of or not at all) would turn the box inside out in one step: the renderer would then
    see the box's outside, a wall over the whole photo."""
    with torch.no_grad():
        inside = rotation_matrix(rotation.numpy()).T @ np.asarray(camera_center, np.float64)
        sides[:3] = torch.minimum(sides[:3], torch.as_tensor(inside - margin))
        sides[3:] = torch.maximum(sides[3:], torch.as_tensor(inside + margin))


def refine_box(
    box: RoomBox,
    targets: Targets,
    settings: RefineSettings,
    seed: int = 0,
    render=None,
    log: logging.Logger = logger,
) -> tuple[OrientedBox, list[dict]]:
    """Adam on Eq. 2 from ``box``; returns the box of the lowest loss seen and the loss at each step. ``render``
    is render_masks_depth's signature (the default; tests may pass the same function)."""
    if render is None:
        from ..render.silhouette import render_masks_depth as render
    from ..render.silhouette import MeshPart

    vertices, faces, labels = box_mesh()
    parts = [MeshPart(vertices, faces, labels)]
    start = theta_of(box)
    rotation, sides = start[:3].clone().requires_grad_(True), start[3:].clone().requires_grad_(True)
    # Adam's step is about the learning rate in each number, and a turn of the box moves its far
    # corners by the turn times their distance (a few median depths): the rotation has a rate of
    # its own (docs/room.md: 0.3 is steadier from a right start, 1 corrects a tilted floor faster).
    optimizer = torch.optim.Adam(
        [{"params": [sides]}, {"params": [rotation], "lr": settings.learning_rate * settings.rotation_rate}],
        lr=settings.learning_rate,
    )
    schedule = torch.optim.lr_scheduler.LambdaLR(
        optimizer, lambda step: 1.0 - 0.9 * step / max(settings.iterations - 1, 1)
    )
    _keep_camera_inside(rotation, sides, targets.camera.center, settings.camera_margin)  # the start too
    history = []
    best = (float("inf"), start)
    started = time.perf_counter()
    for step in range(settings.iterations):
        optimizer.zero_grad()
        theta = torch.cat([rotation, sides])
        masks, depth = render(
            parts, _pose(theta), targets.camera, labels=len(BOX_CLASSES), spp=settings.spp, seed=seed + step
        )
        loss, parts_of = box_loss(masks, depth, targets, settings.depth_weight)
        if float(loss.detach()) < best[0]:
            best = (float(loss.detach()), theta.detach().clone())
        loss.backward()
        optimizer.step()
        schedule.step()
        _keep_camera_inside(rotation, sides, targets.camera.center, settings.camera_margin)
        value = float(loss.detach())
        history.append({"step": step, "loss": value, **parts_of})
        if step % 10 == 0 or step == settings.iterations - 1:
            log.info(
                "room_box: step %d loss %.4f (IoU %s, depth L1 %.4f) %.1f s",
                step,
                value,
                ", ".join("-" if v is None else f"{v:.3f}" for v in parts_of["iou"]),
                parts_of["depth_l1"],
                time.perf_counter() - started,
            )
    # The lowest loss seen, the coarse box (step 0) included: near the optimum Adam's noisy steps
    # wander (the demo's living room: IoU 0.9999 coarse, 0.9993 after 60 steps), and the sides the
    # photo does not show drift with the rotation, so the last iterate is not the best one.
    # (The losses are Monte Carlo estimates; this keeps an iterate at least as good within their noise.)
    return box_of(best[1]), history
