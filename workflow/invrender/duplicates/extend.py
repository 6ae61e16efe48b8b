"""Tracks in every copy that sees their point, photo-consistent points among them (`photo_tracks`).

A copy's pose is as good as the points it observes. COLMAP's tracks hold only the copies that
ASIFT matched: box-6-hd's copy at the back (136 x 208 pixels, one face seen frontally) observes
54 of the model's 437 points, nearly on one plane, and the bundle adjustment leaves it 3 degrees
off (a plane's pose is weak about an axis in it) while its reprojection error is 0.14 px. The
hull's photo-consistent points (photo.py) lie on every printed face two or more copies see,
matched by ASIFT or not: each one is a stretch of print that several copies agree about.

So every such point becomes a track: a first observation in the nearest copy whose mask owns its
projection (``add_points``). Then every track, COLMAP's and these, gets an observation in each
copy that sees it and has none (``extend_tracks``): the copy faces the track's local plane
(cosine MIN_FACING), owns a window of SEARCH_PX around its projection, and the reference's patch,
warped into it by the plane (adjust.reference_surfaces), correlates best at a shift found by a
coarse search (steps of STEP_PX within SEARCH_PX) and refined by adjust's Gauss-Newton; kept at
adjust.MIN_NCC within SEARCH_PX. Tracks left with one observation are removed. The sub-pixel
rounds and bundle adjustment then run again on the model (stage.py).

Measured (docs/duplicates-hull.md, "Photo-consistent tracks"): box-6-hd 586 points and 1,093
observations added, the rotation error 1.02 -> 0.15 degrees mean (the back copy 3.0 -> 0.43);
box-10-hd 651 and 2,679, 0.148 -> 0.080; box-20-hd 911 and 12,796, 0.131 -> 0.063.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pycolmap

from . import adjust
from .refine import project

__all__ = ["ExtendStats", "add_points", "extend_tracks", "remove_single"]

SEARCH_PX = 4  # how far from its projection a point's observation may lie (a pose a few degrees off)
STEP_PX = 2  # the coarse search's step: the Gauss-Newton converges from a pixel or two
MIN_FACING = 0.2  # cosine between the track's plane and the direction to the copy (78 degrees)


@dataclass
class ExtendStats:
    points_added: int  # photo-consistent points made tracks
    candidates: int  # (track, copy) pairs that face each other without an observation
    observations_added: int
    single_removed: int  # new tracks that no second copy confirmed

    def as_dict(self) -> dict:
        return self.__dict__.copy()


def add_points(reconstruction, points: np.ndarray, K: np.ndarray, ids: np.ndarray, names: dict) -> int:
    """Each point (the model's frame) as a new track with one observation: its projection in the
    nearest copy whose mask owns it (``names``: image name -> instance id). Returns how many."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    height, width = ids.shape
    depth, owner, where = np.full(len(points), np.inf), np.full(len(points), -1), np.zeros((len(points), 2))
    for image_id, pose in adjust.cam_from_world(reconstruction).items():
        xy, z = project(K, pose, points)
        inside = (z > 0) & np.all(xy >= 0, axis=1) & (xy[:, 0] < width) & (xy[:, 1] < height)
        instance = names[reconstruction.image(image_id).name]
        owned = np.zeros(len(points), bool)
        owned[inside] = ids[xy[inside, 1].astype(int), xy[inside, 0].astype(int)] == instance
        nearer = owned & (z < depth)
        depth[nearer], owner[nearer], where[nearer] = z[nearer], image_id, xy[nearer]
    kept = owner >= 0
    for X, image_id, xy in zip(points[kept], owner[kept], where[kept]):
        _observe(reconstruction, int(image_id), xy, None, X)
    return int(kept.sum())


def _observe(reconstruction, image_id: int, xy: np.ndarray, point_id: int | None, X=None) -> int:
    """A new keypoint of ``image_id`` at ``xy``, observing ``point_id`` (or a new point at X)."""
    image = reconstruction.image(image_id)
    image.points2D.append(pycolmap.Point2D(xy=xy))
    index = len(image.points2D) - 1
    if point_id is None:
        track = pycolmap.Track()
        track.add_element(image_id, index)
        point_id = reconstruction.add_point3D(X, track, np.zeros(3, np.uint8))
        image.set_point3D_for_point2D(index, point_id)
    else:
        reconstruction.add_observation(point_id, pycolmap.TrackElement(image_id, index))
    return point_id


def _candidates(reconstruction, K: np.ndarray, ids: np.ndarray, names: dict, half: int):
    """(reference pixels, projected surface, (point id, image id)) for every copy that sees a
    track's plane, owns the window around its projection and has no observation of it."""
    poses = adjust.cam_from_world(reconstruction)
    instance = {i: names[reconstruction.image(i).name] for i in poses}
    centre, margin = len(adjust.patch_grid(half)) // 2, half + SEARCH_PX + 1
    height, width = ids.shape
    for point_id, observations, _, pixels, surface, normal in adjust.reference_surfaces(reconstruction, K, half):
        seen = {image_id for image_id, _ in observations}
        X0 = surface[centre]
        for image_id, pose in poses.items():
            if image_id in seen or adjust.facing(pose, normal, X0) < MIN_FACING:
                continue
            projected = project(K, pose, surface)[0]
            x, y = (int(v) for v in projected[centre])
            if not (margin <= x < width - margin and margin <= y < height - margin):
                continue
            window = ids[y - SEARCH_PX : y + SEARCH_PX + 1, x - SEARCH_PX : x + SEARCH_PX + 1]
            if np.all(window == instance[image_id]):
                yield pixels, projected, (point_id, image_id)


def _best_shifts(gray: np.ndarray, refs: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Per candidate, the coarse shift (steps of STEP_PX within SEARCH_PX) of best correlation."""
    reference, reference_norm = adjust.zero_mean(gray, refs)
    best, shift = np.full(len(targets), -2.0), np.zeros((len(targets), 2))
    steps = np.arange(-SEARCH_PX, SEARCH_PX + 1, STEP_PX)
    for dy in steps:
        for dx in steps:
            ncc = adjust.correlation(gray, targets + np.array([dx, dy], np.float64), reference, reference_norm)
            better = ncc > best
            best[better], shift[better] = ncc[better], (dx, dy)
    return shift


def extend_tracks(reconstruction, gray: np.ndarray, K: np.ndarray, ids: np.ndarray, names: dict,
                  half: int = adjust.HALF) -> tuple[int, int]:  # fmt: skip
    """Observations of every track in the copies that see it and had none (module docstring), in
    place. Returns (candidates, observations added)."""
    found = list(_candidates(reconstruction, K, ids, names, half))
    if not found:
        return 0, 0
    refs = np.array([f[0] for f in found])
    targets = np.array([f[1] for f in found])
    coarse = _best_shifts(gray, refs, targets)
    fine, ncc = adjust.patch_shifts(gray, refs, targets + coarse[:, None], adjust.ITERATIONS)
    shift = coarse + fine
    good = (np.abs(shift).max(axis=1) <= SEARCH_PX) & (ncc > adjust.MIN_NCC)
    centre = len(adjust.patch_grid(half)) // 2
    for (_, projected, (point_id, image_id)), delta in zip(
        (f for f, g in zip(found, good) if g), shift[good]
    ):  # fmt: skip
        _observe(reconstruction, image_id, projected[centre] + delta, point_id)
    return len(found), int(good.sum())


def remove_single(reconstruction) -> int:
    """Delete the tracks that only one copy observes (a photo point no other copy confirmed)."""
    single = [i for i in reconstruction.point3D_ids() if reconstruction.point3D(i).track.length() < 2]
    for point_id in single:
        reconstruction.delete_point3D(point_id)
    return len(single)
