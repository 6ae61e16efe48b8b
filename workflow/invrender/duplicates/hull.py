"""The shared mesh as a visual hull: carved in the object frame from every instance's mask and pose.

Structure from Duplicates (section 4) turns N copies of one object in one image into N virtual
cameras around a single object: instance i's pose T_cam_from_obj is a camera looking at the object
frame, and its mask is that camera's silhouette. A point of the object frame that projects onto
background in some instance's view cannot be part of the object: carving those away from a box
leaves the visual hull, the largest shape consistent with every silhouette.

The field. Per instance, a signed distance image of its silhouette (exact Euclidean distance
transform, positive inside, zero on the pixel edges between inside and outside), sampled bilinearly
at every voxel centre's projection and scaled from pixels to object units at the voxel's depth
(pixels x z / fx): the distance from the voxel to the silhouette's cone, measured across the line of
sight. Its zero level set is the cone's surface to sub-voxel accuracy, so marching cubes gets a
smooth field, not a staircase of inside/outside voxels (this is the anti-aliasing: no sub-samples
are needed).

What may carve. Only background pixels (id 0) inside the image: a pixel of another instance may be
that instance occluding this one, and outside the image nothing was seen; both count as inside.

The vote. A wrong pose projects the hull a little off its silhouette and that view carves away
true surface. Per voxel the field is the (k+1)-th smallest distance over the instances: a voxel is
kept unless more than k instances put it outside their silhouette, so k bad poses cannot cut the
object (the price: a hull up to k views looser). Default k = n // 10.

What no hull can recover: concavities (a bowl's hollow, the inside of a handle, a can's recessed
top), which no silhouette sees. docs/duplicates-hull.md says more.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np
import pymeshlab
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from skimage.measure import marching_cubes

from ..scene.types import Mesh

__all__ = [
    "EmptyHull",
    "HullGrid",
    "carve",
    "hull_mesh",
    "visual_hull",
    "bounds_from_points",
    "bounds_from_masks",
    "default_vote",
    "signed_volume",
    "DEFAULT_TARGET_FACES",
]

log = logging.getLogger(__name__)

DEFAULT_TARGET_FACES = 5_000  # the shared object alone: refinement renders it N times per step
CLIP_VOXELS = 8.0  # the field is clipped to +-this many voxels: only its zero crossing matters
UNSEEN = np.float32(np.inf)  # a view that did not see the voxel (behind the camera): no vote
SLAB_VOXELS = 1 << 18  # voxels per batch: (instances x this) float32 distances at a time


@dataclass
class HullGrid:
    """The carved field on a regular grid in the object frame."""

    field: np.ndarray  # (nx, ny, nz) float32, object units: > 0 inside the hull, 0 on its surface
    origin: np.ndarray  # (3,) float64: the centre of voxel (0, 0, 0), object frame
    spacing: float  # voxel edge, object units
    k: int  # how many instances may call a kept voxel outside
    observed: np.ndarray  # (nx, ny, nz) uint16: instances whose image holds the voxel's projection

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The grid's extent: from the first voxel's lower faces to the last voxel's upper faces."""
        lo = self.origin - 0.5 * self.spacing
        return lo, lo + self.spacing * np.asarray(self.field.shape, np.float64)

    def centres(self, index) -> np.ndarray:
        """Object-frame centres of voxels at (..., 3) integer indices."""
        return self.origin + self.spacing * np.asarray(index, np.float64)

    def inside(self) -> np.ndarray:
        return self.field > 0


def default_vote(n: int) -> int:
    """How many instances may disagree: about one in ten (0 below ten instances)."""
    return max(0, int(n) // 10)


# ---------------------------------------------------------------------------- checks


def _check_inputs(ids, poses, K, bounds):
    ids = np.asarray(ids)
    if ids.ndim != 2 or not np.issubdtype(ids.dtype, np.integer):
        raise ValueError(f"carve: ids must be an (H, W) integer instance id image, got {ids.dtype} {ids.shape}")
    if not poses:
        raise ValueError("carve: no instance poses")
    K = np.asarray(K, np.float64)
    if K.shape != (3, 3) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ValueError(f"carve: K must be a 3 x 3 pinhole matrix with positive focal lengths, got {K.tolist()}")
    present = set(np.unique(ids).tolist())
    for i, T in poses.items():
        T = np.asarray(T, np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError(f"carve: the pose of instance {i} must be a finite 4 x 4 T_cam_from_obj")
        if int(i) == 0 or int(i) not in present:
            # its silhouette would be empty and carve everything away
            raise ValueError(f"carve: instance {i} has a pose but no pixels in the id image (ids {sorted(present)})")
    lo, hi = (np.asarray(b, np.float64).reshape(3) for b in bounds)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
        raise ValueError(f"carve: bounds must be finite with lo < hi on every axis, got {lo.tolist()}, {hi.tolist()}")
    return ids, {int(i): np.asarray(T, np.float64) for i, T in poses.items()}, K, lo, hi


# ---------------------------------------------------------------------------- carving


def _grid(lo, hi, resolution: int):
    """Cubic voxels, ``resolution`` along the longest side of the bounds (a can is not a cube)."""
    spacing = float((hi - lo).max()) / int(resolution)
    shape = np.maximum(1, np.ceil((hi - lo) / spacing - 1e-9)).astype(int)
    centre = 0.5 * (lo + hi)
    origin = centre - 0.5 * spacing * (shape - 1)  # the grid centred on the bounds
    return origin, spacing, tuple(int(s) for s in shape)


def _silhouette_distance(ids, instance: int, box) -> np.ndarray:
    """Signed distance (pixels) to the carvable region, over the crop ``box`` = (x0, y0, x1, y1)
    (pixel indices, may reach outside the image): > 0 where the view may not carve (the instance,
    any other instance, outside the image), < 0 on background, 0 on the edges between pixels."""
    x0, y0, x1, y1 = box
    h, w = ids.shape
    background = np.zeros((y1 - y0, x1 - x0), bool)  # outside the image: not carvable
    sx0, sy0, sx1, sy1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
    if sx1 > sx0 and sy1 > sy0:
        background[sy0 - y0 : sy1 - y0, sx0 - x0 : sx1 - x0] = ids[sy0:sy1, sx0:sx1] == 0
    # distances between pixel centres; an inside and an outside neighbour are 1 apart and the edge
    # between them is half way, so each side is shifted by half a pixel towards it
    inside = ndimage.distance_transform_edt(~background) - 0.5
    outside = ndimage.distance_transform_edt(background) - 0.5
    return np.where(background, -outside, inside).astype(np.float32)


def _crop_box(T, K, lo, hi, shape_hw, margin: int = 3):
    """Pixel box around the projection of the bounds' corners, or None if a corner is behind
    the camera (then the whole image, padded, is used)."""
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    cam = corners @ T[:3, :3].T + T[:3, 3]
    h, w = shape_hw
    if np.any(cam[:, 2] <= 0):
        return (-margin, -margin, w + margin, h + margin)
    uv = (cam @ K.T)[:, :2] / cam[:, 2:3]
    x0, y0 = np.floor(uv.min(axis=0) - 0.5).astype(int) - margin
    x1, y1 = np.ceil(uv.max(axis=0) + 0.5).astype(int) + margin
    # a corner far outside the image (a grazing view) would make a huge crop: nothing there is seen
    x0, y0 = max(x0, -margin), max(y0, -margin)
    x1, y1 = min(x1, w + margin), min(y1, h + margin)
    return (int(x0), int(y0), int(max(x1, x0 + 1)), int(max(y1, y0 + 1)))


def _projective_rows(T, K, box, origin, spacing):
    """Rows of the voxel-index -> crop-array homogeneous map: (h_u, h_v, h_w) = M [i, j, k, 1],
    array coordinates (h_u / h_w, h_v / h_w), h_w = the camera depth z. Pixel (x, y)'s centre is
    (x + 0.5, y + 0.5), so array coordinate = pixel coordinate - 0.5 - the crop's corner."""
    shift = np.array([[1.0, 0.0, -0.5 - box[0]], [0.0, 1.0, -0.5 - box[1]], [0.0, 0.0, 1.0]])
    P = shift @ K @ T[:3]  # object point -> homogeneous array coordinates
    M = np.empty((3, 4))
    M[:, :3] = P[:, :3] * spacing
    M[:, 3] = P[:, :3] @ origin + P[:, 3]
    return M


def _affine(row, ix, ny, nz) -> np.ndarray:
    """row . [i, j, k, 1] over the slab (len(ix), ny, nz), float32, in three broadcast adds."""
    f = np.float32
    out = np.empty((len(ix), ny, nz), f)
    out[:] = (f(row[0]) * ix.astype(f) + f(row[3]))[:, None, None]
    out += (f(row[1]) * np.arange(ny, dtype=f))[None, :, None]
    out += (f(row[2]) * np.arange(nz, dtype=f))[None, None, :]
    return out


def _view_distance(sd, M, fx, ix, ny, nz) -> np.ndarray:
    """One view's signed distance (object units) at the slab's voxel centres: the silhouette's
    distance image sampled bilinearly at their projections, times depth / fx; UNSEEN behind."""
    z = _affine(M[2], ix, ny, nz)
    front = z > 0
    inv = np.reciprocal(np.where(front, z, np.float32(1.0)))
    u = (_affine(M[0], ix, ny, nz) * inv).reshape(-1, nz)
    v = (_affine(M[1], ix, ny, nz) * inv).reshape(-1, nz)
    pixels = cv2.remap(sd, u, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).reshape(z.shape)
    out = pixels * (z / np.float32(fx))
    if not front.all():
        out[~front] = UNSEEN
    return out


def carve(ids, poses: dict, K, bounds, resolution: int = 128, k: int | None = None, floors=()) -> HullGrid:
    """The visual hull's field over ``bounds`` = (lo (3,), hi (3,)) in the object frame.

    ``ids``: (H, W) instance id image (0 = background); ``poses``: {instance id: T_cam_from_obj
    (4, 4)} of the instances that carve (ids without a pose only shield their pixels); ``K``: the
    one real camera's 3 x 3 intrinsics (COLMAP pixels); ``resolution``: voxels along the longest
    side of the bounds; ``k``: instances allowed to disagree (default ``default_vote(n)``);
    ``floors``: planes (normal (3,), offset) in the object frame, each the support some copy
    rests on: what lies below one (n . x < offset) is outside, whatever the vote (floor.py).
    """
    ids, poses, K, lo, hi = _check_inputs(ids, poses, K, bounds)
    k = default_vote(len(poses)) if k is None else int(k)
    k = min(max(k, 0), len(poses) - 1)
    origin, spacing, shape = _grid(lo, hi, resolution)
    clip = np.float32(CLIP_VOXELS * spacing)

    views = []
    for i, T in sorted(poses.items()):
        box = _crop_box(T, K, lo, hi, ids.shape)
        views.append((_silhouette_distance(ids, i, box), _projective_rows(T, K, box, origin, spacing)))

    field = np.empty(shape, np.float32)
    observed = np.empty(shape, np.uint16)
    nx, ny, nz = shape
    slab = max(1, SLAB_VOXELS // (ny * nz))
    for x0 in range(0, nx, slab):
        ix = np.arange(x0, min(x0 + slab, nx))
        distances = np.stack([_view_distance(sd, M, K[0, 0], ix, ny, nz) for sd, M in views])
        observed[ix] = np.isfinite(distances).sum(axis=0)
        kth = distances.min(axis=0) if k == 0 else np.partition(distances, k, axis=0)[k]
        if len(floors):
            centres = origin + spacing * np.stack(np.meshgrid(ix, np.arange(ny), np.arange(nz), indexing="ij"), -1)
            above = np.min([centres @ np.asarray(n, np.float64) - d for n, d in floors], axis=0)
            kth = np.minimum(kth, above.astype(np.float32))
        field[ix] = np.clip(kth, -clip, clip)
    return HullGrid(field=field, origin=origin, spacing=spacing, k=k, observed=observed)


# ---------------------------------------------------------------------------- meshing


def signed_volume(positions, faces) -> float:
    """Volume enclosed by a closed triangle mesh: positive when its faces wind counter-clockwise
    seen from outside (outward normals)."""
    p = np.asarray(positions, np.float64)[np.asarray(faces, np.int64)]
    return float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0)


def _largest_component(verts, faces):
    """The connected piece with the most faces (a hull may leave crumbs where few views reach)."""
    n = len(verts)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]]])
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    count, label = connected_components(graph, directed=False)
    if count > 1:
        face_label = label[faces[:, 0]]
        keep_label = np.bincount(face_label).argmax()
        faces = faces[face_label == keep_label]
        log.info("hull: kept the largest of %d connected pieces (%d faces)", count, len(faces))
    used, inverse = np.unique(faces, return_inverse=True)
    return verts[used], inverse.reshape(-1, 3)


def _topology(ms: pymeshlab.MeshSet) -> dict:
    m = ms.get_topological_measures()
    return {key: int(m[key]) for key in ("boundary_edges", "non_two_manifold_edges", "connected_components_number")}


class EmptyHull(ValueError):
    """Every voxel was carved: the poses, masks or bounds disagree (the caller says which input)."""


def hull_mesh(
    grid: HullGrid,
    target_faces: int = DEFAULT_TARGET_FACES,
    smoothing_steps: int = 10,
) -> Mesh:
    """The hull's surface in the object frame: marching cubes on the field, the largest piece,
    Taubin smoothing (no shrinkage, unlike plain Laplacian), quadric simplification to
    ``target_faces``; watertight, faces wound counter-clockwise seen from outside."""
    if not np.any(grid.field > 0):
        raise EmptyHull("hull_mesh: the hull is empty: every voxel was carved (poses, masks or bounds disagree)")
    # one carved layer all round closes the surface where the hull meets the bounds
    clip = CLIP_VOXELS * grid.spacing
    padded = np.pad(grid.field, 1, constant_values=-clip)
    verts, faces, _, _ = marching_cubes(padded, level=0.0, spacing=(grid.spacing,) * 3, allow_degenerate=False)
    verts = verts.astype(np.float64) + (grid.origin - grid.spacing)
    verts, faces = _largest_component(verts, faces.astype(np.int64))

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=verts, face_matrix=faces.astype(np.int32)), "hull")
    ms.meshing_remove_duplicate_vertices()
    ms.meshing_remove_null_faces()
    if smoothing_steps > 0:
        ms.apply_coord_taubin_smoothing(lambda_=0.5, mu=-0.53, stepsmoothnum=int(smoothing_steps))
    if ms.current_mesh().face_number() > target_faces:
        ms.meshing_decimation_quadric_edge_collapse(
            targetfacenum=int(target_faces),
            qualitythr=0.3,
            optimalplacement=True,
            preservenormal=True,
            preservetopology=True,
            planarquadric=True,
            autoclean=True,
        )
    ms.meshing_remove_unreferenced_vertices()
    topology = _topology(ms)
    if topology["boundary_edges"] or topology["non_two_manifold_edges"]:
        log.warning("hull: the mesh is not watertight after simplification: %s", topology)
    mesh = ms.current_mesh()
    positions, faces = mesh.vertex_matrix(), mesh.face_matrix().astype(np.int32)
    if signed_volume(positions, faces) < 0:  # marching cubes' winding depends on its conventions
        faces = faces[:, ::-1].copy()
    log.info(
        "hull: %d vertices, %d faces, volume %.6g (grid %s, voxel %.4g, k = %d)",
        len(positions),
        len(faces),
        signed_volume(positions, faces),
        grid.field.shape,
        grid.spacing,
        grid.k,
    )
    return Mesh(positions=positions.astype(np.float32), faces=faces, uvs=None)


def visual_hull(
    ids,
    poses: dict,
    K,
    bounds,
    resolution: int = 128,
    k: int | None = None,
    target_faces: int = DEFAULT_TARGET_FACES,
    smoothing_steps: int = 10,
    refit: bool = True,
    floors=(),
) -> tuple[Mesh, HullGrid]:
    """``carve`` then ``hull_mesh``. With ``refit``, a coarse carve first shrinks loose bounds
    (COLMAP's points, or the masks' cones) to the hull plus two coarse voxels, so the fine grid
    spends its voxels on the object."""
    if refit:
        coarse = carve(ids, poses, K, bounds, resolution=max(16, int(resolution) // 4), k=k)
        bounds = _refit_bounds(coarse, bounds)
    grid = carve(ids, poses, K, bounds, resolution=resolution, k=k, floors=floors)
    return hull_mesh(grid, target_faces=target_faces, smoothing_steps=smoothing_steps), grid


def _refit_bounds(grid: HullGrid, bounds):
    inside = grid.inside()
    if not inside.any():
        return bounds
    label, count = ndimage.label(inside)
    if count > 1:
        inside = label == np.bincount(label.ravel())[1:].argmax() + 1
    index = np.argwhere(inside)
    lo0, hi0 = (np.asarray(b, np.float64) for b in bounds)
    touches = np.any(index.min(axis=0) == 0) or np.any(index.max(axis=0) == np.asarray(inside.shape) - 1)
    if touches:
        log.warning("hull: the hull reaches the bounds %s .. %s: they may cut the object", lo0.tolist(), hi0.tolist())
    lo = grid.centres(index.min(axis=0)) - 2.5 * grid.spacing
    hi = grid.centres(index.max(axis=0)) + 2.5 * grid.spacing
    return np.maximum(lo, lo0), np.minimum(hi, hi0)


# ---------------------------------------------------------------------------- bounds


def bounds_from_points(points3d, percentiles=(1.0, 99.0), margin: float = 0.25, reach: float = 4.0):
    """Robust bounds of COLMAP's sparse points (object frame). Points farther from the median
    point than ``reach`` x the median such distance are outliers (the ends of a stick are 2x,
    stray triangulations far more); of the rest, the per-axis percentiles, widened by ``margin``
    x their extent on every side (the points lie on textured surface only, and the percentiles
    cut the object's extremes with the last outliers)."""
    points = np.asarray(points3d, np.float64).reshape(-1, 3)
    points = points[np.all(np.isfinite(points), axis=1)]
    if len(points) >= 4:
        distance = np.linalg.norm(points - np.median(points, axis=0), axis=1)
        points = points[distance <= reach * np.median(distance)]
    if len(points) < 4:
        raise ValueError(f"bounds_from_points: need at least 4 finite points, got {len(points)}")
    lo, hi = np.percentile(points, percentiles, axis=0)
    extent = np.maximum(hi - lo, 1e-6 * max(float((hi - lo).max()), 1e-12))
    return lo - margin * extent, hi + margin * extent


def _mask_centroids(ids, instances):
    """Per instance: the centroid of its mask in COLMAP pixels and the pixel coordinates of its pixels."""
    out = {}
    for i in instances:
        y, x = np.nonzero(ids == i)
        xy = np.stack([x + 0.5, y + 0.5], axis=1)
        out[i] = (xy.mean(axis=0), xy)
    return out


def bounds_from_masks(ids, poses: dict, K, margin: float = 0.25):
    """Bounds from the poses and masks alone (no sparse points): the object's centre is the point
    nearest every instance's ray through its mask centroid (in the object frame; least squares),
    and its radius is the farthest mask pixel from that centre's projection, back-projected at
    the centre's depth, largest over the instances; a cube of that half-size, widened by
    ``margin``."""
    ids = np.asarray(ids)
    K = np.asarray(K, np.float64)
    Kinv = np.linalg.inv(K)
    masks = _mask_centroids(ids, poses)
    A, b = np.zeros((3, 3)), np.zeros(3)
    for i, T in poses.items():
        T = np.asarray(T, np.float64)
        R, t = T[:3, :3], T[:3, 3]
        centre_cam = -R.T @ t  # the camera centre in the object frame
        d = R.T @ (Kinv @ np.append(masks[i][0], 1.0))
        d /= np.linalg.norm(d)
        P = np.eye(3) - np.outer(d, d)  # distance to the ray = |P (c - centre_cam)|
        A += P
        b += P @ centre_cam
    if np.linalg.cond(A) > 1e8:
        raise ValueError("bounds_from_masks: the instances' rays are parallel: no centre (need varied poses)")
    centre = np.linalg.solve(A, b)
    radius = 0.0
    for i, T in poses.items():
        T = np.asarray(T, np.float64)
        c = T[:3, :3] @ centre + T[:3, 3]
        if c[2] <= 0:
            continue
        uv = (K @ c)[:2] / c[2]
        reach = np.linalg.norm(masks[i][1] - uv, axis=1).max() + 1.0  # the pixel's far corner
        radius = max(radius, reach * c[2] / K[0, 0])
    if radius <= 0:
        raise ValueError("bounds_from_masks: the centre is behind every camera")
    half = radius * (1.0 + margin)
    return centre - half, centre + half
