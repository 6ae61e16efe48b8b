"""The texels model's reflectance corrected by light transport before any gradient step.

The per-texel guess (texel_model.reflectance_start) reads each texel's observed radiance as if
every texel received the same irradiance: a ceiling lit only by what the walls reflect comes out
dark, a floor in a lamp's pool bright, and the lamps' colour is painted into every wall. A pass
renders every training view with the current maps, projects the renders onto the atlas exactly
as the photographs were (importance.TexelPixels), and multiplies each reflecting texel's kd by
captured / rendered radiance: for a diffuse texel L = kd E / pi, so the ratio is what kd lacks
under the irradiance the whole room gives it (the fixed point of inverse global illumination).

Three things make it converge on captures (measured in docs/milo.md):
- the step is damped (the ratio's square root): in a closed pale room most of a wall's
  irradiance is light the other walls reflect, so the undamped step overshoots and the colour
  cast flips from pass to pass;
- the ratio is averaged over neighbouring texels in log space: irradiance varies slowly over a
  surface, the renders' noise from texel to texel;
- the ratio's median over the reflectors is divided out: the passes fix the relative
  reflectances and keep the guess's global level, since light the model lacks (a window, the
  sun) would otherwise be made up by brightening every wall.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from ..render.batches import iteration_seed
from ..render.scene_buffers import LUMINANCE
from ..scene.neighbours import neighbour_pairs
from .importance import TexelPixels

log = logging.getLogger(__name__)
DAMPING = 0.5  # each pass moves kd by this power of the ratio
RATIO_LIMIT = 4.0  # one pass's ratio is kept within this factor either way
PASS_ITERATIONS = 1 << 40  # the passes' samples are keyed as iterations from here
FLOOR_SHARE = 1e-3  # of the captured median radiance: keeps dark texels' ratio finite


def smoothed_log(ratio: np.ndarray, weight: np.ndarray, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((H, W, 3), (H, W) bool): the `weight`ed mean of log `ratio` over each texel and its
    neighbours `pairs` (flat atlas indices), and which texels had any weight to average (a
    texel no view sees takes its seen neighbours' mean)."""
    values = np.log(ratio).reshape(-1, 3)
    w = weight.reshape(-1).astype(np.float64)
    total, count = values * w[:, None], w.copy()
    for a, b in (pairs.T, pairs[:, ::-1].T):
        count += np.bincount(a, w[b], len(w))
        for c in range(3):
            total[:, c] += np.bincount(a, values[b, c] * w[b], len(w))
    mean = total / np.maximum(count, 1e-12)[:, None]
    return mean.reshape(ratio.shape), (count > 0).reshape(weight.shape)


def correction(captured: np.ndarray, rendered: np.ndarray, reflecting: np.ndarray, pairs, floor: float):
    """(H, W, 3) one pass's factor on kd: the damped, smoothed captured / rendered radiance,
    its median over the `reflecting` texels divided out; 1 where nothing was averaged."""
    if not reflecting.any():
        return np.ones_like(captured)
    ratio = np.clip((captured + floor) / (rendered + floor), 1 / RATIO_LIMIT, RATIO_LIMIT)
    log_ratio, reached = smoothed_log(ratio, reflecting, pairs)
    log_ratio -= np.median(log_ratio[reflecting].mean(-1))
    return np.where(reached[..., None], np.exp(DAMPING * log_ratio), 1.0)


def refine_reflectance(training, pixels: TexelPixels, captured: np.ndarray, lights: np.ndarray) -> list[float]:
    """`reflectance_passes` passes on `training`'s texels model; `captured` is the photographs'
    (H, W, 3) projection, `lights` the texels that emit or are windows (H, W). Returns each pass's median |log| of
    its factor (how far kd still moved); the passes' seconds count as training time."""
    s, model, renderer = training.settings, training.net, training.renderer
    radius = s["reflectance_radius"]
    pairs = neighbour_pairs(pixels.atlas, radius) if radius > 0 else np.zeros((0, 2), np.int64)
    floor = FLOOR_SHARE * max(float(np.median(captured[pixels.rows, pixels.cols] @ LUMINANCE)), 1e-6)
    moved, clock = [], time.perf_counter()
    for step in range(s["reflectance_passes"]):
        renderer.set_maps(training.predict())
        seed = iteration_seed(s["seed"], PASS_ITERATIONS + step)  # no training iteration's samples
        images = [
            renderer.render(c, s["reflectance_spp"], seed, aovs=False)["radiance"] for c in training.views.cameras
        ]
        rendered, views = pixels.project(images)
        reflecting = (views > 0) & ~lights
        factor = correction(captured, rendered, reflecting, pairs, floor)
        moved.append(float(np.median(np.abs(np.log(factor[reflecting]))) if reflecting.any() else 0.0))
        model.scale_reflectance(training.texels.gather_grown(factor))
        log.info("milo: reflectance pass %d, kd moved by a median factor %.3f", step + 1, np.exp(moved[-1]))
    training.wall_time += time.perf_counter() - clock  # part of what the training costs
    return moved
