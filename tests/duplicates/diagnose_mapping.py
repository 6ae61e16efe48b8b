"""What limits COLMAP's poses of the copies (docs/duplicates.md, "Where it stands"): the same
mapping.register fed (1) ideal correspondences, true surface points of the object projected
through the true poses into every copy that shows them (facing the camera, and the instance
mask at the projected pixel is that copy's), with pixel noise, each point one keypoint per copy so
that tracks chain through every copy that sees it, or cut to tracks of at most k copies; and
(2) the stage's own matches, all of them and only those within 2 px of the truth.

    PYTHONPATH=$PWD/workflow python tests/duplicates/diagnose_mapping.py CAPTURE SEGMENTATION [PAIRS.pkl]

CAPTURE: a duplicates fixture (images/, sparse/, ground_truth/); SEGMENTATION: the segment
stage's folder of it (the provided backend on ground_truth/masks isolates pose error from
segmentation error); PAIRS.pkl: {"pairs": {(a, b): (xy_a, xy_b)}} in full-image pixels, as
stage.match_all returns them (pickled), or {"keypoints": {i: (K, 2)}, "matches": {(a, b): (M, 2)}}.
"""

import itertools
import json
import logging
import pickle
import sys
from pathlib import Path

import numpy as np
import trimesh

from invrender.duplicates import mapping
from invrender.evaluate.duplicates import rotation_metrics
from invrender.scene.cameras import read_cameras
from invrender.scene.images import read_mask

sys.path.insert(0, str(Path(__file__).parent))
from test_matching import first_hit  # noqa: E402


class Truth:
    """The fixture's camera, true poses (by the segmentation's ids), object and instance masks."""

    def __init__(self, capture, segmentation):
        capture = Path(capture)
        self.cam = read_cameras(capture / "sparse")[0]
        doc = json.loads((capture / "ground_truth/poses.json").read_text())
        by_value = {p["mask_value"]: np.asarray(p["T_obj2world"], np.float64) for p in doc["instances"]}
        listed = json.loads((Path(segmentation) / "instances.json").read_text())["instances"]
        self.value = {e["id"]: e.get("source", e["id"]) for e in listed}  # segment id -> true mask value
        self.T_cam = {i: self.cam.world_to_camera() @ by_value[v] for i, v in self.value.items()}
        self.mesh = trimesh.load(capture / "ground_truth/object.ply", process=False)
        self.masks = read_mask(capture / "ground_truth/masks/view_000.png")
        (fx, fy), (cx, cy) = self.cam.focal, self.cam.principal_point
        self.K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])

    def shows(self, i, xy):
        """Whether copy i's mask holds each full-image point."""
        px = np.floor(xy).astype(int)
        height, width = self.masks.shape
        inside = (px[:, 0] >= 0) & (px[:, 1] >= 0) & (px[:, 0] < width) & (px[:, 1] < height)
        out = np.zeros(len(xy), bool)
        out[inside] = self.masks[px[inside, 1], px[inside, 0]] == self.value[i]
        return out

    def project(self, i, points):
        world = points @ self.T_cam[i][:3, :3].T + self.T_cam[i][:3, 3]  # camera frame
        xy = world[:, :2] / world[:, 2:] * np.diag(self.K)[:2] + self.K[:2, 2]
        return xy

    def errors(self, a, b, xy_a, xy_b):
        """Per match, full-image pixels from where a's surface point appears in b (inf: a's ray
        misses the object, or b does not show the point)."""
        if len(xy_a) == 0:
            return np.zeros(0)
        T = np.linalg.inv(self.T_cam[a])
        rays = np.c_[(np.asarray(xy_a) - self.K[:2, 2]) / np.diag(self.K)[:2], np.ones(len(xy_a))]
        directions = rays @ T[:3, :3].T
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        origins = np.broadcast_to(T[:3, 3], rays.shape)
        t = first_hit(np.asarray(self.mesh.triangles, np.float64), origins, directions)
        xy = self.project(b, origins + t[:, None] * directions)  # NaN where the ray misses
        ok = np.isfinite(xy).all(axis=1)
        ok[ok] &= self.shows(b, xy[ok])
        return np.where(ok, np.linalg.norm(np.asarray(xy_b) - xy, axis=1), np.inf)

    def rotation_errors(self, poses):
        ids = sorted(poses)
        R_true = np.stack([self.T_cam[i][:3, :3] for i in ids])
        return np.array(rotation_metrics(R_true, np.stack([poses[i][:3, :3] for i in ids]))["per_instance_deg"])


def ideal_pairs(truth: Truth, noise_px: float, rng, max_track: int | None = None, samples: int = 3000):
    """Ideal correspondences of every pair; each surface point one keypoint per copy."""
    points, face = trimesh.sample.sample_surface_even(truth.mesh, samples, seed=1)
    normals = truth.mesh.face_normals[face]
    ids = sorted(truth.T_cam)
    xy, seen = {}, []
    for i in ids:
        R, t = truth.T_cam[i][:3, :3], truth.T_cam[i][:3, 3]
        facing = ((points @ R.T + t) * (normals @ R.T)).sum(axis=1) < 0
        xy[i] = truth.project(i, points)
        seen.append(facing & truth.shows(i, xy[i]))
        xy[i] = xy[i] + rng.normal(0, noise_px, xy[i].shape)
    seen = np.array(seen)
    if max_track is not None:  # each point kept in at most max_track of the copies that show it
        for p in range(seen.shape[1]):
            on = np.flatnonzero(seen[:, p])
            seen[rng.choice(on, max(0, len(on) - max_track), replace=False), p] = False
    return {
        (a, b): (xy[a][seen[k] & seen[m]], xy[b][seen[k] & seen[m]])
        for (k, a), (m, b) in itertools.combinations(enumerate(ids), 2)
    }


def report(tag, truth: Truth, pairs, workdir, max_error_px=2.0) -> str:
    reg = mapping.register(workdir, truth.K, truth.cam.width, truth.cam.height, sorted(truth.T_cam), pairs,
                           max_error_px=max_error_px)  # fmt: skip
    if len(reg.poses) < 2:
        return f"{tag}: registered {len(reg.poses)} of {len(truth.T_cam)}"
    e = truth.rotation_errors(reg.poses)
    return (
        f"{tag}: registered {len(reg.poses)} of {len(truth.T_cam)}, rotation error mean {e.mean():.3f} "
        f"median {np.median(e):.3f} max {e.max():.3f} deg"
    )


def load_pairs(path):
    data = pickle.loads(Path(path).read_bytes())
    if "pairs" in data:
        return data["pairs"]
    kp = data["keypoints"]
    return {p: (kp[p[0]][m[:, 0]], kp[p[1]][m[:, 1]]) for p, m in data["matches"].items()}


def main(capture, segmentation, pairs_path=None, workdir="/tmp/diagnose_mapping"):
    logging.basicConfig(level=logging.WARNING)
    truth = Truth(capture, segmentation)
    work = Path(workdir)
    for noise in (0.5, 1.0):
        for max_track in (None, 4, 3):
            pairs = ideal_pairs(truth, noise, np.random.default_rng(0), max_track)
            tag = f"ideal, {noise} px, tracks {'all' if max_track is None else f'<= {max_track}'}"
            print(report(tag, truth, pairs, work / "ideal"), flush=True)
    if pairs_path is None:
        return
    pairs = load_pairs(pairs_path)
    correct, total, right = {}, 0, 0
    for (a, b), (xy_a, xy_b) in pairs.items():
        ok = truth.errors(a, b, xy_a, xy_b) < 2.0
        correct[a, b] = (xy_a[ok], xy_b[ok])
        total, right = total + len(ok), right + int(ok.sum())
    print(f"matches {total}, within 2 px of the truth {right}", flush=True)
    print(report("matches", truth, pairs, work / "real"), flush=True)
    print(report("matches within 2 px of the truth", truth, correct, work / "correct"), flush=True)


if __name__ == "__main__":
    main(*sys.argv[1:])
