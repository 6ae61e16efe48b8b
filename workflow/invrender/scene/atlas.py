"""UV atlases: xatlas charts, and the table that maps every atlas texel back to the surface.

Conventions (docs/renderer.md, "Textures"): UVs are in [0, 1] with v up; texel (row, col) of an
(H, W) map covers u in [col, col + 1) / W and v in (1 - (row + 1) / H, 1 - row / H], so its centre
is at u = (col + 0.5) / W, v = 1 - (row + 0.5) / H, and the renderer reads the texel containing a
point (nearest-texel lookup, ``texel_index``).

- ``unwrap``: xatlas charts and packing, at a texel density or into a fixed square resolution.
  Faces keep their order, so per-face attributes (instance ids, part labels) stay aligned.
- ``rasterize_atlas``: per texel, the triangle whose UV triangle contains the texel centre, its
  barycentrics, 3D point and geometric normal (``AtlasTexels``, saved as ``atlas.npz``).
- ``dilate`` / ``bake``: a map is evaluated on covered texels, then grown into the empty texels
  around each chart, because a point inside a triangle can fall in a texel whose centre lies just
  outside it (nearest lookup), and that texel must hold a sensible value too.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import xatlas

from ..scene.atomic import atomic_path
from ..scene.types import SceneError
from .isolate import call_isolated

__all__ = ["UVAtlas", "AtlasTexels", "unwrap", "rasterize_atlas", "dilate", "bake", "texel_index"]

ATLAS_KEYS = ("triangle", "barycentric", "position", "normal", "mask")


class UVAtlas(NamedTuple):
    """The mesh re-indexed for its UVs (xatlas splits vertices along chart seams)."""

    positions: np.ndarray  # (V', 3) float32: input positions[vertex_map]
    faces: np.ndarray  # (F, 3) int32, face f is input face f
    uvs: np.ndarray  # (V', 2) float32 in [0, 1], v up
    vertex_map: np.ndarray  # (V',) int64: the input vertex each new vertex copies
    height: int  # atlas size in texels the UVs were packed for
    width: int


def triangle_areas(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    p = np.asarray(positions, np.float64)[np.asarray(faces)]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def _pack_options(texels_per_unit: float, resolution: int, padding: int) -> xatlas.PackOptions:
    pack = xatlas.PackOptions()
    pack.padding = int(padding)
    pack.texels_per_unit = float(texels_per_unit)
    pack.resolution = int(resolution)
    # Nearest-texel lookup: no extra border for bilinear taps; `padding` is the whole gap.
    pack.bilinear = False
    return pack


class NoCharts(RuntimeError):
    """xatlas charted nothing (every face below its degeneracy threshold, or no atlas)."""


def _chart_scale(positions: np.ndarray) -> float:
    """The power of two that brings the bounding-box diagonal to at least 1 (1 if it is); a
    Python float, so that it scales float32 positions exactly and leaves float64 sums float64
    (a numpy float32 would round the area to float32 under NumPy 2's promotion rules)."""
    diagonal = float(np.linalg.norm(positions.max(axis=0) - positions.min(axis=0))) if len(positions) else 1.0
    return 2.0 ** max(0, int(np.ceil(-np.log2(diagonal)))) if 0 < diagonal < 1 else 1.0


def _chart(meshes, texels_per_unit: float, padding: int, chart_options):
    """xatlas charts (the slow part: segmentation and parametrization) packed at one density."""
    atlas = xatlas.Atlas()
    for positions, faces in meshes:
        atlas.add_mesh(positions, faces)
    atlas.generate(chart_options or xatlas.ChartOptions(), _pack_options(texels_per_unit, 0, padding))
    if atlas.atlas_count != 1:
        raise NoCharts(f"xatlas produced {atlas.atlas_count} atlases, expected 1")
    return atlas


def _repack(uv_meshes, texels_per_unit: float, resolution: int, padding: int):
    """Pack existing charts again (fast): xatlas finds them as UV islands of a UV mesh."""
    atlas = xatlas.Atlas()
    for uvs, faces in uv_meshes:
        atlas.add_uv_mesh(uvs, faces)
    atlas.generate(xatlas.ChartOptions(), _pack_options(texels_per_unit, resolution, padding))
    return atlas


def _fits(atlas, resolution: int) -> bool:
    return atlas.atlas_count == 1 and atlas.width <= resolution and atlas.height <= resolution


# xatlas holds the GIL for its whole run (seconds per 10^4 faces here, 0.2 ms a face; forever on
# some degenerate meshes, and it segfaults on others): ``unwrap`` runs it in a child process that
# a signal or this limit ends. 60 s plus 5 ms a face is 25 times the time measured on spheres.
UNWRAP_LIMIT_S = (60.0, 0.005)  # (seconds, seconds per face)


def unwrap(positions, faces, **options) -> UVAtlas:
    """``_unwrap`` (below) in a child process: a signal stops it at once, and a hang or a crash
    of xatlas is a NativeFailure naming the face count, not a stage that never ends or dies."""
    limit = UNWRAP_LIMIT_S[0] + UNWRAP_LIMIT_S[1] * len(faces)
    return call_isolated(
        _unwrap, positions, faces, limit_s=limit, what=f"xatlas unwrapping {len(faces)} faces", **options
    )


def _unwrap(
    positions,
    faces,
    *,
    texels_per_meter: float | None = None,
    resolution: int | None = None,
    padding: int = 2,
    groups=None,
    chart_options: xatlas.ChartOptions | None = None,
    search_steps: int = 8,
) -> UVAtlas:
    """Chart and pack a triangle mesh with xatlas; give exactly one of the two sizes.

    ``texels_per_meter``: a fixed texel density; the atlas is as large as it needs to be.
    ``resolution``: a ``resolution x resolution`` atlas, with the highest density whose charts
    still fit in it. The charts are computed once; only the packing is repeated, in a bisection
    on xatlas' ``texels_per_unit``.
    ``padding``: empty texels xatlas leaves between charts (room for ``dilate``).
    ``groups``: optional (F,) labels; faces of different groups never share a chart (each group
    is a separate xatlas mesh), so material boundaries fall on chart boundaries.
    The density is measured on ``positions`` as given: scale a part's positions before calling
    to give it more or fewer texels (the returned ``positions`` are the ones passed in).
    """
    if (texels_per_meter is None) == (resolution is None):
        raise ValueError("unwrap: give exactly one of texels_per_meter and resolution")
    positions = np.ascontiguousarray(positions, np.float32)
    faces = np.asarray(faces, np.int64)
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise ValueError(f"unwrap: faces: expected a non-empty (F, 3) array, got shape {faces.shape}")
    groups = np.zeros(len(faces), np.int64) if groups is None else np.asarray(groups)
    if groups.shape != (len(faces),):
        raise ValueError(f"unwrap: groups: expected shape ({len(faces)},), got {groups.shape}")

    # One xatlas mesh per group, each with its own compact vertex list.
    parts = []
    for g in np.unique(groups):
        face_idx = np.flatnonzero(groups == g)
        verts, local = np.unique(faces[face_idx], return_inverse=True)
        parts.append((face_idx, verts, local.reshape(-1, 3).astype(np.uint32)))
    # xatlas takes faces below about 1e-7 of area as degenerate: a mesh a few millimetres across
    # gave no atlas at all. Then it charts a copy scaled by a power of two (exact) to at least
    # 1 m, densities per unit of that copy. Meshes it charts as they are keep their exact atlas.
    try:
        atlas, results = _chart_parts(
            positions, faces, parts, 1.0, texels_per_meter, resolution, padding, chart_options, search_steps
        )
    except NoCharts:
        k = _chart_scale(positions)
        if k == 1:
            raise
        atlas, results = _chart_parts(
            positions, faces, parts, k, texels_per_meter, resolution, padding, chart_options, search_steps
        )

    width, height = int(atlas.width), int(atlas.height)
    out_faces = np.empty((len(faces), 3), np.int64)
    vertex_maps, uv_list, offset = [], [], 0
    for (face_idx, verts, _), (vmapping, indices, uvs) in zip(parts, results):
        out_faces[face_idx] = indices.astype(np.int64).reshape(-1, 3) + offset
        vertex_maps.append(verts[vmapping.astype(np.int64)])
        uv_list.append(uvs)
        offset += len(vmapping)
    vertex_map = np.concatenate(vertex_maps)
    # xatlas keeps the face order and corner order; check it, since everything relies on it.
    if not np.array_equal(vertex_map[out_faces], faces):
        raise RuntimeError("xatlas reordered faces or corners; per-face attributes would be misaligned")
    return UVAtlas(
        positions=positions[vertex_map],
        faces=out_faces.astype(np.int32),
        uvs=np.concatenate(uv_list).astype(np.float32),
        vertex_map=vertex_map,
        height=height,
        width=width,
    )


def _chart_parts(positions, faces, parts, k, texels_per_meter, resolution, padding, chart_options, search_steps):
    """(xatlas atlas, [(vertex mapping, indices, uvs)] per part) of the parts scaled by k."""
    meshes = [(positions[verts] * k, local) for _, verts, local in parts]

    if texels_per_meter is not None:
        atlas = _chart(meshes, texels_per_meter / k, padding, chart_options)
        results = [atlas[i] for i in range(len(parts))]
    else:
        resolution = int(resolution)
        area = float(triangle_areas(positions, faces).sum()) * k * k
        if area <= 0:
            raise ValueError("unwrap: the mesh has zero area")
        density = resolution / np.sqrt(area)  # every texel used: an upper bound
        charted = _chart(meshes, density, padding, chart_options)
        scale = np.array([charted.width, charted.height], np.float32) / np.float32(density)
        charts = [charted[i] for i in range(len(parts))]
        uv_meshes = [(np.ascontiguousarray(uv * scale, np.float32), ind) for _, ind, uv in charts]
        atlas = _densest_packing(uv_meshes, density, resolution, padding, search_steps)
        results = []
        for (vm0, _, _), (vm1, ind, uv) in zip(charts, (atlas[i] for i in range(len(parts)))):
            results.append((vm0[vm1.astype(np.int64)], ind, uv))

    return atlas, results


def _densest_packing(uv_meshes, hi: float, resolution: int, padding: int, steps: int):
    """The densest packing of the charts that fits one resolution x resolution atlas."""
    best = _repack(uv_meshes, hi, resolution, padding)
    if _fits(best, resolution):
        return best
    lo = hi
    for _ in range(40):
        hi, lo = lo, lo * 0.7
        best = _repack(uv_meshes, lo, resolution, padding)
        if _fits(best, resolution):
            break
    else:
        raise RuntimeError(f"unwrap: the charts do not fit a {resolution}^2 atlas at any density tried")
    for _ in range(steps):
        mid = np.sqrt(lo * hi)
        atlas = _repack(uv_meshes, mid, resolution, padding)
        if _fits(atlas, resolution):
            lo, best = mid, atlas
        else:
            hi = mid
    return best


def texel_index(uvs, shape) -> tuple[np.ndarray, np.ndarray]:
    """(row, col) of the texel the renderer reads at ``uvs`` (nearest texel, clamped)."""
    h, w = shape[:2]
    uvs = np.asarray(uvs, np.float64)
    col = np.clip(np.floor(uvs[..., 0] * w), 0, w - 1).astype(np.int64)
    row = np.clip(np.floor((1.0 - uvs[..., 1]) * h), 0, h - 1).astype(np.int64)
    return row, col


@dataclass
class AtlasTexels:
    """Per texel: the triangle whose UV triangle holds its centre (-1 = none) and that point."""

    triangle: np.ndarray  # (H, W) int32, -1 = empty
    barycentric: np.ndarray  # (H, W, 3) float32, weights of the triangle's corners 0, 1, 2
    position: np.ndarray  # (H, W, 3) float32, meters
    normal: np.ndarray  # (H, W, 3) float32, unit geometric normal (counter-clockwise front)
    mask: np.ndarray  # (H, W) bool, triangle >= 0

    @property
    def shape(self) -> tuple[int, int]:
        return self.triangle.shape

    def save(self, path) -> None:
        """Write ``atlas.npz`` (keys triangle, barycentric, position, normal, mask) atomically."""
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as f:
                np.savez_compressed(f, **{k: getattr(self, k) for k in ATLAS_KEYS})

    @classmethod
    def load(cls, path) -> AtlasTexels:
        path = Path(path)
        with np.load(path) as data:
            missing = [k for k in ATLAS_KEYS if k not in data]
            if missing:
                raise SceneError(path, ", ".join(missing), "the atlas.npz keys " + ", ".join(ATLAS_KEYS))
            return cls(**{k: data[k] for k in ATLAS_KEYS})


def rasterize_atlas(mesh, height: int, width: int, chunk_texels: int = 1 << 22) -> AtlasTexels:
    """Find, for every texel centre, the triangle that contains it in UV space.

    Vectorised over chunks of triangles: each chunk enumerates the texel centres inside its
    triangles' UV bounding boxes (about ``chunk_texels`` of them at a time) and keeps those
    inside. A centre exactly on a shared edge goes to one of the two triangles.
    """
    h, w = int(height), int(width)
    faces = np.asarray(mesh.faces, np.int64)
    pos = np.asarray(mesh.positions, np.float64)
    uv = np.asarray(mesh.uvs, np.float64)[faces]  # (F, 3, 2)
    # Continuous texel coordinates: x to the right, y down; texel (r, c) centre = (c + .5, r + .5).
    x = uv[..., 0] * w
    y = (1.0 - uv[..., 1]) * h
    c0 = np.clip(np.ceil(x.min(1) - 0.5), 0, w).astype(np.int64)
    c1 = np.clip(np.floor(x.max(1) - 0.5), -1, w - 1).astype(np.int64)
    r0 = np.clip(np.ceil(y.min(1) - 0.5), 0, h).astype(np.int64)
    r1 = np.clip(np.floor(y.max(1) - 0.5), -1, h - 1).astype(np.int64)
    nx = np.maximum(c1 - c0 + 1, 0)
    ny = np.maximum(r1 - r0 + 1, 0)
    # Edge vectors for barycentrics; triangles with no UV area cover nothing.
    e1x, e1y = x[:, 1] - x[:, 0], y[:, 1] - y[:, 0]
    e2x, e2y = x[:, 2] - x[:, 0], y[:, 2] - y[:, 0]
    den = e1x * e2y - e2x * e1y
    counts = np.where(np.abs(den) > 1e-12, nx * ny, 0)

    tri_map = np.full((h, w), -1, np.int32)
    bary = np.zeros((h, w, 3), np.float32)
    ends = np.cumsum(counts)
    start = 0
    while start < len(faces):
        # Largest run of triangles whose candidate texels fit in one chunk (at least one).
        base = ends[start - 1] if start else 0
        stop = max(int(np.searchsorted(ends, base + chunk_texels, side="right")), start + 1)
        cnt = counts[start:stop]
        total = int(cnt.sum())
        if total:
            tri = np.repeat(np.arange(start, stop), cnt)
            k = np.arange(total) - np.repeat(np.cumsum(cnt) - cnt, cnt)
            col = c0[tri] + k % nx[tri]
            row = r0[tri] + k // nx[tri]
            px = col + 0.5 - x[tri, 0]
            py = row + 0.5 - y[tri, 0]
            b1 = (px * e2y[tri] - e2x[tri] * py) / den[tri]
            b2 = (e1x[tri] * py - px * e1y[tri]) / den[tri]
            b0 = 1.0 - b1 - b2
            eps = -1e-9
            inside = (b0 >= eps) & (b1 >= eps) & (b2 >= eps)
            row, col, tri = row[inside], col[inside], tri[inside]
            tri_map[row, col] = tri
            bary[row, col] = np.stack([b0[inside], b1[inside], b2[inside]], axis=1)
        start = stop

    mask = tri_map >= 0
    t = tri_map[mask]
    corners = pos[faces[t]]  # (n, 3, 3)
    b = bary[mask].astype(np.float64)
    position = np.zeros((h, w, 3), np.float32)
    position[mask] = np.einsum("nk,nkc->nc", b, corners)
    tri_normal = np.cross(pos[faces[:, 1]] - pos[faces[:, 0]], pos[faces[:, 2]] - pos[faces[:, 0]])
    length = np.linalg.norm(tri_normal, axis=1, keepdims=True)
    tri_normal = np.divide(tri_normal, length, out=np.zeros_like(tri_normal), where=length > 0)
    normal = np.zeros((h, w, 3), np.float32)
    normal[mask] = tri_normal[t]
    return AtlasTexels(triangle=tri_map, barycentric=bary, position=position, normal=normal, mask=mask)


_NEIGHBOURS = [(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dr, dc) != (0, 0)]


def dilate(values, mask, iterations: int) -> tuple[np.ndarray, np.ndarray]:
    """Grow a map into empty texels: each pass fills every empty texel that has filled
    8-neighbours with their mean. Returns the map (float32, same shape) and the grown mask."""
    values = np.array(values, np.float32, copy=True)
    mask = np.array(mask, bool, copy=True)
    h, w = mask.shape
    v = values.reshape(h, w, -1)
    for _ in range(int(iterations)):
        empty = ~mask
        if not empty.any():
            break
        acc = np.zeros_like(v)
        cnt = np.zeros((h, w), np.float32)
        weighted = v * mask[..., None]
        for dr, dc in _NEIGHBOURS:
            dst = (slice(max(dr, 0), h + min(dr, 0)), slice(max(dc, 0), w + min(dc, 0)))
            src = (slice(max(-dr, 0), h + min(-dr, 0)), slice(max(-dc, 0), w + min(-dc, 0)))
            acc[dst] += weighted[src]
            cnt[dst] += mask[src]
        fill = empty & (cnt > 0)
        v[fill] = acc[fill] / cnt[fill][:, None]
        mask |= fill
    return values, mask


def bake(
    texels: AtlasTexels,
    shade: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray],
    channels: int,
    dilation: int,
    background: float = 0.0,
) -> np.ndarray:
    """Evaluate ``shade(triangle_ids, positions, normals) -> (n, channels)`` on covered texels,
    dilate ``dilation`` times, set the rest to ``background``. Returns (H, W, C), or (H, W) if
    ``channels`` is 1."""
    h, w = texels.shape
    out = np.full((h, w, channels), background, np.float32)
    m = texels.mask
    values = np.asarray(shade(texels.triangle[m], texels.position[m], texels.normal[m]), np.float32)
    out[m] = values.reshape(-1, channels)
    out, grown = dilate(out, m, dilation)
    out[~grown] = background
    return out[..., 0] if channels == 1 else out
