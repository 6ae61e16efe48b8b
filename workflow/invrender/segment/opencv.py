"""The built-in backend: instances of one repeated object in one photograph, with OpenCV alone
(no downloaded weights).

The copies are identical, so they share one colour distribution that the support (a floor, a
table) lacks. The steps:

1. Object colours. Without an exemplar: the support is what the image's border shows (objects
   rarely cover it), so ``P(c | support) / P(c)`` (border histogram over the whole image's, in
   Lab) is about 1 / (support share) on the support and near 0 on colours only the objects
   have. With an exemplar box: GrabCut in the box gives the object's own pixels, and a colour
   is the object's where ``P(c | object)`` beats ``P(c | support)``.
2. Cores: the pixels of object colours, opened (noise) and closed over gaps such as a white
   band across a label, a fraction of the instance size wide. One core per copy, except where
   copies touch.
3. Touching copies are split, not merged: a core of about k times the expected instance area
   (the median core, or the exemplar's) is cut into k by a watershed of its distance transform
   from the k plateaus of that transform (the copies' middles; the neck between them is low).
4. Extent: GrabCut, seeded with the cores as foreground and the far support as background,
   adds the object's parts in support-like colours (caps, a white band); each added pixel goes
   to the nearest core (a watershed of the distance to the cores), so GrabCut never merges two
   copies. Then each instance is its convex hull, not crossing another instance: a convex
   object's silhouette is convex (cans, boxes), which restores parts no colour separates.
5. Specks (below ``min_area_fraction`` of the expected area) are dropped.

Score of an instance: the Bhattacharyya similarity of its colour histogram to the pooled
histogram of the other instances, in [0, 1]: the evidence that it is a copy of the same
object (rotation-invariant, as a histogram ignores where the colours are).

What it cannot do: a copy seen so that only support-like colours show (a can end-on, its grey
cap on grey tiles) has no core and is missed; copies of one clump with no lone copy beside it
(the expected area is then wrong) are not split, unless an exemplar gives the area.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage

from ..scene.images import linear_to_srgb

__all__ = ["OpenCVSettings", "segment_instances", "to_srgb8", "colour_histogram"]

logger = logging.getLogger(__name__)

LAB_BINS = (16, 24, 24)  # L, a, b: coarse in lightness (shading), fine in chroma


@dataclass
class OpenCVSettings:
    exemplar: tuple[float, float, float, float] | None = None  # x0, y0, x1, y1 pixels of one copy
    core_threshold: float = 0.3  # P(c|support)/P(c) below this: an object colour
    border_fraction: float = 0.04  # width of the border band that shows the support
    close_fraction: float = 0.15  # closing radius over sqrt(expected area): gaps in a core
    split_factor: float = 1.5  # a core this many expected areas or more is touching copies
    min_area_fraction: float = 0.3  # specks below this share of the expected area are dropped
    grabcut_iterations: int = 5
    convex: bool = True  # each instance its convex hull (convex objects: cans, boxes)


def to_srgb8(rgb: np.ndarray) -> np.ndarray:
    """Linear RGB -> 8-bit sRGB, exposed so that the 99th percentile is white (as the capture's
    PNG previews are), so the colour bins mean the same at any exposure."""
    level = float(np.percentile(rgb.max(axis=2), 99)) if rgb.size else 0.0
    return np.round(linear_to_srgb(rgb / (level if level > 0 else 1.0)) * 255).astype(np.uint8)


def _disk(radius: float) -> np.ndarray:
    r = max(1, int(round(radius)))
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))


def colour_histogram(lab: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Normalised Lab histogram of the pixels in ``mask``, blurred by a bin so that colours
    near a seen one count as seen (the sample is finite, the photograph noisy)."""
    h = cv2.calcHist([lab], [0, 1, 2], mask.astype(np.uint8), list(LAB_BINS), [0, 256] * 3)
    h = ndimage.gaussian_filter(h, 1.0, mode="constant")
    return h / max(float(h.sum()), 1e-12)


def _backproject(lab: np.ndarray, hist: np.ndarray) -> np.ndarray:
    idx = [(lab[..., i].astype(np.int32) * bins) // 256 for i, bins in enumerate(LAB_BINS)]
    return hist[idx[0], idx[1], idx[2]]


def _border(shape, fraction: float) -> np.ndarray:
    h, w = shape
    b = max(2, round(fraction * min(h, w)))
    band = np.zeros((h, w), bool)
    band[:b] = band[-b:] = True
    band[:, :b] = band[:, -b:] = True
    return band


def _areas(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    _, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    return labels, stats[1:, cv2.CC_STAT_AREA]


def _typical_area(areas: np.ndarray) -> float:
    """The expected instance area: the median of the components of at least a fifth of the
    largest (specks do not pull it down; touching pairs are a minority)."""
    return float(np.median(areas[areas >= 0.2 * areas.max()]))


def _exemplar_object(bgr: np.ndarray, box, iterations: int) -> np.ndarray:
    """The exemplar copy's own pixels: GrabCut initialised by its box."""
    h, w = bgr.shape[:2]
    x0, y0, x1, y1 = (int(round(v)) for v in box)
    x0, y0, x1, y1 = max(0, x0), max(0, y0), min(w, x1), min(h, y1)
    mask = np.zeros((h, w), np.uint8)
    bgd, fgd = np.zeros((1, 65)), np.zeros((1, 65))
    cv2.grabCut(bgr, mask, (x0, y0, x1 - x0, y1 - y0), bgd, fgd, iterations, cv2.GC_INIT_WITH_RECT)
    return (mask == cv2.GC_FGD) | (mask == cv2.GC_PR_FGD)


def _object_colours(lab, bgr, s: OpenCVSettings) -> tuple[np.ndarray, float | None]:
    """Per pixel True where its colour is the object's (step 1), and the exemplar's area (None
    without one)."""
    support = _border(lab.shape[:2], s.border_fraction)
    if s.exemplar is None:
        ratio = _backproject(lab, colour_histogram(lab, support)) / np.maximum(
            _backproject(lab, colour_histogram(lab, np.ones(lab.shape[:2], bool))), 1e-12
        )
        return ratio < s.core_threshold, None
    exemplar = _exemplar_object(bgr, s.exemplar, s.grabcut_iterations)
    x0, y0, x1, y1 = (int(round(v)) for v in s.exemplar)
    ring = np.zeros(exemplar.shape, bool)
    ring[max(0, y0) : y1, max(0, x0) : x1] = True
    support |= ring & ~exemplar  # the exemplar box's own background is support too
    p_obj = _backproject(lab, colour_histogram(lab, exemplar))
    p_sup = _backproject(lab, colour_histogram(lab, support))
    return p_obj > 2.0 * p_sup, float(exemplar.sum())


def _watershed(markers: np.ndarray, region: np.ndarray, elevation: np.ndarray) -> np.ndarray:
    """Grow ``markers`` (0 = unlabelled) over ``region`` by ``elevation`` (scipy's image
    foresting transform); 0 outside the region."""
    m = markers.astype(np.int32)
    outside = int(m.max()) + 1
    m = np.where(region, m, outside)
    e = elevation.astype(np.float64)
    span = np.ptp(e[region]) if region.any() else 1.0
    e = (e - (e[region].min() if region.any() else 0.0)) / max(span, 1e-12)
    e = np.where(region, np.clip(e, 0, 1) * 65000, 65535).astype(np.uint16)
    grown = ndimage.watershed_ift(e, m)
    grown[(grown == outside) | ~region] = 0
    return grown


def _split(blob: np.ndarray, k: int) -> np.ndarray:
    """Cut a core of k touching copies into k (step 3): markers are the plateaus of its distance
    transform above the highest level that gives k of them (or the nearest count)."""
    dist = cv2.distanceTransform(blob.astype(np.uint8), cv2.DIST_L2, 5)
    best = None
    for level in np.linspace(0.9, 0.1, 17):
        markers, count = ndimage.label(dist > level * dist.max())
        if best is None or abs(count - k) < abs(best[1] - k):
            best = markers, count
        if count == k:
            break
    return _watershed(best[0], blob, dist.max() - dist)


def _cores(is_object: np.ndarray, s: OpenCVSettings, area: float | None):
    """Labelled cores, one per copy (steps 2, 3 and 5), and the expected instance area."""
    core = cv2.morphologyEx(is_object.astype(np.uint8), cv2.MORPH_OPEN, _disk(1))
    _, areas = _areas(core)
    if not len(areas):
        return np.zeros(core.shape, np.int32), core, 0.0
    expected = area or _typical_area(areas)
    closed = cv2.morphologyEx(core, cv2.MORPH_CLOSE, _disk(s.close_fraction * np.sqrt(expected)))
    closed = ndimage.binary_fill_holes(closed)
    labels, areas = _areas(closed)
    expected = area or _typical_area(areas)
    seeds = np.zeros(core.shape, np.int32)
    for i in np.flatnonzero(areas >= s.min_area_fraction * expected) + 1:
        blob = labels == i
        k = int(round(areas[i - 1] / expected))
        parts = _split(blob, k) if k >= 2 and areas[i - 1] >= s.split_factor * expected else blob.astype(np.int32)
        for j in range(1, int(parts.max()) + 1):
            seeds[parts == j] = seeds.max() + 1
    return seeds, core, expected


def _extent(bgr, seeds, core, expected, s: OpenCVSettings) -> np.ndarray:
    """GrabCut's foreground around the cores, each pixel given to its nearest core (step 4)."""
    length = np.sqrt(expected)
    cores = (seeds > 0).astype(np.uint8)
    trimap = np.full(seeds.shape, cv2.GC_BGD, np.uint8)
    trimap[cv2.dilate(cores, _disk(0.4 * length)) > 0] = cv2.GC_PR_BGD
    trimap[cv2.dilate(cores, _disk(0.1 * length)) > 0] = cv2.GC_PR_FGD
    trimap[(cv2.erode(core, _disk(1)) > 0) & (seeds > 0)] = cv2.GC_FGD
    if (trimap == cv2.GC_BGD).any() and s.grabcut_iterations > 0:
        bgd, fgd = np.zeros((1, 65)), np.zeros((1, 65))
        cv2.grabCut(bgr, trimap, None, bgd, fgd, s.grabcut_iterations, cv2.GC_INIT_WITH_MASK)
    fg = (trimap == cv2.GC_FGD) | (trimap == cv2.GC_PR_FGD)
    fg = (cv2.morphologyEx(fg.astype(np.uint8), cv2.MORPH_OPEN, _disk(1)) > 0) | (seeds > 0)
    distance = cv2.distanceTransform((seeds == 0).astype(np.uint8), cv2.DIST_L2, 5)
    return _watershed(seeds, fg, distance)


def _convex(ids: np.ndarray) -> np.ndarray:
    """Each instance its convex hull, never over another instance's pixels."""
    out = np.zeros_like(ids)
    for i in range(1, int(ids.max()) + 1):
        points = cv2.findNonZero((ids == i).astype(np.uint8))
        if points is None:
            continue
        hull = np.zeros(ids.shape, np.uint8)
        cv2.fillConvexPoly(hull, cv2.convexHull(points), 1)
        out[(hull > 0) & ((ids == 0) | (ids == i)) & (out == 0)] = i
    return out


def repeat_scores(lab: np.ndarray, ids: np.ndarray) -> dict[int, float]:
    """Per instance: Bhattacharyya similarity of its colour histogram to the other instances'."""
    hists = {i: colour_histogram(lab, ids == i).astype(np.float32) for i in np.unique(ids[ids > 0])}
    scores = {}
    for i, h in hists.items():
        others = sum((g for j, g in hists.items() if j != i), np.zeros_like(h))
        if others.sum() == 0:
            scores[int(i)] = 0.0
            continue
        distance = cv2.compareHist(h, others / others.sum(), cv2.HISTCMP_BHATTACHARYYA)
        scores[int(i)] = float(np.clip(1.0 - distance, 0.0, 1.0))
    return scores


def segment_instances(rgb: np.ndarray, settings: OpenCVSettings | None = None, log=logger):
    """(H, W) int32 instance ids (0 background, in no particular order) and per-id scores."""
    s = settings or OpenCVSettings()
    cv2.setRNGSeed(0)  # GrabCut's k-means draws from OpenCV's RNG: the same image, the same masks
    srgb = cv2.medianBlur(to_srgb8(rgb), 3)  # a photograph's (or a render's) pixel noise
    bgr = np.ascontiguousarray(srgb[:, :, ::-1])
    lab = cv2.cvtColor(srgb, cv2.COLOR_RGB2Lab)
    is_object, exemplar_area = _object_colours(lab, bgr, s)
    seeds, core, expected = _cores(is_object, s, exemplar_area)
    log.info(
        "segment: %d cores of object colours (%.1f %% of the image), expected instance area %.0f px (%s)",
        int(seeds.max()),
        100 * float(is_object.mean()),
        expected,
        "the exemplar's" if exemplar_area else "median core",
    )
    if seeds.max() == 0:
        return seeds, {}
    ids = _extent(bgr, seeds, core, expected, s)
    if s.convex:
        ids = _convex(ids)
    return ids, repeat_scores(lab, ids)
