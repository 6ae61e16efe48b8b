"""The `texels` model: the atlas maps optimised directly, texel by texel, through the adjoint (no
network), with smoothness priors; a baseline for MILO-Net and, at CPU budgets, an
alternative to it (docs/milo.md measures the two).

Every texel either emits or reflects, as MILO's finite-material constraint says, and which one is
decided once, from the photographs (importance.emitting_start, the same rule as MILO-Net's warm
start): an emitter has ke = exp(e) (RGB, started at its observed radiance) and kd = ks = 0; a
reflecting texel has kd = sigmoid(a) (RGB, started at its observed radiance over the typical
irradiance: the per-texel guess without light transport), a grey specular ks = sigmoid(b) and a
roughness ka, and no emission; kd is a share of 1 - ks, so kd + ks <= 1 holds by construction.
A window texel (window.py finds them in the photographs) has kw = 1 and nothing else: it shows
the sky, kg = exp(g) per cube texel. Priors: an L1 difference between texels that are
neighbours on the surface (a wall is one colour unless the photographs say otherwise, and texels
few rays reach follow their neighbours), the same in log radiance over the sky, and a pull of ks
towards a dielectric's 0.04. Before the gradient steps, reflectance.py corrects kd by light
transport (captured over rendered radiance, texel by texel).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from ..render.adjoint import ATLAS_CHANNELS, GRAD_CHANNELS
from ..render.losses import log_sky_variation
from ..scene.neighbours import point_neighbour_pairs, sky_neighbour_pairs
from .network import EMITTER_KA, RANGES, SKY_LOG_LIMIT

F0 = 0.04  # a dielectric's reflectance at normal incidence: where ks starts and what its prior pulls to
START_KA = 0.3
CLAMP = 1e-3  # starting values kept this far inside (0, 1) so that their logits are finite


def _logit(x) -> torch.Tensor:
    x = np.clip(np.asarray(x, np.float64), CLAMP, 1 - CLAMP)
    return torch.as_tensor(np.log(x / (1 - x)).astype(np.float32))


def reflectance_start(radiance: np.ndarray, seen: np.ndarray, emitting: np.ndarray) -> np.ndarray:
    """(n, 3) the per-texel guess without light transport: each seen reflecting texel's observed
    radiance times one global factor, the one that puts their median luminance at 0.5 (a room of
    mid-grey walls under the irradiance it has); 0.5 where no view sees the texel."""
    reflecting = seen & ~emitting
    kd = np.full((len(radiance), 3), 0.5, np.float32)
    if reflecting.any():
        scale = 0.5 / max(float(np.median(radiance[reflecting].mean(-1))), 1e-6)
        kd[reflecting] = np.clip(radiance[reflecting] * scale, 0.02, 0.95)
    return kd


class TexelMaps(nn.Module):
    """One parameter per texel and channel; `surface` gives rows of the 11-channel maps in
    render/adjoint.GRAD_CHANNELS' layout, as MiloNet's does."""

    def __init__(self, settings: dict, texels, sky: float):
        super().__init__()
        n = len(texels)
        self.kd_logit = nn.Parameter(torch.zeros(n, 3))
        self.ks_logit = nn.Parameter(torch.full((n, 1), float(_logit(F0))))
        self.ka_logit = nn.Parameter(torch.full((n, 1), float(_logit(START_KA))))
        self.ke_log = nn.Parameter(torch.full((n, 3), -10.0))
        self.register_buffer("emitter", torch.zeros(n, 1))
        self.register_buffer("window", torch.zeros(n, 1))
        cube = 6 * settings["sky_resolution"] ** 2
        self.sky_log = nn.Parameter(torch.full((cube, 3), float(np.log(max(sky, 1e-6)))))
        self.pairs = torch.from_numpy(point_neighbour_pairs(texels.positions.numpy(), settings["smoothness_radius"]))
        self.sky_pairs = torch.from_numpy(sky_neighbour_pairs(settings["sky_resolution"]))

    @torch.no_grad()
    def warm_start(self, texels, emitting: np.ndarray, radiance: np.ndarray, seen: np.ndarray, settings: dict) -> None:
        """Emitters from the photographs, their ke at the observed radiance; the others' kd at the
        per-texel guess (reflectance_start). The arrays are the atlas's (H, W); the padding
        texels around each chart take their nearest covered neighbour's values."""
        radiance = texels.gather_grown(radiance)
        emitting, seen = (texels.gather_grown(a.astype(np.float32)) > 0.5 for a in (emitting, seen > 0))
        self.emitter.copy_(torch.from_numpy(emitting.astype(np.float32))[:, None])
        self.kd_logit.copy_(_logit(reflectance_start(radiance, seen, emitting) / (1.0 - F0)))
        self.ke_log.copy_(torch.from_numpy(np.log(np.maximum(radiance, 1e-3)).astype(np.float32)))

    @torch.no_grad()
    def open_windows(self, texels, windows) -> None:
        """kw = 1 on `windows`' texels (window.Windows, the atlas's (H, W)), which neither emit nor
        reflect; the sky starts at what the photographs show through them (where they show
        nothing on its side of the horizon, as it was)."""
        window = texels.gather_grown(windows.texels.astype(np.float32)) > 0.5
        self.window.copy_(torch.from_numpy(window.astype(np.float32))[:, None])
        self.emitter.mul_(1.0 - self.window)
        seen_sky = torch.from_numpy(np.log(np.maximum(windows.sky, 1e-6)).astype(np.float32))
        self.sky_log.copy_(torch.where(torch.from_numpy(windows.filled)[:, None], seen_sky, self.sky_log))

    @torch.no_grad()
    def light_sun(self, index: int, radiance: np.ndarray | None) -> None:
        """The sun in the sky's cube texel `index` (sun.py finds it), at `radiance` (RGB; None:
        as it is, a resumed run's); the sky's smoothness leaves it out (it is not like its
        neighbours)."""
        if radiance is not None:
            self.sky_log[index] = torch.from_numpy(np.log(np.maximum(radiance, 1e-6)).astype(np.float32))
        self.sky_pairs = self.sky_pairs[(self.sky_pairs != index).all(1)]

    @torch.no_grad()
    def scale_reflectance(self, ratio: np.ndarray) -> None:
        """Every reflecting texel's kd times `ratio` (n, 3), kept inside (0, 1 - ks)."""
        share = torch.sigmoid(self.kd_logit) * torch.from_numpy(np.asarray(ratio, np.float32))
        self.kd_logit.copy_(torch.where(self._reflecting() > 0, _logit(share.numpy()), self.kd_logit))

    def optimisers(self, settings: dict) -> list:
        return [torch.optim.Adam(self.parameters(), lr=settings["lr_texels"])]

    def _maps(self, rows=None) -> torch.Tensor:
        """The 11-channel maps of the texels `rows` (None: every texel)."""
        at = slice(None) if rows is None else torch.as_tensor(rows)
        reflecting = self._reflecting(at)
        low_ka, high_ka = RANGES["ka"]
        kd, ks, ka_unit = self._reflectance(at)
        columns = {
            "kd": kd * reflecting,
            "ks": ks.expand(-1, 3) * reflecting,
            "ka": (low_ka + (high_ka - low_ka) * ka_unit) * reflecting + EMITTER_KA * (1.0 - reflecting),
            "ke": self._emission(at),
            "kw": self.window[at],
        }
        maps = torch.cat([columns[name] for name in GRAD_CHANNELS], -1)
        assert maps.shape[1] == ATLAS_CHANNELS
        return maps

    def _reflectance(self, at=slice(None)):
        """kd (n, 3), the grey ks (n, 1) and ka on [0, 1] (n, 1) of the texels `at`; kd is a share
        of what ks leaves, so that no texel reflects more light than it receives."""
        ks = torch.sigmoid(self.ks_logit[at])
        return torch.sigmoid(self.kd_logit[at]) * (1.0 - ks), ks, torch.sigmoid(self.ka_logit[at])

    def _reflecting(self, at=slice(None)) -> torch.Tensor:
        return 1.0 - self.emitter[at] - self.window[at]

    def _emission(self, at=slice(None)):
        return torch.exp(torch.clamp(self.ke_log[at], max=SKY_LOG_LIMIT)) * self.emitter[at]

    def texel_surface(self, texels, rows) -> dict[str, torch.Tensor]:
        maps = self._maps(rows)
        return {"maps": maps, "raw": maps}

    def sky(self, directions: torch.Tensor) -> torch.Tensor:
        assert len(directions) == len(self.sky_log)  # the cube's texels, in texel_directions' order
        return torch.exp(torch.clamp(self.sky_log, max=SKY_LOG_LIMIT))

    def regularisers(self, out: dict, settings: dict) -> dict[str, torch.Tensor]:
        """The priors over the whole atlas (they are cheap beside a render), `out` unused."""
        reflecting = self._reflecting()
        kd, ks, ka = self._reflectance()
        terms = {"specular": settings["specular_prior"] * ((ks - F0).abs() * reflecting).mean()}
        if len(self.pairs):
            i, j = self.pairs[:, 0], self.pairs[:, 1]
            ke = torch.log1p(self._emission())  # emitters: relative differences
            values = torch.cat([kd, ks, ka, ke], -1)
            same_kind = ((self.emitter[i] == self.emitter[j]) & (self.window[i] == self.window[j])).float()[:, 0]
            difference = (values[i] - values[j]).abs().sum(-1) * same_kind
            terms["smoothness"] = settings["smoothness"] * difference.mean()
        sky_terms = log_sky_variation(self.sky_log, self.sky_pairs, SKY_LOG_LIMIT)
        terms["sky_smoothness"] = settings["sky_smoothness"] * sky_terms
        return terms
