"""A contact sheet of the library: every asset from the front-right and a little above, its
parts in distinct colours (emissive parts bright), shaded by a fixed light, with its name."""

from __future__ import annotations

import cv2
import numpy as np

from ..scene.images import write_png_preview
from .asset import Asset
from .primitives import face_normals
from .raster import look_at_pose, rasterize

__all__ = ["thumbnail", "contact_sheet", "write_contact_sheet"]

TILE = 160  # pixels
LABEL = 18  # pixels under each tile
# Linear RGB part colours (the emissive ones are drawn in EMISSIVE instead).
PALETTE = np.array(
    [[0.55, 0.35, 0.18], [0.75, 0.7, 0.6], [0.25, 0.35, 0.55], [0.6, 0.15, 0.12], [0.3, 0.5, 0.25], [0.5, 0.5, 0.5]]
)
EMISSIVE = np.array([1.0, 0.85, 0.4])
LIGHT = np.array([0.4, 0.8, 0.45]) / np.linalg.norm([0.4, 0.8, 0.45])


def thumbnail(asset: Asset, size: int = TILE, azimuth_deg: float = 35.0, elevation_deg: float = 20.0) -> np.ndarray:
    """(size, size, 3) linear RGB of the asset on a dark background."""
    p = asset.mesh.positions
    target = 0.5 * (p.min(axis=0) + p.max(axis=0))
    a, e = np.radians(azimuth_deg), np.radians(elevation_deg)
    eye = target + 3.0 * np.array([np.sin(a) * np.cos(e), np.sin(e), np.cos(a) * np.cos(e)])
    R, t = look_at_pose(eye, target)
    radius = 0.5 * np.linalg.norm(p.max(axis=0) - p.min(axis=0))
    focal = 0.45 * size * (3.0 - radius) / radius
    _, face = rasterize(p @ R.T + t, asset.mesh.faces, (focal, focal), (size / 2, size / 2), (size, size))
    normals = face_normals(p, asset.mesh.faces)
    to_eye = eye - p[asset.mesh.faces[:, 0]]
    normals *= np.sign(np.einsum("ij,ij->i", normals, to_eye))[:, None]  # the side we see
    colour = PALETTE[asset.mesh.part % len(PALETTE)]
    emissive = np.isin(np.asarray(asset.part_names)[asset.mesh.part], asset.emissive_parts)
    shade = 0.25 + 0.75 * np.clip(normals @ LIGHT, 0, 1)
    rgb = np.where(emissive[:, None], EMISSIVE, colour * shade[:, None])
    image = np.full((size, size, 3), 0.02)
    hit = face >= 0
    image[hit] = rgb[face[hit]]
    return image


def contact_sheet(assets: list[Asset], columns: int = 4) -> np.ndarray:
    rows = -(-len(assets) // columns)
    sheet = np.zeros((rows * (TILE + LABEL), columns * TILE, 3))
    for k, asset in enumerate(assets):
        r, c = divmod(k, columns)
        y, x = r * (TILE + LABEL), c * TILE
        sheet[y : y + TILE, x : x + TILE] = thumbnail(asset)
        label = asset.name if len(asset.name) <= 24 else "..." + asset.name[-21:]
        text = np.zeros((LABEL, TILE), np.uint8)  # OpenCV 5 draws text on 8-bit images only
        cv2.putText(text, label, (4, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.42, 255, 1, cv2.LINE_AA)
        sheet[y + TILE : y + TILE + LABEL, x : x + TILE] = 0.6 * (text[..., None] / 255.0)
    return sheet


def write_contact_sheet(path, assets: list[Asset], columns: int = 4) -> None:
    write_png_preview(path, contact_sheet(assets, columns), exposure=1.0)
