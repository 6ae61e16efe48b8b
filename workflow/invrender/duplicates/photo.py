"""Photo-consistency along the hull's normals: surface points where the copies' pixels agree, for
snap.py where COLMAP's matches left none (`hull_photo`).

COLMAP triangulates only what ASIFT matched, and whole faces of the hull can go without a point
(box-10-hd: 367 of 2002 vertices reached). Every copy that sees a stretch of surface shows the
same print there, so the surface is where their pixels agree. For each vertex x with normal n of
the (snapped) hull, a small square of the tangent plane (PATCH x PATCH samples, about a pixel
apart in the nearest copy's view) is moved along n by offsets d in [-reach, reach]; at each d
every copy that faces the square (MIN_FACING) and owns its pixels (MIN_OWNED: no neighbour in
front) samples it bilinearly in the grey photograph; the most frontal one is the reference, and
the score is the mean normalised cross-correlation of the others' samples with it. NCC is blind
to a gain and an offset, so the copies' different shading (each faces the sky another way) does
not matter. The best d, refined by a parabola through its neighbours, gives the point x + d n
when the score is high (MIN_SCORE), the peak is inside the range, the reference square has
texture (MIN_CONTRAST: a plain face correlates as well at any d) and MIN_VIEWS copies took part.

Measured on the HD boxes (docs/duplicates-hull.md, "Photo-consistent points"): on the snapped
hull of box-10-hd 640 points, box-6-hd 440; snapping the floor-carved hull onto COLMAP's and these
points together takes the Chamfer distance from 0.0060 to 0.0046 (box-10-hd) and from 0.0209 to
0.0178 (box-6-hd) of the diagonal.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np

from ..scene.types import Mesh
from .refine import project
from .snap import vertex_normals

__all__ = ["PhotoReport", "consistent_points"]

log = logging.getLogger(__name__)

PATCH = 9  # samples per side of the square
STEPS = 41  # offsets along the normal
MIN_SCORE = 0.7  # mean NCC at the best offset
MIN_CONTRAST = 0.02  # standard deviation of the reference's grey samples (display-referred, 0..1)
MIN_VIEWS = 2  # copies that see the square, the reference included
MIN_FACING = 0.2  # cosine between the normal and the direction to the camera (78 degrees)
MIN_OWNED = 0.7  # share of the square's samples on the copy's own pixels
REMAP_WIDTH = 4096


@dataclass
class PhotoReport:
    vertices: int
    tried: int  # vertices seen by MIN_VIEWS copies with texture
    kept: int  # points returned
    score_median: float

    def as_dict(self) -> dict:
        return self.__dict__.copy()


def _tangent_basis(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(normals, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, np.cross(normals, u)


def _project(K, T, points):
    """refine.project for points of any leading shape (..., 3)."""
    uv, z = project(K, T, points.reshape(-1, 3))
    return uv.reshape(*points.shape[:-1], 2), z.reshape(points.shape[:-1])


def _sample(gray32: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear samples at pixel coordinates (pixel x covers [x, x + 1)); NaN outside."""
    flat = uv.reshape(-1, 2).astype(np.float32) - 0.5
    n = len(flat)
    width = REMAP_WIDTH
    padded = np.full((-(-n // width) * width, 2), -1e4, np.float32)  # cv2.remap's maps: under 32767 rows
    padded[:n] = flat
    maps = padded.reshape(-1, width, 2)
    out = cv2.remap(
        gray32, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan
    )
    return out.reshape(-1)[:n].reshape(uv.shape[:-1])


def _contrast(samples: np.ndarray) -> np.ndarray:
    """Standard deviation of each row's samples; 0 for a row no copy sampled (all NaN)."""
    seen = np.isfinite(samples).all(axis=1)
    out = np.zeros(len(samples))
    out[seen] = samples[seen].std(axis=1)
    return out


def _normalised(samples: np.ndarray) -> np.ndarray:
    centred = samples - samples.mean(axis=-1, keepdims=True)
    return centred / np.maximum(np.linalg.norm(centred, axis=-1, keepdims=True), 1e-9)


def _visibility(positions, normals, poses, K, ids, grid):
    """Per copy (V,) bool: it faces vertex v and owns the square's pixels at d = 0; and per vertex
    the most frontal such copy's id (-1: none)."""
    instances = sorted(poses)
    facing = np.zeros((len(instances), len(positions)))
    usable = np.zeros((len(instances), len(positions)), bool)
    height, width = ids.shape
    for k, i in enumerate(instances):
        T = poses[i]
        centre = -T[:3, :3].T @ T[:3, 3]
        view = centre - positions
        facing[k] = np.einsum("ij,ij->i", normals, view) / np.linalg.norm(view, axis=1)
        uv, z = _project(K, T, positions[:, None, :] + grid)
        x, y = np.floor(uv[..., 0]).astype(np.int64), np.floor(uv[..., 1]).astype(np.int64)
        inside = (x >= 0) & (y >= 0) & (x < width) & (y < height) & (z > 0)
        owned = np.zeros(x.shape, bool)
        owned[inside] = ids[y[inside], x[inside]] == i
        usable[k] = (facing[k] > MIN_FACING) & (owned.mean(axis=1) >= MIN_OWNED)
    reference = np.where(usable.any(0), np.argmax(np.where(usable, facing, -np.inf), axis=0), -1)
    return instances, usable, reference


def consistent_points(
    mesh: Mesh, poses: dict, K, gray: np.ndarray, ids: np.ndarray, reach: float = 0.03
) -> tuple[np.ndarray, PhotoReport]:
    """Points (m, 3) in the mesh's frame where the copies' pixels agree (module docstring).
    ``poses``: {instance id: T_cam_from_obj in the mesh's frame}; ``gray``: the photograph's grey
    (adjust.gray_image); ``ids``: its instance-id image; ``reach``: of the mesh's diagonal."""
    positions = np.asarray(mesh.positions, np.float64)
    normals = vertex_normals(positions, np.asarray(mesh.faces, np.int64))
    limit = reach * float(np.linalg.norm(np.ptp(positions, axis=0)))
    offsets = np.linspace(-limit, limit, STEPS)
    u, v = _tangent_basis(normals)
    # a pixel of the nearest copy in object units: the squares are sampled about a pixel apart
    depth = min(float(np.median(_project(K, T, positions)[1])) for T in poses.values())
    step = depth / K[0, 0]
    a = (np.arange(PATCH) - (PATCH - 1) / 2) * step
    grid = (a[:, None, None, None] * u[None, None] + a[None, :, None, None] * v[None, None]).reshape(
        PATCH * PATCH, -1, 3
    )
    grid = np.transpose(grid, (1, 0, 2))  # (V, S, 3)
    instances, usable, reference = _visibility(positions, normals, poses, K, ids, grid)
    gray32 = np.asarray(gray, np.float32)
    squares = positions[:, None, None, :] + offsets[None, :, None, None] * normals[:, None, None, :] + grid[:, None]
    samples = {}
    for k, i in enumerate(instances):
        rows = np.flatnonzero(usable[k])
        if len(rows):
            samples[k] = (rows, _sample(gray32, _project(K, poses[i], squares[rows])[0]))  # (r, D, S)
    ref = np.full((len(positions), STEPS, PATCH * PATCH), np.nan, np.float32)
    for k, (rows, values) in samples.items():
        mine = reference[rows] == k
        ref[rows[mine]] = values[mine]
    contrast = _contrast(ref[:, STEPS // 2])
    views = usable.sum(0)
    tried = (reference >= 0) & (views >= MIN_VIEWS) & (contrast >= MIN_CONTRAST)
    ref_n = _normalised(ref)
    total, count = np.zeros((len(positions), STEPS)), np.zeros(len(positions))
    for k, (rows, values) in samples.items():
        others = rows[(reference[rows] != k) & tried[rows]]
        if not len(others):
            continue
        pick = np.searchsorted(rows, others)
        ncc = np.einsum("rds,rds->rd", _normalised(values[pick]), ref_n[others])
        total[others] += np.nan_to_num(ncc, nan=-1.0)
        count[others] += 1
    score = total / np.maximum(count, 1)[:, None]
    best = np.argmax(score, axis=1)
    inner = (best > 0) & (best < STEPS - 1)
    peak = score[np.arange(len(best)), best]
    keep = tried & inner & (peak >= MIN_SCORE)
    rows = np.flatnonzero(keep)
    left, mid, right = (score[rows, best[rows] + s] for s in (-1, 0, 1))
    curvature = left - 2 * mid + right
    shift = np.where(curvature < 0, 0.5 * (left - right) / np.where(curvature < 0, curvature, -1.0), 0.0)
    d = offsets[best[rows]] + np.clip(shift, -0.5, 0.5) * (offsets[1] - offsets[0])
    points = positions[rows] + d[:, None] * normals[rows]
    report = PhotoReport(
        vertices=int(len(positions)),
        tried=int(tried.sum()),
        kept=int(len(rows)),
        score_median=float(np.median(peak[rows])) if len(rows) else float("nan"),
    )
    log.info("photo-consistency: %d of %d vertices tried, %d points kept", report.tried, report.vertices, report.kept)
    return points, report
