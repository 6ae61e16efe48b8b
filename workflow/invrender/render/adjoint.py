"""Gradients of an image loss with respect to every parameter map, from kernels/adjoint.cl.

`backward` takes ray requests (as Renderer.render_requests does) and the adjoint radiance
dLoss/dL of each (the gradient of the loss with respect to the ray's estimate) and returns
d Loss / d map for kd, ks, ka, ke, kw (atlas-shaped) and kg (cube-shaped). The default
accumulation is 64-bit fixed point, so the same seed gives the same bytes on the same device;
MILO's bucketed float accumulation is the alternative, and what a device without 64-bit
integer atomics gets (`choose_accumulation`).
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pyopencl as cl

from ..scene.types import ATLAS_MAPS, MAP_CHANNELS, MAP_NAMES, Camera
from .device import DeviceError, describe
from .program import build_program
from .renderer import Renderer

log = logging.getLogger(__name__)

MAPS = MAP_NAMES  # one fixed-point scale each, in this order
_OFFSETS = np.cumsum([0] + [MAP_CHANNELS[name] for name in ATLAS_MAPS])
GRAD_CHANNELS = {name: slice(int(start), int(stop)) for name, start, stop in zip(ATLAS_MAPS, _OFFSETS, _OFFSETS[1:])}
ATLAS_CHANNELS = int(_OFFSETS[-1])  # per texel of the atlas gradient: the atlas maps' channels in order
# The kernel's side of both layouts, generated here so that adjoint.cl has no copy to keep in step.
LAYOUT_DEFINES = (
    *(f"-D GRAD_{name.upper()}={channels.start}" for name, channels in GRAD_CHANNELS.items()),
    f"-D GRAD_CHANNELS={ATLAS_CHANNELS}",
    *(f"-D MAP_{name.upper()}={index}" for index, name in enumerate(MAPS)),
    f"-D GRAD_MAPS={len(MAPS)}",
)
ACCUMULATIONS = ("auto", "fixed", "buckets")
INT64_ATOMICS = "cl_khr_int64_base_atomics"  # 64-bit atom_add, which "fixed" needs
NUM_BUCKETS = 64  # MILO's count of gradient-map copies
BUCKET_BUDGET_BYTES = 1 << 30  # fewer copies when 64 of a large atlas would not fit
# Fixed point: a texel channel takes at most one addition per path vertex, so with the largest
# addition at most 2^62 / (rays x spp x (B + 2)) units ("top") no int64 can overflow; each
# addition is resolved to 2^-RESOLUTION_BITS of the map's largest or better. The first pass
# puts a peak of 1.0 mid-window; a map whose peak falls outside the window runs again.
RESOLUTION_BITS = 24


def backward_seed(seed: int) -> int:
    """The seed of the backward pass for a forward pass with `seed`: its top bit flipped, so the
    adjoint traces other samples than the forward. With a loss like L2, (L - T) and dL/dtheta
    from the same samples are correlated, and their product's mean is not the gradient of the
    expected loss (Azinovic et al. 2019); measured here, kd came out 7% low with shared samples."""
    return int(seed) ^ (1 << 63)


def backward(
    renderer: Renderer,
    cameras: list[Camera],
    requests: np.ndarray,
    adjoint: np.ndarray,
    spp: int,
    seed: int = 0,
    accumulation: str = "auto",
    num_buckets: int = NUM_BUCKETS,
    maps: tuple[str, ...] = MAPS,
) -> dict[str, np.ndarray]:
    """d Loss / d map for each of `maps` (default all), given dLoss/dL of each request (n, 3).

    Only the wanted maps' additions are compiled in (`wanted_defines`): an optimiser of kd alone
    (as Mitsuba differentiates only the parameters with gradients enabled) pays no atomics for
    ke, kw, kg, ks or ka.

    accumulation: "fixed" (64-bit fixed-point atomics: the same seed gives the same bytes on one
    device; see docs/benchmarks.md for its cost), "buckets" (MILO's float copies chosen by ray
    id, compare-and-swap adds, then a reduction; not bitwise reproducible) or "auto" (the
    default: "fixed" where the device has 64-bit integer atomics, else "buckets").
    The kernel sees the adjoint divided by its largest magnitude, so the fixed-point range does
    not depend on how the loss is normalised.
    """
    accumulation = choose_accumulation(renderer.context.devices[0], accumulation)
    wanted = wanted_defines(maps)
    adjoint = np.asarray(adjoint, np.float32)
    if not np.isfinite(adjoint).all():
        raise ValueError("backward: adjoint: expected finite dLoss/dL for every ray, got NaN or Inf")
    host = renderer.host
    sizes = (host.atlas_w * host.atlas_h * ATLAS_CHANNELS, 6 * host.cube_n * host.cube_n * 3)
    norm = float(np.abs(adjoint).max()) if adjoint.size else 0.0
    if norm == 0.0:
        atlas, kg = np.zeros((sizes[0] // ATLAS_CHANNELS, ATLAS_CHANNELS)), np.zeros(sizes[1])
    else:
        per_sample = adjoint / np.float32(norm * spp)  # each sample is 1/spp of the estimate
        launch = lambda dtype, buckets, defines, scales: _accumulate(
            renderer, cameras, requests, per_sample, spp, seed, sizes, dtype, buckets, defines + wanted, scales
        )
        if accumulation == "fixed":
            atlas, kg = _fixed_point(launch, len(requests) * spp * (renderer.features.max_bounces + 2))
        else:
            buckets = _bucket_count(num_buckets, sizes)
            (atlas, kg), _ = launch(np.float32, buckets, accumulation_defines(buckets), np.ones(len(MAPS)))
            atlas = atlas.reshape(-1, ATLAS_CHANNELS).astype(np.float64)
        atlas, kg = atlas * norm, kg.astype(np.float64) * norm
    atlas = atlas.reshape(host.atlas_h, host.atlas_w, ATLAS_CHANNELS)
    out = {
        name: atlas[..., channels].squeeze(-1) if channels.stop - channels.start == 1 else atlas[..., channels]
        for name, channels in GRAD_CHANNELS.items()
    }
    out["kg"] = kg.reshape(6, host.cube_n, host.cube_n, 3)
    return {name: out[name] for name in MAPS if name in maps}


def wanted_defines(maps) -> tuple[str, ...]:
    """adjoint.cl's GRAD_WANTED, a bit per map of MAPS; empty for all of them (the default)."""
    unknown = sorted(set(maps) - set(MAPS))
    if unknown or not maps:
        raise ValueError(f"backward: maps: expected a non-empty subset of {MAPS}, got {tuple(maps)}")
    if set(maps) == set(MAPS):
        return ()
    return (f"-D GRAD_WANTED={sum(1 << MAPS.index(name) for name in set(maps))}",)


_told_buckets: set[str] = set()  # devices already named in the log


def choose_accumulation(device, accumulation: str = "auto") -> str:
    """The accumulation mode, "fixed" or "buckets", for `device` (a pyopencl Device: only its
    `extensions` string is read). Fixed point adds with 64-bit atom_add, an extension
    (cl_khr_int64_base_atomics) that PoCL, NVIDIA's and AMD's drivers report but OpenCL 1.2 does
    not require, so "auto" falls back to buckets (32-bit compare-and-swap, core) without it and
    says so once per device; asking for "fixed" there is an error rather than a build failure
    deep in the kernel."""
    if accumulation not in ACCUMULATIONS:
        raise ValueError(f"backward: accumulation: expected one of {ACCUMULATIONS}, got {accumulation!r}")
    has_int64 = INT64_ATOMICS in device.extensions.split()
    if accumulation == "fixed" and not has_int64:
        raise DeviceError(
            f"backward: accumulation 'fixed' needs 64-bit integer atomics ({INT64_ATOMICS}), which "
            f"{describe(device)} does not report; use 'buckets' or 'auto'"
        )
    if accumulation != "auto":
        return accumulation
    if has_int64:
        return "fixed"
    if describe(device) not in _told_buckets:
        _told_buckets.add(describe(device))
        log.info("adjoint: %s has no %s: float buckets, not bitwise reproducible", describe(device), INT64_ATOMICS)
    return "buckets"


def accumulation_defines(buckets: int | None) -> tuple[str, ...]:
    """adjoint.cl's build options for an accumulation mode: fixed point (None) or `buckets` float copies."""
    return () if buckets is None else ("-D ACCUMULATE_BUCKETS", f"-D NUM_BUCKETS={buckets}")


def _fixed_point(launch, additions: int) -> tuple[np.ndarray, np.ndarray]:
    """Accumulate in 64-bit fixed point with one power-of-two scale per map, chosen so that
    `additions` (an upper bound on the additions to one texel channel) of the map's largest
    value cannot overflow. The first pass guesses (the normalised adjoint keeps peaks within
    2^+-12 of 1 in ordinary scenes); where a map's largest addition says the guess risked
    overflow or resolved too coarsely, the pass runs again with the scale its peak calls for.
    Peaks are maxima, independent of order, so the choice and the bytes stay deterministic."""
    top = math.floor(62 - math.log2(max(additions, 1)))
    scales = np.full(len(MAPS), 2.0 ** (top - RESOLUTION_BITS // 2))
    for _ in range(2):
        (atlas, kg), peaks = launch(np.int64, 1, accumulation_defines(None), scales)
        units = peaks * scales
        off = (peaks > 0) & ((units < 2.0 ** (top - RESOLUTION_BITS)) | (units > 2.0**top))
        if not off.any():
            break
        fitted = 2.0 ** np.minimum(100, top - 1 - np.ceil(np.log2(np.maximum(peaks, 1e-30))))
        scales = np.where(off, fitted, scales)
        log.debug("adjoint: largest additions %s, fixed-point scales 2^%s, running again", peaks, np.log2(scales))
    channel_scale = np.concatenate(
        [np.full(c.stop - c.start, scales[MAPS.index(name)]) for name, c in GRAD_CHANNELS.items()]
    )
    return atlas.reshape(-1, ATLAS_CHANNELS) / channel_scale, kg / scales[MAPS.index("kg")]


def _bucket_count(requested: int, sizes: tuple[int, int]) -> int:
    fits = BUCKET_BUDGET_BYTES // (4 * sum(sizes))
    buckets = max(1, min(requested, fits))
    if buckets < requested:
        log.info("adjoint: %d gradient buckets instead of %d (%d MB each)", buckets, requested, 4 * sum(sizes) >> 20)
    return buckets


def _accumulate(renderer, cameras, requests, per_sample_adjoint, spp, seed, sizes, dtype, buckets, defines, scales):
    """Run adjoint_rays over all samples; returns the (atlas, kg) sums, reduced over buckets,
    and the largest single addition to each map."""
    context, queue = renderer.context, renderer.queue
    program = build_program(context, "adjoint.cl", renderer.defines + LAYOUT_DEFINES + defines)
    n = len(requests)
    cams, reqs = renderer.request_buffers(cameras, requests)
    per_sample = np.zeros((n, 4), np.float32)
    per_sample[:, :3] = per_sample_adjoint
    adj = cl.Buffer(context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=per_sample)
    grads = [np.zeros(size * buckets, dtype) for size in sizes]
    rw = cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR
    bufs = [cl.Buffer(context, rw, hostbuf=grad) for grad in grads]
    peaks = np.zeros(len(MAPS), np.float32)
    peaks_buf = cl.Buffer(context, rw, hostbuf=peaks)
    scales_buf = renderer._buffer(np.asarray(scales, np.float32))
    renderer.sample_launches(
        cl.Kernel(program, "adjoint_rays"),
        n,
        spp,
        seed,
        (cams, reqs, np.int32(n)),
        (adj, *bufs, *(np.int32(size) for size in sizes), scales_buf, peaks_buf),
        desc="adjoint",
    )
    cl.enqueue_copy(queue, peaks, peaks_buf)
    results = []
    for size, grad, buf in zip(sizes, grads, bufs):
        if buckets > 1:
            reduce = cl.Kernel(program, "reduce_buckets")
            reduce(queue, (-(-size // 64) * 64,), (64,), buf, np.int32(size), np.int32(buckets))
        out = np.empty(size, dtype)
        cl.enqueue_copy(queue, out, buf)  # the first `size` words: the sum
        results.append(out)
    return results, peaks.astype(np.float64)
