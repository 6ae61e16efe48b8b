"""Which faces of a scene are window openings and which emit, read from the texels under them.

MILO's export to other renderers (papers/milo.txt, "Exporting scene to other renderers") splits
windows and ceiling lights from the geometry: other renderers have no kw * kg window term and
sample only uniform emitters. The Mitsuba cross-checks and the USD export split them the same
way, by this one rule, so that both show the same scene:

- a face is a *hole* when every texel under it is a pure opening (kw = 1, kd = ks = ke = 0):
  left out, the environment shows through it exactly as our renderer shows it;
- a face *emits* when some texel under it has ke > 0 (and it is not a hole).
"""

from __future__ import annotations

import numpy as np

from .types import Scene

__all__ = ["face_texels", "classify_faces"]


def face_texels(positions_uv: np.ndarray, faces: np.ndarray, atlas_shape) -> tuple[np.ndarray, np.ndarray]:
    """Texels under each face, sampled at <= half-texel spacing over its UV triangle.

    Returns (face index, flat texel index) pairs. A texel cell that a triangle grazes by less than
    about half a texel may be missed; every texel a triangle covers substantially is found. The
    samples of one face are a uniform barycentric grid, so they weigh equal areas of that face.
    """
    h, w = atlas_shape
    if len(faces) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    tri = positions_uv[faces].astype(np.float64) * np.array([w, h])  # (F, 3, 2) in texels
    tri[..., 1] = h - tri[..., 1]  # row coordinate: (1 - v) H
    extent = np.max(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=-1), axis=1)
    levels = np.clip(np.ceil(2.0 * extent), 1, 256).astype(np.int64)
    face_ids, texel_ids = [], []
    for n in np.unique(levels):
        which = np.nonzero(levels == n)[0]
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = i + j <= n
        b1, b2 = i[keep] / n, j[keep] / n
        bary = np.stack([1.0 - b1 - b2, b1, b2], axis=-1)  # (S, 3)
        points = np.einsum("sk,fkc->fsc", bary, tri[which])  # (F', S, 2)
        col = np.clip(np.floor(points[..., 0]).astype(np.int64), 0, w - 1)
        row = np.clip(np.floor(points[..., 1]).astype(np.int64), 0, h - 1)
        face_ids.append(np.repeat(which, points.shape[1]))
        texel_ids.append((row * w + col).ravel())
    return np.concatenate(face_ids), np.concatenate(texel_ids)


def classify_faces(scene: Scene, window_as_hole: bool = True) -> dict[str, np.ndarray]:
    """Boolean masks over faces: `hole` (left out), `emitter` (some texel has ke > 0) and
    `window_dropped` (kept although some texel has kw > 0: the kw kg term is lost there)."""
    maps, mesh = scene.maps, scene.mesh
    f = len(mesh.faces)
    face_ids, texels = face_texels(mesh.uvs, mesh.faces, maps.atlas_shape)

    def any_per_face(texel_mask):
        out = np.zeros(f, bool)
        np.logical_or.at(out, face_ids, texel_mask.ravel()[texels])
        return out

    kw = maps.kw.reshape(maps.kw.shape[:2])
    opening = (kw == 1) & np.all(maps.kd == 0, -1) & np.all(maps.ks == 0, -1) & np.all(maps.ke == 0, -1)
    hole = ~any_per_face(~opening) if window_as_hole else np.zeros(f, bool)
    emitter = any_per_face(np.any(maps.ke > 0, -1)) & ~hole
    window_dropped = any_per_face(kw > 0) & ~hole if window_as_hole else np.zeros(f, bool)
    return {"hole": hole, "emitter": emitter, "window_dropped": window_dropped}
