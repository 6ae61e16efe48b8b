"""The training loop: per iteration a random ray batch, maps from MILO-Net, the path tracer's
estimate and its adjoint, and the chain rule back into the network.

What is evaluated per iteration (docs/milo.md measures the cost of each):
1. the network on every texel without gradients (the renderer needs whole maps: a path may
   bounce anywhere), and the sky MLP on the 6 N N cube directions;
2. the forward render of the batch and the adjoint pass, giving dLoss_image/dmap per texel;
3. the network again, with gradients, only on the texels the adjoint reached plus a random
   `regularised_fraction` of all texels for the regularisers (Eq. 8, 10, value): the chain rule
   through maps is sum(map * dLoss/dmap) over the texels whose gradient is not zero.

Every random draw is keyed by (seed, iteration): the batch (render/batches.py), the path samples
(iteration_seed) and the regularised texels, so iteration k computes the same thing whether the
run started at 0 or resumed at k.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import torch

from ..render.adjoint import GRAD_CHANNELS, backward, backward_seed
from ..render.batches import iteration_seed, ray_batch  # noqa: F401 (iteration_seed: milo's, kept importable here)
from ..render.renderer import Renderer
from ..scene.types import ATLAS_MAPS, Camera, Maps
from .losses import image_loss
from .network import LOWER, MiloNet
from .texel_model import TexelMaps
from .texels import Texels, sky_directions

PRIORS = ("category", "texture", "value", "smoothness", "sky_smoothness", "specular")  # MILO-Net's, then texels'
CHUNK = 1 << 16  # texels per network call without gradients
LOG_COLUMNS = (
    "iteration",
    "wall_time",
    "loss",
    "image",
    "category",
    "texture",
    "value",
    "smoothness",
    "sky_smoothness",
    "specular",
    "texels_touched",
    "texels_with_grad",
    "dropped_samples",
    "seconds_network",
    "seconds_render",
    "seconds_adjoint",
    "seconds_update",
    "lr_mlp",
    "lr_template",
)


@dataclass
class Views:
    """The training cameras and their captured pixels, flat in ray-id order (Renderer.ray_offset:
    camera after camera, row by row), so a batch's targets are one gather."""

    cameras: list[Camera]
    pixels: np.ndarray  # (total, 3) float32

    @classmethod
    def from_images(cls, cameras: list[Camera], images: list[np.ndarray]) -> Views:
        return cls(cameras, np.concatenate([image.reshape(-1, 3) for image in images]).astype(np.float32))


@dataclass
class Training:
    """One run: the model (MILO-Net, or the texels model), its optimisers and schedules, where it
    stands. ("lr_mlp" in the log is the first optimiser's rate: the texels' for that model.)"""

    settings: dict
    net: MiloNet | TexelMaps
    texels: Texels
    renderer: Renderer
    views: Views
    loss_epsilon: float = 0.1  # relative_mse's epsilon in radiance units
    iteration: int = 0
    wall_time: float = 0.0
    optimisers: list = field(default_factory=list)
    schedules: list = field(default_factory=list)

    def __post_init__(self):
        s = self.settings
        self.directions = sky_directions(s["sky_resolution"])
        self.optimisers = self.net.optimisers(s)
        milestones = sorted({max(1, round(f * s["iterations"])) for f in s["decay_at"]})
        self.schedules = [
            torch.optim.lr_scheduler.MultiStepLR(o, milestones, gamma=s["decay"]) for o in self.optimisers
        ]

    # --- the maps ---------------------------------------------------------------------------
    @torch.no_grad()
    def predict(self) -> Maps:
        """The six maps the network gives now, at the atlas resolution."""
        t = self.texels
        chunks = [np.arange(i, min(i + CHUNK, len(t))) for i in range(0, len(t), CHUNK)]
        values = torch.cat([self.net.texel_surface(t, rows)["maps"] for rows in chunks]).numpy()
        atlas = t.scatter(values, values.shape[1], LOWER.numpy())  # texels no UV reads: valid, dark, smooth
        maps = {
            name: atlas[..., c].squeeze(-1) if c.stop - c.start == 1 else atlas[..., c]
            for name, c in GRAD_CHANNELS.items()
        }
        n = self.settings["sky_resolution"]
        kg = self.net.sky(self.directions).numpy().reshape(6, n, n, 3)
        return Maps(**{name: np.ascontiguousarray(maps[name]) for name in ATLAS_MAPS}, kg=kg)

    # --- one iteration -------------------------------------------------------------------------
    def step(self) -> dict:
        s, it = self.settings, self.iteration
        clock = time.perf_counter()
        cameras = self.views.cameras
        total = len(self.views.pixels)
        requests = ray_batch(cameras, min(s["rays"], total), s["seed"], it)
        target = self.views.pixels[requests[:, 3]]
        self.renderer.set_maps(self.predict())
        t_predict = time.perf_counter()
        seed = iteration_seed(s["seed"], it)
        radiance, _, dropped = self.renderer.render_requests(cameras, requests, s["spp"], seed)
        loss, adjoint = image_loss(radiance, target, s["image_loss"], self.loss_epsilon)
        t_render = time.perf_counter()
        grads = backward(
            self.renderer, cameras, requests, s["alpha"] * adjoint, s["spp"], backward_seed(seed), s["accumulation"]
        )
        t_adjoint = time.perf_counter()
        stats = self._update(grads, it)
        t_update = time.perf_counter()
        self.iteration += 1
        self.wall_time += t_update - clock
        return {
            "iteration": self.iteration,
            "wall_time": self.wall_time,
            "loss": s["alpha"] * loss + sum(stats["terms"].values()),
            "image": loss,
            **{name: stats["terms"].get(name, 0.0) for name in PRIORS},
            "texels_touched": stats["touched"],
            "texels_with_grad": stats["with_grad"],
            "dropped_samples": dropped,
            "seconds_network": (t_predict - clock) + stats["seconds"],
            "seconds_render": t_render - t_predict,
            "seconds_adjoint": t_adjoint - t_render,
            "seconds_update": t_update - t_adjoint - stats["seconds"],
            "lr_mlp": self.optimisers[0].param_groups[0]["lr"],
            "lr_template": self.optimisers[-1].param_groups[0]["lr"] if len(self.optimisers) > 1 else 0.0,
        }

    def _update(self, grads: dict, iteration: int) -> dict:
        """The chain rule from dLoss/dmap into the network, the regularisers, one optimiser step."""
        t = self.texels
        atlas_grad = np.concatenate([grads[name].reshape(*t.shape, -1) for name in ATLAS_MAPS], -1)
        texel_grad = t.gather(atlas_grad)
        touched = np.flatnonzero(np.any(texel_grad != 0, axis=1))
        rng = np.random.default_rng([int(self.settings["seed"]), int(iteration), 1])
        share = max(1, round(self.settings["regularised_fraction"] * len(t)))
        regularised = np.sort(rng.choice(len(t), size=share, replace=False))
        rows = np.union1d(touched, regularised)
        clock = time.perf_counter()
        out = self.net.texel_surface(t, rows)
        surrogate = (out["maps"] * torch.from_numpy(texel_grad[rows].astype(np.float32))).sum()
        picked = np.searchsorted(rows, regularised)
        terms = self.net.regularisers({name: value[picked] for name, value in out.items()}, self.settings)
        sky_grad = torch.from_numpy(grads["kg"].reshape(-1, 3).astype(np.float32))
        surrogate = surrogate + (self.net.sky(self.directions) * sky_grad).sum()
        for optimiser in self.optimisers:
            optimiser.zero_grad(set_to_none=True)
        (surrogate + sum(terms.values())).backward()
        for optimiser, schedule in zip(self.optimisers, self.schedules):
            optimiser.step()
            schedule.step()
        return {
            "terms": {name: float(value.detach()) for name, value in terms.items()},
            "touched": len(touched),
            "with_grad": len(rows),
            "seconds": time.perf_counter() - clock,
        }

    # --- checkpoints ------------------------------------------------------------------------
    def state(self) -> dict:
        return {
            "iteration": self.iteration,
            "wall_time": self.wall_time,
            "network": self.net.state_dict(),
            "optimisers": [o.state_dict() for o in self.optimisers],
            "schedules": [s.state_dict() for s in self.schedules],
            "torch_rng": torch.get_rng_state(),
        }

    def restore(self, state: dict) -> None:
        self.net.load_state_dict(state["network"])
        for optimiser, saved in zip(self.optimisers, state["optimisers"]):
            optimiser.load_state_dict(saved)
        for schedule, saved in zip(self.schedules, state["schedules"]):
            schedule.load_state_dict(saved)
        torch.set_rng_state(state["torch_rng"])
        self.iteration, self.wall_time = int(state["iteration"]), float(state["wall_time"])
