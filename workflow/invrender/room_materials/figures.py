"""The stage's pictures: each crop pair (the photo's crop, the render's before and after Eq. 4,
side by side, as the paper's Figure 7) and each part's material thumbnail."""

from __future__ import annotations

import cv2
import numpy as np
import torch

from ..scene.images import linear_to_srgb

__all__ = ["crops_figure", "thumbnails"]

TILE = 96


def _bgr(image) -> np.ndarray:
    image = np.clip(np.asarray(image, np.float32), 0, 1)
    return np.ascontiguousarray((linear_to_srgb(image) * 255 + 0.5).astype(np.uint8)[..., ::-1])


def _tile(image, exposure: float) -> np.ndarray:
    return cv2.resize(_bgr(np.asarray(image) * exposure), (TILE, TILE), interpolation=cv2.INTER_AREA)


def crops_figure(pairs, photo_crops, before, after) -> np.ndarray:
    """One row per crop pair: photo | before | after, each exposed by the photo crop's 95th
    percentile (the same for the three), the part's name above."""
    rows = []
    for pair, p, b, a in zip(pairs, photo_crops, before, after):
        exposure = 0.9 / max(float(np.percentile(p, 95)), 1e-4)
        row = np.concatenate([_tile(p, exposure), _tile(b, exposure), _tile(a, exposure)], axis=1)
        label = np.full((18, row.shape[1], 3), 255, np.uint8)
        cv2.putText(
            label, f"{pair.part} ({pair.source})", (3, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA
        )
        rows.append(np.concatenate([label, row], axis=0))
    if not rows:
        return np.full((TILE, 3 * TILE, 3), 255, np.uint8)
    head = np.full((18, 3 * TILE, 3), 255, np.uint8)
    for k, text in enumerate(("photo", "before Eq. 4", "after Eq. 4")):
        cv2.putText(head, text, (3 + k * TILE, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    return np.concatenate([head, *rows], axis=0)


def thumbnails(names, materials, columns: int = 6) -> np.ndarray:
    """Each part's kd over 2 x 2 material units under its transform, labelled."""
    tiles = []
    for name, mat in zip(names, materials):
        with torch.no_grad():
            kd = mat.material.image(64, mat.params, mat.transform).numpy()
        tile = cv2.resize(_bgr(kd), (TILE, TILE), interpolation=cv2.INTER_NEAREST)
        label = np.full((14, TILE, 3), 255, np.uint8)
        cv2.putText(label, name[:16], (2, 10), cv2.FONT_HERSHEY_SIMPLEX, 0.3, (0, 0, 0), 1, cv2.LINE_AA)
        tiles.append(np.concatenate([label, tile], axis=0))
    while len(tiles) % columns:
        tiles.append(np.full_like(tiles[0], 255) if tiles else np.full((TILE + 14, TILE, 3), 255, np.uint8))
    rows = [np.concatenate(tiles[k : k + columns], axis=1) for k in range(0, len(tiles), columns)]
    return np.concatenate(rows, axis=0)
