"""Sub-pixel tracks and a joint bundle adjustment of all copies (after COLMAP's first model).

COLMAP's poses of the copies are limited by where the matcher puts the keypoints, not by the
mapper: with true correspondences at 1 px of independent noise it places box-20-hd's copies at
0.09 degrees, with XFeat's keypoints at 0.88 median (docs/duplicates.md). XFeat's keypoints sit
on whole pixels of each copy's crop and are detected separately in each copy, so one corner of
the print is found about a pixel apart in two copies, in a direction fixed to the image and not
to the object: the errors are correlated within a copy and bend its pose.

Here every track of the first model (one 3D point, seen by several copies) is aligned onto one
reference patch, as Pixel-Perfect SfM's keypoint adjustment does: the reference is the copy that
sees the point's local plane most frontally; the plane (the 3D point and the normal of its
nearest model points) maps the reference's patch into every other copy that sees the point, and
each of those observations moves by the sub-pixel shift that best aligns the warped patch with
the reference (Gauss-Newton on zero-mean patches with a free gain). Then a bundle adjustment of
all copies and points (pycolmap, intrinsics fixed, Cauchy loss) after dropping observations
farther than ``max_error_px`` from their reprojection; a few rounds, the warps sharpening with
the poses. Every observation of a track then refers to the same point of the object, whichever
pixel the reference's keypoint happened to be.

Before that, ``resolve_flips``: a copy that sees one face has two poses that fit its observations
(the face's tilt mirrored about the line of sight); its mask decides. Measured on the HD box
fixtures with true masks: docs/duplicates.md, "Sub-pixel tracks, the planar flip and one bundle
adjustment" (box-20-hd 2.77 -> 0.31 degrees mean, 0.88 -> 0.22 median).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import pycolmap
from scipy.ndimage import map_coordinates
from scipy.spatial import cKDTree

from ..scene.images import linear_to_srgb
from .refine import project

__all__ = ["AlignStats", "align_tracks", "bundle_adjust", "gray_image", "poses_by_instance", "resolve_flips"]

log = logging.getLogger(__name__)

HALF = 7  # patch half-size in full-image pixels: 15 x 15 around the keypoint
NEIGHBOURS = 16  # model points whose plane is the track's local surface
MIN_NCC = 0.8  # an observation moves only when its aligned patch correlates this well...
MAX_SHIFT_PX = 2.5  # ... and the shift is this small (more: a different feature, or occluded)
ITERATIONS = 15
PLANARITY = 0.1  # a copy's observed points nearly on one plane: smallest / largest singular value
# the flipped pose is kept when it fits the mask this much better. The IoU is of the convex hull of
# the model's points, which cover only the faces some copy saw: 0.12-0.89 at either pose on these
# fixtures, and no floor separated the measured right flips (box-20-hd 0.53, 0.88, 0.89) from the
# wrong ones (box-6-hd 0.56), so the gain alone decides; a rendered hull would be the better test
FLIP_IOU_GAIN = 0.05


@dataclass
class AlignStats:
    observations: int  # observations of tracks that were aligned (the references excluded)
    moved: int  # of them, moved
    median_shift_px: float


def gray_image(photo: np.ndarray) -> np.ndarray:
    """Display-referred grey of the linear photograph, float64 (what a patch is compared on)."""
    lum = np.asarray(photo, np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    level = float(np.percentile(lum, 99.0))
    return linear_to_srgb(np.clip(lum / level if level > 0 else lum, 0.0, None)).astype(np.float64)


def sample_bilinear(image: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Bilinear samples at COLMAP pixel coordinates (pixel x covers [x, x + 1))."""
    return map_coordinates(image, [xy[..., 1] - 0.5, xy[..., 0] - 0.5], order=1, mode="nearest")


def cam_from_world(reconstruction) -> dict[int, np.ndarray]:
    """{image id: 3 x 4 cam_from_world} of every registered image."""
    return {i: reconstruction.image(i).cam_from_world().matrix() for i in reconstruction.reg_image_ids()}


def patch_grid(half: int) -> np.ndarray:
    """Pixel offsets (P, 2) of a (2 half + 1)^2 patch, row by row; its centre is entry P // 2."""
    return np.stack(np.meshgrid(np.arange(-half, half + 1), np.arange(-half, half + 1)), -1).reshape(-1, 2)


def reference_surfaces(reconstruction, K: np.ndarray, half: int):
    """Per track of the model: (point id, its observations [(image_id, point2D_idx)], the
    reference observation, the reference patch's pixels (P, 2), the same pixels as points of the
    track's local plane (P, 3), that plane's normal turned towards the reference camera). The
    plane: the 3D point and the normal of its NEIGHBOURS nearest model points; the reference: the
    observation that sees the plane most frontally."""
    ids = list(reconstruction.point3D_ids())
    points = np.array([reconstruction.point3D(i).xyz for i in ids]).reshape(-1, 3)
    if len(points) < 4:
        return
    _, near = cKDTree(points).query(points, k=min(NEIGHBOURS, len(points)))
    poses = cam_from_world(reconstruction)
    grid = patch_grid(half)
    K_inv = np.linalg.inv(K)
    for k, point_id in enumerate(ids):
        local = points[near[k]] - points[near[k]].mean(axis=0)
        normal, X0 = np.linalg.svd(local)[2][-1], points[k]
        observations = [(e.image_id, e.point2D_idx) for e in reconstruction.point3D(point_id).track.elements]
        ref = max(observations, key=lambda obs: abs(facing(poses[obs[0]], normal, X0)))
        R, t = poses[ref[0]][:, :3], poses[ref[0]][:, 3]
        pixels = np.asarray(reconstruction.image(ref[0]).points2D[ref[1]].xy, np.float64) + grid
        # the reference's pixels as rays (pinhole: u = K X; pixel centres in COLMAP's convention
        # are the same coordinates K maps to), intersected with the local plane
        rays = (np.c_[pixels, np.ones(len(pixels))] @ K_inv.T) @ R  # world directions
        centre = -R.T @ t
        surface = centre + ((normal @ (X0 - centre)) / (rays @ normal))[:, None] * rays
        normal = normal if facing(poses[ref[0]], normal, X0) > 0 else -normal
        yield point_id, observations, ref, pixels, surface, normal


def facing(pose: np.ndarray, normal: np.ndarray, X0: np.ndarray) -> float:
    """Cosine between ``normal`` at X0 and the direction from X0 to the camera of ``pose``
    (3 x 4 cam_from_world): positive where the camera sees that side of the plane."""
    R, t = pose[:, :3], pose[:, 3]
    ray = R @ X0 + t
    return float(-(R @ normal) @ ray / np.linalg.norm(ray))


def _patches(reconstruction, K: np.ndarray, half: int):
    """Per observation of every track except its reference: the reference patch's pixels, the
    same surface points projected into the observation's image (centred on its keypoint), and
    the observation's (image_id, point2D_idx)."""
    poses = cam_from_world(reconstruction)
    centre = len(patch_grid(half)) // 2
    refs, targets, handles = [], [], []
    for _, observations, ref, pixels, surface, _ in reference_surfaces(reconstruction, K, half):
        for obs in observations:
            if obs == ref:
                continue
            projected = project(K, poses[obs[0]], surface)[0]
            keypoint = np.asarray(reconstruction.image(obs[0]).points2D[obs[1]].xy, np.float64)
            refs.append(pixels)
            targets.append(projected - projected[centre] + keypoint)
            handles.append(obs)
    if not handles:
        return np.zeros((0, 0, 2)), np.zeros((0, 0, 2)), []
    return np.array(refs), np.array(targets), handles


def zero_mean(gray: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each patch's samples at ``at`` (N, P, 2) less their mean, and their norms with 1e-12 added
    (a plain patch divides nothing by zero)."""
    values = sample_bilinear(gray, at)
    values -= values.mean(axis=1, keepdims=True)
    return values, np.linalg.norm(values, axis=1) + 1e-12


def correlation(gray: np.ndarray, at: np.ndarray, reference: np.ndarray, reference_norm: np.ndarray) -> np.ndarray:
    """Normalised cross-correlation of the patches at ``at`` with a ``zero_mean`` reference."""
    values = zero_mean(gray, at)[0]
    return (values * reference).sum(axis=1) / (np.linalg.norm(values, axis=1) * reference_norm + 1e-12)


def patch_shifts(gray: np.ndarray, refs: np.ndarray, targets: np.ndarray, iterations: int):
    """Per observation, the shift of its warped patch that best matches the reference patch up
    to gain and offset, and the normalised correlation there."""
    grad_y, grad_x = np.gradient(gray)
    reference, reference_norm = zero_mean(gray, refs)
    shift = np.zeros((len(targets), 2))
    for _ in range(iterations):
        at = targets + shift[:, None]
        values, gx, gy = (sample_bilinear(image, at) for image in (gray, grad_x, grad_y))
        values, gx, gy = (v - v.mean(axis=1, keepdims=True) for v in (values, gx, gy))
        gain = np.linalg.norm(values, axis=1) / reference_norm
        residual = values - gain[:, None] * reference
        J = np.stack([gx, gy], axis=-1)
        normal = np.einsum("npi,npj->nij", J, J) + 1e-12 * np.eye(2)
        step = -np.linalg.solve(normal, np.einsum("npi,np->ni", J, residual)[..., None])[..., 0]
        shift += np.clip(step, -0.5, 0.5)  # Gauss-Newton, damped: patches are small
    return shift, correlation(gray, targets + shift[:, None], reference, reference_norm)


def align_tracks(reconstruction, gray: np.ndarray, K: np.ndarray, half: int = HALF) -> AlignStats:
    """Move every track's observations (but its reference's) onto the reference patch, in place."""
    refs, targets, handles = _patches(reconstruction, K, half)
    if not handles:
        return AlignStats(0, 0, 0.0)
    shift, ncc = patch_shifts(gray, refs, targets, ITERATIONS)
    good = (np.abs(shift).max(axis=1) < MAX_SHIFT_PX) & (ncc > MIN_NCC)
    for (image_id, index), delta in zip((h for h, g in zip(handles, good) if g), shift[good]):
        point = reconstruction.image(image_id).points2D[index]
        point.xy = point.xy + delta
    moved = np.linalg.norm(shift[good], axis=1)
    return AlignStats(len(handles), int(good.sum()), float(np.median(moved)) if len(moved) else 0.0)


def bundle_adjust(reconstruction, max_error_px: float, threads: int = 1) -> None:
    """Drop observations farther than max_error_px from their reprojection (and points left with
    too short tracks or too small angles), then adjust every pose and point together, the one real
    camera's intrinsics held fixed, with a Cauchy loss of 1 px against what remains wrong."""
    pycolmap.ObservationManager(reconstruction).filter_all_points3D(max_error_px, 1.0)
    options = pycolmap.BundleAdjustmentOptions()
    options.refine_focal_length = False
    options.refine_principal_point = False
    options.refine_extra_params = False
    options.print_summary = False
    options.ceres.loss_function_type = pycolmap.LossFunctionType.CAUCHY
    options.ceres.loss_function_scale = 1.0
    options.ceres.solver_options.max_num_iterations = 200
    options.ceres.solver_options.num_threads = threads
    pycolmap.bundle_adjustment(reconstruction, options)


def poses_by_instance(reconstruction, instance_of_name: dict[str, int]) -> dict[int, np.ndarray]:
    """T_cam_from_obj of every registered copy (mapping.py: cam_from_world, not inverted)."""
    out = {}
    for image in reconstruction.images.values():
        if image.has_pose:
            T = np.eye(4)
            T[:3] = image.cam_from_world().matrix()
            out[instance_of_name[image.name]] = T
    return out


# ---------------------------------------------------------------- the planar flip


def _flipped(R: np.ndarray, t: np.ndarray, normal: np.ndarray, X0: np.ndarray):
    """The other pose under which a plane (normal, through X0; object frame) projects the same
    in an affine camera: depth mirrored along the line of sight to X0 (I - 2vv^T), made a
    rotation again by the mirror across the plane itself (I - 2nn^T), which fixes the plane's
    points. R' = (I - 2vv^T)(I - 2nn^T) R, and X0 stays where it was in the camera."""
    v = R @ X0 + t
    v /= np.linalg.norm(v)
    n = R @ normal
    Q = (np.eye(3) - 2 * np.outer(v, v)) @ (np.eye(3) - 2 * np.outer(n, n))
    R2 = Q @ R
    return R2, R @ X0 + t - R2 @ X0


def _silhouette_iou(points: np.ndarray, R, t, K, mask: np.ndarray) -> float:
    """IoU of the convex hull of the model's points projected at (R, t) with the copy's mask (a
    box's, a can's silhouette is its hull's)."""
    import cv2

    cam = points @ R.T + t
    cam = cam[cam[:, 2] > 0]
    if len(cam) < 3:
        return 0.0
    xy = cam[:, :2] / cam[:, 2:] * np.diag(K)[:2] + K[:2, 2] - 0.5  # array coordinates
    drawn = np.zeros(mask.shape, np.uint8)
    hull = cv2.convexHull(np.round(xy * 16).astype(np.int32))
    cv2.fillConvexPoly(drawn, hull, 1, lineType=cv2.LINE_8, shift=4)
    inter = np.logical_and(drawn > 0, mask).sum()
    return float(inter / max(1, np.logical_or(drawn > 0, mask).sum()))


def resolve_flips(reconstruction, ids: np.ndarray, K: np.ndarray, instance_of_name: dict[str, int],
                  planarity: float = PLANARITY, gain: float = FLIP_IOU_GAIN) -> list[int]:  # fmt: skip
    """Copies whose observed points lie nearly on one plane (the smallest to largest singular
    value of their spread below ``planarity``: the copy shows one face) have two poses that fit
    their observations equally in a near-affine view; measured on box-20-hd, one such copy took
    the wrong one (39 degrees off; PnP on its 2D-3D matches agrees with it within 0.2 degrees).
    The other pose is tried, refined on the same observations, and kept when the model's points
    projected with it cover the copy's mask better by ``gain`` (IoU). Returns the flipped copies."""
    points = np.array([p.xyz for p in reconstruction.points3D.values()]).reshape(-1, 3)
    camera = next(iter(reconstruction.cameras.values()))
    flipped = []
    for image_id in list(reconstruction.reg_image_ids()):
        image = reconstruction.image(image_id)
        observed = [
            (np.asarray(p.xy), reconstruction.point3D(p.point3D_id).xyz) for p in image.points2D if p.has_point3D()
        ]
        if len(observed) < 6:
            continue
        xy, X = (np.array(v, np.float64) for v in zip(*observed))
        s = np.linalg.svd(X - X.mean(axis=0), compute_uv=False)
        if s[2] >= planarity * s[0]:
            continue
        normal = np.linalg.svd(X - X.mean(axis=0))[2][-1]
        T = image.cam_from_world().matrix()
        R2, t2 = _flipped(T[:, :3], T[:, 3], normal, X.mean(axis=0))
        refined = pycolmap.refine_absolute_pose(
            pycolmap.Rigid3d(pycolmap.Rotation3d(R2), t2), xy, X, np.ones(len(xy), bool), camera
        )
        if refined is None:
            continue
        T2 = refined["cam_from_world"].matrix()
        mask = ids == instance_of_name[image.name]
        before = _silhouette_iou(points, T[:, :3], T[:, 3], K, mask)
        after = _silhouette_iou(points, T2[:, :3], T2[:, 3], K, mask)
        log.info("%s: one face seen; silhouette IoU %.3f, flipped %.3f", image.name, before, after)
        if after > before + gain:
            reconstruction.frame(image.frame_id).set_cam_from_world(image.camera_id, refined["cam_from_world"])
            flipped.append(instance_of_name[image.name])
    return flipped
