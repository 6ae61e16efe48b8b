"""Gradients: spp and bounces of the adjoint pass against a high-spp reference gradient.

The loss is the gradients stage's (MILO's Eq. 5 on a batch of rays against the captured
images); its adjoint dLoss/dL is fixed once from a converged forward render, so that each row
measures the backward pass alone. The reference gradient is two independent halves: their
difference is its own noise, taken out of each row's error.
"""

from __future__ import annotations

import math

import numpy as np

from ..render.adjoint import backward
from ..render.batches import ray_batch
from ..render.device import choose_device, describe
from ..render.features import Features
from ..render.measure import clock
from ..render.renderer import Renderer
from ..render.scene_buffers import HostScene
from ..scene.capture import pixel_targets
from .forward import measured_seed

REFERENCE_SEED = (1 << 41) + 7
# Gradients are compared summed over blocks of BLOCK x BLOCK texels (kg: BLOCK_KG x BLOCK_KG per
# cube face): per texel, a batch of a few thousand rays leaves most texels unhit, and the error
# would be that sparsity's; a network's parameters (MILO-Net) see the gradient pooled like this.
BLOCK = 32
BLOCK_KG = 4


def pooled(name: str, gradient: np.ndarray) -> np.ndarray:
    """The gradient summed over blocks (edges that do not fill a block dropped)."""
    g = np.asarray(gradient, np.float64)
    if name == "kg":  # (6, N, N, 3)
        n = g.shape[1] // BLOCK_KG * BLOCK_KG
        b = max(n // BLOCK_KG, 1)
        return g[:, :n, :n].reshape(6, BLOCK_KG, b, BLOCK_KG, b, -1).sum(axis=(2, 4))
    g = g[..., None] if g.ndim == 2 else g
    h, w = g.shape[0] // BLOCK * BLOCK, g.shape[1] // BLOCK * BLOCK
    return g[:h, :w].reshape(h // BLOCK, BLOCK, w // BLOCK, BLOCK, -1).sum(axis=(1, 3))


def maps_with_gradient(features: Features) -> tuple[str, ...]:
    """The maps a gradient reaches under these features: kw and kg only through the sky."""
    maps = ["kd", "ks", "ka"] if features.specular else ["kd"]
    maps += ["ke"] if features.emission else []
    maps += ["kw", "kg"] if features.environment else []
    return tuple(maps)


class GradientSweep:
    def __init__(self, scene, features: Features, images_dir, budget, device=None, seed: int = 0):
        self.scene, self.features, self.budget, self.device = scene, features, budget, device
        self.device_name = describe(choose_device(device))
        self.host = HostScene.pack(scene.mesh, scene.maps)
        total = sum(c.width * c.height for c in scene.cameras)
        self.requests = ray_batch(scene.cameras, min(budget.gradient_rays, total), seed, 0)
        target = pixel_targets(images_dir, scene.cameras, self.requests)
        reference_features = features.with_bounces(max(budget.reference_bounces, features.max_bounces))
        self.maps = maps_with_gradient(features)
        self._renderers = {}
        renderer = Renderer(scene, reference_features, device, host_scene=self.host)
        # its own seed: a synthetic capture rendered with seed 0 at this spp would be this render exactly
        radiance, _, _ = renderer.render_requests(
            scene.cameras, self.requests, budget.gradient_reference_spp, REFERENCE_SEED - 1 - seed
        )
        residual = radiance.astype(np.float64) - target
        norm = np.linalg.norm(residual, axis=1, keepdims=True)
        self.adjoint = np.where(norm > 0, residual / np.where(norm > 0, norm, 1), 0.0)  # d ||r|| / d L
        half = budget.gradient_reference_spp // 2
        a, b = (self._pass(reference_features, half, REFERENCE_SEED + k)[0] for k in (0, 1))
        self.reference = {m: (a[m] + b[m]) / 2 for m in self.maps}
        # squared norm of the reference's own noise: |a - b|^2 / 4 is that of (a + b) / 2
        self.reference_noise = {m: float(np.sum((a[m] - b[m]) ** 2)) / 4 for m in self.maps}

    def renderer(self, features: Features) -> Renderer:
        """A renderer per feature set, warmed by one small pass (the adjoint kernel's build is
        not the configuration's time per pass)."""
        if features not in self._renderers:
            renderer = Renderer(self.scene, features, self.device, host_scene=self.host)
            backward(renderer, self.scene.cameras, self.requests[:64], self.adjoint[:64], 1, 0, maps=self.maps)
            self._renderers[features] = renderer
        return self._renderers[features]

    def _pass(self, features: Features, spp: int, seed: int):
        grads, seconds, _ = clock(
            backward,
            self.renderer(features),
            self.scene.cameras,
            self.requests,
            self.adjoint,
            max(int(spp), 1),
            seed,
            maps=self.maps,
        )
        return {m: pooled(m, grads[m]) for m in self.maps}, seconds

    def measure(self, label: str, sweep: str, features: Features, spp: int, seed: int) -> dict:
        """One backward pass: each map's relative error |g - g_ref| / |g_ref| over BLOCK-pooled
        texels (the reference's noise taken out), their mean, and the pass's time."""
        grads, seconds = self._pass(features, spp, seed)
        errors = {}
        for m in self.maps:
            scale = float(np.sum(self.reference[m] ** 2))
            if scale > 0:
                excess = float(np.sum((grads[m] - self.reference[m]) ** 2)) - self.reference_noise[m]
                errors[f"grad_rel_error_{m}"] = math.sqrt(max(excess, 1e-30) / scale)
        return {
            "family": "gradients",
            "sweep": sweep,
            "label": label,
            "spp": int(spp),
            "max_bounces": features.max_bounces,
            "nee": features.nee,
            "rays": len(self.requests),
            # the median over maps: one map with a tiny gradient (ka, whose noise swamps it at
            # these ray counts) would decide a mean
            "grad_rel_error": float(np.median(list(errors.values()))),
            **errors,
            "time_s": seconds,
            "samples_per_s": len(self.requests) * spp / seconds,
            "seed": int(seed),
            "device": self.device_name,
            "cause": None
            if sweep == "spp"
            else f"bounce limit: adjoint paths cut after {features.max_bounces} "
            f"bounce{'s' * (features.max_bounces > 1)}",
            "pasteable": True,
        }


def sweep(sweep: GradientSweep, default_spp: int, seed: int, progress=None) -> list[dict]:
    """The configured features at every spp of the ladder (with the configured spp), then each
    bounce limit at the budget's variant spp."""
    budget, features = sweep.budget, sweep.features
    jobs = [("default", "spp", features, spp) for spp in sorted(set(budget.gradient_spp) | {int(default_spp)})]
    jobs += [
        (f"{b} bounces", "bounces", features.with_bounces(b), budget.gradient_variant_spp)
        for b in budget.gradient_bounces
        if b != features.max_bounces
    ]
    rows = []
    for k, (label, kind, f, spp) in enumerate(progress(jobs) if progress else jobs):
        row = sweep.measure(label, kind, f, spp, measured_seed(seed, 500_000 + k))
        row["default"] = kind == "spp" and spp == default_spp
        rows.append(row)
    return rows
