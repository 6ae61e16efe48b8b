"""Random ray batches over all pixels of all images, reproducible from (seed, iteration).

MILO samples 65,536 rays per iteration from every pixel of every image. A batch here is drawn by
index with a generator keyed by (seed, iteration), so iteration k of a run can be redrawn alone;
each ray keeps the id its pixel has in a full render (Renderer.ray_offset + y W + x), so its
random numbers are the same whether it comes in a batch or in an image.
"""

from __future__ import annotations

import numpy as np

from ..scene.types import Camera


def ray_batch(cameras: list[Camera], size: int, seed: int, iteration: int) -> np.ndarray:
    """int4 requests (camera index, x, y, ray id) of `size` pixels drawn without replacement."""
    counts = np.array([c.width * c.height for c in cameras], np.int64)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    total = int(offsets[-1])
    if not 0 < size <= total:
        raise ValueError(f"ray_batch: size: expected 1..{total} (all pixels of all images), got {size}")
    rng = np.random.default_rng([int(seed), int(iteration)])
    ids = np.sort(rng.choice(total, size=size, replace=False))
    camera = np.searchsorted(offsets, ids, side="right") - 1
    local = ids - offsets[camera]
    widths = np.array([c.width for c in cameras], np.int64)[camera]
    return np.stack([camera, local % widths, local // widths, ids], -1).astype(np.int32)


def iteration_seed(seed: int, iteration: int) -> int:
    """The path samples' seed of one iteration: 63 bits, so backward_seed's flipped top bit is
    another seed."""
    state = np.random.SeedSequence([int(seed), int(iteration)]).generate_state(2, np.uint32)
    return ((int(state[0]) << 32) | int(state[1])) & ((1 << 63) - 1)


def pool_batch(pools: list[np.ndarray], sizes: list[int], seed: int, iteration: int) -> np.ndarray:
    """Masked ray batches: from each pool of int4 requests (the pixels a loss may see, e.g. an
    object's mask and its support's), `sizes[k]` rows drawn without replacement (at most the
    pool's size), keyed by (seed, iteration) like ray_batch; the pools' rows one after another."""
    rng = np.random.default_rng([int(seed), int(iteration)])
    picked = []
    for pool, size in zip(pools, sizes):
        size = min(int(size), len(pool))
        picked.append(pool[np.sort(rng.choice(len(pool), size=size, replace=False))] if size else pool[:0])
    return np.concatenate(picked).astype(np.int32)
