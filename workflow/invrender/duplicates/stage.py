"""The `duplicates` stage (`invrender duplicates`): poses of N identical objects and their shared
mesh, from one photograph and its instance masks (Structure from Duplicates, section 3.1).

Two steps, so that the per-instance work fans out from the segment checkpoint:

    invrender duplicates crop   one instance: its crop (crops.py) and its features at every
                                rotation angle (matching.py) -> crops/instance_NNN.npz,
                                crops/instance_NNN.features.npz
    invrender duplicates solve  every pair matched with the rotation search (matching.py),
                                COLMAP's virtual cameras (mapping.py), the visual hull (hull.py),
                                render-and-compare refinement (refine.py), then out_dir/:

      sparse/            COLMAP's model of the virtual cameras (one camera: the real one), in the
                         object frame of poses.json
      poses.json         T_obj2world per instance (scene/poses.py), after refinement if `refine`; `registered`
                         false for an instance nothing could place
      poses_colmap.json  the same from COLMAP alone (before refinement)
      object.ply         the shared mesh in the object frame (the geometry stage unwraps it)
      duplicates.json    the report: pairs, angles, match counts, verified inliers, who registered,
                         refinement residuals, timings, what fixed the scale
      overlay.png        the photo with the mesh's outline at every recovered pose

The object frame: origin at the hull's centroid, axes COLMAP's; the scale is COLMAP's arbitrary one
unless `object_size` (the object's largest bounding-box extent, meters) fixes it, and poses.json
says which.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import json
import logging
import shutil
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..scene.atomic import atomic_dir, atomic_path, check_output
from ..scene.cameras import read_cameras
from ..scene.capture import read_view
from ..scene.images import read_mask
from ..scene.mesh_io import write_ply
from ..scene.poses import write_poses
from ..scene.types import Camera, Mesh, SceneError
from . import adjust, extend, floor, hull, mapping, matching, photo, refine, snap, tracks
from .crops import Crop, instance_boxes, make_crop
from .figures import write_overlay

__all__ = ["Settings", "run_crop", "run"]

log = logging.getLogger(__name__)

MIN_INSTANCES = 3  # two views give one relative pose and nothing to check it against
# The hull carved from the poses, drawn back at each (refine.coverage), covers a copy's mask at
# 0.85-0.99 IoU where the model is right (box-20-hd, box-6-hd with track_search), 0.03-0.88 where
# it is wrong (box-10-hd: 0.24-0.65 on average; box-20-hd's copy at 67 degrees: 0.36): below this
# the stage says that a copy's pose disagrees with the others'.
MIN_COVERAGE = 0.8
# The camera frame's up for an upright photograph: where the fit of the floor's normal starts
IMAGE_UP = np.array([0.0, -1.0, 0.0])


@dataclass
class Settings:
    matcher: str = "xfeat"
    rotation_search: bool = True
    step_deg: float = 4.0
    crop_size: int = 256
    crop_pad: float = 0.1
    masked: bool = True
    refine: bool = False
    refine_rounds: int = 2
    hull_resolution: int = 96
    hull_faces: int = 4000
    hull_outliers: int | None = None  # copies that may call a kept voxel outside; None: n // 10 (hull.py)
    hull_floor: bool = False  # the floor the copies rest on carves the hull too (floor.py)
    hull_snap: bool = False  # the hull moved onto COLMAP's triangulated points (snap.py)
    hull_photo: bool = False  # with hull_snap, onto photo-consistent points too (photo.py)
    photo_tracks: bool = False  # with hull_photo: those points made tracks, the copies adjusted again (extend.py)
    object_size: float | None = None
    max_error_px: float = 2.0
    seed: int = 0
    track_size: int = 0  # > 0: re-match every pair at its angle on fixed keypoints of crops this big (tracks.py)
    subpixel_rounds: int = 0  # > 0: tracks aligned to sub-pixel and all copies adjusted jointly (adjust.py)
    track_search: bool = False  # with track_size: every pair's angle searched again on the fixed keypoints
    pair_support: float = 0.0  # > 0: pairs whose matches the first model's poses explain less are dropped, mapped again


def intrinsics(camera: Camera) -> np.ndarray:
    if np.any(camera.distortion):
        raise SceneError(camera.name, "camera model", "a pinhole camera (undistort the photograph first)")
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    return np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], np.float64)


def load_photo(cameras_dir, image: str | None = None) -> tuple[Camera, np.ndarray]:
    """The photograph's camera (the cameras stage's model: the only camera, or the one named
    `image`) and its linear RGB pixels."""
    cameras = read_cameras(cameras_dir)
    if image is not None:
        cameras = [c for c in cameras if Path(c.name).stem == Path(image).stem]
    if len(cameras) != 1:
        raise SceneError(cameras_dir, "cameras", f"one camera for the photograph, got {len(cameras)}")
    return cameras[0], read_view(Path(cameras_dir) / "images", cameras[0])


def load_ids(masks_path, camera: Camera) -> np.ndarray:
    ids = read_mask(masks_path)
    if ids.shape != (camera.height, camera.width):
        raise SceneError(
            masks_path,
            "size",
            f"the photograph's size {camera.width} x {camera.height}, got {ids.shape[1]} x {ids.shape[0]}",
        )
    return ids


# ---------------------------------------------------------------------------- per instance


def save_crop(path, crop: Crop) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.savez_compressed(f, **asdict(crop))


def load_crop(path) -> Crop:
    with np.load(path) as data:
        return Crop(int(data["instance_id"]), data["image"], data["mask"], data["offset"], float(data["scale"]))


def run_crop(cameras_dir, masks_path, instance_id: int, crop_path, features_path, settings: Settings, image=None):
    """One instance's crop and features."""
    camera, photo = load_photo(cameras_dir, image)
    ids = load_ids(masks_path, camera)
    box = instance_boxes(ids).get(instance_id)
    if box is None:
        raise SceneError(masks_path, f"instance {instance_id}", "an instance id present in the mask")
    crop = make_crop(photo, ids, instance_id, box, settings.crop_size, settings.crop_pad, settings.masked)
    features = matching.extract(crop, settings.matcher, settings.step_deg, rotations=settings.rotation_search)
    save_crop(crop_path, crop)
    with atomic_path(features_path) as tmp:
        features.save(tmp)
    log.info("instance %d: crop %.2f px/px at %s", instance_id, crop.scale, np.round(crop.offset, 1).tolist())


# ---------------------------------------------------------------------------- all instances


def match_all(crops: dict[int, Crop], features: dict, settings: Settings, progress: bool = True):
    """Every pair, a at angle 0 against b at every angle: full-image correspondences per pair,
    and what the search chose (for the report)."""
    pairs, report = {}, []
    todo = list(itertools.combinations(sorted(crops), 2))
    for a, b in tqdm(todo, desc="match", unit="pair", disable=not progress):
        m = matching.match_pair(features[a], features[b], settings.matcher, rotation_search=settings.rotation_search)
        xy_b = matching.snap_to_upright(m.xy_b, features[b])
        pairs[a, b] = (crops[a].to_full(m.xy_a), crops[b].to_full(xy_b))
        report.append({"pair": [a, b], "angle_deg": float(m.angle_deg), "matches": int(len(m.xy_a))})
    return pairs, report


def track_pairs(photo, ids, crops: dict[int, Crop], pair_report: list[dict], settings: Settings):
    """Every pair the search matched at all, matched again at the angle it chose on each copy's
    one fixed set of keypoints (tracks.py), from crops of ``track_size`` pixels; with
    ``track_search``, every pair, at the better of that angle and the one the search on the fixed
    keypoints finds (tracks.rematch)."""
    boxes = instance_boxes(ids)
    features = {
        i: tracks.detect(make_crop(photo, ids, i, boxes[i], settings.track_size, settings.crop_pad, settings.masked))
        for i in crops
    }
    angles = {tuple(r["pair"]): r["angle_deg"] for r in pair_report if r["matches"] > 0 or settings.track_search}
    if settings.track_search:
        found, chosen = tracks.rematch(features, angles, tracks.search_angles(features, list(angles)))
        for r in pair_report:
            r["track_angle_deg"] = chosen.get(tuple(r["pair"]))
    else:
        found = tracks.match_pairs(features, angles)
    empty = np.zeros((0, 2))
    pairs = {p: found.get(p, (empty, empty)) for p in itertools.combinations(sorted(crops), 2)}
    for r in pair_report:
        r["track_matches"] = int(len(pairs[tuple(r["pair"])][0]))
    return pairs


def object_frame(mesh: Mesh, object_size: float | None) -> tuple[np.ndarray, float, str]:
    """(centre, scale, what fixed the scale): p_colmap = centre + scale * p_obj."""
    positions = mesh.positions.astype(np.float64)
    centre = positions.mean(axis=0)
    extent = float((positions.max(axis=0) - positions.min(axis=0)).max())
    if object_size is None:
        return centre, 1.0, "arbitrary: COLMAP's gauge (set duplicates.object_size to fix it in meters)"
    return centre, extent / object_size, f"object_size: the object's largest extent is {object_size} m"


def reframe(T: np.ndarray, centre: np.ndarray, scale: float) -> np.ndarray:
    """T_cam_from_obj for p_colmap = centre + scale * p_obj, the camera frame divided by scale
    (one camera cannot tell a scene from a scaled copy of it)."""
    out = np.eye(4)
    out[:3, :3] = T[:3, :3]
    out[:3, 3] = (T[:3, :3] @ centre + T[:3, 3]) / scale
    return out


def mask_names(entries: list[dict]) -> dict[int, dict]:
    """Per segment id, what names its copy in the masks the user gave (instances.json's
    ``source``): ``mask_value`` (its pixels' value in their id image) or ``mask_file`` (its file in
    their folder); with masks the segment stage made, the value of its pixels in those."""
    names = {}
    for entry in entries:
        source = entry.get("source", entry["id"])
        names[int(entry["id"])] = {"mask_file": source} if isinstance(source, str) else {"mask_value": int(source)}
    return names


def poses_document(poses, names: dict[int, dict], world_from_cam, scale_note: str, source: str) -> dict:
    """poses.json (scene/poses.py): ``instance_id`` is the segment's id (the pixels' value in
    segmentation/masks), ``mask_value`` or ``mask_file`` the user's own name for the copy."""
    return {
        "convention": (
            "p_world = T_obj2world @ [p_obj, 1]; T_obj2world row-major 4x4; world = the photograph's "
            "camera model's world; object frame = object.ply"
        ),
        "scale": scale_note,
        "source": source,
        "instances": [
            {
                "instance_id": int(i),
                **named,
                "registered": i in poses,
                "T_obj2world": (world_from_cam @ poses[i] if i in poses else np.eye(4)).tolist(),
            }
            for i, named in names.items()
        ],
    }


def _carve(ids, poses, K, points, settings: Settings, gray=None) -> tuple[Mesh, dict, np.ndarray]:
    """The visual hull of the posed masks; its bounds from COLMAP's points while they are the
    best guess, else from the masks' cones. With ``hull_floor``, carved again with the floor the
    copies rest on (floor.py); with ``hull_snap``, moved onto the points (snap.py), and with
    ``hull_photo`` (and the photograph's ``gray``) moved again from the carved hull onto those and
    the points where the copies' pixels agree about the snapped one (photo.py). The second value
    says what those did ({"floor": ..., "snap": ..., "photo": ...}, None where not done) and which
    copies were set aside because their poses left no voxel ({"set_aside": {id: hull coverage}});
    the third is the photo-consistent points (none without hull_photo)."""
    bounds = hull.bounds_from_points(points) if len(points) >= 20 else hull.bounds_from_masks(ids, poses, K)

    def carve(kept, k=settings.hull_outliers, plane=None, misposed=()):
        on_floor = {i: T for i, T in kept.items() if i not in misposed}
        floors = floor.floors_in_object_frame(plane, on_floor) if plane is not None else ()
        return hull.visual_hull(ids, kept, K, bounds, resolution=settings.hull_resolution, k=k,
                                target_faces=settings.hull_faces, floors=floors)  # fmt: skip

    mesh, kept, set_aside = _agreeing_hull(carve, poses, ids, K, settings)
    report = {"floor": None, "snap": None, "photo": None, "set_aside": set_aside}
    agreed = np.zeros((0, 3))
    fitted = floor.fit_floor(mesh, kept, IMAGE_UP, points) if settings.hull_floor else None
    if fitted is not None:
        report["floor"] = {"normal_camera": fitted.normal.tolist(), "offset_camera": fitted.offset,
                           "misposed": fitted.misposed, "carved": True}  # fmt: skip
        resting = functools.partial(carve, plane=fitted.plane, misposed=fitted.misposed)
        try:
            mesh, kept, more = _agreeing_hull(resting, kept, ids, K, settings)
            set_aside.update(more)
        except SceneError:  # the fit is off (a wrong model tilts it): the hull without it
            log.warning("the floor fitted under the copies leaves no hull: carved without it")
            report["floor"]["carved"] = False
    if not settings.hull_snap:
        return mesh, report, agreed
    snapped, how = snap.snap_to_points(mesh, points)
    if settings.hull_photo and how is not None and gray is not None:
        agreed, found = photo.consistent_points(snapped, kept, K, gray, ids)
        report["photo"] = found.as_dict()
        snapped, how = snap.snap_to_points(mesh, np.vstack([points, agreed]))
    report["snap"] = None if how is None else how.as_dict()
    return snapped, report, agreed


def _agreeing_hull(carve, poses: dict, ids, K, settings: Settings) -> tuple[Mesh, dict, dict[int, float]]:
    """(mesh, the poses it was carved from, {set-aside id: its hull coverage}). One wrong pose can
    carve every voxel away when no copy may disagree (``hull_outliers`` 0): then the loosest vote
    that leaves a hull (one copy allowed to disagree, then two, ...) is drawn back at every copy,
    the copy it covers worst is set aside, and the rest carved again, down to two copies."""
    kept, set_aside = dict(poses), {}
    while True:
        try:
            return carve(kept)[0], kept, set_aside
        except hull.EmptyHull:
            worst = _worst_covered(carve, kept, ids, K) if len(kept) > 2 else None
        if worst is None:
            hint = (
                ""
                if settings.hull_outliers is None
                else " (rough poses need hull_outliers null, a tenth of the copies)"
            )
            raise SceneError(
                "duplicates",
                "hull",
                f"a visual hull inside the masks of the {len(kept)} posed copies; every voxel lies outside some "
                f"copy's mask (hull_outliers {settings.hull_outliers}), whichever copies are set aside: their "
                f"poses disagree{hint}",
            )
        instance, covered = worst
        log.warning(
            "the posed copies leave no voxel of a hull: copy %d set aside (the loosest hull that leaves any covers "
            "its mask worst, at IoU %.2f), carving again from %d copies", instance, covered, len(kept) - 1,
        )  # fmt: skip
        set_aside[instance] = covered
        del kept[instance]


def _worst_covered(carve, poses: dict, ids, K) -> tuple[int, float] | None:
    """(id, coverage) of the copy that the loosest non-empty hull covers worst; None if no vote up
    to half the copies leaves one."""
    for k in range(1, len(poses) // 2 + 1):
        try:
            mesh, _ = carve(poses, k=k)
        except hull.EmptyHull:
            continue
        coverage = refine.coverage(mesh, K, ids, poses)
        instance = min(coverage, key=coverage.get)
        return instance, float(coverage[instance])
    return None


def solve(photo, ids, K, crops, features, workdir, settings: Settings, progress: bool = True) -> dict:
    """Match, map, carve and refine; returns everything run writes (COLMAP's frame)."""
    started = time.perf_counter()
    pairs, pair_report = match_all(crops, features, settings, progress)
    if settings.track_size:
        pairs = track_pairs(photo, ids, crops, pair_report, settings)
    if not any(len(xy_a) for xy_a, _ in pairs.values()):
        raise SceneError(
            "duplicates", "matches", f"matches between some of the {len(crops)} crops; found none in any pair"
        )
    height, width = ids.shape
    registration = mapping.register(
        workdir, K, width, height, sorted(crops), pairs, seed=settings.seed, max_error_px=settings.max_error_px
    )
    if settings.pair_support:
        registration = _drop_unsupported(registration, sorted(crops), pairs, pair_report, K, (width, height), workdir,
                                         settings)  # fmt: skip
    timings = {"match_and_map_s": time.perf_counter() - started}
    if len(registration.poses) < 2:
        raise SceneError(
            "duplicates",
            "registration",
            f"COLMAP to register at least 2 of the {len(crops)} instances; it registered "
            f"{len(registration.poses)} (unregistered: {registration.unregistered}; "
            f"{len(registration.verified_pairs)} pairs passed geometric verification)",
        )
    subpixel = {}
    if settings.subpixel_rounds and registration.reconstruction is not None:
        subpixel = _subpixel_rounds(photo, ids, K, registration, workdir, settings)
        timings["subpixel_s"] = time.perf_counter() - started - timings["match_and_map_s"]
    gray = adjust.gray_image(photo)
    mesh, shaped, agreed = _carve(ids, registration.poses, K, registration.points, settings, gray)
    set_aside = shaped["set_aside"]
    tracked = {}
    if settings.photo_tracks and len(agreed) and registration.reconstruction is not None:
        began = time.perf_counter()
        tracked = _photo_tracks(gray, ids, K, registration, agreed, settings)
        timings["photo_tracks_s"] = time.perf_counter() - began
        mesh, shaped, _ = _carve(ids, _without(registration.poses, set_aside), K, registration.points, settings, gray)
        set_aside = shaped["set_aside"] = {**set_aside, **shaped["set_aside"]}
    trusted = _without(registration.poses, set_aside)
    coverage = refine.coverage(mesh, K, ids, trusted)
    doubtful = sorted(i for i, c in coverage.items() if c < MIN_COVERAGE)
    if doubtful:
        log.warning(
            "the hull covers the masks of %s at IoU %s (mean %.2f): their poses disagree with the others'",
            doubtful, [round(coverage[i], 2) for i in doubtful], float(np.mean(list(coverage.values()))),
        )  # fmt: skip
    # COLMAP's origin can lie anywhere, even behind the camera: the object frame starts at the
    # hull's centroid, so every pose's translation is the object's centre in the camera
    centre = mesh.positions.astype(np.float64).mean(axis=0)
    registration.poses = {i: reframe(T, centre, 1.0) for i, T in registration.poses.items()}
    registration.points = registration.points - centre
    registration.origin = centre
    mesh = Mesh((mesh.positions - centre).astype(np.float32), mesh.faces, uvs=None)
    poses, rounds = _without(registration.poses, set_aside), []
    if settings.refine:
        unplaced = registration.unregistered + sorted(set_aside)  # placed from the others
        poses, mesh, rounds = _refine_rounds(photo, ids, K, poses, mesh, unplaced, settings)
    timings["total_s"] = time.perf_counter() - started
    return {
        "registration": registration,
        "pairs": pair_report,
        "poses": poses,
        "mesh": mesh,
        "rounds": rounds,
        "subpixel": subpixel,
        "photo_tracks": tracked,
        "shape": shaped,
        "coverage": coverage,
        "timings": timings,
    }


def _without(poses: dict, set_aside) -> dict:
    return {i: T for i, T in poses.items() if i not in set_aside}


def _drop_unsupported(registration, instance_ids, pairs, pair_report, K, size, workdir, settings: Settings):
    """The pairs whose matches agree with the first model's epipolar geometry (within twice the
    verification threshold) less than ``pair_support`` of the time are dropped and the copies
    mapped again without them. On box-20-hd's first model the 83 pairs it drops at 0.5 are all
    wrong, yet the model mapped again is worse (one copy at 67 degrees); box-6-hd's 6, all wrong,
    and it is better (2.65 -> 2.40); a wrong first model's shares say nothing (box-10-hd)."""
    support = mapping.pair_support(registration.poses, K, pairs, 2 * settings.max_error_px)
    for r in pair_report:
        r["support"] = support.get(tuple(r["pair"]))
    dropped = sorted(p for p, share in support.items() if share < settings.pair_support)
    if not dropped:
        return registration
    log.info("%d pairs dropped (support below %.2f): %s", len(dropped), settings.pair_support, dropped)
    for r in pair_report:
        r["dropped"] = tuple(r["pair"]) in dropped
    kept = {p: m for p, m in pairs.items() if p not in dropped}
    return mapping.register(workdir, K, *size, instance_ids, kept, seed=settings.seed,
                            max_error_px=settings.max_error_px)  # fmt: skip


def _subpixel_rounds(photo, ids, K, registration: mapping.Registration, workdir, settings: Settings) -> dict:
    """COLMAP's model with copies that took the planar flip turned back, every verified match
    triangulated, every track aligned to sub-pixel and all copies adjusted together (adjust.py):
    the registration's model, poses and points become the adjusted ones. Returns what it did,
    for duplicates.json."""
    gray = adjust.gray_image(photo)
    reconstruction = registration.reconstruction
    names = {mapping.image_name(i): i for i in list(registration.poses) + registration.unregistered}
    adjust.bundle_adjust(reconstruction, 2 * settings.max_error_px)
    flipped = adjust.resolve_flips(reconstruction, ids, K, names)
    adjust.bundle_adjust(reconstruction, settings.max_error_px)
    reconstruction = mapping.retriangulate(reconstruction, workdir, settings.seed)
    registration.reconstruction = reconstruction
    adjust.bundle_adjust(reconstruction, 2 * settings.max_error_px)
    rounds = []
    for k in range(settings.subpixel_rounds):
        stats = adjust.align_tracks(reconstruction, gray, K)
        adjust.bundle_adjust(reconstruction, settings.max_error_px)
        # again on the cleaner model: a copy's stray off-face points can hide that it sees one
        # face (box-20-hd: copy 18, 40 degrees off, passed the first check; its points' planarity was
        # 0.05 after the rounds)
        again = adjust.resolve_flips(reconstruction, ids, K, names)
        if again:
            flipped += again
            adjust.bundle_adjust(reconstruction, settings.max_error_px)
        error = reconstruction.compute_mean_reprojection_error()
        rounds.append({**dataclasses.asdict(stats), "reprojection_error_px": error})
        log.info(
            "sub-pixel round %d: %d of %d observations moved (median %.2f px), reprojection error %.3f px",
            k, stats.moved, stats.observations, stats.median_shift_px, error,
        )  # fmt: skip
    registration.poses = adjust.poses_by_instance(reconstruction, names)
    registration.points = np.array([p.xyz for p in reconstruction.points3D.values()]).reshape(-1, 3)
    return {"flipped": flipped, "rounds": rounds}


def _photo_tracks(gray, ids, K, registration: mapping.Registration, points, settings: Settings) -> dict:
    """The photo-consistent ``points`` made tracks, every track observed in every copy that sees
    it, then the sub-pixel rounds and bundle adjustment again (extend.py): the registration's
    poses and points become the adjusted ones. Returns what it did, for duplicates.json."""
    reconstruction = registration.reconstruction
    names = {mapping.image_name(i): i for i in list(registration.poses) + registration.unregistered}
    added = extend.add_points(reconstruction, points, K, ids, names)
    candidates, observed = extend.extend_tracks(reconstruction, gray, K, ids, names)
    single = extend.remove_single(reconstruction)
    adjust.bundle_adjust(reconstruction, settings.max_error_px)
    for _ in range(settings.subpixel_rounds):
        adjust.align_tracks(reconstruction, gray, K)
        adjust.bundle_adjust(reconstruction, settings.max_error_px)
    stats = extend.ExtendStats(added, candidates, observed, single)
    error = reconstruction.compute_mean_reprojection_error()
    log.info(
        "photo tracks: %d points added, %d of %d candidate observations kept, %d single tracks removed; "
        "reprojection error %.3f px", added, observed, candidates, single, error,
    )  # fmt: skip
    registration.poses = adjust.poses_by_instance(reconstruction, names)
    registration.points = np.array([p.xyz for p in reconstruction.points3D.values()]).reshape(-1, 3)
    return {**stats.as_dict(), "reprojection_error_px": error}


def _refine_rounds(photo, ids, K, poses, mesh, unregistered: list[int], settings: Settings):
    """Refine the poses against the masks and pixels with the hull, carve again; keep a round
    while the mean residual falls. ``unregistered`` copies are placed from the others first."""
    rounds, best = [], None
    for k in range(settings.refine_rounds):
        result = refine.refine_poses(mesh, K, ids, photo, poses, unregistered=unregistered, seed=settings.seed)
        residual = float(np.nanmean(list(result.residual_after.values())))
        rounds.append({"round": k, "mean_residual": residual, **_summary(result)})
        if best is not None and residual >= best:
            break
        best, poses, unregistered = residual, result.poses, []
        mesh, _, _ = _carve(ids, poses, K, np.zeros((0, 3)), settings)
    return poses, mesh, rounds


def _summary(result) -> dict:
    """A refinement round for duplicates.json."""
    keys = ("residual_before", "residual_after", "silhouette_before", "silhouette_after", "evaluations", "seconds")
    out = {key: {str(i): float(v) for i, v in getattr(result, key).items()} for key in keys}
    return {**out, "reinitialised": list(result.reinitialised), "initialised": list(result.initialised)}


def run(
    cameras_dir,
    masks_path,
    instances_path,
    crops_dir,
    features_dir,
    out_dir,
    settings: Settings,
    image=None,
    progress: bool = True,
) -> dict:
    check_output(out_dir, "duplicates")
    camera, photo = load_photo(cameras_dir, image)
    ids = load_ids(masks_path, camera)
    names = mask_names(json.loads(Path(instances_path).read_text())["instances"])
    listed = list(names)
    if len(listed) < MIN_INSTANCES:
        raise SceneError(
            instances_path, "instances", f"at least {MIN_INSTANCES} instances of the object; found {len(listed)}"
        )
    crops = {i: load_crop(Path(crops_dir) / f"instance_{i:03d}.npz") for i in listed}
    features = {i: matching.CropFeatures.load(Path(features_dir) / f"instance_{i:03d}.features.npz") for i in listed}
    K = intrinsics(camera)
    with atomic_dir(out_dir, kind="duplicates") as tmp:
        found = solve(photo, ids, K, crops, features, tmp / "colmap", settings, progress)
        report = _write(tmp, found, camera, K, photo, names, settings)
        # keep COLMAP's database (its matches open in COLMAP's GUI); its models are sparse/ now
        for models in ("models", "retriangulated"):
            shutil.rmtree(tmp / "colmap" / models, ignore_errors=True)
    log.info("duplicates: %d of %d instances placed -> %s", len(found["poses"]), len(listed), out_dir)
    return report


def _write(tmp: Path, found: dict, camera: Camera, K, photo, names: dict[int, dict], settings: Settings) -> dict:
    centre, scale, note = object_frame(found["mesh"], settings.object_size)
    world_from_cam = np.linalg.inv(camera.world_to_camera())
    registration = found["registration"]
    before = {i: reframe(T, centre, scale) for i, T in registration.poses.items()}
    after = {i: reframe(T, centre, scale) for i, T in found["poses"].items()}
    mesh = found["mesh"]
    mesh = Mesh(((mesh.positions - centre) / scale).astype(np.float32), mesh.faces, uvs=None)
    write_ply(tmp / "object.ply", mesh)
    write_poses(tmp / "poses_colmap.json", poses_document(before, names, world_from_cam, note, "COLMAP"))
    source = "COLMAP, refined by render-and-compare" if settings.refine else "COLMAP"
    write_poses(tmp / "poses.json", poses_document(after, names, world_from_cam, note, source))
    mapping.write_model(registration, tmp / "sparse", registration.origin + centre, scale)
    write_overlay(tmp / "overlay.png", photo, mesh, K, after)
    report = {
        "settings": asdict(settings),
        "instances": list(names),
        "registered_by_colmap": sorted(registration.poses),
        "unregistered_by_colmap": registration.unregistered,
        "placed": sorted(found["poses"]),
        "sparse_points": int(len(registration.points)),
        "verified_pairs": [{"pair": list(p), "inliers": n} for p, n in sorted(registration.verified_pairs.items())],
        "pairs": found["pairs"],
        "refinement": found["rounds"],
        "subpixel": found["subpixel"],
        "photo_tracks": found["photo_tracks"],
        "hull_shape": {key: value for key, value in found["shape"].items() if key != "set_aside"},
        "hull_coverage": {str(i): float(c) for i, c in sorted(found["coverage"].items())},
        "set_aside": [{"instance": i, "hull_coverage": c} for i, c in sorted(found["shape"]["set_aside"].items())],
        "scale": note,
        "mesh": {"vertices": int(len(mesh.positions)), "faces": int(len(mesh.faces))},
        "timings": found["timings"],
    }
    (tmp / "duplicates.json").write_text(json.dumps(report, indent=2) + "\n")
    return report


def settings_from(values: dict) -> Settings:
    """Settings with `values` (config `duplicates:` keys) over the defaults; an unknown key or a
    value of the wrong type is refused by name."""
    known = {f.name: f for f in dataclasses.fields(Settings)}
    for key, value in values.items():
        if key not in known:
            raise SceneError("duplicates --set", key, f"one of {', '.join(known)}")
    settings = Settings(**values)
    if settings.matcher not in matching.MATCHERS:
        allowed = ", ".join(matching.MATCHERS)
        raise SceneError("duplicates --set", "matcher", f"one of {allowed}, got {settings.matcher!r}")
    if settings.hull_photo and not settings.hull_snap:
        raise SceneError("duplicates --set", "hull_photo", "hull_snap true too (the photo's points are snapped onto)")
    if settings.photo_tracks and not (settings.hull_photo and settings.subpixel_rounds):
        raise SceneError(
            "duplicates --set", "photo_tracks", "hull_photo true and subpixel_rounds > 0 too (the photo's points on "
            "the sub-pixel model)",
        )  # fmt: skip
    if settings.track_size and settings.matcher != "xfeat":
        raise SceneError(
            "duplicates --set", "track_size", f"0 with the {settings.matcher} matcher (tracks.py is XFeat's)"
        )
    return settings
