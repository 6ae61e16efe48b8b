"""The sun, found from the patch of light it throws in through a window.

The sky a window shows lights a room softly; the sun, which no view sees, throws a sharp patch
that lines up with the window: for a direction d, the texels whose line towards d passes through
a window are the patch a sun in d would light. The sun's direction is the d whose patch is
brightest against the ring of texels around it (the photographs' log luminance, median inside
minus median of the ring, over the sky above the horizon), then where its edge steps most (the
same across its edge, around that direction, in caps that halve); a patch less
than SUN_CONTRAST times brighter than its ring is no sun (an overcast sky, a room with no window
in the sun). Occluders between the window and the patch are ignored: their shadow lowers the
patch's median, not which direction wins.

Its radiance is the one that makes the patch's reflectance its ring's: the irradiance comes from a
render of the maps (radiance / kd, texel by texel), the sun adds L_sun * solid angle * cos(theta)
/ pi to it inside the patch, and the reflectance the ring shows (captured / irradiance) is asked
of the patch too; a second render with the sun in adds the light its patch throws onto the ring.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from ..render.batches import iteration_seed
from ..render.scene_buffers import LUMINANCE
from ..scene.cubemap import cube_texel_solid_angles, texel_index
from ..scene.neighbours import point_spacing
from .importance import TexelPixels
from .window import MIN_TEXELS, Windows, covered_pairs, neighbours_of, patches

log = logging.getLogger(__name__)
SUN_CONTRAST = 1.6  # least patch / ring (medians) of a sun: 1.8-2.0 measured, 1.44 by an overcast window
MIN_PATCH = 32  # texels: a smaller patch is a highlight, not the sun's
COARSE_DIRECTIONS = 400  # over the sphere
COARSE_SPACING_DEG = 10.0  # about their spacing: the first fine search's cap
REFINE_ROUNDS = 4  # each halves the cap searched around the best direction
REFINE_DIRECTIONS = 96
CORE_GAP = 2  # neighbour steps between the patch's edge and its core
RING_START, RING_END = 3, 6  # the ring: this many steps beyond the patch's edge
SAME_SURFACE = 0.95  # cosine between a texel's normal and the patch's mean normal
EDGE_BAND = 2  # neighbour steps either side of the edge that the fine search compares
SUN_ROUNDS = 2  # renders that fit the sun's radiance
SUN_PASS = 1 << 41  # the render's samples are keyed as iterations from here (no pass's, no step's)


@dataclass
class WindowPlane:
    """One window's plane (centre, normal into the room, in-plane axes) and its texels'
    occupancy on a grid of one texel spacing in that plane."""

    centre: np.ndarray
    normal: np.ndarray
    axes: np.ndarray  # (2, 3)
    origin: np.ndarray  # (2,) the grid's corner in plane coordinates
    spacing: float
    occupied: np.ndarray  # (rows, cols) bool

    @classmethod
    def fit(cls, points: np.ndarray, room_centre: np.ndarray, spacing: float) -> WindowPlane:
        centre = points.mean(0)
        _, _, vt = np.linalg.svd(points - centre, full_matrices=False)
        normal = vt[2] if np.dot(room_centre - centre, vt[2]) > 0 else -vt[2]
        uv = (points - centre) @ vt[:2].T
        origin = uv.min(0) - spacing
        cells = np.floor((uv - origin) / spacing).astype(int)
        occupied = np.zeros(tuple(cells.max(0) + 2), bool)
        occupied[cells[:, 0], cells[:, 1]] = True
        occupied[1:] |= occupied[:-1].copy()  # one cell more each way: the texels' footprints
        occupied[:, 1:] |= occupied[:, :-1].copy()
        return cls(centre, normal, vt[:2], origin, spacing, occupied)

    def through(self, points: np.ndarray, d: np.ndarray) -> np.ndarray:
        """(n,) bool: which of `points` (on the room's side) see this window along d."""
        towards = float(d @ self.normal)  # < 0: d leaves the room through the plane
        if towards > -1e-3:
            return np.zeros(len(points), bool)
        height = (points - self.centre) @ self.normal
        crossing = points - (height / towards)[:, None] * d[None]
        cells = np.floor(((crossing - self.centre) @ self.axes.T - self.origin) / self.spacing).astype(int)
        inside = (cells >= 0).all(1) & (cells[:, 0] < self.occupied.shape[0]) & (cells[:, 1] < self.occupied.shape[1])
        hit = np.zeros(len(points), bool)
        hit[inside] = self.occupied[cells[inside, 0], cells[inside, 1]]
        return hit & (height > 0.5 * self.spacing)


@dataclass
class Sun:
    direction: np.ndarray  # (3,) unit, towards the sun
    patch: np.ndarray  # (covered texels,) bool: the core of the patch it lights through the windows
    ring: np.ndarray  # (covered texels,) bool: the texels around the patch
    contrast: float  # the patch's median luminance over the ring's


def fibonacci_directions(count: int, cap: float = np.pi) -> np.ndarray:
    """`count` directions evenly spread (a Fibonacci spiral) within `cap` radians of +y."""
    i = np.arange(count) + 0.5
    y = 1 - (1 - np.cos(cap)) * i / count
    r, phi = np.sqrt(np.maximum(1 - y**2, 0.0)), np.pi * (1 + 5**0.5) * i
    return np.stack([r * np.cos(phi), y, r * np.sin(phi)], 1)


class PatchScore:
    """The brightness of the patch a sun in d would light, against its ring."""

    def __init__(self, pixels: TexelPixels, windows: Windows, captured: np.ndarray, seen: np.ndarray):
        atlas = pixels.atlas
        self.points = atlas.position[pixels.rows, pixels.cols].astype(np.float64)
        self.normals = atlas.normal[pixels.rows, pixels.cols].astype(np.float64)
        window = windows.texels[pixels.rows, pixels.cols]
        self.receiver = ~window & (seen[pixels.rows, pixels.cols] > 0)
        luminance = captured[pixels.rows, pixels.cols] @ LUMINANCE
        self.log_luminance = np.log(np.maximum(luminance, 1e-6 * max(float(np.median(luminance)), 1e-12)))
        self.pairs = covered_pairs(pixels)
        spacing = point_spacing(self.points)
        centre = self.points.mean(0)
        self.planes = [WindowPlane.fit(self.points[p], centre, spacing) for p in patches(window, self.pairs)]

    def patch(self, d: np.ndarray) -> np.ndarray:
        facing = self.receiver & (self.normals @ d > 0.05)
        lit = np.zeros(len(self.points), bool)
        for plane in self.planes:
            lit[facing] |= plane.through(self.points[facing], d)
        return lit

    def dilate(self, members: np.ndarray, rings: int) -> np.ndarray:
        """`members` and the texels within `rings` neighbour steps of them."""
        for _ in range(rings):
            members = members | neighbours_of(members, self.pairs)
        return members

    def core_and_ring(self, patch: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The patch without its edge and the ring beyond it, on the surface most of the patch
        lies on: the sun's disc blurs the edge over a few texels (penumbra), so both keep
        CORE_GAP steps away from it."""
        core = patch & ~self.dilate(~patch & self.receiver, CORE_GAP)
        ring = self.dilate(patch, RING_END) & ~self.dilate(patch, RING_START) & self.receiver
        if core.any():  # both on the surface most of the patch lies on: one material, one reflectance
            mean = self.normals[core].mean(0)
            same = self.normals @ (mean / max(np.linalg.norm(mean), 1e-12)) > SAME_SURFACE
            core, ring = core & same, ring & same
        return core, ring

    def broad(self, d: np.ndarray) -> float:
        """Log of the patch's core's median luminance over its ring's: -inf for a patch too small.
        Tolerant of a d some degrees off, for the coarse search."""
        patch = self.patch(d)
        if patch.sum() < MIN_PATCH:
            return -np.inf
        core, ring = self.core_and_ring(patch)
        if core.sum() < MIN_PATCH // 2 or ring.sum() < MIN_PATCH // 2:
            return -np.inf
        return float(np.median(self.log_luminance[core]) - np.median(self.log_luminance[ring]))

    def edge(self, d: np.ndarray) -> float:
        """The same across the patch's edge (EDGE_BAND steps either side): it peaks where the edge
        lies, for the fine search."""
        patch = self.patch(d)
        if patch.sum() < MIN_PATCH:
            return -np.inf
        inner = patch & self.dilate(~patch & self.receiver, EDGE_BAND)
        outer = ~patch & self.dilate(patch, EDGE_BAND) & self.receiver
        return float(np.median(self.log_luminance[inner]) - np.median(self.log_luminance[outer]))


def find_sun(pixels: TexelPixels, windows: Windows, captured: np.ndarray, seen: np.ndarray) -> Sun | None:
    """The sun that lights the brightest window-shaped patch, or None (no patch SUN_CONTRAST
    times brighter than its ring)."""
    score = PatchScore(pixels, windows, captured, seen)
    if not score.planes:
        log.info("milo: no sun (no window of %d texels to let it in)", MIN_TEXELS)
        return None
    candidates = fibonacci_directions(COARSE_DIRECTIONS)
    candidates = candidates[candidates[:, 1] > 0.02]  # above the horizon
    scores = np.array([score.broad(d) for d in candidates])
    if not np.isfinite(scores).any():
        log.info("milo: no sun (no window lets in a patch of %d texels)", MIN_PATCH)
        return None
    best = candidates[int(np.argmax(scores))]
    cap = np.radians(COARSE_SPACING_DEG)
    for _ in range(REFINE_ROUNDS):
        candidates = directions_around(best, cap, REFINE_DIRECTIONS)
        best = candidates[int(np.argmax([score.edge(d) for d in candidates]))]
        cap /= 2
    best_score = score.broad(best)
    if best_score < np.log(SUN_CONTRAST):
        log.info("milo: no sun (the brightest window-shaped patch is %.2f times its ring)", np.exp(best_score))
        return None
    patch = score.patch(best)
    core, ring = score.core_and_ring(patch)
    log.info(
        "milo: the sun at %s (a patch of %d texels, %.1f times its ring)",
        np.round(best, 3),
        patch.sum(),
        np.exp(best_score),
    )
    return Sun(best, core, ring, float(np.exp(best_score)))


def directions_around(d: np.ndarray, cap: float, count: int) -> np.ndarray:
    """d and `count` directions within `cap` radians of it, evenly spread (the spiral around +y
    turned onto d)."""
    local = fibonacci_directions(count, cap)
    axis = np.cross([0.0, 1.0, 0.0], d)
    sine, cosine = np.linalg.norm(axis), float(d[1])
    if sine < 1e-9:
        return np.vstack([d[None], local if cosine > 0 else -local])
    k = axis / sine
    rotated = local * cosine + np.cross(k, local) * sine + np.outer(local @ k, k) * (1 - cosine)
    return np.vstack([d[None], rotated])


def fit_sun(training, pixels: TexelPixels, captured: np.ndarray, sun: Sun, index: int) -> np.ndarray:
    """Light `training`'s sun (the sky's texel `index`) at the RGB radiance that asks of its patch
    the reflectance its ring shows (module doc), over SUN_ROUNDS renders: the first has no sun, so
    the light its patch throws onto the ring is missing there, and the next ones add what is still
    lacking. Returns the radiance; the renders' seconds count as training time."""
    clock, radiance = time.perf_counter(), np.zeros(3)
    for round_ in range(SUN_ROUNDS):
        radiance = np.maximum(radiance + lacking_sun(training, pixels, captured, sun, round_), 0.0)
        training.net.light_sun(index, radiance)
        log.info("milo: the sun's radiance %s after render %d", np.round(radiance, 1), round_ + 1)
    training.wall_time += time.perf_counter() - clock
    return radiance


def lacking_sun(training, pixels: TexelPixels, captured: np.ndarray, sun: Sun, round_: int) -> np.ndarray:
    """(3,) the sun's radiance still lacking under `training`'s maps as they are, from a render."""
    s, renderer = training.settings, training.renderer
    maps = training.predict()
    renderer.set_maps(maps)
    seed = iteration_seed(s["seed"], SUN_PASS + round_)
    images = [renderer.render(c, s["reflectance_spp"], seed, aovs=False)["radiance"] for c in training.views.cameras]
    rendered, _ = pixels.project(images)
    at = (pixels.rows, pixels.cols)
    irradiance = np.maximum(rendered[at], 1e-9) / np.maximum(maps.kd[at], 1e-3)  # over pi
    observed = captured[at]
    reflectance = np.median(observed[sun.ring] / irradiance[sun.ring], axis=0)
    n = s["sky_resolution"]
    solid_angle = cube_texel_solid_angles(n).reshape(-1)[sun_texel(sun, s) % (n * n)]  # the same on every face
    cosine = np.clip(pixels.atlas.normal[at][sun.patch] @ sun.direction, 0.05, 1.0)[:, None]
    needed = observed[sun.patch] / reflectance - irradiance[sun.patch]
    return np.median(needed * np.pi / (solid_angle * cosine), axis=0)


def sun_texel(sun: Sun, settings: dict) -> int:
    """The sky's cube texel the sun lies in."""
    return int(texel_index(sun.direction[None], settings["sky_resolution"])[0])
