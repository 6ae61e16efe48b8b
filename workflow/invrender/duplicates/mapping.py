"""Virtual cameras by COLMAP: the crops of N identical objects are N views of one object.

Every crop is declared as an image of the one real camera (full-frame intrinsics, held fixed),
with its keypoints in full-image pixels (crops.py says why). COLMAP verifies each pair's matches
(an essential matrix: the camera is calibrated) and maps incrementally; a registered image's
``cam_from_world`` is then the pose of that instance in the real camera's frame, the object frame
being COLMAP's world: T_cam_from_obj_i = cam_from_world_i (FACTS.md: do not invert it again).

Rotation-aware matching (matching.py) gives each pair its own keypoints (those of the rotated
crop, rotated back), so an image's keypoint list is the union of what its pairs matched,
deduplicated at a quarter pixel: a keypoint of an unrotated crop seen by several pairs is one
keypoint, and COLMAP can chain it into tracks.
"""

from __future__ import annotations

import logging
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pycolmap

__all__ = ["Registration", "register", "retriangulate", "image_name", "pair_support"]

log = logging.getLogger(__name__)

QUANTUM = 4  # keypoints closer than 1/QUANTUM pixel are one keypoint
# Incremental mapping can run from several seeds (different initial pairs and orders), keeping
# the model that registers the most copies, then reprojects best. The copies' virtual cameras see
# a small object almost affinely, so a model can start from a depth-reversed pair and still
# register every copy, consistently wrong: with the true correspondences of box-20-hd at 1 px
# noise, 3 of 6 seeds gave 20 of 20 copies at 85 degrees (mean reprojection error 1.23 px) and 3
# gave them at 0.19 degrees (0.99 px). On the matchers' matches every seed is wrong (27-94 degrees
# on box-20-hd's matches within 2 px of the truth) and the least reprojection error picked the
# worst, so one seed stays the default (docs/duplicates.md, "Where it stands").
ATTEMPTS = 1


def image_name(instance_id: int) -> str:
    return f"instance_{instance_id:03d}.png"


@dataclass
class Registration:
    """What COLMAP made of the instances: poses of the registered ones (T_cam_from_obj), the
    sparse points (object frame), the reconstruction itself, and per-pair verification."""

    poses: dict[int, np.ndarray]
    unregistered: list[int]
    points: np.ndarray  # (P, 3) object frame
    reconstruction: pycolmap.Reconstruction | None
    verified_pairs: dict[tuple[int, int], int] = field(default_factory=dict)  # inlier count per pair
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))  # of the poses' frame in COLMAP's


class _Keypoints:
    """Per image, the union of matched keypoints (full-image pixels), deduplicated."""

    def __init__(self):
        self.index: dict[tuple[int, int], int] = {}
        self.xy: list[np.ndarray] = []

    def add(self, points: np.ndarray) -> np.ndarray:
        out = np.empty(len(points), np.uint32)
        for k, p in enumerate(points):
            key = (int(round(p[0] * QUANTUM)), int(round(p[1] * QUANTUM)))
            if key not in self.index:
                self.index[key] = len(self.xy)
                self.xy.append(p)
            out[k] = self.index[key]
        return out

    def array(self) -> np.ndarray:
        return np.asarray(self.xy, np.float32).reshape(-1, 2)


def _unique_matches(idx: np.ndarray) -> np.ndarray:
    """Each keypoint used at most once per pair (the first match kept)."""
    _, first_a = np.unique(idx[:, 0], return_index=True)
    idx = idx[np.sort(first_a)]
    _, first_b = np.unique(idx[:, 1], return_index=True)
    return idx[np.sort(first_b)]


def _write_camera(db, K: np.ndarray, width: int, height: int) -> int:
    camera = pycolmap.Camera(model="PINHOLE", width=width, height=height, params=[K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
    camera.has_prior_focal_length = True  # calibrated: pairs are verified by essential matrices
    camera_id = db.write_camera(camera)
    rig = pycolmap.Rig()
    rig.add_ref_sensor(pycolmap.Camera(camera_id=camera_id).sensor_id)
    db.write_rig(rig)
    return camera_id


def _write_images(db, camera_id: int, instance_ids, keypoints: dict[int, _Keypoints]) -> dict[int, int]:
    image_ids = {}
    for rig_id, instance in enumerate(instance_ids, 1):
        image_id = db.write_image(pycolmap.Image(name=image_name(instance), camera_id=camera_id))
        image = db.read_image(image_id)
        frame = pycolmap.Frame()
        frame.rig_id = 1
        frame.add_data_id(image.data_id)
        db.write_frame(frame)
        db.write_keypoints(image_id, keypoints[instance].array())
        image_ids[instance] = image_id
    return image_ids


def _database(path: Path, K, width, height, instance_ids, pairs) -> dict[int, int]:
    """Write the database: one camera, one image per instance, keypoints and raw matches."""
    keypoints = {i: _Keypoints() for i in instance_ids}
    matches = {}
    for (a, b), (xy_a, xy_b) in pairs.items():
        if len(xy_a) == 0:
            continue
        idx = np.stack([keypoints[a].add(xy_a), keypoints[b].add(xy_b)], axis=1)
        matches[a, b] = _unique_matches(idx)
    db = pycolmap.Database.open(str(path))
    try:
        camera_id = _write_camera(db, K, width, height)
        image_ids = _write_images(db, camera_id, instance_ids, keypoints)
        for (a, b), idx in matches.items():
            db.write_matches(image_ids[a], image_ids[b], idx)
    finally:
        db.close()
    return image_ids


def _verify(path: Path, max_error_px: float, seed: int) -> None:
    options = pycolmap.TwoViewGeometryOptions()
    options.ransac.max_error = max_error_px
    options.ransac.random_seed = seed
    options.detect_watermark = False
    # a point that does not move between two crops is background seen by both (unmasked crops
    # of neighbours overlap), not the object
    options.filter_stationary_matches = True
    verifier = pycolmap.GeometricVerifierOptions()
    verifier.num_threads = 1
    pycolmap.geometric_verification(str(path), verifier, pycolmap.ExistingMatchedPairingOptions(), options)


def _verified(path: Path, image_ids: dict[int, int]) -> dict[tuple[int, int], int]:
    instance_of = {v: k for k, v in image_ids.items()}
    out = {}
    with pycolmap.Database.open(str(path)) as db:
        pair_ids, geometries = db.read_two_view_geometries()
        for pair_id, geometry in zip(pair_ids, geometries):
            a, b = pycolmap.pair_id_to_image_pair(pair_id)
            out[tuple(sorted((instance_of[a], instance_of[b])))] = int(len(geometry.inlier_matches))
    return out


def _mapper_options(seed: int, min_model_size: int) -> pycolmap.IncrementalPipelineOptions:
    options = pycolmap.IncrementalPipelineOptions()
    options.min_model_size = min_model_size
    options.extract_colors = False  # the crops are not full-frame images of the camera
    options.random_seed = seed
    options.num_threads = 1
    # one real camera whose intrinsics are known: bundle adjustment must not move them
    options.ba_refine_focal_length = False
    options.ba_refine_principal_point = False
    options.ba_refine_extra_params = False
    options.mapper.init_min_num_inliers = 15
    options.mapper.abs_pose_min_num_inliers = 8
    options.mapper.init_min_tri_angle = 4.0
    return options


def _largest(reconstructions: dict) -> pycolmap.Reconstruction | None:
    if not reconstructions:
        return None
    return max(reconstructions.values(), key=lambda r: r.num_reg_images())


def _best_of(db_path: Path, workdir: Path, seed: int, min_model_size: int, attempts: int):
    """The largest model of incremental mapping from seeds seed .. seed + attempts - 1 that
    registers the most images, then has the least mean reprojection error (ATTEMPTS says why)."""
    best, best_key = None, None
    for k in range(attempts):
        out = workdir / "models" / str(k)
        out.mkdir(parents=True)
        options = _mapper_options(seed + k, min_model_size)
        found = _largest(pycolmap.incremental_mapping(str(db_path), str(workdir), str(out), options))
        if found is None:
            continue
        key = (found.num_reg_images(), -found.compute_mean_reprojection_error())
        log.info("mapping seed %d: %d images, mean reprojection error %.3f px", seed + k, key[0], -key[1])
        if best_key is None or key > best_key:
            best, best_key = found, key
    return best


def register(
    workdir,
    K: np.ndarray,
    width: int,
    height: int,
    instance_ids: list[int],
    pairs: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]],
    seed: int = 0,
    max_error_px: float = 4.0,
    attempts: int = ATTEMPTS,
) -> Registration:
    """Map the instances. ``pairs[(a, b)] = (xy_a, xy_b)``: matched points in full-image pixels.
    ``workdir`` receives database.db and COLMAP's models (replaced if present)."""
    workdir = Path(workdir)
    if workdir.exists():
        shutil.rmtree(workdir)
    (workdir / "models").mkdir(parents=True)
    db_path = workdir / "database.db"
    image_ids = _database(db_path, K, width, height, instance_ids, pairs)
    _verify(db_path, max_error_px, seed)
    verified = _verified(db_path, image_ids)
    best = _best_of(db_path, workdir, seed, min(3, len(instance_ids)), attempts)
    poses = {}
    if best is not None:
        by_name = {image_name(i): i for i in instance_ids}
        for image in best.images.values():
            if image.has_pose:
                T = np.eye(4)
                T[:3] = image.cam_from_world().matrix()
                poses[by_name[image.name]] = T
    points = np.array([p.xyz for p in best.points3D.values()]) if best is not None else np.zeros((0, 3))
    unregistered = [i for i in instance_ids if i not in poses]
    log.info("COLMAP registered %d of %d instances (%d points)", len(poses), len(instance_ids), len(points))
    return Registration(poses, unregistered, points.reshape(-1, 3), best, verified)


def retriangulate(reconstruction, workdir, seed: int = 0) -> pycolmap.Reconstruction:
    """The model with every verified match of workdir/database.db triangulated at its poses (the
    points kept, tracks extended): the incremental mapper leaves many out (box-20-hd: 2,783 points
    with 15,000 observations, 3,129 with 28,000 after this)."""
    workdir = Path(workdir)
    out = workdir / "retriangulated"
    out.mkdir(parents=True, exist_ok=True)
    return pycolmap.triangulate_points(
        reconstruction, str(workdir / "database.db"), str(workdir), str(out), clear_points=False,
        options=_mapper_options(seed, 3),
    )  # fmt: skip


def write_model(registration: Registration, out_dir, centre: np.ndarray, scale: float) -> None:
    """COLMAP's model as a text model anyone can open, moved into the object frame of poses.json
    (p_obj = (p_colmap - centre) / scale)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    reconstruction = pycolmap.Reconstruction(registration.reconstruction)
    matrix = np.hstack([np.eye(3) / scale, (-np.asarray(centre, np.float64) / scale)[:, None]])
    reconstruction.transform(pycolmap.Sim3d(matrix))
    reconstruction.write_text(str(out_dir))


def _sampson(F: np.ndarray, xy_a: np.ndarray, xy_b: np.ndarray) -> np.ndarray:
    """Sampson distance (pixels) of each correspondence to the epipolar geometry F (x_b^T F x_a = 0)."""
    a = np.c_[xy_a, np.ones(len(xy_a))]
    b = np.c_[xy_b, np.ones(len(xy_b))]
    Fa, Fb = a @ F.T, b @ F
    numerator = np.einsum("ij,ij->i", b, Fa) ** 2
    return np.sqrt(numerator / np.maximum(Fa[:, 0] ** 2 + Fa[:, 1] ** 2 + Fb[:, 0] ** 2 + Fb[:, 1] ** 2, 1e-30))


def pair_support(
    poses: dict[int, np.ndarray], K: np.ndarray, pairs, max_error_px: float
) -> dict[tuple[int, int], float]:
    """Per pair of posed copies with matches: the share of its matches within ``max_error_px``
    (Sampson) of the epipolar geometry of the two poses. A pair that verified on look-alike faces
    (box-10-hd's (9, 10): 386 matches, 1 correct) disagrees with the poses the other pairs fix."""
    Kinv = np.linalg.inv(K)
    out = {}
    for (a, b), (xy_a, xy_b) in pairs.items():
        if a not in poses or b not in poses or len(xy_a) == 0:
            continue
        T = poses[b] @ np.linalg.inv(poses[a])  # cam b from cam a
        t = T[:3, 3]
        E = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]]) @ T[:3, :3]
        out[a, b] = float(np.mean(_sampson(Kinv.T @ E @ Kinv, np.asarray(xy_a), np.asarray(xy_b)) < max_error_px))
    return out
