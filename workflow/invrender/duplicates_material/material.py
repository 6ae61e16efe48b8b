"""The shared material, parametrised directly on texels, and its regularisers.

Per material set (the copies' shared atlas "object", the support's "support") three unconstrained
arrays over the whole atlas: kd = sigmoid(a) (RGB), the specular strength s = sigmoid(b) with
ks = F0 + (1 - F0) s (grey: the paper's F = (1 - m) F0 + m a has one degree of freedom per point,
and a single photograph says little about a specular tint), and ka = KA_MIN + (1 - KA_MIN) sigmoid(c)
(Beckmann alpha^2). The sky is kg = exp(g) per cube texel: a step changes it by a factor, so a
sun hundreds of times brighter than the sky is reached in as many steps as a dim sky. Every value stays in MILO's ranges
whatever step Adam takes, so no value loss is needed beside the energy bound. ke and kw are 0: the
copies and their support are lit by kg alone (no emitters are built).

Texels are whole atlas arrays: the renderer reads a padding texel at a chart's edge as readily
as a covered one, so it is a parameter like any other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..render.losses import energy_excess, log_sky_variation
from ..scene.types import ATLAS_MAPS, Atlas, Maps

F0 = 0.04  # a dielectric's reflectance at normal incidence (the paper's 0.02; MILO's default ks 0.04)
KA_MIN = 1e-3  # ka > 0 keeps the Beckmann lobe finite
SKY_LOG_LIMIT = 20.0  # kg = exp(g), g below this: no overflow while a step overshoots
CLAMP = 1e-3  # starting values are kept this far inside (0, 1) so their logits are finite


def _logit(x) -> torch.Tensor:
    x = np.clip(np.asarray(x, np.float64), CLAMP, 1 - CLAMP)
    return torch.from_numpy(np.log(x / (1 - x)).astype(np.float32))


def _log(y) -> torch.Tensor:
    return torch.from_numpy(np.log(np.maximum(np.asarray(y, np.float64), 1e-6)).astype(np.float32))


@dataclass(frozen=True)
class Ground:
    """The sky below the support's horizon as the light a ground of ``albedo`` (Lambertian, grey)
    reflects under the sky above it: kg = albedo E / pi, E = sum(weights kg) the irradiance on the
    support's plane (support.irradiance_weights). No pixel sees that half of the sphere (the
    support hides it from every copy), so a prior sets it; this one stays in step with the sky
    the copies do constrain, and its gradient (the few rays that pass the support's edge) reaches
    that sky through E."""

    below: np.ndarray  # (6, n, n) bool
    weights: np.ndarray  # (6, n, n)
    albedo: float

    def radiance(self, sky: torch.Tensor) -> torch.Tensor:
        """The sky (6, n, n, 3) with the ground put below the horizon."""
        weights = torch.from_numpy(np.asarray(self.weights, np.float32))
        irradiance = (sky * weights[..., None]).sum((0, 1, 2))
        ground = (self.albedo / np.pi) * irradiance
        return torch.where(torch.from_numpy(np.asarray(self.below))[..., None], ground, sky)


class TexelMaterial(torch.nn.Module):
    """The unconstrained arrays of every material set and of the sky (and the ground's rule, if any:
    its texels' own values are then unused)."""

    def __init__(
        self,
        start: dict[str, Atlas],
        kg: np.ndarray,
        pairs: dict[str, np.ndarray],
        sky_pairs: np.ndarray,
        ground: Ground | None = None,
        seen: dict[str, np.ndarray] | None = None,
    ):
        super().__init__()
        self.ground = ground  # not a buffer: checkpoints hold the same state with and without it
        # Per set, (H, W) 1 where a photograph shows the texel (first_guess.seen_texels), else 0;
        # the render's gradient reaches only those (``surrogate``). Not a buffer either.
        self.seen = {name: torch.from_numpy(np.asarray(m, np.float32)) for name, m in (seen or {}).items()}
        self.names = list(start)
        self.pairs = {name: torch.from_numpy(p) for name, p in pairs.items()}
        self.sky_pairs = torch.from_numpy(sky_pairs)
        for name, atlas in start.items():
            strength = (np.asarray(atlas.ks, np.float64).mean(-1) - F0) / (1 - F0)
            self.register_parameter(f"{name}_kd", torch.nn.Parameter(_logit(atlas.kd)))
            self.register_parameter(f"{name}_s", torch.nn.Parameter(_logit(strength)))
            self.register_parameter(f"{name}_ka", torch.nn.Parameter(_logit((atlas.ka - KA_MIN) / (1 - KA_MIN))))
        self.sky = torch.nn.Parameter(_log(kg))

    def maps(self, name: str) -> dict[str, torch.Tensor]:
        """kd (H, W, 3), s (H, W), ks (H, W, 3), ka (H, W) of one set."""
        s = torch.sigmoid(getattr(self, f"{name}_s"))
        return {
            "kd": torch.sigmoid(getattr(self, f"{name}_kd")),
            "s": s,
            "ks": (F0 + (1 - F0) * s)[..., None].expand(*s.shape, 3),
            "ka": KA_MIN + (1 - KA_MIN) * torch.sigmoid(getattr(self, f"{name}_ka")),
        }

    def kg(self) -> torch.Tensor:
        sky = torch.exp(torch.clamp(self.sky, max=SKY_LOG_LIMIT))
        return sky if self.ground is None else self.ground.radiance(sky)

    @torch.no_grad()
    def atlases(self) -> dict[str, Atlas]:
        out = {}
        for name in self.names:
            m = {key: value.numpy().astype(np.float32) for key, value in self.maps(name).items()}
            zero_rgb, zero = np.zeros_like(m["kd"]), np.zeros_like(m["ka"])
            out[name] = Atlas(kd=m["kd"], ks=np.ascontiguousarray(m["ks"]), ka=m["ka"], ke=zero_rgb, kw=zero)
        return out

    @torch.no_grad()
    def sky_map(self) -> np.ndarray:
        return self.kg().numpy().astype(np.float32)

    def set_maps(self, name: str) -> Maps:
        """One set's atlas with the sky, as a maps file holds them (scene/snapshots.py)."""
        atlas = self.atlases()[name]
        return Maps(**{m: getattr(atlas, m) for m in ATLAS_MAPS}, kg=self.sky_map())

    def surrogate(self, grads: dict[str, Atlas], kg_grad: np.ndarray) -> torch.Tensor:
        """sum(map * dLoss/dmap): its gradient with respect to the parameters is the chain rule
        from the adjoint's map gradients. A texel no photograph shows (``seen``) gets none: light
        it bounces onto what the photograph does show would make it a free variable that soaks
        up the residuals (the support behind each copy took the copy's colours, which a user sees
        as ghosts once the copies move); the regularisers alone move it, towards its neighbours."""
        total = (self.kg() * torch.from_numpy(np.asarray(kg_grad, np.float32))).sum()
        for name in self.names:
            m, g = self.maps(name), grads[name]
            seen = self.seen.get(name)
            for key in ("kd", "ks", "ka"):
                grad = torch.from_numpy(np.asarray(getattr(g, key), np.float32))
                if seen is not None:
                    grad = grad * (seen[..., None] if grad.dim() == 3 else seen)
                total = total + (m[key] * grad).sum()
        return total

    def regularisers(self, settings: dict) -> dict[str, torch.Tensor]:
        """The weighted regularisers (config.py says why each is there), summed over the sets."""
        terms = {key: torch.zeros(()) for key in ("smoothness", "binary", "sparsity", "energy")}
        terms["sky_smoothness"] = settings["sky_smoothness"] * log_sky_variation(
            self.sky, self.sky_pairs, SKY_LOG_LIMIT
        )
        for name in self.names:
            m = self.maps(name)
            s = m["s"]
            terms["binary"] = terms["binary"] + settings["binary"] * (s * (1 - s)).mean()
            terms["sparsity"] = terms["sparsity"] + settings["sparsity"] * s.mean()
            terms["energy"] = terms["energy"] + settings["energy"] * energy_excess(m["kd"], m["ks"]).sum(-1).mean()
            pairs = self.pairs[name]
            if len(pairs):
                values = torch.cat([m["kd"].reshape(-1, 3), s.reshape(-1, 1), m["ka"].reshape(-1, 1)], -1)
                difference = (values[pairs[:, 0]] - values[pairs[:, 1]]).abs().sum(-1).mean()
                terms["smoothness"] = terms["smoothness"] + settings["smoothness"] * difference
        return terms
