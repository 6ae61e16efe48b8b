"""Windows found in the photographs: the texels through which the views see the sky.

A window texel shows kg(d), the sky in the direction d that the view looks through it (MILO's
E = ke + kw kg with kw = 1); a texel that reflects or emits diffusely shows nearly the same
radiance to every view. So a window is a patch whose views disagree texel by texel but agree
direction by direction: two views that look through two of its texels in the same direction see
the same thing. A glossy table disagrees both ways (what it mirrors is near, not at infinity), an
edge's mixed pixels are scattered, not a patch.

Found in three steps: seeds are texels whose views' radiance spreads widely; a connected patch
of seeds is a window when binning its views by direction (the sky's cube texels) explains them
far better than binning them by texel and the views' rays, continued, leave the room (a glossy
table mirrors the sky as a window shows it, but the floor lies beyond it); a window grows into
its neighbours whose views the sky it has seen predicts (its top sees sky from every view, its
bottom the ground: they spread little).
What the window's views saw is the sky's start (cube texels no view saw take the nearest seen one
on their side of the horizon).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..render.scene_buffers import LUMINANCE
from ..scene.cubemap import texel_directions, texel_index
from ..scene.neighbours import neighbour_pairs, point_spacing
from ..scene.types import Camera
from .importance import TexelPixels, per_group_median

log = logging.getLogger(__name__)
SEED_SPREAD = 0.25  # a seed's views' log radiance lies this far from their median (a factor 1.28)
MIN_VIEWS = 3  # views a texel needs before its spread says anything
MIN_TEXELS = 8  # a patch of fewer seeds is noise (an edge, a highlight)
MIN_PAIRS = 32  # pairs of observations a residual needs to say anything
DIRECTION_GAIN = 0.05  # a window's residual by direction is at most this share of its residual by texel
GROW_TOLERANCE = 0.15  # a grown texel's views lie within this of the sky seen (median |log|)
NEIGHBOUR_RADIUS = 1.5  # texel spacings
LEAVING = 0.8  # least share of a window's views' rays that meet nothing beyond it
MARCHED = 256  # rays marched per patch
LOG_FLOOR = 1e-3  # of the capture's median radiance: black pixels keep a finite log


@dataclass
class Views:
    """Every (texel, view) observation of the covered texels: its texel and view, its RGB
    radiance, its log luminance and the sky's cube texel in the direction the view looks
    through it."""

    texel: np.ndarray
    view: np.ndarray
    rgb: np.ndarray
    log_luminance: np.ndarray
    direction: np.ndarray

    @classmethod
    def gather(cls, pixels: TexelPixels, images, cameras: list[Camera], sky_resolution: int) -> Views:
        points = pixels.atlas.position[pixels.rows, pixels.cols].astype(np.float64)
        texel, view, rgb, direction = [], [], [], []
        for index, ((seen, flat), image, camera) in enumerate(zip(pixels.seen, images, cameras)):
            texel.append(seen)
            view.append(np.full(len(seen), index))
            rgb.append(np.asarray(image).reshape(-1, 3)[flat])
            direction.append(texel_index(points[seen] - camera.center, sky_resolution))
        rgb = np.concatenate(rgb).astype(np.float64)
        luminance = rgb @ LUMINANCE
        floor = LOG_FLOOR * max(float(np.median(luminance)), 1e-9)
        return cls(
            np.concatenate(texel),
            np.concatenate(view),
            rgb,
            np.log(np.maximum(luminance, 0.0) + floor),
            np.concatenate(direction),
        )

    def select(self, keep: np.ndarray) -> Views:
        return Views(self.texel[keep], self.view[keep], self.rgb[keep], self.log_luminance[keep], self.direction[keep])


def group_median(groups: np.ndarray, values: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """((size, C) median of `values` (N, C) per group, (size,) how many)."""
    count = np.bincount(groups, minlength=size)
    return per_group_median(groups, values, count), count


def pair_difference(views: Views, groups: np.ndarray, other: np.ndarray) -> float:
    """The median |log luminance difference| between observations of one group (a texel, or a
    cube texel) that differ in `other` (the view, or the texel): each paired with the next of its
    group in a fixed shuffle, so that big and small groups weigh alike."""
    order = np.lexsort((np.random.default_rng(0).permutation(len(groups)), groups))
    g, o, v = groups[order], other[order], views.log_luminance[order]
    paired = (g[1:] == g[:-1]) & (o[1:] != o[:-1])
    return float(np.median(np.abs(np.diff(v)[paired]))) if paired.sum() >= MIN_PAIRS else np.inf


class Beyond:
    """What lies beyond a surface along the views' rays, marched against the covered texels'
    points: a window's rays leave the room, a glossy table's (which mirrors the sky as a window
    shows it) meet the floor under it."""

    def __init__(self, points: np.ndarray):
        self.points, self.tree = points, cKDTree(points)
        self.spacing = point_spacing(points, self.tree)
        self.reach = float(np.linalg.norm(points.max(0) - points.min(0)))

    def leaving(self, views: Views, cameras: list[Camera]) -> float:
        """The share of (at most MARCHED) `views`' rays that meet no texel beyond their own."""
        pick = np.random.default_rng(0).permutation(len(views.texel))[:MARCHED]
        start = self.points[views.texel[pick]]
        centres = np.array([c.center for c in cameras])[views.view[pick]]
        d = start - centres
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        steps = np.arange(2, int(self.reach / self.spacing) + 2) * self.spacing
        along = start[:, None] + steps[None, :, None] * d[:, None]
        distance, _ = self.tree.query(along.reshape(-1, 3), distance_upper_bound=self.spacing)
        met = np.isfinite(distance).reshape(len(pick), len(steps)).any(1)
        return float(1.0 - met.mean()) if len(pick) else 0.0


@dataclass
class Windows:
    texels: np.ndarray  # (H, W) bool: the atlas's window texels
    sky: np.ndarray  # (6 n n, 3) the sky's start: what the windows' views saw
    seen: np.ndarray  # (6 n n,) bool: which cube texels any window view saw
    filled: np.ndarray  # (6 n n,) bool: which `sky` gives a start (the others keep theirs)


def find_windows(pixels: TexelPixels, images, cameras: list[Camera], sky_resolution: int) -> Windows | None:
    """The window texels among the covered ones and the sky they show; None when no patch looks
    like a window. (A window may be the brightest thing seen, brighter than the lamps: it is
    found among every texel, the emitters too.)"""
    views = Views.gather(pixels, images, cameras, sky_resolution)
    n, cube = len(pixels.rows), 6 * sky_resolution**2
    median, count = group_median(views.texel, views.log_luminance[:, None], n)
    spread, _ = group_median(views.texel, np.abs(views.log_luminance - median[views.texel, 0])[:, None], n)
    seeds = (count >= MIN_VIEWS) & (spread[:, 0] > SEED_SPREAD)
    pairs = covered_pairs(pixels)
    beyond = Beyond(pixels.atlas.position[pixels.rows, pixels.cols].astype(np.float64))
    window = np.zeros(n, bool)
    for patch in patches(seeds, pairs):
        of_patch = views.select(np.isin(views.texel, patch))
        by_direction = pair_difference(of_patch, of_patch.direction, of_patch.texel)
        by_texel = pair_difference(of_patch, of_patch.texel, of_patch.view)
        if not (np.isfinite(by_texel) and by_direction < DIRECTION_GAIN * by_texel):
            continue
        leaving = beyond.leaving(of_patch, cameras)
        log.info(
            "milo: %d texels agree by direction, %.0f %% of their views' rays leave the room", len(patch), 100 * leaving
        )
        if leaving >= LEAVING:
            window[patch] = True
            log.info(
                "milo: a window of %d texels (views differ by %.3f in log by direction, %.3f by texel)",
                len(patch),
                by_direction,
                by_texel,
            )
    if not window.any():
        return None
    window = grow(window, views, pairs, cube)
    log.info("milo: %d window texels after growing", window.sum())
    in_atlas = np.zeros(pixels.atlas.shape, bool)
    in_atlas[pixels.rows[window], pixels.cols[window]] = True
    return Windows(in_atlas, *sky_seen(views.select(window[views.texel]), sky_resolution))


def covered_pairs(pixels: TexelPixels) -> np.ndarray:
    """(m, 2) neighbouring covered texels, as indices into pixels.rows."""
    flat = pixels.rows * pixels.atlas.shape[1] + pixels.cols
    index = np.full(pixels.atlas.shape[0] * pixels.atlas.shape[1], -1)
    index[flat] = np.arange(len(flat))
    return index[neighbour_pairs(pixels.atlas, NEIGHBOUR_RADIUS)]


def patches(members: np.ndarray, pairs: np.ndarray) -> list[np.ndarray]:
    """The connected patches of `members` (bool) of at least MIN_TEXELS texels."""
    both = members[pairs[:, 0]] & members[pairs[:, 1]]
    a, b = pairs[both].T
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(len(members),) * 2)
    _, label = connected_components(graph, directed=False)
    index = np.flatnonzero(members)
    order = np.argsort(label[index], kind="stable")
    _, starts, sizes = np.unique(label[index][order], return_index=True, return_counts=True)
    return [index[order[a : a + k]] for a, k in zip(starts, sizes) if k >= MIN_TEXELS]


def neighbours_of(members: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """(n,) bool: the texels one of the neighbour `pairs` links to a member (members too, where
    two members neighbour)."""
    out = np.zeros_like(members)
    for a, b in (pairs.T, pairs[:, ::-1].T):
        out[b[members[a]]] = True
    return out


def grow(window: np.ndarray, views: Views, pairs: np.ndarray, cube: int) -> np.ndarray:
    """`window` grown ring by ring into neighbouring texels whose views the sky seen
    through the window so far predicts within GROW_TOLERANCE, colour by colour."""
    window = window.copy()
    log_rgb = np.log(views.rgb + np.exp(views.log_luminance.min()))
    while True:
        keep = window[views.texel]
        sky, seen = group_median(views.direction[keep], log_rgb[keep], cube)
        ring = neighbours_of(window, pairs) & ~window
        of_ring = ring[views.texel] & (seen[views.direction] > 0)
        error = np.abs(log_rgb - sky[views.direction]).max(1)[of_ring][:, None]
        misfit, count = group_median(views.texel[of_ring], error, len(window))
        accepted = ring & (count >= 2) & (misfit[:, 0] < GROW_TOLERANCE)
        if not accepted.any():
            return window
        window |= accepted


def sky_seen(views: Views, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """((6 n n, 3) the median RGB the window's views saw per cube texel, elsewhere the nearest
    seen cube texel's on the same side of the horizon (+Y is up: the sky is not the ground);
    (6 n n,) which were seen; (6 n n,) which have a value (a side no view saw has none))."""
    sky, count = group_median(views.direction, views.rgb, 6 * n * n)
    seen = count > 0
    directions = texel_directions(n).reshape(-1, 3)
    filled = seen.copy()
    for side in (directions[:, 1] >= 0, directions[:, 1] < 0):
        if (seen & side).any():
            _, nearest = cKDTree(directions[seen & side]).query(directions[side])
            sky[side] = sky[seen & side][nearest]
            filled |= side
    return sky.astype(np.float32), seen, filled
