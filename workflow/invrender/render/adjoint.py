"""Gradients of an image loss with respect to every parameter map, from kernels/adjoint.cl.

`backward` takes ray requests (as Renderer.render_requests does) and the adjoint radiance
dLoss/dL of each (the gradient of the loss with respect to the ray's estimate) and returns
d Loss / d map for kd, ks, ka, ke, kw (atlas-shaped) and kg (cube-shaped). The accumulation is
64-bit fixed point, so the same seed gives the same bytes on the same device.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..scene.types import Camera
from .program import build_program
from .renderer import Renderer

GRAD_CHANNELS = {"kd": slice(0, 3), "ks": slice(3, 6), "ka": slice(6, 7), "ke": slice(7, 10), "kw": slice(10, 11)}
FIXED_POINT_SCALE = float(2**32)  # resolution 2.3e-10 per addition, range +-2.1e9 per texel


def backward(renderer: Renderer, cameras: list[Camera], requests: np.ndarray, adjoint: np.ndarray, spp: int,
             seed: int = 0, scale: float = FIXED_POINT_SCALE) -> dict[str, np.ndarray]:
    context, queue = renderer.context, renderer.queue
    kernel = cl.Kernel(build_program(context, "adjoint.cl", renderer.features.defines()), "adjoint_rays")
    host = renderer.host
    n = len(requests)
    cams, reqs = renderer.request_buffers(cameras, requests)
    per_sample = np.zeros((n, 4), np.float32)
    per_sample[:, :3] = np.asarray(adjoint, np.float32) / spp  # each sample is 1/spp of the estimate
    adj = cl.Buffer(context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=per_sample)
    grad_atlas = np.zeros(host.atlas_w * host.atlas_h * 11, np.int64)
    grad_kg = np.zeros(6 * host.cube_n * host.cube_n * 3, np.int64)
    rw = cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR
    atlas_buf, kg_buf = cl.Buffer(context, rw, hostbuf=grad_atlas), cl.Buffer(context, rw, hostbuf=grad_kg)
    renderer.sample_launches(kernel, n, spp, seed, (cams, reqs, np.int32(n)),
                             (adj, atlas_buf, kg_buf, np.float32(scale)), desc="adjoint")
    cl.enqueue_copy(queue, grad_atlas, atlas_buf)
    cl.enqueue_copy(queue, grad_kg, kg_buf)
    atlas = (grad_atlas / scale).reshape(host.atlas_h, host.atlas_w, 11)
    out = {name: atlas[..., channels].squeeze(-1) if channels.stop - channels.start == 1 else atlas[..., channels]
           for name, channels in GRAD_CHANNELS.items()}
    out["kg"] = (grad_kg / scale).reshape(6, host.cube_n, host.cube_n, 3)
    return out
