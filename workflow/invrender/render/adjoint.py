"""Gradients of an image loss with respect to every parameter map, from kernels/adjoint.cl.

`backward` takes ray requests (as Renderer.render_requests does) and the adjoint radiance
dLoss/dL of each (the gradient of the loss with respect to the ray's estimate) and returns
d Loss / d map for kd, ks, ka, ke, kw (atlas-shaped) and kg (cube-shaped). The default
accumulation is 64-bit fixed point, so the same seed gives the same bytes on the same device;
MILO's bucketed float accumulation is the alternative.
"""

from __future__ import annotations

import logging

import numpy as np
import pyopencl as cl

from ..scene.types import Camera
from .program import build_program
from .renderer import Renderer

log = logging.getLogger(__name__)

GRAD_CHANNELS = {"kd": slice(0, 3), "ks": slice(3, 6), "ka": slice(6, 7), "ke": slice(7, 10), "kw": slice(10, 11)}
ATLAS_CHANNELS = 11
FIXED_POINT_SCALE = float(2**32)  # resolution 2.3e-10 per addition, range +-2.1e9 per texel
ACCUMULATIONS = ("fixed", "buckets")
NUM_BUCKETS = 64  # MILO's count of gradient-map copies
BUCKET_BUDGET_BYTES = 1 << 30  # fewer copies when 64 of a large atlas would not fit


def backward(renderer: Renderer, cameras: list[Camera], requests: np.ndarray, adjoint: np.ndarray, spp: int,
             seed: int = 0, accumulation: str = "fixed", num_buckets: int = NUM_BUCKETS) -> dict[str, np.ndarray]:
    """d Loss / d map for every map, given dLoss/dL of each request (n, 3).

    accumulation: "fixed" (64-bit fixed-point atomics: the same seed gives the same bytes on one
    device; the default, see docs/benchmarks.md for its cost) or "buckets" (MILO's float copies
    chosen by ray id, compare-and-swap adds, then a reduction; not bitwise reproducible).
    """
    if accumulation not in ACCUMULATIONS:
        raise ValueError(f"backward: accumulation: expected one of {ACCUMULATIONS}, got {accumulation!r}")
    host = renderer.host
    sizes = (host.atlas_w * host.atlas_h * ATLAS_CHANNELS, 6 * host.cube_n * host.cube_n * 3)
    if accumulation == "fixed":
        atlas, kg = _accumulate(renderer, cameras, requests, adjoint, spp, seed, sizes, np.int64, 1, ())
        atlas, kg = atlas / FIXED_POINT_SCALE, kg / FIXED_POINT_SCALE
    else:
        buckets = _bucket_count(num_buckets, sizes)
        defines = ("-D ACCUMULATE_BUCKETS", f"-D NUM_BUCKETS={buckets}")
        atlas, kg = _accumulate(renderer, cameras, requests, adjoint, spp, seed, sizes, np.float32, buckets, defines)
    atlas = atlas.astype(np.float64).reshape(host.atlas_h, host.atlas_w, ATLAS_CHANNELS)
    out = {name: atlas[..., channels].squeeze(-1) if channels.stop - channels.start == 1 else atlas[..., channels]
           for name, channels in GRAD_CHANNELS.items()}
    out["kg"] = kg.astype(np.float64).reshape(6, host.cube_n, host.cube_n, 3)
    return out


def _bucket_count(requested: int, sizes: tuple[int, int]) -> int:
    fits = BUCKET_BUDGET_BYTES // (4 * sum(sizes))
    buckets = max(1, min(requested, fits))
    if buckets < requested:
        log.info("adjoint: %d gradient buckets instead of %d (%d MB each)", buckets, requested, 4 * sum(sizes) >> 20)
    return buckets


def _accumulate(renderer, cameras, requests, adjoint, spp, seed, sizes, dtype, buckets, defines):
    """Run adjoint_rays over all samples; returns the (atlas, kg) sums, reduced over buckets."""
    context, queue = renderer.context, renderer.queue
    program = build_program(context, "adjoint.cl", renderer.features.defines() + defines)
    n = len(requests)
    cams, reqs = renderer.request_buffers(cameras, requests)
    per_sample = np.zeros((n, 4), np.float32)
    per_sample[:, :3] = np.asarray(adjoint, np.float32) / spp  # each sample is 1/spp of the estimate
    adj = cl.Buffer(context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=per_sample)
    grads = [np.zeros(size * buckets, dtype) for size in sizes]
    rw = cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR
    bufs = [cl.Buffer(context, rw, hostbuf=grad) for grad in grads]
    renderer.sample_launches(cl.Kernel(program, "adjoint_rays"), n, spp, seed, (cams, reqs, np.int32(n)),
                             (adj, *bufs, np.float32(FIXED_POINT_SCALE), *(np.int32(size) for size in sizes)),
                             desc="adjoint")
    results = []
    for size, grad, buf in zip(sizes, grads, bufs):
        if buckets > 1:
            reduce = cl.Kernel(program, "reduce_buckets")
            reduce(queue, (-(-size // 64) * 64,), (64,), buf, np.int32(size), np.int32(buckets))
        out = np.empty(size, dtype)
        cl.enqueue_copy(queue, out, buf)  # the first `size` words: the sum
        results.append(out)
    return results
