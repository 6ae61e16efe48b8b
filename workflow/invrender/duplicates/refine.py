"""Pose refinement by render-and-compare (beyond SfD, which keeps COLMAP's poses).

Every instance is the same mesh at its own 6-DoF pose T_cam_from_obj. Each pose is refined against
what the photo shows of that instance:

- its silhouette: the mesh's anti-aliased silhouette (triangles rasterised by OpenCV at
  ``supersample`` x the working resolution, box-filtered down) against the instance's mask, in a
  window around its box; pixels of other instances are left out, as they may occlude it.
- its pixels (photometric): what a silhouette cannot see (a can's turn about its axis, which end is
  up). Points spread over the mesh's surface are looked up in the photo through every *other*
  instance's pose where the id image says that instance is seen; their median chromaticity is
  the shared appearance this instance's pixels must show at the same points.

The optimiser is scipy's least_squares (Levenberg-Marquardt) on those residuals with forward
differences, per instance, on 6 parameters all in pixels of motion at the object's rim (so one
step size fits all): rotation about the object's centre in the camera frame, image-plane
translation, and depth as a scaling of the translation along its ray. The mesh's scale is not
refined: under one camera a shared scale of the mesh and of every translation renders the same
image (a gauge), so the scale stays the mesh's.

Order: silhouettes alone first; then the registered-but-wrong instances are found, by their
residual against the median of all or by their colours disagreeing with the others' (a can
flipped end over end has the same silhouette), and re-initialised like the unregistered ones:
candidates are the trusted instances' rotations placed at this instance's mask centroid and at
the depth its mask's size implies, plus 180-degree turns about their object axes; each is scored,
the best few refined, the winner searched in turns about its axes; last, one photometric sweep
over all. docs/duplicates-refine.md has the measurements behind these choices.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from ..scene.types import Mesh, SceneError
from .crops import instance_boxes

__all__ = ["RefineResult", "refine_poses", "project", "rasterise_silhouette", "silhouette", "surface_samples"]

SUPERSAMPLE = 4  # sub-pixels per pixel side: coverage in steps of 1/16
SHIFT = 4  # fractional bits of the vertex positions cv2.fillConvexPoly is given
ERODE = np.ones((2, 2), np.uint8)
STEP_PX = 0.5  # finite-difference step: a parameter unit is one pixel of motion at the rim
DAMPING = 0.02  # per pixel of motion: a pixel costs 4e-4, a silhouette off by a pixel ~1e-2


@dataclass
class RefineResult:
    poses: dict[int, np.ndarray]  # instance id -> T_cam_from_obj (4, 4) float64, every instance
    residual_before: dict[int, float]  # at the given pose; nan for an instance given none
    residual_after: dict[int, float]
    silhouette_before: dict[int, float]  # 1 - soft IoU, the geometric part of the residual
    silhouette_after: dict[int, float]
    reinitialised: list[int]  # registered, found wrong (residual or colours), re-initialised
    initialised: list[int]  # not registered: posed by refinement, not by COLMAP
    evaluations: dict[int, int]  # residual evaluations spent per instance
    seconds: dict[int, float]
    log: list[str] = field(default_factory=list)


# --- geometry ---------------------------------------------------------------------------


def project(K: np.ndarray, T: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (N, 2) (COLMAP: pixel (x, y) covers [x, x+1)) and depths (N,) of
    object-frame points under T_cam_from_obj."""
    p = points @ T[:3, :3].T + T[:3, 3]
    z = p[:, 2]
    uv = (p @ K.T)[:, :2] / np.where(z > 1e-9, z, 1e-9)[:, None]
    return uv, z


def rasterise_silhouette(uv: np.ndarray, faces: np.ndarray, shape: tuple[int, int], supersample: int = SUPERSAMPLE):
    """Coverage (H, W) float32 in [0, 1] of the union of the triangles ``faces`` with pixel
    coordinates ``uv`` (pixel (x, y) covers [x, x+1) x [y, y+1)): each triangle filled by OpenCV at
    ``supersample`` x the resolution (one at a time: fillPoly's even-odd rule would cancel where
    front and back overlap), then box-filtered."""
    h, w = shape
    s = supersample
    fine = np.zeros((h * s, w * s), np.uint8)
    # OpenCV fills the rows and columns from the rounded first to the rounded last vertex
    # coordinate, both ends included: half a sub-pixel too much on every side. Rasterised at
    # sub-pixel coordinates shifted by half a sub-pixel and eroded by one sub-pixel towards
    # the far side, the coverage is unbiased in area and centroid (measured: 0.04 and 0.006 px
    # mean errors over random rectangles at supersample 4, against 3.8 and 0.007 without).
    fixed = np.round(uv * s * (1 << SHIFT)).astype(np.int64)
    lo, hi = -(1 << 30), 1 << 30
    tri = np.clip(fixed[faces], lo, hi).astype(np.int32)
    box = np.stack([tri.min(1), tri.max(1)], 1) >> SHIFT  # (F, 2, 2)
    onscreen = (box[:, 1, 0] >= 0) & (box[:, 1, 1] >= 0) & (box[:, 0, 0] < w * s) & (box[:, 0, 1] < h * s)
    for t in tri[onscreen]:
        cv2.fillConvexPoly(fine, t, 1, lineType=cv2.LINE_8, shift=SHIFT)
    fine = cv2.erode(fine, ERODE, anchor=(0, 0), borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return fine.reshape(h, s, w, s).mean(axis=(1, 3), dtype=np.float32)


def silhouette(mesh: Mesh, K: np.ndarray, T: np.ndarray, window, supersample: int = SUPERSAMPLE) -> np.ndarray:
    """Anti-aliased silhouette of ``mesh`` at T_cam_from_obj in the pixel window
    (x0, y0, x1, y1) of the image of ``K``: (y1 - y0, x1 - x0) float32 coverage."""
    x0, y0, x1, y1 = (int(v) for v in window)
    uv, z = project(K, np.asarray(T, np.float64), np.asarray(mesh.positions, np.float64))
    faces = np.asarray(mesh.faces)
    faces = faces[np.all(z[faces] > 1e-9, axis=1)]  # a triangle behind the camera is not drawn
    return rasterise_silhouette(uv - [x0, y0], faces, (y1 - y0, x1 - x0), supersample)


def surface_samples(mesh: Mesh, count: int = 1500, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``count`` points spread over the surface by area (fixed seed) and their face normals."""
    v = np.asarray(mesh.positions, np.float64)[np.asarray(mesh.faces)]
    cross = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    area = np.linalg.norm(cross, axis=1)
    rng = np.random.default_rng(seed)
    f = rng.choice(len(v), size=count, p=area / area.sum())
    a, b = rng.random((2, count))
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    points = v[f, 0] + a[:, None] * (v[f, 1] - v[f, 0]) + b[:, None] * (v[f, 2] - v[f, 0])
    normals = cross[f] / np.maximum(area[f], 1e-30)[:, None]
    return points, normals


def _rotation_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    return float(np.degrees(Rotation.from_matrix(Ra.T @ Rb).magnitude()))


# --- what the photo shows of one instance -------------------------------------------------


@dataclass
class _Target:
    """One instance's mask in a window of the image, at a working resolution 1/n of it:
    ``K`` maps the object to the window's pixels; ``mask`` is the fraction of each working pixel
    that is the instance's, ``weight`` the fraction that is not another instance's."""

    instance_id: int
    K: np.ndarray
    mask: np.ndarray
    weight: np.ndarray
    n: int

    @property
    def shape(self) -> tuple[int, int]:
        return self.mask.shape


def _pool(a: np.ndarray, n: int) -> np.ndarray:
    h, w = a.shape
    return a.reshape(h // n, n, w // n, n).mean(axis=(1, 3), dtype=np.float32)


def _target(ids: np.ndarray, K: np.ndarray, instance_id: int, box, max_side: int, margin: float) -> _Target:
    """The instance's window: its box grown by ``margin`` of its longer side, at the working
    resolution 1/n (n the least integer that brings the box's longer side to ``max_side``)."""
    x0, y0, x1, y1 = box
    side = max(x1 - x0, y1 - y0)
    n = max(1, int(np.ceil(side / max_side)))
    pad = int(np.ceil(margin * side)) + 2
    H, W = ids.shape
    # A window aligned to n in the image's pixel grid, not clipped: pixels outside the image are
    # neither the instance's nor another's (they count as background).
    wx0, wy0 = (x0 - pad) // n * n, (y0 - pad) // n * n
    wx1, wy1 = -(-(x1 + pad) // n) * n, -(-(y1 + pad) // n) * n
    crop = np.zeros((wy1 - wy0, wx1 - wx0), ids.dtype)
    sx0, sy0, sx1, sy1 = max(wx0, 0), max(wy0, 0), min(wx1, W), min(wy1, H)
    crop[sy0 - wy0 : sy1 - wy0, sx0 - wx0 : sx1 - wx0] = ids[sy0:sy1, sx0:sx1]
    own = _pool((crop == instance_id).astype(np.float32), n)
    other = _pool(((crop != instance_id) & (crop != 0)).astype(np.float32), n)
    Kw = np.array([[K[0, 0] / n, K[0, 1] / n, (K[0, 2] - wx0) / n], [0, K[1, 1] / n, (K[1, 2] - wy0) / n], [0, 0, 1]])
    return _Target(instance_id, Kw, own, 1.0 - other, n)


def _levels(ids, K, instance_id: int, box, sides, margin: float) -> list[_Target]:
    """The instance's targets coarse to fine, one per distinct working resolution: a box smaller
    than a level's side is seen at full resolution once, not again at every finer level."""
    out: list[_Target] = []
    for side in sides:
        target = _target(ids, K, instance_id, box, side, margin)
        if not out or target.n != out[-1].n:
            out.append(target)
    return out


def _front_faces(mesh: Mesh, T: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The faces in front of the camera that face it: a closed mesh's silhouette is the union of
    these alone (half the triangles to fill)."""
    p = mesh.positions @ T[:3, :3].T + T[:3, 3]
    a, b, c = (p[mesh.faces[:, k]] for k in range(3))
    facing = np.einsum("ij,ij->i", np.cross(b - a, c - a), a) < 0
    return mesh.faces[facing & np.all(z[mesh.faces] > 1e-9, axis=1)]


def _silhouette_residual(mesh: Mesh, target: _Target, T: np.ndarray) -> tuple[np.ndarray, float]:
    """Per working pixel, (coverage - mask) where no other instance is seen, scaled so its
    squared sum is the soft symmetric difference over the mask's area; and 1 - soft IoU."""
    uv, z = project(target.K, T, mesh.positions)
    S = rasterise_silhouette(uv, _front_faces(mesh, T, z), target.shape)
    M, w = target.mask, target.weight
    inter = (w * S * M).sum()
    union = (w * (S + M - S * M)).sum()
    res = np.sqrt(w) * (S - M) / np.sqrt(max(M.sum(), 1.0))
    return res.ravel(), float(1.0 - inter / max(union, 1e-9))


def coverage(mesh: Mesh, K: np.ndarray, ids: np.ndarray, poses: dict[int, np.ndarray], max_side: int = 256,
             margin: float = 0.1) -> dict[int, float]:  # fmt: skip
    """Per posed instance, the soft IoU of ``mesh``'s silhouette at its pose with its mask (pixels
    another instance covers left out), at a working resolution of ``max_side`` pixels per box.
    The hull carved from a wrong model's poses covers the masks poorly: a self-check of the
    poses that needs no truth (docs/duplicates.md, "Angles searched again")."""
    boxes = instance_boxes(ids)
    out = {}
    for i, T in poses.items():
        if i in boxes:
            target = _target(ids, K, i, boxes[i], max_side, margin)
            out[i] = 1.0 - _silhouette_residual(mesh, target, np.asarray(T, np.float64))[1]
    return out


@dataclass
class _Appearance:
    """The photo (slightly blurred against render noise), the id image, and the surface points
    whose colours are compared between instances."""

    image: np.ndarray
    ids: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    min_cos: float = 0.3  # grazing points: their pixels mix the object's edge with what is behind

    def __post_init__(self):
        # The id image where a pixel's 3 x 3 neighbourhood is one instance; 0 elsewhere.
        lo = cv2.erode(self.ids.astype(np.float32), np.ones((3, 3), np.uint8), borderType=cv2.BORDER_REPLICATE)
        hi = cv2.dilate(self.ids.astype(np.float32), np.ones((3, 3), np.uint8), borderType=cv2.BORDER_REPLICATE)
        self.core = np.where(lo == hi, self.ids, 0)

    def facing(self, T: np.ndarray) -> np.ndarray:
        """The points that face the camera at pose T by more than ``min_cos``."""
        p = self.points @ T[:3, :3].T + T[:3, 3]
        n = self.normals @ T[:3, :3].T
        return -np.einsum("ij,ij->i", n, p) > self.min_cos * np.linalg.norm(p, axis=1)

    def colours(self, K: np.ndarray, T: np.ndarray, instance_id: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Chromaticities (S, 3), rgb / (r + g + b), of the surface points at pose T; ``seen``
        (S,) where the point faces the camera and lies well inside this instance's mask;
        ``hidden`` (S,) where it faces the camera but another instance is in front.
        Chromaticity, not colour: the copies are lit from different angles, so a point's
        brightness follows its normal more than its label (measured: with brightness in the
        comparison, a wrong turn about a can's axis often cost less than the true one; with
        chromaticity alone every turn of 30 degrees or more, and every flip, cost 1.3 .. 3.9 x
        the truth's, on 8 cans at 320 x 240)."""
        uv, _ = project(K, T, self.points)
        H, W = self.ids.shape
        inside = self.facing(T) & np.all(np.isfinite(uv), axis=1) & (uv[:, 0] >= 0) & (uv[:, 1] >= 0)
        inside &= (uv[:, 0] < W) & (uv[:, 1] < H)
        xy = np.where(inside[:, None], uv, 0.5)
        row, col = xy[:, 1].astype(int), xy[:, 0].astype(int)
        # Seen: well inside the mask, not on its border where the photo blends it with what is
        # around it.
        seen = inside & (self.core[row, col] == instance_id)
        hidden = inside & (self.ids[row, col] != instance_id) & (self.ids[row, col] != 0)
        grid = (xy - 0.5).astype(np.float32)  # array index of a pixel centre
        rgb = cv2.remap(self.image, grid[:, 0:1], grid[:, 1:2], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        rgb = rgb.reshape(-1, 3).astype(np.float64)
        return rgb / np.maximum(rgb.sum(axis=1, keepdims=True), 1e-6), seen, hidden

    def reference(self, K: np.ndarray, poses: dict[int, np.ndarray], exclude: int) -> np.ndarray:
        """The shared appearance (S, 3): per point the median over the other instances that see
        it (a median: a minority of wrong poses does not move it); NaN where none does."""
        stack = [np.full((len(self.points), 3), np.nan)]
        for j, T in poses.items():
            if j != exclude:
                col, seen, _ = self.colours(K, T, j)
                stack.append(np.where(seen[:, None], col, np.nan))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns: points nobody sees
            return np.nanmedian(np.stack(stack), axis=0)

    def residual(self, K: np.ndarray, T: np.ndarray, instance_id: int, reference: np.ndarray) -> np.ndarray:
        """(S * C,) colour differences to the reference where this instance's point faces the
        camera and is not hidden by another instance (on the background it counts: a wrong
        pose shows floor there), scaled so the squared sum is a mean over those points."""
        col, _, hidden = self.colours(K, T, instance_id)
        use = self.facing(T) & ~hidden & np.all(np.isfinite(reference), axis=1)
        diff = np.where(use[:, None], col - np.nan_to_num(reference), 0.0)
        # A mean over the points compared, not over all: a pose that turns towards the camera
        # points no other instance shows (no reference) must not look better for it.
        return diff.ravel() / np.sqrt(max(use.sum(), len(self.points) / 20))


# --- the optimiser --------------------------------------------------------------------------


class _Problem:
    """Everything one instance's residual needs: the shared mesh, its targets per level, the
    appearance and the reference colours from the others' current poses."""

    def __init__(self, mesh, K, targets, appearance, reference, photometric_weight, instance_id):
        self.mesh, self.K, self.targets, self.app = mesh, K, targets, appearance
        self.reference, self.weight, self.id = reference, photometric_weight, instance_id
        self.radius = float(np.linalg.norm(mesh.positions, axis=1).max())
        self.evaluations = 0

    def residual(self, T: np.ndarray, level: int) -> tuple[np.ndarray, float]:
        self.evaluations += 1
        sil, one_minus_iou = _silhouette_residual(self.mesh, self.targets[level], T)
        if self.weight <= 0:
            return sil, one_minus_iou
        photo = self.app.residual(self.K, T, self.id, self.reference)
        return np.concatenate([sil, np.sqrt(self.weight) * photo]), one_minus_iou

    def cost(self, T: np.ndarray, level: int = -1) -> tuple[float, float]:
        res, sil = self.residual(T, level)
        return float(res @ res), sil

    def rim_px(self, T: np.ndarray, level: int) -> float:
        """The object's radius in working pixels at T: the lever that turns a rotation or a
        change of depth into pixels of motion."""
        return max(self.targets[level].K[0, 0] * self.radius / max(T[2, 3], 1e-9), 1.0)

    def pose(self, T0: np.ndarray, x: np.ndarray, level: int) -> np.ndarray:
        """T0 moved by x (6,), all in working pixels at the rim: a rotation about the object's
        centre (camera axes), an image-plane shift, and a depth change that grows the image by
        x[5] pixels at the rim (the translation scaled along its own ray)."""
        r = self.rim_px(T0, level)
        f = self.targets[level].K[0, 0]
        T = np.eye(4)
        T[:3, :3] = Rotation.from_rotvec(x[:3] / r).as_matrix() @ T0[:3, :3]
        t = T0[:3, 3] + T0[2, 3] * np.array([x[3] / f, x[4] / f, 0.0])
        T[:3, 3] = t * r / max(r + x[5], 0.25 * r)
        return T

    def refine(self, T0: np.ndarray, levels, iterations: int) -> np.ndarray:
        levels = range(len(self.targets)) if levels is None else levels
        """Levenberg-Marquardt steps (scipy's least_squares) at each level in turn, coarse to
        fine, re-centred at every level. Forward differences of half a working pixel: the
        coverage moves in steps of 1/16 of a pixel, so an infinitesimal step sees nothing."""
        T = T0
        for level in levels:
            last = {}

            def fun(x, T=T, level=level):
                # A weak pull towards where the level started keeps what the residuals cannot
                # see (a can's turn about its axis, under silhouettes alone) where it was.
                f = np.concatenate([self.residual(self.pose(T, x, level), level)[0], DAMPING * x])
                last["x"], last["f"] = x.copy(), f
                return last["f"]

            def jac(x, T=T, level=level):
                f0 = last["f"] if "x" in last and np.array_equal(last["x"], x) else fun(x)
                columns = [
                    np.concatenate(
                        [self.residual(self.pose(T, x + STEP_PX * e, level), level)[0], DAMPING * (x + STEP_PX * e)]
                    )
                    - f0
                    for e in np.eye(6)
                ]
                return np.stack(columns, axis=1) / STEP_PX

            sol = least_squares(fun, np.zeros(6), jac=jac, method="lm", max_nfev=iterations)
            T = self.pose(T, sol.x, level)
        return T


# --- initialisation -------------------------------------------------------------------------

FLIPS = [np.diag(d).astype(np.float64) for d in ([1, -1, -1], [-1, 1, -1], [-1, -1, 1])]  # 180 deg about x, y, z


def _place(problem: _Problem, R: np.ndarray, depth: float, level: int) -> np.ndarray:
    """A pose of rotation R whose silhouette has the mask's area and centroid: put on the ray
    through the mask's centroid at ``depth``, then moved along the ray by the ratio of areas and
    across it by the difference of centroids."""
    target = problem.targets[level]
    M = target.mask
    ys, xs = np.mgrid[0 : M.shape[0], 0 : M.shape[1]] + 0.5
    centroid = np.array([(M * xs).sum(), (M * ys).sum()]) / max(M.sum(), 1e-9)
    Kinv = np.linalg.inv(target.K)
    T = np.eye(4)
    T[:3, :3] = R
    aim = centroid
    for _ in range(3):  # again: perspective moves the drawn centroid off the aimed ray
        T[:3, 3] = depth * (Kinv @ [*aim, 1.0])
        uv, z = project(target.K, T, problem.mesh.positions)
        S = rasterise_silhouette(uv, _front_faces(problem.mesh, T, z), target.shape)
        if S.sum() < 1e-6:
            break
        depth *= np.sqrt(S.sum() / max(M.sum(), 1e-9))  # area goes as 1 / depth^2
        drawn = np.array([(S * xs).sum(), (S * ys).sum()]) / S.sum()
        aim = aim - (drawn - centroid)
    T[:3, 3] = depth * (Kinv @ [*aim, 1.0])
    return T


def _axis_sweep(problem: _Problem, T: np.ndarray, degrees, level: int = 0) -> np.ndarray:
    """The best of T and T turned about each of its object axes by each of ``degrees``, by
    cost: a turn the silhouette cannot see (a can about its axis) is found by the photometric
    term only, whose basin is narrower than a borrowed rotation's error and rough (the label's
    texels, the render's noise), so least squares alone stops in it short of the truth."""
    best, best_cost = T, problem.cost(T, level)[0]
    for axis in np.eye(3):
        for angle in degrees:
            turned = _turned(T, Rotation.from_rotvec(axis * np.radians(angle)).as_matrix())
            cost = problem.cost(turned, level)[0]
            if cost < best_cost:
                best, best_cost = turned, cost
    return best


# Rotations spread over all of SO(3) (the icosahedral group: 60, none further than about 40
# degrees from any rotation), candidates when the borrowed ones all fail: with few instances
# posed, none of theirs may be near this one's. Not together with them: scored at the coarse
# level, 60 more candidates pushed the right borrowed one out of the few refined.
SPREAD = list(Rotation.create_group("I").as_matrix())

FULL_TURN = np.arange(15, 360, 15)  # degrees: re-initialisation
NEAR_TURN = np.array([-15, -10, -6, -3, 3, 6, 10, 15])  # degrees: after a local refinement


def _disagreement(app: _Appearance, K: np.ndarray, poses: dict[int, np.ndarray], least: int = 20) -> dict[int, float]:
    """Per instance, the median over the others of the mean squared colour difference at the
    surface points both see, at the best of small turns of this one about its axes (turns the
    silhouettes left loose): a can flipped end over end disagrees with every right one, a right
    one only with the wrong few. Compared pairwise, not with a median reference, because a
    reference made from few instances takes in the wrong one's colours."""
    seen = {i: app.colours(K, T, i)[:2] for i, T in poses.items()}
    turns = [np.eye(3)] + [
        Rotation.from_rotvec(axis * np.radians(a)).as_matrix() for axis in np.eye(3) for a in NEAR_TURN
    ]
    out = {}
    for i, T in poses.items():
        turned = [app.colours(K, _turned(T, R), i)[:2] for R in turns]
        pairs = []
        for j, (col_j, seen_j) in seen.items():
            costs = [
                ((col_i[both] - col_j[both]) ** 2).sum(axis=1).mean()
                for col_i, seen_i in turned
                if (both := seen_i & seen_j).sum() >= least
            ]
            if j != i and costs:
                pairs.append(float(min(costs)))
        out[i] = float(np.median(pairs)) if pairs else float("nan")
    return out


def _turned(T: np.ndarray, R_obj: np.ndarray) -> np.ndarray:
    out = T.copy()
    out[:3, :3] = T[:3, :3] @ R_obj
    return out


def _reinitialise(problem: _Problem, rotations, depth: float, keep, count: int, iterations: int) -> np.ndarray:
    """The best pose from ``rotations`` placed on the mask (scored at the coarse level, the best
    ``count`` refined, with the poses in ``keep``), searched in turns about its axes and refined
    again."""
    placed = [_place(problem, R, depth, 0) for R in rotations]
    scored = sorted(placed, key=lambda T: problem.cost(T, 0)[0])[:count] + list(keep)
    results = [problem.refine(T, None, iterations) for T in scored]
    best = min(results, key=lambda T: problem.cost(T)[0])
    return problem.refine(_axis_sweep(problem, best, FULL_TURN), None, iterations)


def _candidates(rotations: list[np.ndarray], tolerance_deg: float = 10.0) -> list[np.ndarray]:
    """The rotations and their 180-degree turns about their object axes, without near-repeats."""
    out: list[np.ndarray] = []
    for R in rotations:
        for turned in (R, *(R @ F for F in FLIPS)):
            if all(_rotation_deg(turned, Q) > tolerance_deg for Q in out):
                out.append(turned)
    return out


# --- the whole image ------------------------------------------------------------------------


def _check_inputs(mesh, K, ids, image, poses, unregistered) -> dict:
    where = "refine_poses"
    if np.asarray(K).shape != (3, 3):
        raise SceneError(where, "K", f"a 3 x 3 intrinsic matrix, got shape {np.shape(K)}")
    if np.ndim(ids) != 2:
        raise SceneError(where, "ids", f"an (H, W) instance id image, got shape {np.shape(ids)}")
    if np.shape(image) != (*np.shape(ids), 3):
        raise SceneError(
            where, "image", f"an (H, W, 3) photo of the id image's size {np.shape(ids)}, got {np.shape(image)}"
        )
    if len(mesh.faces) == 0:
        raise SceneError(where, "mesh", "a mesh with faces")
    for i, T in poses.items():
        T = np.asarray(T, np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)) or T[2, 3] <= 0:
            raise SceneError(
                where, f"poses[{i}]", "a finite 4 x 4 T_cam_from_obj with the object in front of the camera"
            )
    boxes = instance_boxes(np.asarray(ids))
    missing = sorted((set(poses) | set(unregistered)) - set(boxes))
    if missing:
        raise SceneError(
            where, "ids", f"pixels of every instance to refine; none for {missing} (found {sorted(boxes)})"
        )
    if not poses:
        raise SceneError(where, "poses", "at least one registered instance to initialise the others from")
    return boxes


def refine_poses(
    mesh: Mesh,
    K: np.ndarray,
    ids: np.ndarray,
    image: np.ndarray,
    poses: dict[int, np.ndarray],
    unregistered=(),
    *,
    levels=(24, 64, 128),
    margin: float = 0.3,
    photometric_weight: float = 1.0,
    iterations: int = 10,
    outlier_factor: float = 3.0,
    outlier_floor: float = 0.05,
    disagreement_factor: float = 2.5,
    photometric_passes: int = 1,
    refine_candidates: int = 3,
    samples: int = 1500,
    blur_px: float = 1.0,
    seed: int = 0,
) -> RefineResult:
    """Refine every registered instance's T_cam_from_obj against its mask and pixels, find the
    registered-but-wrong ones and re-initialise them, and give every ``unregistered`` instance
    a pose. ``levels``: the longest side, in working pixels, of an instance's box at each
    coarse-to-fine level; ``iterations``: least-squares iterations per level (each costs 7
    evaluations); a pose is wrong when its residual is above ``outlier_factor`` x the median of
    all and above ``outlier_floor``, or its colour disagreement with the others is above
    ``disagreement_factor`` x the median; ``refine_candidates``: how many of the best-scored
    candidate poses of a re-initialised instance are refined; ``samples``: surface points of
    the photometric term; ``blur_px``: the photo's Gaussian blur (render or sensor noise)."""
    boxes = _check_inputs(mesh, K, ids, image, poses, unregistered)
    K = np.asarray(K, np.float64)
    ids = np.asarray(ids)
    shape = Mesh(positions=np.asarray(mesh.positions, np.float64), faces=np.asarray(mesh.faces, np.int64), uvs=None)
    photo = np.ascontiguousarray(image, np.float32)
    if blur_px > 0:
        photo = cv2.GaussianBlur(photo, (0, 0), blur_px)
    app = _Appearance(photo, ids, *surface_samples(shape, samples, seed))
    registered = sorted(int(i) for i in poses)
    unregistered = sorted(int(i) for i in unregistered if int(i) not in poses)
    targets = {i: _levels(ids, K, i, boxes[i], levels, margin) for i in registered + unregistered}
    current = {i: np.asarray(poses[i], np.float64).copy() for i in registered}
    evaluations = dict.fromkeys(registered + unregistered, 0)
    seconds = dict.fromkeys(registered + unregistered, 0.0)
    log: list[str] = []

    def problem(i, trusted, weight=photometric_weight) -> _Problem:
        reference = app.reference(K, {j: current[j] for j in trusted if j != i}, i)
        return _Problem(shape, K, targets[i], app, reference, weight, i)

    def costs(trusted) -> dict[int, tuple[float, float]]:
        return {i: problem(i, trusted).cost(current[i]) for i in current}

    def sweep(instances, trusted, weight) -> None:
        """Gauss-Seidel: each instance refined against the others' latest poses."""
        for i in instances:
            start = time.perf_counter()
            p = problem(i, trusted, weight)
            current[i] = p.refine(current[i], None, iterations)
            if weight > 0:
                current[i] = p.refine(_axis_sweep(p, current[i], NEAR_TURN, -1), [-1], iterations)
            evaluations[i] += p.evaluations
            seconds[i] += time.perf_counter() - start

    before = costs(registered)
    # Silhouettes first: they fix position, depth and tilt; the photometric term compares with
    # the other instances, so it is only as good as their poses, and a wrong one (flipped)
    # must be found before it drags the others' turns with it.
    sweep(registered, registered, 0.0)
    refined = costs(registered)
    median = float(np.median([c for c, _ in refined.values()]))
    threshold = max(outlier_factor * median, outlier_floor)
    # A can flipped end over end keeps its silhouette: its residual need not stand out, but its
    # colours disagree with the others'.
    disagreement = _disagreement(app, K, current)
    compared = [d for d in disagreement.values() if np.isfinite(d)]  # none with one instance
    typical = float(np.median(compared)) if compared else float("nan")
    flipped = [i for i in registered if compared and disagreement[i] > disagreement_factor * typical]
    wrong = [i for i in registered if refined[i][0] > threshold or i in flipped]
    trusted = [i for i in registered if i not in wrong] or registered
    log.append(
        f"residual median {median:.4f}, threshold {threshold:.4f}; colour disagreement median {typical:.4f}, "
        f"above {disagreement_factor} x: {flipped}; wrong {wrong}"
    )

    posed = list(trusted)  # the instances others may borrow rotations and colours from
    for i in wrong + unregistered:
        start = time.perf_counter()
        p = problem(i, posed)
        own = [current[i][:3, :3]] if i in current else []
        borrowed = _candidates(own + [current[j][:3, :3] for j in posed if j != i])
        depth = float(np.median([current[j][2, 3] for j in posed]))
        keep = [current[i]] if i in current else []
        best = _reinitialise(p, borrowed, depth, keep, refine_candidates, iterations)
        cost, tried = p.cost(best)[0], len(borrowed)
        if cost > threshold:  # none of the borrowed rotations was near: try all around
            spread = _reinitialise(p, SPREAD, depth, [best], refine_candidates, iterations)
            cost, best, tried = p.cost(spread)[0], spread, tried + len(SPREAD)
        current[i] = best
        if cost <= threshold:  # posed well enough to lend its rotation to the next ones
            posed.append(i)
        evaluations[i] += p.evaluations
        seconds[i] += time.perf_counter() - start
        log.append(f"instance {i}: {tried} candidate rotations, best cost {cost:.4f}")
    # Once more, every instance against the corrected ones.
    everyone = registered + unregistered
    for _ in range(photometric_passes):
        sweep(everyone, everyone, photometric_weight)

    after = costs(everyone)
    nan = (float("nan"), float("nan"))
    return RefineResult(
        poses=current,
        residual_before={i: before.get(i, nan)[0] for i in current},
        residual_after={i: after[i][0] for i in current},
        silhouette_before={i: before.get(i, nan)[1] for i in current},
        silhouette_after={i: after[i][1] for i in current},
        reinitialised=wrong,
        initialised=unregistered,
        evaluations=evaluations,
        seconds=seconds,
        log=log,
    )
