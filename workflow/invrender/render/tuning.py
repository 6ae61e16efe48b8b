"""The light strategies' weights for one scene, chosen by a short pilot render.

Which light to sample matters more than any other knob of the estimator: in the benchmark room
(a small sun through a window, two ceiling panels) sending 90 % of the light samples to the sky
has 0.58x the variance per sample of an even split, and MILO's mixture with (w_env, w_emit) =
(0.4, 0.1) 0.67x that of (0.25, 0.25) (docs/benchmarks.md). No closed form knows this (by power the
panels outshine the sun 2.7 to 1, yet the sun's glossy reflection holds the variance), so a few
candidates are rendered on a subset of the scene's own pixels and the best is kept.

With next-event estimation every candidate traces the same rays per sample, so the variance
alone decides; in the mixture the weights change the path lengths too, so variance x time does.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from .features import Features

# With nee only the ratio counts: the sky's share of light samples, w_env / (w_env + w_emit).
NEE_CANDIDATES = tuple((round(0.5 * share, 6), round(0.5 * (1 - share), 6)) for share in (0.05, 0.25, 0.5, 0.75, 0.95))
MIXTURE_CANDIDATES = ((0.25, 0.25), (0.4, 0.1), (0.1, 0.4), (0.6, 0.05), (0.05, 0.6))
PILOT_REQUESTS = 2048  # pixels, spread over every camera
PILOT_SPP = 16


def needs_tuning(features: Features) -> bool:
    """Only when both light strategies are compiled in is there a choice to make."""
    return features.env_sampling and features.emitter_sampling


def pilot_requests(cameras, count: int, seed: int) -> np.ndarray:
    """int4 (camera, x, y, ray id) for `count` pixels drawn uniformly over all cameras' pixels."""
    sizes = np.array([c.width * c.height for c in cameras])
    flat = np.random.default_rng(seed).choice(sizes.sum(), size=min(count, int(sizes.sum())), replace=False)
    camera = np.searchsorted(np.cumsum(sizes), flat, side="right")
    pixel = flat - np.concatenate([[0], np.cumsum(sizes)[:-1]])[camera]
    widths = np.array([c.width for c in cameras])[camera]
    return np.stack([camera, pixel % widths, pixel // widths, flat], -1).astype(np.int32)


def choose_strategy_weights(scene, features: Features, device: str | None = None, seed: int = 0):
    """(features with the chosen w_env, w_emit; evidence: each candidate's variance and time per
    sample). Unchanged when there is nothing to choose or no camera to look through."""
    if not (needs_tuning(features) and scene.cameras):
        return features, None
    from .renderer import Renderer  # the pilot renders; renderer imports features only
    from .scene_buffers import HostScene

    host = HostScene.pack(scene.mesh, scene.maps)
    requests = pilot_requests(scene.cameras, PILOT_REQUESTS, seed)
    candidates = NEE_CANDIDATES if features.nee else MIXTURE_CANDIDATES
    trials = []
    warm = True
    for w_env, w_emit in candidates:
        renderer = Renderer(scene, replace(features, w_env=w_env, w_emit=w_emit), device=device, host_scene=host)
        if warm:  # the first launch's one-time cost is not the candidate's
            renderer.render_requests(scene.cameras, requests[:64], 1, seed)
            warm = False
        start = time.perf_counter()
        _, variance, _ = renderer.render_requests(scene.cameras, requests, PILOT_SPP, seed)
        seconds = (time.perf_counter() - start) / (len(requests) * PILOT_SPP)
        per_sample = float(variance.mean() * PILOT_SPP)
        cost = per_sample if features.nee else per_sample * seconds
        trials.append(
            {"w_env": w_env, "w_emit": w_emit, "var_per_sample": per_sample, "s_per_sample": seconds, "cost": cost}
        )
    best = min(trials, key=lambda t: t["cost"])
    chosen = replace(features, w_env=best["w_env"], w_emit=best["w_emit"])
    return chosen, {"criterion": "variance" if features.nee else "variance x time", "trials": trials}
