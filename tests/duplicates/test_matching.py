"""Rotation-aware matching (duplicates/matching.py) against known in-plane rotations.

The pair is a textured crop and the same crop turned by OpenCV's own rotation about its
centre (cv2.getRotationMatrix2D, independent of matching.py's warp), so the true
correspondence of every pixel and the true angle are known exactly."""

import cv2
import numpy as np
import pytest

from invrender.duplicates.crops import Crop
from invrender.duplicates.matching import (
    CropFeatures,
    canvas_size,
    extract,
    fundamental_inliers,
    match_pair,
    neighbour_consistent,
    rotate_image,
    rotate_points,
    smooth_counts,
    snap_to_upright,
)
from invrender.scene.images import srgb_to_linear
from invrender.scene.types import SceneError

S = 160  # crop side: small keeps XFeat on the CPU fast


def textured_image(seed: int = 3) -> np.ndarray:
    """(S, S, 3) float32 linear RGB: smooth colour noise, rectangles and letters (no rotational
    symmetry, corners for SIFT and XFeat alike)."""
    rng = np.random.default_rng(seed)
    noise = cv2.GaussianBlur(rng.random((S, S, 3)).astype(np.float32), (0, 0), 4.0)
    img = np.round(255 * (noise - noise.min()) / (noise.max() - noise.min())).astype(np.uint8)
    for _ in range(12):
        x0, y0 = rng.integers(10, S - 40, 2)
        w, h = rng.integers(6, 28, 2)
        cv2.rectangle(img, (int(x0), int(y0)), (int(x0 + w), int(y0 + h)), rng.integers(0, 256, 3).tolist(), -1)
    cv2.putText(img, "SfD", (38, 92), cv2.FONT_HERSHEY_SIMPLEX, 1.3, (10, 25, 230), 3)
    cv2.putText(img, "7q", (60, 130), cv2.FONT_HERSHEY_SIMPLEX, 0.9, (240, 230, 25), 2)
    return srgb_to_linear(img / 255.0).astype(np.float32)


def disc_mask() -> np.ndarray:
    """The object inscribed in the crop: a disc, so turning the crop keeps all of it."""
    ys, xs = np.mgrid[0:S, 0:S] + 0.5
    return (xs - S / 2) ** 2 + (ys - S / 2) ** 2 < (0.47 * S) ** 2


def turned_crop(theta_deg: float, instance_id: int) -> Crop:
    """The textured crop turned by theta counter-clockwise on screen (OpenCV's convention)
    about its centre (pixel indices: (S - 1) / 2)."""
    M = cv2.getRotationMatrix2D(((S - 1) / 2, (S - 1) / 2), theta_deg, 1.0)
    img = cv2.warpAffine(textured_image(), M, (S, S), flags=cv2.INTER_LINEAR)
    mask = disc_mask()
    return Crop(instance_id, img * mask[..., None], mask, np.zeros(2), 1.0)


def true_xy_a(xy_b: np.ndarray, theta_deg: float) -> np.ndarray:
    """Where crop b's pixels (b = a turned counter-clockwise by theta) come from in crop a:
    a counter-clockwise turn on screen is R(-theta) in pixel axes, so a = R(theta) b."""
    return rotate_points(xy_b, theta_deg, (S / 2, S / 2), (S / 2, S / 2))


def angle_gap(a: float, b: float) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


@pytest.fixture(scope="module")
def features():
    """Per matcher: features of the upright crop and of it turned by 110 degrees (between two
    angle steps) and by 90, at 20-degree steps (18 angles)."""
    crops = {0: turned_crop(0.0, 1), 110: turned_crop(110.0, 2), 90: turned_crop(90.0, 3)}
    return {m: {t: extract(c, m, step_deg=20.0) for t, c in crops.items()} for m in ("sift", "xfeat")}


@pytest.mark.parametrize("matcher", ["sift", "xfeat"])
def test_rotation_search_finds_the_turn_and_true_correspondences(features, matcher):
    a, b = features[matcher][0], features[matcher][110]
    pm = match_pair(a, b, matcher, window=3)
    assert angle_gap(pm.angle_deg, 110.0) <= 20.0, (pm.angle_deg, pm.counts)
    assert len(pm.xy_a) >= 20, pm.counts
    err = np.linalg.norm(pm.xy_a - true_xy_a(pm.xy_b, 110.0), axis=1)
    assert np.median(err) < 2.0, np.median(err)
    assert pm.xy_a.shape == pm.xy_b.shape and pm.scores.shape == (len(pm.xy_a),)


@pytest.mark.parametrize("matcher", ["sift", "xfeat"])
def test_matchers_need_the_search(features, matcher):
    """XFeat + LighterGlue and upright SIFT are not rotation invariant: at 90 degrees without the
    search they find few matches, with it many (the paper's reason for rotating)."""
    a, b = features[matcher][0], features[matcher][90]
    searched = match_pair(a, b, matcher)
    upright = match_pair(a, b, matcher, rotation_search=False)
    assert upright.angle_deg == 0.0 and len(upright.counts) == 1
    assert angle_gap(searched.angle_deg, 90.0) <= 20.0
    assert len(searched.xy_a) > 3 * len(upright.xy_a), (len(searched.xy_a), len(upright.xy_a))


def test_filters_keep_the_true_matches(features):
    """min_score keeps the confident subset; the fundamental-matrix RANSAC keeps nearly all of a
    pair that is one rigid turn (every match consistent) and drops planted outliers."""
    a, b = features["xfeat"][0], features["xfeat"][110]
    raw = match_pair(a, b, "xfeat")
    confident = match_pair(a, b, "xfeat", min_score=0.5)
    assert 0 < len(confident.xy_a) < len(raw.xy_a) and confident.scores.min() >= 0.5
    good = np.linalg.norm(raw.xy_a - true_xy_a(raw.xy_b, 110.0), axis=1) < 2.0
    xy_b = raw.xy_b.copy()
    xy_b[::4] = np.random.default_rng(1).uniform(20, S - 20, xy_b[::4].shape)  # a quarter made wrong
    planted = np.zeros(len(xy_b), bool)
    planted[::4] = True
    keep = fundamental_inliers(raw.xy_a, xy_b, 2.0)
    assert keep[good & ~planted].mean() > 0.9 and keep[planted].mean() < 0.2, (keep[good].mean(), keep[planted].mean())
    # neighbour consistency, on b turned like a (the true turn): the planted matches disagree
    turned_b = rotate_points(xy_b, 110.0, (S / 2, S / 2), (S / 2, S / 2))
    keep = neighbour_consistent(raw.xy_a, turned_b, radius_px=4.0)
    assert keep[good & ~planted].mean() > 0.8 and keep[planted].mean() < 0.1, (keep[good].mean(), keep[planted].mean())
    consistent = match_pair(a, b, "xfeat", consistency_px=4.0)
    assert len(consistent.xy_a) > 0.6 * len(raw.xy_a)


def test_batched_angles_match_one_by_one(features):
    """LighterGlue over all angles in one batch gives the same matches as angle by angle with the
    same keypoints (each angle cut to the fewest any angle has)."""
    from invrender.duplicates.matching import _glue_pairs

    a, b = features["xfeat"][0], features["xfeat"][110]
    ks = list(range(len(b.angles_deg)))
    batched = _glue_pairs(a, b, ks, batch=True)
    single = _glue_pairs(a, b, ks, batch=False, cap=int(b.counts().min()))
    assert sum(len(p) for p, _ in batched) > 50
    for (p1, s1), (p2, s2) in zip(batched, single, strict=True):
        np.testing.assert_array_equal(p1, p2)
        np.testing.assert_allclose(s1, s2, atol=1e-5)


def test_rotate_back_is_exact():
    """A Gaussian spot at a sub-pixel position, turned by rotate_image: its centroid in the turned
    canvas (pixel centres at +0.5) maps back onto the spot within 0.01 px."""
    size, canvas, sigma = 96, canvas_size(96), 2.5
    spot = np.array([31.37, 58.81])  # COLMAP pixels of the crop
    ys, xs = np.mgrid[0:size, 0:size] + 0.5
    img = np.exp(-((xs - spot[0]) ** 2 + (ys - spot[1]) ** 2) / (2 * sigma**2)).astype(np.float32)
    for angle in (0.0, 4.0, 37.0, 90.0, 213.0):
        turned = rotate_image(img, angle, canvas).astype(np.float64)
        cy, cx = np.mgrid[0:canvas, 0:canvas] + 0.5
        centroid = np.array([(turned * cx).sum(), (turned * cy).sum()]) / turned.sum()
        back = rotate_points(centroid, -angle, (canvas / 2, canvas / 2), (size / 2, size / 2))[0]
        assert np.linalg.norm(back - spot) < 0.01, (angle, back, spot)


def test_features_rotated_back_agree_across_angles(features):
    """Keypoints found at angle k, rotated back, land on the same crop pixels as at angle 0: the
    median nearest distance is small (detector noise), not the metres a sign error would give."""
    f = features["sift"][0]
    base = f.keypoints[f.at(0)]
    for k in (3, 9):
        d = np.linalg.norm(f.keypoints[f.at(k)][:, None] - base[None], axis=2).min(axis=1)
        assert np.median(d) < 0.5, (k, np.median(d))


def test_save_load_round_trip(features, tmp_path):
    f = features["xfeat"][110]
    f.save(tmp_path / "f.npz")
    g = CropFeatures.load(tmp_path / "f.npz")
    assert (g.instance_id, g.matcher, g.size) == (f.instance_id, f.matcher, f.size)
    for name in ("image_size", "angles_deg", "offsets", "keypoints_rot", "keypoints", "descriptors", "scores"):
        np.testing.assert_array_equal(getattr(g, name), getattr(f, name))
        assert getattr(g, name).dtype == getattr(f, name).dtype
    (tmp_path / "bad.npz").write_bytes(b"not an npz")
    with pytest.raises(SceneError, match="bad.npz"):
        CropFeatures.load(tmp_path / "bad.npz")


def test_no_rotations_and_bad_input():
    crop = turned_crop(0.0, 1)
    f = extract(crop, "sift", rotations=False)
    assert f.angles_deg.tolist() == [0.0] and len(f.keypoints) > 20
    mask = crop.mask
    assert mask[np.round(f.keypoints[:, 1] - 0.5).astype(int), np.round(f.keypoints[:, 0] - 0.5).astype(int)].all()
    with pytest.raises(SceneError, match="matcher"):
        extract(crop, "orb")
    with pytest.raises(SceneError, match="step_deg"):
        extract(crop, "sift", step_deg=0.0)


def test_smooth_counts_is_circular():
    np.testing.assert_allclose(smooth_counts(np.array([3, 0, 0, 0, 0, 6]), 3), [3, 1, 0, 0, 2, 3])
    np.testing.assert_array_equal(smooth_counts(np.array([1, 5, 2]), 1), [1, 5, 2])


def oblique_crop(A: np.ndarray, instance_id: int) -> Crop:
    """The textured disc mapped by the 2 x 2 matrix A about the crop's centre: a face seen
    obliquely (foreshortened) and turned."""
    centre = np.full(2, (S - 1) / 2)  # pixel indices, as warpAffine's
    M = np.c_[A, centre - A @ centre]
    img = cv2.warpAffine(textured_image(), M, (S, S), flags=cv2.INTER_LINEAR)
    mask = cv2.warpAffine(disc_mask().astype(np.float32), M, (S, S)) > 0.5
    return Crop(instance_id, img * mask[..., None], mask, np.zeros(2), 1.0)


def test_asift_matches_a_face_foreshortened_where_the_searching_matchers_do_not():
    """A face tilted away 66 degrees (foreshortened 2.5x along a direction 30 degrees from x) and
    turned 70 degrees, as an upright box's top against a lying box's side: ASIFT, with no
    rotation search, finds 30x the correct correspondences of upright SIFT and XFeat searched
    over every turn (measured 190 against 6 and 6 within 2 pixels of the true affine map)."""
    turn, axis = np.radians(70.0), np.radians(30.0)
    T = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    R = np.array([[np.cos(axis), -np.sin(axis)], [np.sin(axis), np.cos(axis)]])
    A = T @ R @ np.diag([1 / 2.5, 1.0]) @ R.T
    upright = Crop(1, textured_image() * disc_mask()[..., None], disc_mask(), np.zeros(2), 1.0)
    oblique = oblique_crop(A, 2)
    correct = {}
    for matcher in ("asift", "sift", "xfeat"):
        a, b = extract(upright, matcher, step_deg=10.0), extract(oblique, matcher, step_deg=10.0)
        assert len(a.angles_deg) == (1 if matcher == "asift" else 36)  # ASIFT has no search
        pm = match_pair(a, b, matcher)
        true_a = (pm.xy_b - S / 2) @ np.linalg.inv(A).T + S / 2
        correct[matcher] = int((np.linalg.norm(pm.xy_a - true_a, axis=1) < 2.0).sum())
    assert correct["asift"] >= 100, correct
    assert correct["asift"] > 5 * max(correct["sift"], correct["xfeat"]), correct


def test_sift_keypoints_in_colmap_pixels():
    """A dark Gaussian spot's SIFT keypoint lands on the spot's centre in COLMAP pixels (OpenCV
    reports it 0.25 px short of that: matching.PIXEL_SHIFT)."""
    size = 96
    ys, xs = np.mgrid[0:size, 0:size] + 0.5
    for spot in ((40.3, 51.6), (47.75, 44.2)):
        img = np.exp(-((xs - spot[0]) ** 2 + (ys - spot[1]) ** 2) / (2 * 3.0**2))
        srgb = 0.85 - 0.7 * img
        crop = Crop(
            1,
            np.repeat(srgb_to_linear(srgb)[..., None], 3, axis=2).astype(np.float32),
            np.ones((size, size), bool),
            np.zeros(2),
            1.0,
        )
        f = extract(crop, "sift", rotations=False)
        nearest = np.linalg.norm(f.keypoints - np.array(spot), axis=1).min()
        assert nearest < 0.1, (spot, nearest)


# ---------------------------------------------------------------------------- a rendered capture
# Cans of a synthetic duplicates capture, cropped from the true instance masks, matched pair by
# pair and scored against the true poses: python tests/duplicates/test_matching.py CAPTURE_DIR
# (or the benchmark below, which renders one). Precision: matches whose b point lies within 3 crop
# pixels of where a's surface point projects in b (and is visible there).

CROP = 256


def fixture_crops(capture) -> list[Crop]:
    """Square crops around each true instance (1.1 x its box's longer side), masked, at CROP px."""
    from invrender.scene.images import read_image

    image = read_image(capture / "images" / "view_000.exr")
    ids = cv2.imread(str(capture / "ground_truth" / "masks" / "view_000.png"), cv2.IMREAD_UNCHANGED)
    crops = []
    for i in range(1, int(ids.max()) + 1):
        ys, xs = np.nonzero(ids == i)
        centre = np.array([xs.min() + xs.max() + 1, ys.min() + ys.max() + 1]) / 2.0
        side = 1.1 * max(xs.max() + 1 - xs.min(), ys.max() + 1 - ys.min())
        scale, offset = CROP / side, centre - side / 2.0
        # crop xy = (full xy - offset) * scale in COLMAP pixels; warpAffine takes pixel indices
        M = np.array([[scale, 0, scale * (0.5 - offset[0]) - 0.5], [0, scale, scale * (0.5 - offset[1]) - 0.5]])
        img = cv2.warpAffine(image, M, (CROP, CROP), flags=cv2.INTER_LINEAR)
        mask = cv2.warpAffine((ids == i).astype(np.uint8), M, (CROP, CROP), flags=cv2.INTER_NEAREST) > 0
        crops.append(Crop(i, img * mask[..., None], mask, offset, float(scale)))
    return crops


def first_hit(triangles: np.ndarray, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Ray parameter t of each ray's nearest triangle (inf: a miss), by brute force over
    (F, 3, 3) triangles (render/bvh.py's float64 Moller-Trumbore)."""
    from invrender.render.bvh import _intersect_mt

    a, b, c = (triangles[None, :, k] for k in range(3))
    t = np.full(len(origins), np.inf)
    for s in range(0, len(origins), 256):
        o, d = origins[s : s + 256, None], directions[s : s + 256, None]
        t[s : s + 256] = _intersect_mt(o, d, a, b, c).min(axis=1)
    return t


class Truth:
    """Where a crop pixel of one instance lies on the object, and where that point appears in
    another instance's crop: rays through the true camera cast at the true object mesh."""

    def __init__(self, capture, crops):
        import json

        import trimesh  # reads the PLY

        from invrender.scene.cameras import read_cameras

        self.cam = read_cameras(capture / "sparse")[0]
        poses = json.loads((capture / "ground_truth" / "poses.json").read_text())["instances"]
        self.T = {p["instance_id"]: np.array(p["T_obj2world"], np.float64) for p in poses}
        obj = trimesh.load(capture / "ground_truth" / "object.ply", process=False)
        self.obj = np.asarray(obj.triangles, np.float64)
        self.world = np.concatenate([self.obj @ T[:3, :3].T + T[:3, 3] for T in self.T.values()])
        self.crops = {c.instance_id: c for c in crops}
        self.centre = -self.cam.R.T @ self.cam.t

    def rays(self, crop, xy):
        (fx, fy), (cx, cy) = self.cam.focal, self.cam.principal_point
        full = np.asarray(xy) / crop.scale + crop.offset
        d_cam = np.stack([(full[:, 0] - cx) / fx, (full[:, 1] - cy) / fy, np.ones(len(full))], axis=1)
        d = d_cam @ self.cam.R  # R^T d_cam
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def surface(self, ia, xy_a):
        """(N, 3) object-frame points seen at crop a's pixels (NaN where the ray misses a)."""
        T_inv = np.linalg.inv(self.T[ia])
        d = self.rays(self.crops[ia], xy_a) @ T_inv[:3, :3].T
        o = np.broadcast_to(T_inv[:3, :3] @ self.centre + T_inv[:3, 3], d.shape)
        t = first_hit(self.obj, o, d)
        return np.where(np.isfinite(t)[:, None], o + t[:, None] * d, np.nan)

    def project(self, ib, p_obj):
        """Crop b pixels of object points placed by instance b's pose, and whether each is the
        first surface its camera ray meets (visible)."""
        crop = self.crops[ib]
        pw = p_obj @ self.T[ib][:3, :3].T + self.T[ib][:3, 3]
        pc = pw @ self.cam.R.T + self.cam.t
        (fx, fy), (cx, cy) = self.cam.focal, self.cam.principal_point
        full = np.stack([fx * pc[:, 0] / pc[:, 2] + cx, fy * pc[:, 1] / pc[:, 2] + cy], axis=1)
        xy = (full - crop.offset) * crop.scale
        visible = np.zeros(len(pw), bool)
        ok = np.flatnonzero(np.isfinite(pw).all(axis=1))
        if len(ok):
            d = pw[ok] - self.centre
            dist = np.linalg.norm(d, axis=1)
            hit = first_hit(self.world, np.broadcast_to(self.centre, d.shape), d / dist[:, None])
            visible[ok] = hit > dist - 1e-4
        return xy, visible

    def errors(self, ia, ib, xy_a, xy_b):
        """Per match: distance (crop b pixels) from the true position, inf where the true point is
        hidden in b or a's ray misses its object."""
        truth, visible = self.project(ib, self.surface(ia, xy_a))
        err = np.linalg.norm(np.asarray(xy_b) - truth, axis=1)
        return np.where(visible & np.isfinite(err), err, np.inf)

    def inplane_angle(self, ia, ib, spacing=6):
        """The true turn of b onto a: the rotation of a 2D Procrustes fit of a's mask pixels (on a
        grid) to their true positions in b, over the points visible in both; None below 30."""
        crop = self.crops[ia]
        ys, xs = np.mgrid[spacing // 2 : CROP : spacing, spacing // 2 : CROP : spacing]
        grid = np.stack([xs.ravel(), ys.ravel()], axis=1) + 0.5
        grid = grid[crop.mask[ys.ravel(), xs.ravel()]]
        truth, visible = self.project(ib, self.surface(ia, grid))
        ok = visible & np.isfinite(truth).all(axis=1)
        if ok.sum() < 30:
            return None
        pa, pb = grid[ok] - grid[ok].mean(0), truth[ok] - truth[ok].mean(0)
        H = pb.T @ pa  # maximise sum a . R b
        return float(np.degrees(np.arctan2(H[0, 1] - H[1, 0], H[0, 0] + H[1, 1])))


def measure(capture, matchers=("sift", "xfeat"), step_deg=4.0, **match_options) -> list[dict]:
    """Per matcher, with and without the search: matches, precision (within 3 crop px, and within
    3 full-image px), the chosen angle's error against the true turn, seconds per crop and per pair."""
    import itertools
    import time

    crops = fixture_crops(capture)
    truth = Truth(capture, crops)
    pairs = list(itertools.combinations([c.instance_id for c in crops], 2))
    true_angle = {p: truth.inplane_angle(*p) for p in pairs}
    rows = []
    for matcher in matchers:
        start = time.perf_counter()
        feats = {c.instance_id: extract(c, matcher, step_deg=step_deg) for c in crops}
        per_crop = (time.perf_counter() - start) / len(crops)
        for search in (True, False):
            start = time.perf_counter()
            found = {
                p: match_pair(feats[p[0]], feats[p[1]], matcher, rotation_search=search, **match_options) for p in pairs
            }
            per_pair = (time.perf_counter() - start) / len(pairs)
            err = {p: truth.errors(*p, pm.xy_a, pm.xy_b) for p, pm in found.items()}
            full_px = {p: err[p] / truth.crops[p[1]].scale for p in pairs}  # crop b px -> full-image px
            n = sum(len(e) for e in err.values())
            gaps = [angle_gap(found[p].angle_deg, a) for p, a in true_angle.items() if a is not None]
            rows.append(
                {
                    "matcher": matcher,
                    "search": search,
                    "matches": n,
                    "precision_3px_crop": sum(int((e < 3).sum()) for e in err.values()) / max(n, 1),
                    "precision_3px_full": sum(int((e < 3).sum()) for e in full_px.values()) / max(n, 1),
                    "angle_error_median": float(np.median(gaps)),
                    "angle_within_8deg": float(np.mean(np.array(gaps) <= 8.0)),
                    "seconds_per_crop": per_crop,
                    "seconds_per_pair": per_pair,
                }
            )
    return rows


@pytest.mark.benchmark
def test_precision_on_rendered_cans(tmp_path):
    """Ten cans at 640 x 480 (64 spp), cropped at 256 px: the table of docs/duplicates.md."""
    import json
    import subprocess
    import sys

    config = tmp_path / "cans.json"
    config.write_text(
        json.dumps({"camera": {"width": 640, "height": 480}, "count": 10, "placement": {"extent": [0.6, 0.4]}})
    )
    capture = tmp_path / "cans"
    cmd = [sys.executable, "-m", "invrender.cli", "synthesize", "duplicates", "--out", str(capture), "--spp", "64"]
    subprocess.run([*cmd, "--config", str(config)], check=True)
    rows = measure(capture)
    for r in rows:
        print(r)
    xfeat = {r["search"]: r for r in rows if r["matcher"] == "xfeat"}
    assert xfeat[True]["matches"] > xfeat[False]["matches"]


if __name__ == "__main__":
    import sys
    from pathlib import Path

    for row in measure(Path(sys.argv[1])):
        print(row)


def test_coarse_to_fine_search_finds_what_the_full_search_finds(features):
    """LighterGlue's coarse pass (every 60 degrees here, 256 keypoints) then the fine one around
    its best: the same turn as matching every angle, on fewer calls. (The crop turned 90 degrees,
    on a step: at 110, between two, the two searches' counts tie at 100 and 120 and which wins
    depends on the CPU's arithmetic.)"""
    a, b = features["xfeat"][0], features["xfeat"][90]
    full = match_pair(a, b, "xfeat", coarse_deg=0.0)
    fast = match_pair(a, b, "xfeat", coarse_deg=60.0)
    assert fast.angle_deg == full.angle_deg and len(fast.xy_a) == len(full.xy_a)
    assert np.count_nonzero(fast.counts) <= 7 < np.count_nonzero(full.counts)


def test_snapping_moves_matches_onto_the_upright_keypoints_only_when_near(features):
    b = features["xfeat"][110]
    own = b.keypoints[b.at(0)]
    xy = np.vstack([own[:5] + [0.8, -0.6], own[5:10] + [4.0, 0.0]])
    snapped = snap_to_upright(xy, b, radius_px=1.5)
    np.testing.assert_array_equal(snapped[:5], own[:5])
    nearest = np.min(np.linalg.norm(own[None] - xy[5:, None], axis=2), axis=1)
    np.testing.assert_array_equal(snapped[5:][nearest > 1.5], xy[5:][nearest > 1.5])
