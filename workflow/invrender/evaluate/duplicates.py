"""A duplicates scene against its truth: masks, poses and the shared mesh.

The recovered poses live in the capture camera's world (the truth's world for a synthetic
capture), but the recovered object frame and the scale are arbitrary: the shared mesh is carved in
whatever frame COLMAP's first virtual camera gave, at whatever scale fixed it. So every metric
first aligns what cannot be known:

1. Masks (``match_instances``): IoU of every recovered instance with every true one, matched by the
   Hungarian assignment (scipy's ``linear_sum_assignment``) on IoU; a pair below ``MIN_IOU`` is no
   match. The matching also names the true instance of each recovered pose.
2. Rotations (``rotation_metrics``): with R_i world-from-object, the recovered R'_i = R_i Q for one
   unknown Q (the recovered object frame in the true one). Q is the chordal mean (the sum projected
   on SO(3) by SVD) of R_i^T R'_i over the matched registered instances, started at their medoid and
   re-estimated from those within ``max(3 x median, ROBUST_FLOOR_DEG)`` of it (a flipped can does
   not tilt everybody else). The error of instance i is the geodesic angle of
   E_i = R_i^T R'_i Q^T (in the true object frame). For a symmetric object, E_i = S_i T_i with T_i a
   twist about the axis a and S_i the swing that tilts it; the error with the symmetry modded out
   (min over twists of the angle) is the angle between R_i a and R'_i b, b the axis in the recovered
   frame, estimated from the axes alone (a wrong twist does not move it).
3. Translations (``translation_metrics``): instance centres (the recovered mesh's area-weighted
   surface centroid c' mapped by each recovered pose, and the point p of the true object frame that
   c' is mapped by each true pose) aligned by Umeyama's similarity (rotation, translation, scale;
   recovered -> true), started from the three instances whose fit has the least median residual and
   trimmed like Q (floor ``ROBUST_FLOOR_FRACTION`` of the diagonal); the error is the distance after
   it, in the truth's meters and as a fraction of the true object's bounding-box diagonal. p comes
   from the poses alone (``corresponding_point``: the p whose centres the recovered ones match best),
   not from the true mesh's centroid: a recovered shape's centroid is not the truth's (a visual hull
   bulges where no silhouette grazes it: 3 mm off on box-10-hd), and taking it for the true one
   charged every copy an error that turns with it (box-10-hd: 0.018 of the diagonal, 0.007 with p).
4. Mesh (``chamfer``): the recovered mesh mapped into the true object frame by p = s Q p' + o (Q from
   2., s from 3., o first putting the recovered centroid on the point of 3., then moved by a
   translation-only trimmed ICP of the recovered surface onto the true one, ``SHAPE_KEEP``). The
   poses fix Q and s well, but o poorly: each copy's depth is off by about a millimetre, and copies
   turned about one axis leave a shift along it to the weak pull of 3. (box-10-hd: COLMAP's points,
   0.07 mm from the truth after their own best similarity, were 0.57 mm from it at the poses' o,
   0.12 mm after the shift). The rotation stays the poses': a whole-surface ICP turns a hull with
   bulges on one side by a degree. Every surface comparison of the appearance (the albedo looked
   up at the same point, the copies rearranged) uses this alignment; the symmetric Chamfer distance
   is the mean of the two directed mean distances from area-weighted random surface samples to the
   other surface (exact point-to-triangle distances, ``correspond.py``'s search); then again after a
   rigid trimmed point-to-plane ICP (``icp``, no twist about a symmetry axis) from there, which
   says how much of it is the poses' rotation rather than the shape.
"""

from __future__ import annotations

import json
from itertools import combinations
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from ..scene.atlas import triangle_areas
from ..scene.types import Mesh, SceneError
from .correspond import _candidates, _face_normals, _nearest, surface_samples

__all__ = [
    "PAPER_TABLE2",
    "MIN_IOU",
    "ROBUST_FLOOR_DEG",
    "ROBUST_FLOOR_FRACTION",
    "rotation_angle_deg",
    "project_to_rotation",
    "robust_rotation_mean",
    "twist_swing_deg",
    "umeyama",
    "robust_umeyama",
    "iou_table",
    "match_instances",
    "mask_metrics",
    "rotation_metrics",
    "translation_metrics",
    "corresponding_point",
    "surface_centroid",
    "sample_surface",
    "distance_to_surface",
    "chamfer",
    "icp",
    "load_inputs",
    "evaluate",
    "outline_figure",
]

MIN_IOU = 0.5  # a recovered mask is the same instance as a true one from this IoU on (COCO's lowest)
ROBUST_FLOOR_DEG = 5.0  # rotations this near the alignment always take part in it
ROBUST_FLOOR_FRACTION = 0.1  # centres this near (of the object's diagonal) always take part in theirs
CHAMFER_SAMPLES = 10_000  # per surface: the mean distance to about 1 % of its spread (1 / sqrt n)
ICP_SAMPLES = 2_000
ICP_ITERATIONS = 10  # point-to-plane: exact cases converge in 3-4
# The object frame's offset is refined on the surface by a translation-only ICP of this fraction of
# the recovered samples nearest the truth: a hull's bulges (box-10-hd: a fifth of its surface more
# than 2 mm out) are left out, the faces the points fixed are fitted (module docstring 4.)
SHAPE_KEEP = 0.8
DISTANCE_GRID = 20_000  # grid samples per surface for the exact nearest-point search
# SfD (NeurIPS 2023) Table 2, "color box" scenes, per copy count: rotation in degrees, translation
# ("length") and Chamfer distance in the paper's (unstated) units; the rotation's definition is not
# given either (docs/evaluate.md compares).
PAPER_TABLE2 = {
    "6": {"rotation_deg": 2.515, "translation": 0.070, "chamfer": 0.025},
    "10": {"rotation_deg": 0.186, "translation": 0.003, "chamfer": 0.029},
    "20": {"rotation_deg": 0.299, "translation": 0.005, "chamfer": 0.021},
}


# --- rotations -------------------------------------------------------------------------------


def rotation_angle_deg(R) -> np.ndarray:
    """Geodesic angle of rotation matrices (..., 3, 3) in degrees, by atan2 of sin and cos: exact
    near 0 (where arccos of the trace loses half the digits) as near 180."""
    R = np.asarray(R, np.float64)
    v = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    cos = (np.trace(R, axis1=-2, axis2=-1) - 1) / 2
    return np.degrees(np.arctan2(np.linalg.norm(v, axis=-1) / 2, cos))


def project_to_rotation(M) -> np.ndarray:
    """The rotation nearest M in the Frobenius norm (SVD, the reflection removed)."""
    U, _, Vt = np.linalg.svd(np.asarray(M, np.float64))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    return U @ D @ Vt


def _trimmed(errors_of, mean_of, start, count: int, floor: float, iterations: int = 20):
    """A robust mean: from ``start``, the mean of the members whose error is at most
    max(3 x median error, floor), until the members stop changing. Returns (mean, inliers)."""
    estimate = start
    inliers = np.ones(count, bool)
    for _ in range(iterations):
        errors = errors_of(estimate)
        now = errors <= max(3 * float(np.median(errors)), floor)
        estimate = mean_of(now)
        if np.array_equal(now, inliers):
            break
        inliers = now
    return estimate, inliers


def robust_rotation_mean(Rs, floor_deg: float = ROBUST_FLOOR_DEG) -> tuple[np.ndarray, np.ndarray]:
    """The chordal mean of rotations (n, 3, 3), started at their medoid (the one with the least
    median angle to the others) and trimmed (``_trimmed``). Returns (mean, inliers (n,) bool)."""
    Rs = np.asarray(Rs, np.float64)
    pairwise = rotation_angle_deg(np.einsum("iba,jbc->ijac", Rs, Rs))  # R_i^T R_j
    start = Rs[np.argmin(np.median(pairwise, axis=1))]
    return _trimmed(
        lambda M: rotation_angle_deg(np.einsum("ba,ibc->iac", M, Rs)),
        lambda keep: project_to_rotation(Rs[keep].sum(axis=0)),
        start,
        len(Rs),
        floor_deg,
    )


def _angle_deg(u, v) -> np.ndarray:
    """Angles between unit vectors (..., 3), by atan2 (exact near 0)."""
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1), np.einsum("...c,...c->...", u, v)))


def _robust_axis(us, floor_deg: float = ROBUST_FLOOR_DEG) -> tuple[np.ndarray, np.ndarray]:
    """The robust mean direction of unit vectors (n, 3), as ``robust_rotation_mean``."""
    us = np.asarray(us, np.float64)
    start = us[np.argmin(np.median(_angle_deg(us[:, None], us[None]), axis=1))]

    def mean_of(keep):
        m = us[keep].sum(axis=0)
        return m / np.linalg.norm(m)

    return _trimmed(lambda b: _angle_deg(us, b), mean_of, start, len(us), floor_deg)


def twist_swing_deg(E, axis) -> tuple[np.ndarray, np.ndarray]:
    """Rotations E (n, 3, 3) split as E = S T, T a twist about the unit ``axis`` and S the swing
    that tilts it: (|twist| degrees, swing degrees). The swing is the angle between the axis and
    E axis; the twist, of the quaternion's part along the axis (0 where E turns the axis over)."""
    a = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    q = Rotation.from_matrix(np.asarray(E, np.float64)).as_quat()  # (x, y, z, w)
    along = q[:, :3] @ a
    twist = np.degrees(2 * np.arctan2(np.abs(along), np.abs(q[:, 3])))
    swing = _angle_deg(np.broadcast_to(a, (len(q), 3)), np.asarray(E, np.float64) @ a)
    return twist, swing


# --- similarities ------------------------------------------------------------------------------


def umeyama(src, dst, scale: bool = True) -> tuple[float, np.ndarray, np.ndarray]:
    """The similarity (s, R, t) minimising sum |dst - (s R src + t)|^2 (Umeyama 1991); s = 1 with
    ``scale`` False (Kabsch). Points (n, 3), n >= 3 not on one line for a unique R."""
    src, dst = np.asarray(src, np.float64), np.asarray(dst, np.float64)
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    X, Y = src - mu_s, dst - mu_d
    U, S, Vt = np.linalg.svd(Y.T @ X / len(src))
    D = np.diag([1.0, 1.0, -1.0 if np.linalg.det(U) * np.linalg.det(Vt) < 0 else 1.0])
    R = U @ D @ Vt
    variance = (X**2).sum() / len(src)
    s = float(np.trace(np.diag(S) @ D) / variance) if scale and variance > 0 else 1.0
    return s, R, mu_d - s * R @ mu_s


def robust_umeyama(src, dst, floor: float, trials: int = 300) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """``umeyama``, robustly: started from the fit to three points with the least median residual
    over all (every triple of up to 12 points, else ``trials`` random ones; least median of
    squares), then from those within max(3 x median residual, floor) of it (at least 3), until they
    stop changing. Returns (s, R, t, inliers)."""
    src, dst = np.asarray(src, np.float64), np.asarray(dst, np.float64)

    def residuals(fit):
        s, R, t = fit
        return np.linalg.norm(dst - (s * src @ R.T + t), axis=1)

    def fit_of(keep):
        return umeyama(src[keep], dst[keep]) if keep.sum() >= 3 else umeyama(src, dst)

    n = len(src)
    if n <= 12:
        triples = np.array(list(combinations(range(n), 3)))
    else:
        rng = np.random.default_rng(0)
        triples = np.array([rng.choice(n, 3, replace=False) for _ in range(trials)])
    fits = [umeyama(src[k], dst[k]) for k in triples]
    start = fits[int(np.argmin([np.median(residuals(fit)) for fit in fits]))]
    (s, R, t), inliers = _trimmed(residuals, fit_of, start, n, floor)
    return s, R, t, inliers


# --- masks -------------------------------------------------------------------------------------


def iou_table(truth_ids, recovered_ids, truth_labels, recovered_labels) -> np.ndarray:
    """IoU (T, R) of every true instance (``truth_labels``) with every recovered one, from the
    two id images (0 = background) by one joint histogram."""
    truth_ids, recovered_ids = np.asarray(truth_ids), np.asarray(recovered_ids)
    t_index = _label_index(truth_ids, truth_labels)
    r_index = _label_index(recovered_ids, recovered_labels)
    T, R = len(truth_labels), len(recovered_labels)
    joint = np.bincount((t_index * (R + 1) + r_index).ravel(), minlength=(T + 1) * (R + 1)).reshape(T + 1, R + 1)
    intersection = joint[1:, 1:].astype(np.float64)
    union = joint[1:, :].sum(axis=1)[:, None] + joint[:, 1:].sum(axis=0)[None, :] - intersection
    return np.divide(intersection, union, out=np.zeros_like(intersection), where=union > 0)


def _label_index(ids: np.ndarray, labels) -> np.ndarray:
    """Each pixel's position + 1 in ``labels`` (0: background or an id not listed), by a lookup
    table over every uint16 id."""
    table = np.zeros(65536, np.int64)
    table[np.asarray(labels, np.int64)] = np.arange(1, len(labels) + 1)
    table[0] = 0
    return table[np.asarray(ids, np.uint16)]


def match_instances(iou: np.ndarray, truth_labels, recovered_labels, min_iou: float = MIN_IOU) -> dict[int, int]:
    """{true id: recovered id}: the Hungarian assignment maximising the summed IoU, pairs below
    ``min_iou`` dropped."""
    rows, cols = linear_sum_assignment(-np.asarray(iou, np.float64))
    return {
        int(truth_labels[r]): int(recovered_labels[c]) for r, c in zip(rows, cols, strict=True) if iou[r, c] >= min_iou
    }


def mask_metrics(truth_ids, recovered_ids, truth_labels, recovered_labels, min_iou: float = MIN_IOU) -> dict:
    """Per true instance its recovered match and IoU (0 if none); mean IoU over true instances
    (a missed one counts 0) and over the matched pairs; the unmatched of each side."""
    iou = iou_table(truth_ids, recovered_ids, truth_labels, recovered_labels)
    match = match_instances(iou, truth_labels, recovered_labels, min_iou)
    r_pos = {int(r): k for k, r in enumerate(recovered_labels)}
    rows = []
    for k, t in enumerate(truth_labels):
        r = match.get(int(t))
        rows.append({"truth_id": int(t), "recovered_id": r, "iou": float(iou[k, r_pos[r]]) if r is not None else 0.0})
    matched = [row["iou"] for row in rows if row["recovered_id"] is not None]
    return {
        "min_iou": min_iou,
        "mean_iou": float(np.mean([row["iou"] for row in rows])) if rows else 0.0,
        "mean_iou_matched": float(np.mean(matched)) if matched else None,
        "matched": len(matched),
        "unmatched_truth": [row["truth_id"] for row in rows if row["recovered_id"] is None],
        "unmatched_recovered": sorted(set(map(int, recovered_labels)) - set(match.values())),
        "instances": rows,
    }


# --- poses -------------------------------------------------------------------------------------


def _summary(values) -> dict:
    values = np.asarray(values, np.float64)
    return {"mean": float(values.mean()), "median": float(np.median(values)), "max": float(values.max())}


def rotation_metrics(R_true, R_rec, axis=None) -> dict:
    """Rotation errors of matched instances (module docstring, 2.): R_true, R_rec (n, 3, 3)
    world-from-object. With a symmetry ``axis`` (true object frame) also the twist about it, the
    swing, and the error with the symmetry modded out."""
    R_true, R_rec = np.asarray(R_true, np.float64), np.asarray(R_rec, np.float64)
    relative = np.einsum("iba,ibc->iac", R_true, R_rec)  # R_i^T R'_i = Q for a perfect recovery
    Q, inliers = robust_rotation_mean(relative)
    E = relative @ Q.T
    errors = rotation_angle_deg(E)
    out = {
        "error_deg": _summary(errors),
        "per_instance_deg": errors.tolist(),
        "Q": Q.tolist(),
        "alignment_inliers": int(inliers.sum()),
    }
    if axis is not None:
        a = np.asarray(axis, np.float64) / np.linalg.norm(axis)
        twist, swing = twist_swing_deg(E, a)
        b, axis_inliers = _robust_axis(np.einsum("iba,b->ia", relative, a))  # R'_i^T R_i a
        modded = _angle_deg(np.einsum("iab,b->ia", R_true, a), np.einsum("iab,b->ia", R_rec, b))
        out["symmetry"] = {
            "axis": a.tolist(),
            "twist_deg": _summary(twist),
            "swing_deg": _summary(swing),
            "modded_out_deg": _summary(modded),
            "per_instance": {
                "twist_deg": twist.tolist(),
                "swing_deg": swing.tolist(),
                "modded_out_deg": modded.tolist(),
            },
            "axis_in_recovered_frame": b.tolist(),
            "axis_alignment_inliers": int(axis_inliers.sum()),
        }
    return out


def corresponding_point(T_true, T_rec, c_rec, start, floor: float, rounds: int = 50) -> np.ndarray:
    """The point of the true object frame that the recovered frame's point ``c_rec`` is, from the
    poses alone (module docstring, 3.): the p whose images R_i p + t_i under the true poses the
    recovered ones' images of ``c_rec`` match best after one similarity. Alternately Umeyama's
    robust similarity at p, and p with the similarity's scale and translation by linear least
    squares at its rotation, from ``start``; a weak pull towards ``start`` (1e-3 of a copy's
    weight) decides a direction the poses cannot (every copy turned about one axis: a shift along
    it moves every centre alike)."""
    T_true, T_rec = np.asarray(T_true, np.float64), np.asarray(T_rec, np.float64)
    centres_rec = np.einsum("iab,b->ia", T_rec[:, :3, :3], c_rec) + T_rec[:, :3, 3]
    p = np.asarray(start, np.float64)
    for _ in range(rounds):
        centres_true = np.einsum("iab,b->ia", T_true[:, :3, :3], p) + T_true[:, :3, 3]
        _, R, _, inliers = robust_umeyama(centres_rec, centres_true, floor)
        n = int(inliers.sum())
        # R_true_i p - t - s R c_i = -t_true_i, unknowns (p, t, s)
        A = np.zeros((3 * n + 3, 7))
        A[: 3 * n, :3] = T_true[inliers, :3, :3].reshape(-1, 3)
        A[: 3 * n, 3:6] = -np.tile(np.eye(3), (n, 1))
        A[: 3 * n, 6] = -(centres_rec[inliers] @ R.T).ravel()
        A[3 * n :, :3] = 1e-3 * np.eye(3)
        b = np.concatenate([-T_true[inliers, :3, 3].ravel(), 1e-3 * np.asarray(start, np.float64)])
        moved = np.linalg.lstsq(A, b, rcond=None)[0][:3]
        if np.linalg.norm(moved - p) <= 1e-9 * max(floor, 1e-12):
            return moved
        p = moved
    return p


def translation_metrics(centres_true, centres_rec, diagonal: float) -> dict:
    """Centre errors after the robust similarity recovered -> true (module docstring, 3.)."""
    s, R, t, inliers = robust_umeyama(centres_rec, centres_true, ROBUST_FLOOR_FRACTION * diagonal)
    errors = np.linalg.norm(np.asarray(centres_true) - (s * np.asarray(centres_rec) @ R.T + t), axis=1)
    return {
        "error_m": _summary(errors),
        "error_fraction_of_diagonal": _summary(errors / diagonal),
        "per_instance_m": errors.tolist(),
        "similarity": {"scale": s, "rotation": R.tolist(), "translation": t.tolist()},
        "alignment_inliers": int(inliers.sum()),
    }


# --- meshes ------------------------------------------------------------------------------------


def _triangles(mesh: Mesh) -> np.ndarray:
    return np.asarray(mesh.positions, np.float64)[np.asarray(mesh.faces, np.int64)]


def surface_centroid(mesh: Mesh) -> np.ndarray:
    """The area-weighted centroid of the surface (defined for open meshes too, unlike the volume's)."""
    tri = _triangles(mesh)
    area = triangle_areas(mesh.positions, mesh.faces)
    return (tri.mean(axis=1) * area[:, None]).sum(axis=0) / area.sum()


def sample_surface(mesh: Mesh, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` points uniform on the surface: a triangle by its area, then uniform in it."""
    tri = _triangles(mesh)
    area = triangle_areas(mesh.positions, mesh.faces)
    owner = rng.choice(len(tri), size=count, p=area / area.sum())
    u, v = rng.random((2, count))
    flip = u + v > 1
    u, v = np.where(flip, 1 - u, u), np.where(flip, 1 - v, v)
    a, b, c = tri[owner, 0], tri[owner, 1], tri[owner, 2]
    return a + u[:, None] * (b - a) + v[:, None] * (c - a)


def distance_to_surface(points, mesh: Mesh, grid: int = DISTANCE_GRID) -> np.ndarray:
    """Exact distance of each point to the mesh's surface (``correspond.py``'s search: the
    nearest of a barycentric grid of samples bounds it, every triangle within that bound plus the
    grid spacing is a candidate, the exact point-triangle distances decide)."""
    points = np.asarray(points, np.float64)
    positions, faces = np.asarray(mesh.positions, np.float64), np.asarray(mesh.faces, np.int64)
    spacing = float(np.sqrt(2.0 * triangle_areas(positions, faces).sum() / grid))
    samples, owners = surface_samples(positions, faces, spacing)
    tree = cKDTree(samples)
    d_sample = tree.query(points)[0]
    rows, tris = _candidates(tree, owners, points, d_sample + spacing)
    return _nearest(positions[faces], points, rows, tris, len(points))[2]


def transformed(mesh: Mesh, scale: float, R, t) -> Mesh:
    """The mesh with positions s R p + t."""
    p = np.asarray(mesh.positions, np.float64)
    return Mesh(positions=scale * p @ np.asarray(R).T + np.asarray(t), faces=mesh.faces, uvs=None)


def chamfer(recovered: Mesh, truth: Mesh, samples: int = CHAMFER_SAMPLES, seed: int = 0) -> dict:
    """Symmetric Chamfer distance (module docstring, 4.) of two meshes in one frame, in meters:
    ``accuracy_m`` recovered -> truth, ``completeness_m`` truth -> recovered, ``chamfer_m`` their
    mean."""
    rng = np.random.default_rng(seed)
    a, b = sample_surface(recovered, samples, rng), sample_surface(truth, samples, rng)
    to_truth, to_recovered = distance_to_surface(a, truth), distance_to_surface(b, recovered)
    return {
        "chamfer_m": float((to_truth.mean() + to_recovered.mean()) / 2),
        "accuracy_m": float(to_truth.mean()),
        "completeness_m": float(to_recovered.mean()),
        "p95_m": float(np.percentile(np.concatenate([to_truth, to_recovered]), 95)),
        "samples": samples,
    }


def icp(
    source: Mesh,
    target: Mesh,
    axis=None,
    samples: int = ICP_SAMPLES,
    iterations: int = ICP_ITERATIONS,
    seed: int = 0,
    rotate: bool = True,
    keep: float = 1.0,
):
    """Rigid point-to-plane ICP (Chen and Medioni 1992) of ``source`` onto ``target``'s surface,
    from where it is: each step solves the linearised problem for a small rotation about the
    samples' centroid and a translation against the exact closest points and their triangles'
    normals (point-to-point converges linearly: 60 steps for what this does in a few). With a
    symmetry ``axis`` (target frame) the rotation is kept perpendicular to it: a can's twist
    changes the distances only through its facets, and ICP would otherwise turn it to line them up.
    ``rotate`` False: a translation only. ``keep`` < 1: each step fits only that fraction of the
    samples nearest the target along its normal (trimmed ICP, Chetverikov et al. 2002), so a part
    of the source that stands off the target (a hull's bulge) does not drag the rest towards it.
    Returns (R, t), R p + t the moved source."""
    points = sample_surface(source, samples, np.random.default_rng(seed))
    positions, faces = np.asarray(target.positions, np.float64), np.asarray(target.faces, np.int64)
    spacing = float(np.sqrt(2.0 * triangle_areas(positions, faces).sum() / DISTANCE_GRID))
    grid, owners = surface_samples(positions, faces, spacing)
    tree = cKDTree(grid)
    normals = _face_normals(positions, faces)
    # the rotations allowed: all, or those about axes perpendicular to the symmetry axis
    basis = np.eye(3) if axis is None else np.linalg.svd(np.reshape(axis, (1, 3)))[2][1:].T
    if not rotate:
        basis = np.zeros((3, 0))
    R, t = np.eye(3), np.zeros(3)
    for _ in range(iterations):
        moved = points @ R.T + t
        rows, tris = _candidates(tree, owners, moved, tree.query(moved)[0] + spacing)
        triangle, closest, _ = _nearest(positions[faces], moved, rows, tris, len(moved))
        n = normals[triangle]
        centre = moved.mean(axis=0)
        # d/d(omega, v) of (R (p - c) + c + t - q) . n at the identity, omega = basis @ w
        A = np.hstack([np.cross(moved - centre, n) @ basis, n])
        b = -np.einsum("ic,ic->i", moved - closest, n)
        if keep < 1.0:
            nearest = np.abs(b) <= np.quantile(np.abs(b), keep)
            A, b = A[nearest], b[nearest]
        step = np.linalg.lstsq(A, b, rcond=None)[0]
        omega, v = basis @ step[: basis.shape[1]], step[basis.shape[1] :]
        dR = Rotation.from_rotvec(omega).as_matrix()
        R, t = dR @ R, dR @ (t - centre) + centre + v
        if np.linalg.norm(omega) < 1e-10 and np.linalg.norm(v) < 1e-9 * spacing:
            break
    return R, t


# --- the whole evaluation on loaded inputs --------------------------------------------------------


def pose_metrics(truth_poses: dict, recovered_poses: dict, match: dict, centroids, diagonal: float, axis) -> dict:
    """Rotation and translation errors of the registered recovered instances matched to a true one.
    ``*_poses`` {id: 4x4 T_obj2world}; ``match`` {true id: recovered id}; ``centroids`` (true,
    recovered) in their object frames."""
    pairs = [(t, r) for t, r in sorted(match.items()) if r in recovered_poses and t in truth_poses]
    out = {"registered": len(recovered_poses), "evaluated": len(pairs), "pairs": [list(p) for p in pairs]}
    if not pairs:
        return {**out, "rotation": None, "translation": None}
    T_true = np.stack([truth_poses[t] for t, _ in pairs])
    T_rec = np.stack([recovered_poses[r] for _, r in pairs])
    out["rotation"] = rotation_metrics(T_true[:, :3, :3], T_rec[:, :3, :3], axis)
    if len(pairs) < 3:
        return {**out, "translation": None}
    point = corresponding_point(T_true, T_rec, centroids[1], centroids[0], ROBUST_FLOOR_FRACTION * diagonal)
    centres_true = np.einsum("iab,b->ia", T_true[:, :3, :3], point) + T_true[:, :3, 3]
    centres_rec = np.einsum("iab,b->ia", T_rec[:, :3, :3], centroids[1]) + T_rec[:, :3, 3]
    out["translation"] = translation_metrics(centres_true, centres_rec, diagonal)
    out["translation"]["corresponding_point"] = point.tolist()
    out["translation"]["centroid_offset_m"] = float(np.linalg.norm(point - centroids[0]))
    return out


def mesh_metrics(
    recovered: Mesh, truth: Mesh, poses: dict, centroids, diagonal: float, axis=None, seed: int = 0
) -> dict | None:
    """Chamfer of the recovered mesh in the true object frame (p = s Q p' + o: s and Q from
    ``poses``, ``pose_metrics``'s result, o from them and then the surface, module docstring 4.),
    before and after a rigid trimmed ICP (no twist about a symmetry ``axis``); None without a
    rotation and a similarity."""
    if poses.get("rotation") is None or poses.get("translation") is None:
        return None
    Q = np.asarray(poses["rotation"]["Q"])
    s = poses["translation"]["similarity"]["scale"]
    from_poses = np.asarray(poses["translation"]["corresponding_point"]) - s * Q @ centroids[1]
    _, shift = icp(transformed(recovered, s, Q, from_poses), truth, seed=seed, rotate=False, keep=SHAPE_KEEP)
    o = from_poses + shift
    aligned = transformed(recovered, s, Q, o)
    out = {
        "alignment": {
            "scale": s, "rotation": Q.tolist(), "offset": o.tolist(),
            "offset_from_poses": from_poses.tolist(), "surface_shift_m": float(np.linalg.norm(shift)),
        },
    }  # fmt: skip
    out.update(_with_fraction(chamfer(aligned, truth, seed=seed), diagonal))
    R, t = icp(aligned, truth, axis, seed=seed, keep=SHAPE_KEEP)
    moved = transformed(aligned, 1.0, R, t)
    out["icp"] = {
        "rotation_deg": float(rotation_angle_deg(R)),
        "translation_m": float(np.linalg.norm(t)),
        **_with_fraction(chamfer(moved, truth, seed=seed), diagonal),
    }
    return out


def _with_fraction(document: dict, diagonal: float) -> dict:
    return {**document, "chamfer_fraction_of_diagonal": document["chamfer_m"] / diagonal}


def diagonal_of(mesh: Mesh) -> float:
    p = np.asarray(mesh.positions, np.float64)
    return float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))


# --- inputs from disk ----------------------------------------------------------------------------


def symmetry_axis(metadata: dict | None) -> tuple[list[float] | None, str]:
    """The object's axis of rotational symmetry in its frame, and where it came from: the
    generator's ``object.symmetry`` ({"type", "axis": [x, y, z] or null}) when present, else +Y for
    a can (the generator's can stands on +Y; before object kinds, every object was a can)."""
    if not metadata:
        return None, "no generator metadata: no symmetry"
    obj = metadata.get("object") if isinstance(metadata.get("object"), dict) else {}
    if "symmetry" in obj:
        value = obj["symmetry"]
        axis = value.get("axis") if isinstance(value, dict) else value
        if axis is None:
            return None, "metadata.object.symmetry"
        a = np.asarray(axis, np.float64) if isinstance(axis, list) else np.zeros(0)
        if a.shape != (3,) or not np.isfinite(a).all() or not np.linalg.norm(a) > 0:
            raise SceneError("metadata.object", "symmetry", f'{{"axis": [x, y, z] or null}}, got {value!r}')
        return (a / np.linalg.norm(a)).tolist(), "metadata.object.symmetry"
    kind = obj.get("kind") or ((metadata.get("config") or {}).get("object") or {}).get("kind") or "can"
    if kind == "can":
        return [0.0, 1.0, 0.0], "a can (metadata without object.symmetry): +Y"
    return None, f"a {kind} (metadata without object.symmetry): none"


def read_instances(path) -> dict:
    """The segmentation's instances.json: {"image", "instances": [{"id", ...}]}, checked."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(path, "(file)", "the segment stage's instances.json")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SceneError(path, "(document)", f"a readable JSON document ({exc})") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("instances"), list):
        raise SceneError(path, "instances", "a list of {id, box, area, score}")
    ids = [entry.get("id") if isinstance(entry, dict) else None for entry in doc["instances"]]
    if not all(isinstance(i, int) and 0 < i < 65536 for i in ids) or len(set(ids)) != len(ids):
        raise SceneError(path, "instances[].id", f"distinct integer ids in 1..65535, got {ids}")
    if not isinstance(doc.get("image"), str):
        raise SceneError(path, "image", "the segmented image's file name")
    return doc


def poses_by_id(doc, where, key: str = "mask_value") -> tuple[dict[int, np.ndarray], int]:
    """({id: T_obj2world} of the registered instances, how many instances are listed), each known
    by the value its pixels have in the id image it goes with: the truth's masks name copies by
    ``mask_value`` (else ``instance_id``); the duplicates stage's poses name them by
    ``instance_id``, the segment stage's id (their ``mask_value`` is the user's own masks')."""
    from ..scene.poses import validate_poses

    validate_poses(doc, where)
    out = {}
    for k, entry in enumerate(doc["instances"]):
        value = entry.get(key, entry["instance_id"])
        if not isinstance(value, int) or isinstance(value, bool):
            raise SceneError(where, f"instances[{k}].{key}", f"an integer id of the mask, got {value!r}")
        if entry.get("registered", True):
            out[value] = np.asarray(entry["T_obj2world"], np.float64)
    return out, len(doc["instances"])


def load_inputs(segmentation_dir, duplicates_dir, truth_dir) -> dict:
    """Everything the evaluation reads, checked before any work (docs/evaluate.md, "Duplicates")."""
    from ..scene.format import read_scene_json
    from ..scene.images import read_mask
    from ..scene.mesh_io import read_mesh
    from ..scene.poses import read_poses

    seg, dup, truth = Path(segmentation_dir), Path(duplicates_dir), Path(truth_dir)
    table = read_instances(seg / "instances.json")
    stem = Path(table["image"]).stem
    recovered_ids, truth_ids = read_mask(seg / "masks" / f"{stem}.png"), read_mask(truth / "masks" / f"{stem}.png")
    if recovered_ids.shape != truth_ids.shape:
        h, w = truth_ids.shape
        got = f"{recovered_ids.shape[1]} x {recovered_ids.shape[0]}"
        raise SceneError(seg / "masks" / f"{stem}.png", "size", f"{w} x {h} as the true mask, got {got}")
    labels = [entry["id"] for entry in table["instances"]]
    beyond = sorted(set(np.unique(recovered_ids).tolist()) - {0} - set(labels))
    if beyond:
        raise SceneError(seg / "masks" / f"{stem}.png", "ids", f"only ids of instances.json ({labels}), got {beyond}")
    inputs = {
        "image": table["image"],
        "stem": stem,
        "recovered_ids": recovered_ids,
        "truth_ids": truth_ids,
        "labels": labels,
        "poses": {},
        "listed": {},
        "recovered_mesh": read_mesh(dup / "object.ply", require_uvs=False),
        "truth_mesh": read_mesh(truth / "object.ply", require_uvs=False),
    }
    for stage, name in (("after", "poses.json"), ("before", "poses_colmap.json")):
        path = dup / name
        if stage == "after" or path.exists():
            poses, listed = poses_by_id(read_poses(path), path, key="instance_id")
            unknown = sorted(set(poses) - set(labels))
            if unknown:
                raise SceneError(path, "instance_id", f"ids of the segmentation's instances ({labels}), got {unknown}")
            inputs["poses"][stage], inputs["listed"][stage] = poses, listed
    inputs["truth_poses"] = poses_by_id(read_poses(truth / "poses.json"), truth / "poses.json")[0]
    scene_json = truth / "scene" / "scene.json"
    inputs["metadata"] = read_scene_json(scene_json.parent).get("metadata") if scene_json.is_file() else None
    return inputs


def evaluate(inputs: dict, seed: int = 0) -> dict:
    """Masks, poses (after refinement, and before it when poses_colmap.json was there), mesh and
    counts of one duplicates scene, from ``load_inputs``'s result: metrics.json's sections."""
    truth_labels = sorted(inputs["truth_poses"])
    masks = mask_metrics(inputs["truth_ids"], inputs["recovered_ids"], truth_labels, inputs["labels"])
    match = {row["truth_id"]: row["recovered_id"] for row in masks["instances"] if row["recovered_id"] is not None}
    truth_mesh, recovered_mesh = inputs["truth_mesh"], inputs["recovered_mesh"]
    centroids = (surface_centroid(truth_mesh), surface_centroid(recovered_mesh))
    diagonal = diagonal_of(truth_mesh)
    axis, source = symmetry_axis(inputs["metadata"])
    poses = {stage: None for stage in ("before", "after")}
    for stage, recovered in inputs["poses"].items():
        poses[stage] = pose_metrics(inputs["truth_poses"], recovered, match, centroids, diagonal, axis)
    return {
        "counts": {
            "truth": len(truth_labels),
            "segmented": len(inputs["labels"]),
            "matched": masks["matched"],
            "registered": {stage: None if p is None else p["registered"] for stage, p in poses.items()},
            "listed": {stage: inputs["listed"].get(stage) for stage in poses},
        },
        "object": {
            "diagonal_m": diagonal,
            "symmetry_axis": axis,
            "symmetry_from": source,
            "centroid_truth": centroids[0].tolist(),
            "centroid_recovered": centroids[1].tolist(),
        },
        "masks": masks,
        "poses": poses,
        "mesh": mesh_metrics(recovered_mesh, truth_mesh, poses["after"], centroids, diagonal, axis, seed),
    }


def _edges(ids: np.ndarray) -> np.ndarray:
    """Pixels of an instance whose right or lower neighbour has another id."""
    edge = np.zeros(ids.shape, bool)
    right, down = ids[:, 1:] != ids[:, :-1], ids[1:] != ids[:-1]
    edge[:, :-1] |= right
    edge[:, 1:] |= right
    edge[:-1] |= down
    edge[1:] |= down
    return edge & (ids > 0)


def outline_figure(path, photo, truth_ids, recovered_ids, note: str = "") -> None:
    """The photo (linear RGB, or None: grey) with the true instances' outlines in green and the
    recovered ones' in magenta (yellow where they agree)."""
    from .figures import _labelled, _rgb8, _write
    from .metrics import reference_exposure, tone_map

    base = np.full(truth_ids.shape, 0.4) if photo is None else tone_map(photo, reference_exposure(photo))
    image = _rgb8(base)
    truth_edge, recovered_edge = _edges(truth_ids), _edges(recovered_ids)
    image[truth_edge] = (0, 220, 0)  # BGR
    image[recovered_edge] = (255, 0, 255)
    image[truth_edge & recovered_edge] = (0, 255, 255)
    _write(path, _labelled(image, "truth green, recovered magenta, both yellow", note))
