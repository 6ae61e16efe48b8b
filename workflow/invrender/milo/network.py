"""MILO-Net (section 3.4, Fig. 4) and the plain MLPs of its ablation (Fig. 12).

The atlas maps are one 11-D vector per texel, k_m = (kd, ks, ka, ke, kw) in the layout of
render/adjoint.GRAD_CHANNELS (the adjoint's gradients come in the same layout, so the chain rule
is a dot product). MILO-Net: MLP 1 on gamma_c(x) and the normal gives the material probabilities
P_i (softmax over Q), Eq. 7 mixes the template's materials, MLP 2 on gamma_f(x) adds the detail
texture k_t (Eq. 9), MLP 3 on the encoded direction gives the sky kg. Output kernels keep values
in range (below).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from ..render.adjoint import ATLAS_CHANNELS, GRAD_CHANNELS

# Valid ranges of the atlas channels; ka > 0 keeps the Beckmann lobe finite (the paper's "zero
# roughness" extreme), ke has no upper bound.
RANGES = {"kd": (0.0, 1.0), "ks": (0.0, 1.0), "ka": (1e-3, 1.0), "ke": (0.0, math.inf), "kw": (0.0, 1.0)}
LOWER = torch.tensor([RANGES[name][0] for name, c in GRAD_CHANNELS.items() for _ in range(c.stop - c.start)])
UPPER = torch.tensor([RANGES[name][1] for name, c in GRAD_CHANNELS.items() for _ in range(c.stop - c.start)])
EMITTER_KA = 0.05  # the template's roughness of light-emitting materials (section 3.5)
SKY_LOG_LIMIT = 20.0  # kg = exp(out) with out below this: no overflow while a step overshoots


def clamp_through(values: torch.Tensor) -> torch.Tensor:
    """The output kernel: values clamped to RANGES for the renderer, with the gradient passed
    through unchanged (a clamped texel would otherwise never move back); the value loss pulls
    out-of-range values back (section 3.4)."""
    clamped = torch.maximum(torch.minimum(values, UPPER.to(values)), LOWER.to(values))
    return values + (clamped - values).detach()


def hard_through(probabilities: torch.Tensor) -> torch.Tensor:
    """Each texel's most probable material alone (one-hot), with the softmax's gradient.

    Eq. 7 mixes all Q materials by P_i. A light's ke is large (12 in the demo room against albedos
    below 1), so a wall texel with P = 0.005 on the light material glows at 0.06: the softmax never
    reaches 0, and that glow trades against kd (the diffuse-emission ambiguity the template is
    there to remove; measured in docs/milo.md). Rendering the most probable material keeps every
    texel either emitting or reflecting, as the finite material constraint says; the category
    loss (Eq. 8) keeps P near one-hot so the straight-through gradient stays close to Eq. 7's."""
    hard = torch.nn.functional.one_hot(probabilities.argmax(-1), probabilities.shape[-1]).to(probabilities)
    return hard + probabilities - probabilities.detach()


class Encoding(nn.Module):
    """gamma(x) of Eq. 6: sin and cos of 2^l pi x for l < L, per coordinate, beside x itself."""

    def __init__(self, levels: int):
        super().__init__()
        self.register_buffer("frequencies", math.pi * 2.0 ** torch.arange(levels, dtype=torch.float32))

    def out_features(self, dims: int) -> int:
        return dims * (1 + 2 * len(self.frequencies))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        angles = (x[..., None] * self.frequencies).flatten(-2)
        return torch.cat([x, torch.sin(angles), torch.cos(angles)], -1)


class MLP(nn.Module):
    """`layers` linear layers `width` wide with LeakyReLU; the last `skip_layers` hidden ones are
    residual (h + f(h)), the paper's skips against vanishing gradients."""

    def __init__(self, inputs: int, outputs: int, layers: int, width: int, skip_layers: int, slope: float):
        super().__init__()
        self.first = nn.Linear(inputs, width)
        self.hidden = nn.ModuleList(nn.Linear(width, width) for _ in range(max(layers - 2, 0)))
        self.residual_from = len(self.hidden) - min(skip_layers, len(self.hidden))
        self.last = nn.Linear(width, outputs)
        self.act = nn.LeakyReLU(slope)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.act(self.first(x))
        for index, layer in enumerate(self.hidden):
            step = self.act(layer(h))
            h = h + step if index >= self.residual_from else step
        return self.last(h)

    def scale_output(self, factor: float) -> None:
        with torch.no_grad():
            self.last.weight.mul_(factor)
            self.last.bias.mul_(factor)


def _logit(p: float) -> float:
    return math.log(p / (1.0 - p))


class MaterialTemplate(nn.Module):
    """Q materials m_i of Eq. 7: S light-emitting ones (kd = ks = 0, ka = 0.05, learnable ke), one
    window (learnable kw, no ke), and Q - S - 1 normal ones (learnable kd, ks, ka; ke = kw = 0).
    Learnable values live behind sigmoid (albedos, roughness, kw) and exp (ke), so every
    template material is valid whatever SGD does to it."""

    def __init__(self, materials: int, emitters: int, emission: float, generator: torch.Generator):
        super().__init__()
        normal = materials - emitters - 1
        kd = torch.rand(normal, 3, generator=generator) * 0.8 + 0.1  # distinct starts, or all materials move alike
        self.normal_kd = nn.Parameter(torch.log(kd / (1 - kd)))
        self.normal_ks = nn.Parameter(torch.full((normal, 3), _logit(0.04)))
        self.normal_ka = nn.Parameter(torch.full((normal, 1), _logit(0.3)))
        self.emitter_ke = nn.Parameter(torch.full((emitters, 3), math.log(emission)))
        self.window_kw = nn.Parameter(torch.full((1, 1), _logit(0.5)))
        self.materials, self.emitters = materials, emitters
        # Which channels each material may vary (1) and which the constraint fixes (0): the detail
        # texture of Eq. 9 adds only to the former. Section 3.3: every region either emits (ke,
        # or kw for the window) or reflects (kd, ks, ka); a detail on ke over a wall is emission
        # the template forbids, and it trades against kd exactly as a soft P does (docs/milo.md).
        learnable = torch.zeros(materials, ATLAS_CHANNELS)
        learnable[:emitters, GRAD_CHANNELS["ke"]] = 1.0
        learnable[emitters, GRAD_CHANNELS["kw"]] = 1.0
        for name in ("kd", "ks", "ka"):
            learnable[emitters + 1 :, GRAD_CHANNELS[name]] = 1.0
        self.register_buffer("learnable", learnable)

    @torch.no_grad()
    def start_emission(self, rgb) -> None:
        rgb = torch.as_tensor(np.asarray(rgb, np.float32))
        self.emitter_ke.copy_(torch.log(torch.clamp(rgb, min=1e-3)).expand_as(self.emitter_ke))

    def forward(self) -> torch.Tensor:
        """(Q, 11): emitters first, then the window, then the normal materials."""
        rows = torch.zeros(self.materials, ATLAS_CHANNELS)
        s = self.emitters
        put = lambda name, first, last, value: rows.__setitem__((slice(first, last), GRAD_CHANNELS[name]), value)
        put("ka", 0, s + 1, EMITTER_KA)
        put("ke", 0, s, torch.exp(self.emitter_ke))
        put("kw", s, s + 1, torch.sigmoid(self.window_kw))
        put("kd", s + 1, None, torch.sigmoid(self.normal_kd))
        put("ks", s + 1, None, torch.sigmoid(self.normal_ks))
        put("ka", s + 1, None, torch.sigmoid(self.normal_ka))
        return rows


# The plain MLP's outputs are offsets from these (its Fig. 12 ablation has no template to start
# from): a grey diffuse world, a little gloss, no emission.
PLAIN_START = {"kd": 0.5, "ks": 0.04, "ka": 0.3, "ke": 0.0, "kw": 0.0}


class MiloNet(nn.Module):
    """MILO-Net, or with `template=False` the two plain MLPs of Fig. 12. `emission` is the
    emitting materials' starting radiance and `sky` the sky's (the brightest and the typical
    captured radiance), so training starts at the capture's scale."""

    def __init__(self, settings: dict, emission: float, sky: float):
        super().__init__()
        generator = torch.Generator().manual_seed(int(settings["seed"]))
        torch.manual_seed(int(settings["seed"]))  # nn.Linear's initialisation draws from the global generator
        mlp = lambda inputs, outputs: MLP(
            inputs, outputs, settings["layers"], settings["width"], settings["skip_layers"], settings["leaky_slope"]
        )
        self.uses_template = bool(settings["template"])
        self.hard_materials = bool(settings["hard_materials"])
        self.coarse = Encoding(settings["levels_coarse"])
        self.sky_encoding = Encoding(settings["levels_sky"])
        surface_inputs = self.coarse.out_features(3) + 3  # gamma_c(x) and the normal
        if self.uses_template:
            self.fine = Encoding(settings["levels_fine"])
            self.material_mlp = mlp(surface_inputs, settings["materials"])  # MLP 1 -> P_i
            self.detail_mlp = mlp(self.fine.out_features(3) + 3, ATLAS_CHANNELS)  # MLP 2 -> k_t
            self.detail_mlp.scale_output(0.01)  # k_t starts near 0: the template explains first
            self.template = MaterialTemplate(settings["materials"], settings["emitters"], emission, generator)
        else:
            self.maps_mlp = mlp(surface_inputs, ATLAS_CHANNELS)
            self.maps_mlp.scale_output(0.01)
            start = [PLAIN_START[name] for name, c in GRAD_CHANNELS.items() for _ in range(c.stop - c.start)]
            self.register_buffer("plain_start", torch.tensor(start))
        self.sky_mlp = mlp(self.sky_encoding.out_features(3), 3)  # MLP 3 -> kg
        self.sky_mlp.scale_output(0.01)
        self.register_buffer("log_sky", torch.tensor(math.log(max(sky, 1e-6))))

    def optimisers(self, settings: dict) -> list:
        """AMSGrad for the MLPs, with MLP 1's l2 term (reflectance similarity) as its weight decay;
        SGD with Nesterov momentum for the template, whose gradients are too noisy for adaptive
        steps (section 3.5)."""
        template = list(self.template.parameters()) if self.uses_template else []
        first_mlp = list((self.material_mlp if self.uses_template else self.maps_mlp).parameters())
        taken = {id(p) for p in template + first_mlp}
        others = [p for p in self.parameters() if id(p) not in taken]
        groups = [{"params": first_mlp, "weight_decay": settings["l2"]}, {"params": others, "weight_decay": 0.0}]
        optimisers = [torch.optim.Adam(groups, lr=settings["lr_mlp"], amsgrad=True)]
        if template:
            optimisers.append(
                torch.optim.SGD(template, lr=settings["lr_template"], momentum=settings["momentum"], nesterov=True)
            )
        return optimisers

    def warm_start(self, texels, emitting: np.ndarray, radiance: np.ndarray, seen: np.ndarray, settings: dict) -> None:
        """Start MLP 1 from the photographs (importance.py): texels in `emitting` (per texel, bool)
        on the first light material, every other texel on the normal materials, by a few Adam
        steps of cross-entropy; the light material's ke starts at those texels' mean observed
        radiance (RGB). Training then revises both. The arrays are the atlas's (H, W)."""
        if not self.uses_template or settings["warm_start_steps"] == 0:
            return
        emitting, radiance = texels.gather(emitting), texels.gather(radiance)
        if emitting.any() and settings["emitters"] > 0:
            self.template.start_emission(radiance[emitting].mean(0))
        light = torch.from_numpy(emitting)
        optimiser = torch.optim.Adam(self.material_mlp.parameters(), lr=settings["lr_mlp"])
        inputs = torch.cat([self.coarse(texels.positions), texels.normals], -1)
        normal_from = settings["emitters"] + 1
        for _ in range(settings["warm_start_steps"]):
            log_p = torch.log_softmax(self.material_mlp(inputs), -1)
            loss = -torch.where(light, log_p[:, 0], torch.logsumexp(log_p[:, normal_from:], -1)).mean()
            optimiser.zero_grad(set_to_none=True)
            loss.backward()
            optimiser.step()

    def texel_surface(self, texels, rows) -> dict[str, torch.Tensor]:
        """`surface` at the texels' rows `rows` (None: all of them)."""
        if rows is None:
            return self.surface(texels.positions, texels.normals)
        return self.surface(texels.positions[rows], texels.normals[rows])

    def regularisers(self, out: dict, settings: dict) -> dict[str, torch.Tensor]:
        from .losses import regularisers  # losses reads this module's ranges

        return regularisers(out, settings)

    def surface(self, positions: torch.Tensor, normals: torch.Tensor) -> dict[str, torch.Tensor]:
        """Per texel: 'maps' (n, 11) through the output kernel, 'raw' before it (for the value
        loss), and with the template 'probabilities' (n, Q) and 'detail' k_t (n, 11)."""
        coarse = torch.cat([self.coarse(positions), normals], -1)
        if not self.uses_template:
            raw = self.maps_mlp(coarse) + self.plain_start
            return {"raw": raw, "maps": clamp_through(raw)}
        probabilities = torch.softmax(self.material_mlp(coarse), -1)
        detail = self.detail_mlp(torch.cat([self.fine(positions), normals], -1))
        mixing = hard_through(probabilities) if self.hard_materials else probabilities
        detail = detail * (mixing @ self.template.learnable)  # no glow painted onto a wall, no albedo onto a lamp
        raw = mixing @ self.template() + detail  # Eq. 7 and 9
        return {"raw": raw, "maps": clamp_through(raw), "probabilities": probabilities, "detail": detail}

    def sky(self, directions: torch.Tensor) -> torch.Tensor:
        """kg (m, 3) at unit directions: exp keeps it positive over the sky's dynamic range."""
        out = self.sky_mlp(self.sky_encoding(directions)) + self.log_sky
        return torch.exp(torch.clamp(out, max=SKY_LOG_LIMIT))
