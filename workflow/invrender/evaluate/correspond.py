"""Where each recovered texel lies on the true surface: the truth's texel at the same 3D point.

The recovered scene and the truth need not share a mesh or a UV layout (the recovered mesh is the
geometry stage's reconstruction, with its own atlas), so maps are compared on the surface: for
every covered texel of the recovered atlas (its 3D point and normal from ``atlas.npz``), the
nearest point on the truth mesh, that point's barycentric UV in the truth's atlas, and the truth
texel the renderer would read there (``scene.atlas.texel_index``, nearest texel).

Nearest point, exactly: candidates come from a k-d tree (scipy's cKDTree) over points sampled on
every truth triangle at most ``spacing`` apart (a barycentric grid, corners included, so every
point of a triangle lies within ``spacing`` of one of its own samples); the exact point-triangle
closest points of the candidates come from trimesh (Ericson, Real-Time Collision Detection 5.1.5).
The nearest sample is on the surface, at distance d_s >= d*, the true nearest distance; the
nearest triangle's closest point has a sample within ``spacing`` of it, so every triangle within
d_s + spacing of the texel is a candidate and the minimum over candidates is the exact nearest.

Two sides: a thin table top, or a wall seen from both rooms, has two surfaces a few centimetres
apart, and a recovered texel a little off its surface can be nearer the wrong one. When the
nearest triangle faces away from the texel (normals' dot product <= 0), the nearest triangle that
faces the same way is taken instead if it is at most ``side_margin`` farther.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from trimesh.triangles import closest_point, points_to_barycentric

from ..scene.atlas import AtlasTexels, texel_index, triangle_areas
from ..scene.types import Mesh

__all__ = ["Correspondence", "surface_samples", "correspond", "DEFAULT_SAMPLES", "DEFAULT_SIDE_MARGIN"]

DEFAULT_SAMPLES = 200_000  # about this many surface samples set the spacing (a k-d tree of 5 MB)
DEFAULT_SIDE_MARGIN = 0.02  # fraction of the truth's bounding-box diagonal (10 cm in a 5 m room)
NUDGE = 1e-3  # the step off shared edges, as a fraction of the sample spacing (26 um in the demo room)
CHUNK = 16_384  # texels per batch of exact distances (about 50 MB of candidate pairs)


@dataclass
class Correspondence:
    """For each covered texel of the recovered atlas (in ``np.nonzero(mask)`` order)."""

    mask: np.ndarray  # (H, W) bool: the recovered atlas' covered texels
    triangle: np.ndarray  # (n,) int64: the truth triangle
    point: np.ndarray  # (n, 3) float64: the nearest point on it
    distance: np.ndarray  # (n,) float64: from the texel's 3D point
    row: np.ndarray  # (n,) int64: the truth texel the renderer reads at that point
    col: np.ndarray
    # (n,) bool: a triangle facing the texel's way was taken over a nearer (or as near) one that does not
    facing_preferred: np.ndarray
    spacing: float
    side_margin: float

    def truth_values(self, truth_map: np.ndarray) -> np.ndarray:
        """The truth map's values at the texels' surface points, (n,) or (n, C)."""
        return np.asarray(truth_map)[self.row, self.col]

    def summary(self) -> dict:
        d = self.distance
        return {
            "texels": int(len(d)),
            "distance_m": {"mean": float(d.mean()), "p95": float(np.percentile(d, 95)), "max": float(d.max())},
            "facing_triangle_preferred": int(self.facing_preferred.sum()),
            "sample_spacing_m": self.spacing,
            "side_margin_m": self.side_margin,
        }


def surface_samples(positions, faces, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Points on every triangle at most ``spacing`` from any point of it: a barycentric grid of
    n divisions, n = ceil(longest edge / spacing) (a point of a triangle lies in a sub-triangle
    whose edges are at most longest / n, so within that of a corner). Returns (points, triangle)."""
    p = np.asarray(positions, np.float64)[np.asarray(faces, np.int64)]  # (F, 3, 3)
    longest = np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2).max(axis=1)
    divisions = np.maximum(1, np.ceil(longest / spacing)).astype(np.int64)
    points, owners = [], []
    for n in np.unique(divisions):
        tri = np.flatnonzero(divisions == n)
        i, j = np.triu_indices(n + 1)  # i + (n - j) ... every (a, b) with a + b <= n
        a, b = i, j - i
        weights = np.stack([n - a - b, a, b], axis=1) / n  # (m, 3) barycentric
        points.append(np.einsum("mk,fkc->fmc", weights, p[tri]).reshape(-1, 3))
        owners.append(np.repeat(tri, len(weights)))
    return np.concatenate(points), np.concatenate(owners)


def _face_normals(positions, faces) -> np.ndarray:
    p = np.asarray(positions, np.float64)[np.asarray(faces, np.int64)]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def _candidates(tree: cKDTree, owners: np.ndarray, queries: np.ndarray, radius: np.ndarray, k: int = 32):
    """(query index, triangle) pairs of every triangle with a sample within ``radius`` of its
    query, duplicates removed. k nearest samples first; queries whose k-th is still inside the
    radius ask again with twice k, so the pairs are complete."""
    rows, tris = [], []
    todo = np.arange(len(queries))
    while len(todo):
        k_now = min(k, tree.n)
        dist, idx = tree.query(queries[todo], k=k_now)
        dist, idx = dist.reshape(len(todo), k_now), idx.reshape(len(todo), k_now)
        inside = dist <= radius[todo, None]
        full = inside[:, -1] & (k_now < tree.n)
        done = ~full
        r, c = np.nonzero(inside[done])
        rows.append(todo[done][r])
        tris.append(owners[idx[done][r, c]])
        todo, k = todo[full], k * 2
    # one int64 key per pair: a 1-D unique, many times faster than np.unique(..., axis=0)
    span = int(owners.max()) + 1
    keys = np.unique(np.concatenate(rows) * span + np.concatenate(tris))
    return keys // span, keys % span


def _nearest(triangles, queries, rows, tris, n) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per query: the candidate triangle with the nearest exact closest point (ties: lowest id);
    -1 and an infinite distance for a query without candidates."""
    best_tri = np.full(n, -1, np.int64)
    best_pt = np.zeros((n, 3))
    best_d = np.full(n, np.inf)
    if not len(rows):
        return best_tri, best_pt, best_d
    points = closest_point(triangles[tris], queries[rows])
    dist = np.linalg.norm(points - queries[rows], axis=1)
    order = np.lexsort((tris, dist, rows))  # by query, then distance, then triangle
    first = order[np.r_[True, rows[order][1:] != rows[order][:-1]]]
    best_tri[rows[first]], best_pt[rows[first]], best_d[rows[first]] = tris[first], points[first], dist[first]
    return best_tri, best_pt, best_d


def nudged_inwards(points, triangle, mesh: Mesh, step: float) -> np.ndarray:
    """Each point moved ``step`` towards its triangle's centroid, where it lies on that triangle
    (within a thousandth of the step; others stay). A texel centre on a shared edge (xatlas puts
    axis-aligned chart edges on texel-centre lines) is as near the neighbour across the edge, a
    ceiling beside a lamp: the point just inside its own triangle is not."""
    corners = np.asarray(mesh.positions, np.float64)[np.asarray(mesh.faces, np.int64)]
    points = np.array(points, np.float64)
    valid = np.flatnonzero((triangle >= 0) & (triangle < len(corners)))
    own = corners[triangle[valid]]
    on = np.linalg.norm(closest_point(own, points[valid]) - points[valid], axis=1) <= 1e-3 * step
    towards = own.mean(axis=1) - points[valid]
    length = np.linalg.norm(towards, axis=1)
    move = on & (length > step)
    points[valid[move]] += step * towards[move] / length[move, None]
    return points


def correspond(
    texels: AtlasTexels,
    truth_mesh: Mesh,
    truth_shape: tuple[int, int],
    samples: int = DEFAULT_SAMPLES,
    side_margin: float = DEFAULT_SIDE_MARGIN,
    recovered_mesh: Mesh | None = None,
) -> Correspondence:
    """The truth texel at each covered recovered texel's surface point (module docstring).
    ``side_margin`` is a fraction of the truth mesh's bounding-box diagonal. ``recovered_mesh``:
    the mesh whose triangles ``texels.triangle`` names, for the nudge off shared edges."""
    positions = np.asarray(truth_mesh.positions, np.float64)
    faces = np.asarray(truth_mesh.faces, np.int64)
    area = float(triangle_areas(positions, faces).sum())
    spacing = float(np.sqrt(2.0 * area / samples))  # a grid of spacing h holds ~ area / (h^2 / 2) points
    margin = float(side_margin * np.linalg.norm(positions.max(0) - positions.min(0)))
    sample_points, owners = surface_samples(positions, faces, spacing)
    tree = cKDTree(sample_points)
    triangles = positions[faces]
    normals = _face_normals(positions, faces)
    uvs = np.asarray(truth_mesh.uvs, np.float64)[faces]  # (F, 3, 2)

    texel_points = np.asarray(texels.position[texels.mask], np.float64)
    queries_all = texel_points  # the triangle is chosen for the point nudged off shared edges, if known
    if recovered_mesh is not None:
        queries_all = nudged_inwards(texel_points, texels.triangle[texels.mask], recovered_mesh, NUDGE * spacing)
    texel_normals = np.asarray(texels.normal[texels.mask], np.float64)
    n_all = len(queries_all)
    tri = np.empty(n_all, np.int64)
    preferred = np.zeros(n_all, bool)
    for start in range(0, n_all, CHUNK):
        sl = slice(start, min(start + CHUNK, n_all))
        q, nq = queries_all[sl], texel_normals[sl]
        d_sample = tree.query(q)[0]
        rows, tris = _candidates(tree, owners, q, d_sample + spacing)
        t, p, d = _nearest(triangles, q, rows, tris, len(q))
        # the other side: same-facing triangles within the margin, for texels whose nearest faces away
        away = np.flatnonzero(np.einsum("nc,nc->n", normals[t], nq) <= 0)
        if len(away):
            rows, tris = _candidates(tree, owners, q[away], d[away] + margin + spacing)
            same_way = np.einsum("nc,nc->n", normals[tris], nq[away][rows]) > 0
            t2, p2, d2 = _nearest(triangles, q[away], rows[same_way], tris[same_way], len(away))
            take = (t2 >= 0) & (d2 <= d[away] + margin)
            t[away[take]], p[away[take]], d[away[take]] = t2[take], p2[take], d2[take]
            preferred[sl][away[take]] = True
        tri[sl] = t
    # the point on the chosen triangle nearest the texel's own point (not the nudged one)
    point = closest_point(triangles[tri], texel_points)
    dist = np.linalg.norm(point - texel_points, axis=1)
    # a degenerate (zero-area) triangle has no barycentrics: its first corner's UV
    bary = np.nan_to_num(points_to_barycentric(triangles[tri], point), nan=0.0, posinf=0.0, neginf=0.0)
    bary[np.abs(bary.sum(axis=1) - 1.0) > 1e-6] = (1.0, 0.0, 0.0)
    uv = np.einsum("nk,nkc->nc", bary, uvs[tri])
    row, col = texel_index(uv, truth_shape)
    return Correspondence(texels.mask, tri, point, dist, row, col, preferred, spacing, margin)
