"""Refining geometry (PSDR-Room section 4.3, Eq. 3): every object's pose refined jointly by
differentiable rendering of the objects' label masks and the depth, through
render/silhouette.py (anti-aliased coverage, edge-sampled gradients).

    L_obj = sum_i [ (1 - IoU(M^r_i, M^t_i)) + L1(M^r_i D^r, M^t_i D^t) + L1(G(M^r_i), G(M^t_i)) ]

M^r_i and M^t_i are object i's rendered and target masks, D^r and D^t the rendered and target
depths (normalised: median 1), G a Gaussian blur. The paper's Eq. 3 has the two L1 terms; the
brief's IoU (room_box's, Eq. 2) is added because an L1 of a small object's mask is small against
a large one's: each object's terms are divided by its target area, so every object counts alike.

The room box is rendered too (a part of its own label, outside the loss): it hides an object
pushed through a wall, as the photo's wall does. Objects hide each other in the renders, so the
masks are the visible parts, the photo's segments.

Parameters per object (the paper's "scaling, horizontal translation and rotation around the
vertical axis", the vertical kept along the floor's normal): x, z, yaw and log scale; the height
is the support's (0 on the floor, the parent's top: its height plus its scale times its asset's
height, so a child moves with its parent) and is a parameter only for a free object. Adam with a
rate decaying linearly to a tenth; each object keeps the iterate of its own lowest loss (the
start included): the last iterate drifts within the Monte Carlo noise (room_box measured it).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
import torch

from ..scene.cameras import binned_camera
from ..scene.images import block_mean
from ..scene.types import Camera
from .placement import FREE, Placement

__all__ = ["RefineSettings", "Targets", "reduced_targets", "refine", "box_part"]

logger = logging.getLogger(__name__)


@dataclass
class RefineSettings:
    iterations: int = 40
    spp: int = 4  # samples per pixel of each render (the edges get their own samples)
    max_width: int = 160  # the targets' width after block averaging, at most
    position_rate: float = 0.02  # Adam's rates: normalised units (median depths) ...
    yaw_rate: float = 0.06  # ... radians ...
    scale_rate: float = 0.04  # ... log scale (the coarse scale is about half: it must grow)
    depth_weight: float = 1.0
    blur_weight: float = 1.0
    blur_px: float = 3.0  # the blur's sigma in the targets' pixels


@dataclass
class Targets:
    masks: np.ndarray  # (n, h, w) each object's share of a block's pixels
    masked_depth: np.ndarray  # (n, h, w) the block mean of the object's mask times the normalised depth
    camera: Camera  # the reduced camera, normalised units


def block_factor(width: int, max_width: int) -> int:
    return max(1, int(np.ceil(width / max_width)))


def reduced_targets(masks: list[np.ndarray], depth: np.ndarray, camera: Camera, max_width: int) -> Targets:
    """Block averages of each object's mask and of its mask times the (normalised) depth."""
    factor = block_factor(camera.width, max_width)
    shape = (len(masks), camera.height // factor, camera.width // factor)
    out_m, out_d = np.zeros(shape), np.zeros(shape)
    for i, mask in enumerate(masks):
        out_m[i] = block_mean(mask.astype(np.float64), factor)
        out_d[i] = block_mean(np.where(mask, depth, 0.0), factor)
    return Targets(out_m, out_d, binned_camera(camera, factor))


def box_part(center, size, yaw_deg: float, label: int):
    """The room box as a MeshPart of one label (a unit cube, 12 triangles) and its pose row."""
    from ..render.silhouette import MeshPart

    corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = np.array([tri for a, b, c, d in quads for tri in ((a, b, c), (a, c, d))])
    pose = np.array([*center, 0.0, np.radians(yaw_deg), 0.0, *np.log(size)])
    return MeshPart(corners, faces, np.full(len(faces), label)), pose


def blur_matrices(shape, sigma: float) -> tuple[torch.Tensor, torch.Tensor]:
    """(h, h) and (w, w) Gaussian matrices: G_y X G_x^T blurs an (h, w) image, zero outside (two
    small matrix products: torch's float64 conv2d took 50 ms an image here)."""

    def matrix(n):
        x = np.arange(n)
        g = np.exp(-0.5 * ((x[:, None] - x[None, :]) / sigma) ** 2)
        return torch.as_tensor(g / g.sum(axis=1, keepdims=True).max(), dtype=torch.float64)

    return matrix(shape[0]), matrix(shape[1])


def _blur(images: torch.Tensor, kernel) -> torch.Tensor:
    gy, gx = kernel
    return gy @ images @ gx.T


def object_losses(masks, masked_depth, targets: Targets, settings: RefineSettings, kernel) -> tuple[torch.Tensor, dict]:
    """Eq. 3's terms per object (n,) and their values for the record. ``masks`` (n, h, w) the
    objects' rendered coverages, ``masked_depth`` (n, h, w) each mask times the rendered depth."""
    t_m = torch.as_tensor(targets.masks, dtype=masks.dtype)
    t_d = torch.as_tensor(targets.masked_depth, dtype=masks.dtype)
    area = t_m.sum(dim=(1, 2)).clamp_min(1e-6)
    inter = (masks * t_m).sum(dim=(1, 2))
    union = (masks + t_m - masks * t_m).sum(dim=(1, 2)).clamp_min(1e-6)
    iou = inter / union
    depth_l1 = (masked_depth - t_d).abs().sum(dim=(1, 2)) / area
    loss = (1 - iou) + settings.depth_weight * depth_l1
    blur_l1 = torch.zeros_like(iou)
    if settings.blur_weight > 0:
        blur_l1 = (_blur(masks, kernel) - _blur(t_m, kernel)).abs().sum(dim=(1, 2)) / area
        loss = loss + settings.blur_weight * blur_l1
    record = {
        "iou": iou.detach().tolist(),
        "depth_l1": depth_l1.detach().tolist(),
        "blur_l1": blur_l1.detach().tolist(),
    }
    return loss, record


class Poses:
    """The objects' parameters (x, z, yaw, log scale, free height) and their pose rows, built in
    support order so that a child stands on its parent's current top."""

    def __init__(self, placements: list[Placement], supports: list[str], parents: list[int | None]):
        self.assets = [p.asset for p in placements]
        self.supports, self.parents = supports, parents
        P = torch.tensor(np.array([p.position for p in placements]), dtype=torch.float64)
        self.xz = P[:, [0, 2]].clone().requires_grad_(True)
        self.height = P[:, 1].clone().requires_grad_(True)
        self.yaw = torch.tensor([np.radians(p.yaw_deg) for p in placements], dtype=torch.float64, requires_grad=True)
        self.log_scale = torch.tensor([np.log(p.scale) for p in placements], dtype=torch.float64, requires_grad=True)
        self.asset_height = torch.tensor([a.extent[1] for a in self.assets], dtype=torch.float64)

    def tensors(self) -> list[torch.Tensor]:
        return [self.xz, self.height, self.yaw, self.log_scale]

    def heights(self) -> list[torch.Tensor]:
        """Each object's y: its support's top (parents come before children in the list)."""
        ys: list[torch.Tensor] = []
        for i, support in enumerate(self.supports):
            if self.parents[i] is not None:
                j = self.parents[i]
                ys.append(ys[j] + torch.exp(self.log_scale[j]) * self.asset_height[j])
            elif support == FREE:
                ys.append(self.height[i])
            else:
                ys.append(self.height.new_zeros(()))
        return ys

    def rows(self) -> torch.Tensor:
        zero = self.yaw.new_zeros(())
        ys = self.heights()
        rows = [
            torch.stack([self.xz[i, 0], ys[i], self.xz[i, 1], zero, self.yaw[i], zero, *[self.log_scale[i]] * 3])
            for i in range(len(self.assets))
        ]
        return torch.stack(rows)

    def placements(self) -> list[Placement]:
        with torch.no_grad():
            ys = [float(y) for y in self.heights()]
            return [
                Placement(
                    a,
                    [float(self.xz[i, 0]), ys[i], float(self.xz[i, 1])],
                    float(np.degrees(float(self.yaw[i]))) % 360.0,
                    float(torch.exp(self.log_scale[i])),
                )
                for i, a in enumerate(self.assets)
            ]


def refine(
    placements: list[Placement],
    supports: list[str],
    parents: list[int | None],
    targets: Targets,
    box,
    settings: RefineSettings,
    seed: int = 0,
    render=None,
    device: str | None = None,
    log: logging.Logger = logger,
) -> tuple[list[Placement], np.ndarray, list[dict]]:
    """Adam on Eq. 3 from ``placements`` (in support order: ``parents[i]`` < i). ``box``:
    (center, size, yaw_deg) of the room, normalised. Returns each object's placement at its own
    lowest loss, those losses (n,), and the record of every step."""
    if render is None:
        from ..render.silhouette import render_masks_depth as render
    from ..render.silhouette import MeshPart

    n = len(placements)
    parts = [
        MeshPart(p.asset.mesh.positions, p.asset.mesh.faces, np.full(len(p.asset.mesh.faces), i))
        for i, p in enumerate(placements)
    ]
    room, room_pose = box_part(*box, label=n)
    parts.append(room)
    room_row = torch.tensor(room_pose, dtype=torch.float64).reshape(1, 9)
    poses = Poses(placements, supports, parents)
    rates = (settings.position_rate, settings.position_rate, settings.yaw_rate, settings.scale_rate)
    optimizer = torch.optim.Adam([{"params": [t], "lr": r} for t, r in zip(poses.tensors(), rates)])
    schedule = torch.optim.lr_scheduler.LambdaLR(
        optimizer, lambda step: 1.0 - 0.9 * step / max(settings.iterations - 1, 1)
    )
    kernel = blur_matrices(targets.masks.shape[1:], settings.blur_px)
    best_loss = np.full(n, np.inf)
    best = poses.placements()
    history = []
    started = time.perf_counter()
    for step in range(settings.iterations):
        optimizer.zero_grad()
        params = torch.cat([poses.rows(), room_row])
        masks, depth = render(
            parts, params, targets.camera, labels=n + 1, spp=settings.spp, seed=seed + step, device=device
        )
        losses, record = object_losses(masks[:n], masks[:n] * depth[None], targets, settings, kernel)
        values = losses.detach().numpy()
        better = values < best_loss
        if better.any():
            current = poses.placements()
            for i in np.flatnonzero(better):
                best[i], best_loss[i] = current[i], values[i]
        losses.sum().backward()
        optimizer.step()
        schedule.step()
        history.append({"step": step, "loss": float(values.sum()), "losses": values.tolist(), **record})
        if step % 10 == 0 or step == settings.iterations - 1:
            log.info(
                "room_objects: step %d loss %.4f (IoU %s) %.1f s",
                step,
                float(values.sum()),
                " ".join(f"{v:.3f}" for v in record["iou"]),
                time.perf_counter() - started,
            )
    return _restack(best, parents), best_loss, history


def _restack(placements: list[Placement], parents: list[int | None]) -> list[Placement]:
    """Each child's height set again on its parent's kept top (parent and child may keep iterates of
    different steps)."""
    for i, j in enumerate(parents):
        if j is not None:
            placements[i].position[1] = placements[j].top
    return placements


def exact_losses(placements: list[Placement], targets: Targets, settings: RefineSettings, supersample: int = 3):
    """Eq. 3's terms per object (n,) from exact z-buffer labels (placement.label_image at
    ``supersample`` times the targets' size, block-averaged: anti-aliased without Monte Carlo
    noise), for comparing candidates: the refinement's own losses are noisy, and were taken with
    other objects' candidates around (which hide different pixels)."""
    from .placement import label_image

    cam = targets.camera
    fx, fy, cx, cy = np.asarray(cam.params, np.float64) * supersample
    big = Camera(cam.name, "PINHOLE", cam.width * supersample, cam.height * supersample,
                 np.array([fx, fy, cx, cy]), cam.R, cam.t)  # fmt: skip
    labels, depth = label_image(placements, big)
    masks = np.stack([block_mean((labels == i).astype(np.float64), supersample) for i in range(len(placements))])
    masked = np.stack([block_mean(np.where(labels == i, depth, 0.0), supersample) for i in range(len(placements))])
    kernel = blur_matrices(targets.masks.shape[1:], settings.blur_px)
    losses, _ = object_losses(torch.as_tensor(masks), torch.as_tensor(masked), targets, settings, kernel)
    return losses.numpy()
