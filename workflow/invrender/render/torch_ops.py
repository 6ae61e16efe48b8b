"""The renderer as a PyTorch operation: parameter maps in, per-ray radiance out, and the adjoint
kernel as its backward (MILO's image loss back-propagated to the six maps)."""

from __future__ import annotations

import numpy as np
import torch

from ..scene.types import MAP_NAMES, Camera, Maps
from .adjoint import backward, backward_seed
from .renderer import Renderer

MAP_ORDER = MAP_NAMES  # the operation's map arguments and gradients, in the scenes' order


class RenderRays(torch.autograd.Function):
    """RenderRays.apply(kd, ks, ka, ke, kw, kg, renderer, cameras, requests, spp, seed) -> (n, 3).

    The backward traces other samples than the forward (adjoint.backward_seed). Sampling is
    detached (docs/renderer.md, "Gradients")."""

    @staticmethod
    def forward(
        ctx,
        kd,
        ks,
        ka,
        ke,
        kw,
        kg,
        renderer: Renderer,
        cameras: list[Camera],
        requests: np.ndarray,
        spp: int,
        seed: int,
    ):
        arrays = {
            name: t.detach().cpu().numpy().astype(np.float32) for name, t in zip(MAP_ORDER, (kd, ks, ka, ke, kw, kg))
        }
        renderer.set_maps(Maps(**arrays))
        mean, _, _ = renderer.render_requests(cameras, requests, spp, seed)
        ctx.state = (renderer, cameras, requests, spp, seed)
        return torch.from_numpy(mean)

    @staticmethod
    def backward(ctx, grad_output):
        renderer, cameras, requests, spp, seed = ctx.state
        grads = backward(renderer, cameras, requests, grad_output.detach().cpu().numpy(), spp, backward_seed(seed))
        return tuple(torch.from_numpy(grads[name].astype(np.float32)) for name in MAP_ORDER) + (None,) * 5


def render_rays(maps: dict[str, torch.Tensor], renderer: Renderer, cameras, requests, spp: int, seed: int):
    """Per-ray radiance (n, 3) of the maps given as tensors (any of them may require grad)."""
    return RenderRays.apply(*(maps[name] for name in MAP_ORDER), renderer, cameras, requests, spp, seed)
