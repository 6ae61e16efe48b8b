"""One keypoint set per copy, matched at the rotation search's angle, so that COLMAP's tracks run
through many copies (Structure from Duplicates, section 3.1, after the search).

The search (matching.py) matches crop a upright against crop b's keypoints *detected on b turned*
by each angle; b's keypoints then differ from pair to pair, and a point seen by three copies
becomes a track of three only where ``snap_to_upright`` finds one of b's own keypoints nearby.
On box-10-hd that left 1,138 matches over 45 pairs, 39 % of them correct, and almost every correct
one in a track of two: even the correct ones alone registered 4 of 10 copies at 15 degrees,
where the true correspondences register all 10 at 0.04 (docs/duplicates.md, "Where it stands").

Here each copy's keypoints are detected once, upright, on a larger crop (``size`` pixels: the
HD copies are about 200 px, so 512 doubles them, and XFeat finds 4x the keypoints on the print),
with a low detection threshold. A pair is matched at the angle the search chose: b's own
keypoints are turned to that angle and described there (XFeat's descriptor map of the turned
crop, sampled at them), and LighterGlue matches them with a's upright ones. Every match joins
two of the copies' fixed keypoints, so a point matched across k copies is one track of k.

Measured with true masks (docs/duplicates.md, "What limits COLMAP's poses"): at 512 px, 13x the
search's correct matches on box-10-hd and 8x on box-20-hd, whose 20 copies COLMAP then places at
2.8 degrees mean, 0.88 median (82 mean from the search's matches); box-10-hd's ten it registers
all, but wrong (look-alike faces matched across copies), so ``track_size`` is off by default.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import matching
from .crops import Crop

__all__ = [
    "TrackFeatures", "detect", "match_at_angle", "match_pairs", "search_angles", "rematch",
    "DETECTION_THRESHOLD", "MAX_KEYPOINTS",
]  # fmt: skip

DETECTION_THRESHOLD = 0.01  # XFeat's default 0.05 keeps a third of the print's corners and dots
MAX_KEYPOINTS = 4096  # per copy, the most confident first
# The angle search again on the fixed keypoints (``search_angles``): the most confident keypoints
# of each copy vote, as mutual nearest neighbours of XFeat's descriptors that pass Lowe's ratio
# test (on test_tracks' turned crops the peak stands 10-13x above the angles half a turn away
# with the ratio test at 0.8; with a floor of 0.8 on the similarity instead, 1.6-1.7x).
# Cheap (a product of two descriptor tables per angle; LighterGlue's 3-4 s per angle on 4,096
# keypoints is not). On box-10-hd the crop search's angle was wrong for most pairs that share
# faces ((2, 3): no correct match at its 16 degrees, 313 at the 240 this search found), but on
# most pairs the counts peak at 4-35 of 1,024 and the peak is noise; LighterGlue at both angles
# then keeps the crop search's (docs/duplicates.md, "Angles searched again").
SEARCH_KEYPOINTS = 1024
SEARCH_RATIO = 0.8
SEARCH_STEP_DEG = 8.0


@dataclass
class TrackFeatures:
    """A copy's fixed keypoints: crop pixels (COLMAP's convention) and upright descriptors."""

    crop: Crop
    canvas: int  # side of the turned images (matching.canvas_size)
    keypoints: np.ndarray  # (K, 2) float64, crop pixels
    descriptors: np.ndarray  # (K, 64) float32, of the upright crop

    def on_canvas(self, angle_deg: float) -> np.ndarray:
        """The keypoints in the canvas of the crop turned by angle_deg (COLMAP pixels)."""
        size = self.crop.image.shape[0]
        return matching.rotate_points(self.keypoints, angle_deg, np.full(2, size / 2.0), np.full(2, self.canvas / 2.0))


def _turned(crop: Crop, angle_deg: float, canvas: int):
    ((gray, mask),) = matching._rotated_inputs(crop, np.array([float(angle_deg)]), canvas)
    return gray, mask


def detect(crop: Crop, threshold: float = DETECTION_THRESHOLD, max_keypoints: int = MAX_KEYPOINTS) -> TrackFeatures:
    """XFeat keypoints of the upright crop inside its eroded mask, and their descriptors."""
    size = int(crop.image.shape[0])
    canvas = matching.canvas_size(size)
    gray, mask = _turned(crop, 0.0, canvas)
    with matching._torch_threads(1):
        model = matching._xfeat()
        x = _tensor(gray)
        out = model.detectAndCompute(x, top_k=16 * max_keypoints, detection_threshold=threshold)[0]
    xy = out["keypoints"].numpy().astype(np.float64)
    keep = np.flatnonzero(matching._inside(mask, xy))[:max_keypoints]  # sorted by score
    centre, centre_rot = np.full(2, size / 2.0), np.full(2, canvas / 2.0)
    keypoints = xy[keep] + matching.PIXEL_SHIFT["xfeat"] - centre_rot + centre  # angle 0: a shift
    return TrackFeatures(crop, canvas, keypoints, out["descriptors"].numpy()[keep].astype(np.float32))


def _tensor(gray: np.ndarray):
    import torch

    return torch.from_numpy(gray.astype(np.float32) / 255.0)[None, None]


def describe(features: TrackFeatures, angle_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """(keypoints on the turned canvas, their descriptors there): XFeat's normalised descriptor
    map of the turned crop, sampled (bicubic, as XFeat samples its own keypoints) at the fixed
    keypoints turned with it."""
    import torch.nn.functional as F

    gray, _ = _turned(features.crop, angle_deg, features.canvas)
    points = features.on_canvas(angle_deg)
    with matching._torch_threads(1) as torch:
        model = matching._xfeat()
        with torch.inference_mode():
            x, _, _ = model.preprocess_tensor(_tensor(gray))
            descriptor_map = F.normalize(model.net(x)[0], dim=1)
            pos = torch.from_numpy(points - matching.PIXEL_SHIFT["xfeat"]).float()[None]
            sampled = model.interpolator(descriptor_map, pos, H=x.shape[2], W=x.shape[3])[0]
    return points, sampled.numpy().astype(np.float32)


def match_at_angle(a: TrackFeatures, b: TrackFeatures, angle_deg: float) -> np.ndarray:
    """(M, 2) indices into a's and b's keypoints: LighterGlue, a upright against b turned."""
    if len(a.keypoints) == 0 or len(b.keypoints) == 0:
        return np.zeros((0, 2), np.int64)
    points_b, descriptors_b = describe(b, angle_deg)
    shift = matching.PIXEL_SHIFT["xfeat"]
    with matching._torch_threads(1) as torch:
        glue = matching._lighterglue()
        data = {
            "keypoints0": torch.from_numpy(a.on_canvas(0.0) - shift).float()[None],
            "descriptors0": torch.from_numpy(a.descriptors)[None],
            "image_size0": torch.tensor([[a.canvas, a.canvas]]).float(),
            "keypoints1": torch.from_numpy(points_b - shift).float()[None],
            "descriptors1": torch.from_numpy(descriptors_b)[None],
            "image_size1": torch.tensor([[b.canvas, b.canvas]]).float(),
        }
        with torch.inference_mode():
            out = glue(data, min_conf=matching.LIGHTERGLUE_MIN_CONF)
    return out["matches"][0].numpy().astype(np.int64).reshape(-1, 2)


def match_pairs(features: dict[int, TrackFeatures], angles: dict[tuple[int, int], float]):
    """Every pair at its angle: {(a, b): (xy_a, xy_b)} in full-image pixels, each point one of
    its copy's fixed keypoints (so identical across pairs: mapping.py dedupes them into one)."""
    full = {i: f.crop.to_full(f.keypoints) for i, f in features.items()}
    out = {}
    for (a, b), angle in angles.items():
        idx = match_at_angle(features[a], features[b], angle)
        out[a, b] = (full[a][idx[:, 0]], full[b][idx[:, 1]])
    return out


def _mutual_count(da: np.ndarray, db: np.ndarray, ratio: float) -> int:
    """Mutual nearest neighbours of two descriptor tables (unit rows) whose distance is below
    ``ratio`` times the distance to a's second nearest in b."""
    if len(da) < 1 or len(db) < 2:
        return 0
    s = da @ db.T
    rows = np.arange(len(da))
    ab, ba = s.argmax(axis=1), s.argmax(axis=0)
    first = s[rows, ab]
    s[rows, ab] = -np.inf
    second = s.max(axis=1)
    distance = lambda similarity: np.sqrt(np.maximum(2.0 - 2.0 * similarity, 0.0))  # noqa: E731
    return int(((ba[ab] == rows) & (distance(first) < ratio * distance(second))).sum())


def search_angles(features: dict[int, TrackFeatures], pairs, step_deg: float = SEARCH_STEP_DEG,
                  keypoints: int = SEARCH_KEYPOINTS, ratio: float = SEARCH_RATIO):  # fmt: skip
    """Per pair (a, b): (angles, counts), the rotation search on the copies' fixed keypoints: a's
    ``keypoints`` most confident upright against b's turned by every multiple of ``step_deg``, the
    count of mutual nearest neighbours that pass the ratio test per angle. b's descriptors are
    computed once per angle."""
    angles = np.arange(0.0, 360.0, step_deg)
    out = {}
    for b in sorted({q for _, q in pairs}):
        turned = [describe(features[b], angle)[1][:keypoints] for angle in angles]
        for a in sorted(p for p, q in pairs if q == b):
            da = features[a].descriptors[:keypoints]
            out[a, b] = angles, np.array([_mutual_count(da, db, ratio) for db in turned])
    return out


def rematch(features: dict[int, TrackFeatures], angles: dict[tuple[int, int], float], curves, window: int = 3):
    """``match_pairs`` at the better of two angles per pair: the crop search's and the peak of
    ``search_angles``' smoothed counts; LighterGlue at both (one when they are within a step),
    the angle with more matches kept. Returns (matches as match_pairs', chosen angle per pair)."""
    full = {i: f.crop.to_full(f.keypoints) for i, f in features.items()}
    out, chosen = {}, {}
    for (a, b), angle in angles.items():
        grid, counts = curves[a, b]
        peak = float(grid[int(np.argmax(matching.smooth_counts(counts, window)))])
        step = float(grid[1] - grid[0]) if len(grid) > 1 else 360.0
        distance = abs((peak - angle + 180.0) % 360.0 - 180.0)
        candidates = [angle] if distance < step else [angle, peak]
        found = [(match_at_angle(features[a], features[b], c), c) for c in candidates]
        idx, chosen[a, b] = max(found, key=lambda f: len(f[0]))
        out[a, b] = (full[a][idx[:, 0]], full[b][idx[:, 1]])
    return out, chosen
