"""The hull drawn onto COLMAP's points: the shared mesh where the copies' matched pixels put it.

A visual hull is the largest shape every silhouette allows, so wherever no silhouette grazes the
surface it stands off the object: a box's faces bulge by the voxels and the vote, its corners are
cut off by the cones of the few views that see them. What the copies' pixels say about the surface
is in the model already: after the sub-pixel rounds (adjust.py) each triangulated point lies within
a fraction of a pixel of its track in every copy that sees it, on the printed surface itself. Their
spread across the copies is what the material stage suffers from (a texel that the copies' rays
reach at different true points is a blur of the print), so the shared mesh should pass through them.

Each vertex moves along its normal n_v by one scalar o_v, the minimiser of

    sum_j w_j (o_v(j) - d_j)^2  +  lam * sum_(a,b) in edges (o_a - o_b)^2  +  mu * sum_v o_v^2

where point j belongs to its nearest vertex v(j) and d_j = n_v . (p_j - x_v) is its offset along that
normal: a sparse linear system (one row per vertex). The smoothness term carries the offsets into
the parts no point reached (a face with no print), the small mu keeps those at the hull when no
point is near. The weights w_j are Huber's on the residual (iteratively reweighted): a wrong
match's point, triangulated off the surface, pulls with a bounded force. Points farther than
``reach`` from the hull along the normal are ignored: they belong to no surface of this hull.

The fit runs twice (``PASSES``): a point near an edge of the true shape can belong to the wrong
face's vertex while the hull still bulges (a box's +x print, nearest to a -z vertex of a hull 4 mm
out on +x, pulls that face inwards); on the snapped mesh the points find their own face's
vertices. Measured on the HD boxes' hulls (Chamfer of the diagonal, 10 / 6 / 20 copies): one
pass at reach 0.03 and smoothness 0.25, 0.0076 / 0.0295 / 0.0036; at reach 0.06 and smoothness
0.1, 0.0064 / 0.0212 / 0.0034; two passes of that, 0.0060 / 0.0209 / 0.0034.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

from ..scene.types import Mesh

__all__ = ["SnapReport", "snap_to_points", "vertex_normals"]

log = logging.getLogger(__name__)

REACH = 0.06  # of the hull's bounding-box diagonal: a point this far off the hull is not on it
SMOOTHNESS = 0.1  # lam, in points: an edge holds its two offsets together like a tenth of a point
PASSES = 2  # the points assigned again to the snapped mesh's vertices (module docstring)
ANCHOR = 1e-3  # mu, in points: the hull where no point is near
HUBER = 1.5  # Huber's threshold in robust standard deviations (1.4826 MAD) of the residuals
ROUNDS = 4  # reweighting rounds
MIN_POINTS = 20


@dataclass
class SnapReport:
    points: int  # points within reach
    vertices_reached: int  # vertices with at least one point
    offset_mean: float  # mean signed offset (negative: inwards), the hull's units
    offset_max: float  # largest |offset|
    residual_before: float  # median |d_j|: the points' distance to the hull
    residual_after: float  # median |o_v(j) - d_j|: to the snapped mesh

    def as_dict(self) -> dict:
        return self.__dict__.copy()


def vertex_normals(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (unit; outward for a mesh with counter-clockwise faces)."""
    tri = positions[faces]
    face_normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # length: twice the area
    normals = np.zeros_like(positions)
    for k in range(3):
        np.add.at(normals, faces[:, k], face_normals)
    return normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)


def _edge_laplacian(faces: np.ndarray, count: int) -> sparse.csr_matrix:
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges = np.unique(np.sort(edges, axis=1), axis=0)
    ones = np.ones(len(edges))
    adjacency = sparse.coo_matrix((ones, (edges[:, 0], edges[:, 1])), shape=(count, count))
    adjacency = (adjacency + adjacency.T).tocsr()
    return (sparse.diags(np.asarray(adjacency.sum(axis=1)).ravel()) - adjacency).tocsr()


def _solve(owner, offsets, weights, laplacian, count: int, smoothness: float, anchor: float) -> np.ndarray:
    data = np.bincount(owner, weights=weights, minlength=count)
    rhs = np.bincount(owner, weights=weights * offsets, minlength=count)
    system = sparse.diags(data + anchor) + smoothness * laplacian
    return spsolve(system.tocsc(), rhs)


def _huber(residuals: np.ndarray) -> np.ndarray:
    scale = max(1.4826 * float(np.median(np.abs(residuals))), 1e-12) * HUBER
    return np.minimum(1.0, scale / np.maximum(np.abs(residuals), 1e-30))


def snap_to_points(
    mesh: Mesh, points, reach: float = REACH, smoothness: float = SMOOTHNESS, anchor: float = ANCHOR,
    passes: int = PASSES,
) -> tuple[Mesh, SnapReport | None]:  # fmt: skip
    """The mesh with every vertex moved along its normal onto the points, ``passes`` times (module
    docstring); unchanged, with no report, when fewer than MIN_POINTS points lie within reach.
    The report is the last pass's."""
    report = None
    for _ in range(passes):
        moved, last = _snap_once(mesh, points, reach, smoothness, anchor)
        if last is None:
            break
        mesh, report = moved, last
    return mesh, report


def _snap_once(mesh: Mesh, points, reach: float, smoothness: float, anchor: float) -> tuple[Mesh, SnapReport | None]:
    positions = np.asarray(mesh.positions, np.float64)
    faces = np.asarray(mesh.faces, np.int64)
    points = np.asarray(points, np.float64).reshape(-1, 3)
    limit = reach * float(np.linalg.norm(positions.max(axis=0) - positions.min(axis=0)))
    normals = vertex_normals(positions, faces)
    owner = cKDTree(positions).query(points)[1] if len(points) else np.zeros(0, np.int64)
    offsets = np.einsum("ij,ij->i", points - positions[owner], normals[owner])
    near = np.abs(offsets) <= limit
    if near.sum() < MIN_POINTS:
        log.info("snap: %d points within %.3g of the hull: the hull is kept", int(near.sum()), limit)
        return mesh, None
    owner, offsets = owner[near], offsets[near]
    laplacian = _edge_laplacian(faces, len(positions))
    weights = np.ones(len(offsets))
    for _ in range(ROUNDS):
        solution = _solve(owner, offsets, weights, laplacian, len(positions), smoothness, anchor)
        weights = _huber(solution[owner] - offsets)
    moved = positions + solution[:, None] * normals
    report = SnapReport(
        points=int(len(offsets)),
        vertices_reached=int(len(np.unique(owner))),
        offset_mean=float(solution.mean()),
        offset_max=float(np.abs(solution).max()),
        residual_before=float(np.median(np.abs(offsets))),
        residual_after=float(np.median(np.abs(solution[owner] - offsets))),
    )
    log.info(
        "snap: %d points on %d vertices; offsets mean %.3g, max %.3g; the points' median distance %.3g -> %.3g",
        report.points, report.vertices_reached, report.offset_mean, report.offset_max,
        report.residual_before, report.residual_after,
    )  # fmt: skip
    return Mesh(positions=moved.astype(np.float32), faces=mesh.faces, uvs=None), report
