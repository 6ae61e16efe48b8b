"""A small true room, and the same truth on another mesh and UV layout: each triangle split in
four, unwrapped again by xatlas, the truth's maps baked onto the new atlas through the parent
triangle's barycentrics (independent of the evaluation's nearest-point search)."""

from __future__ import annotations

import numpy as np
from trimesh.triangles import points_to_barycentric

from invrender.scene.atlas import bake, rasterize_atlas, texel_index, unwrap
from invrender.scene.types import ATLAS_MAPS, Maps, Mesh, Scene
from invrender.synthesize.room import make_room

SMALL_ROOM = {"atlas_resolution": 128, "cameras": {"count": 2, "width": 32, "height": 24}}


def small_room() -> Scene:
    return make_room(SMALL_ROOM)[0]


def split_in_four(positions, faces) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(positions, faces, parent face of each new face): every triangle into four at its edge
    midpoints (the same surface, other triangles)."""
    p, f = np.asarray(positions, np.float64), np.asarray(faces, np.int64)
    a, b, c = f.T
    n, m = len(p), len(f)
    mids = np.concatenate([(p[a] + p[b]) / 2, (p[b] + p[c]) / 2, (p[c] + p[a]) / 2])
    ab, bc, ca = n + np.arange(m), n + m + np.arange(m), n + 2 * m + np.arange(m)
    new = np.concatenate([np.stack(t, 1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    return np.concatenate([p, mids]), new, np.tile(np.arange(m), 4)


def rebaked(truth: Scene, resolution: int = 96):
    """(scene, atlas texels): the truth on the split mesh with its own xatlas atlas."""
    positions, faces, parent = split_in_four(truth.mesh.positions, truth.mesh.faces)
    uv = unwrap(positions, faces, resolution=resolution, padding=2)
    mesh = Mesh(uv.positions, uv.faces, uv.uvs)
    texels = rasterize_atlas(mesh, uv.height, uv.width)
    corners = np.asarray(truth.mesh.positions, np.float64)[truth.mesh.faces]
    corner_uvs = np.asarray(truth.mesh.uvs, np.float64)[truth.mesh.faces]

    def baked(name):
        truth_map = getattr(truth.maps, name)
        channels = 1 if truth_map.ndim == 2 else 3

        def shade(triangle, position, normal):
            owner = parent[triangle]
            weights = points_to_barycentric(corners[owner], np.asarray(position, np.float64))
            row, col = texel_index(np.einsum("nk,nkc->nc", weights, corner_uvs[owner]), truth_map.shape)
            return truth_map[row, col].reshape(len(triangle), channels)

        return bake(texels, shade, channels, 2, background=0.1 if name == "ka" else 0.0)  # ka > 0 (format)

    maps = Maps(**{name: baked(name) for name in ATLAS_MAPS}, kg=truth.maps.kg.copy())
    return Scene(mesh=mesh, maps=maps, cameras=list(truth.cameras)), texels
