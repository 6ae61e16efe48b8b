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
