"""The loop: per iteration a masked ray batch, the path tracer's estimate of it with the current
maps, the adjoint's dLoss/dmap for kd, ks, ka and kg, the chain rule into the texels' values and
one Adam step. Every random draw is keyed by (seed, iteration) (render/batches.py), the adjoint
accumulates in fixed point and torch runs deterministically, so a run resumed at iteration k
computes what an uninterrupted one does.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import torch

from ..render.adjoint import backward, backward_seed
from ..render.batches import iteration_seed
from ..render.losses import image_loss
from ..render.renderer import Renderer
from ..scene.packing import Packing
from ..scene.types import ATLAS_MAPS, Camera, Maps
from .material import TexelMaterial
from .rays import RayPools

REGULARISERS = ("smoothness", "binary", "sparsity", "energy", "sky_smoothness")
LOG_COLUMNS = (
    "iteration",
    "wall_time",
    "loss",
    "image",
    *REGULARISERS,
    "rays_object",
    "rays_support",
    "dropped_samples",
    "seconds_render",
    "seconds_adjoint",
    "seconds_update",
    "lr",
)
DECAY_AT = 0.6  # fraction of the iterations after which both learning rates drop


@dataclass
class Training:
    settings: dict
    material: TexelMaterial
    renderer: Renderer
    packing: Packing
    cameras: list[Camera]
    pools: RayPools
    loss_epsilon: float
    iteration: int = 0
    wall_time: float = 0.0
    optimiser: torch.optim.Optimizer = field(init=False)
    schedule: object = field(init=False)

    def __post_init__(self):
        s = self.settings
        texels = [p for name, p in self.material.named_parameters() if name != "sky"]
        self.optimiser = torch.optim.Adam(
            [{"params": texels, "lr": s["lr"]}, {"params": [self.material.sky], "lr": s["lr_sky"]}]
        )
        milestone = max(1, round(DECAY_AT * s["iterations"]))
        self.schedule = torch.optim.lr_scheduler.MultiStepLR(self.optimiser, [milestone], gamma=s["decay"])

    def packed_maps(self) -> Maps:
        """The renderer's maps: every set's atlas packed as the scene's objects read them."""
        atlas = self.packing.pack_atlas(self.material.atlases())
        return Maps(**{m: getattr(atlas, m) for m in ATLAS_MAPS}, kg=self.material.sky_map())

    def step(self) -> dict:
        s, it = self.settings, self.iteration
        clock = time.perf_counter()
        requests, target, n_object = self.pools.batch(s["rays"], s["object_share"], s["seed"], it)
        self.renderer.set_maps(self.packed_maps())
        seed = iteration_seed(s["seed"], it)
        radiance, _, dropped = self.renderer.render_requests(self.cameras, requests, s["spp"], seed)
        loss, adjoint = image_loss(radiance, target, s["image_loss"], self.loss_epsilon)
        t_render = time.perf_counter()
        grads = backward(
            self.renderer,
            self.cameras,
            requests,
            adjoint,
            s["spp"],
            backward_seed(seed),
            s["accumulation"],
            maps=("kd", "ks", "ka", "kg"),
        )
        t_adjoint = time.perf_counter()
        unused = {"ke": np.zeros_like(grads["kd"]), "kw": np.zeros_like(grads["ka"])}  # not optimised
        per_set = self.packing.unpack_atlas({**grads, **unused})
        terms = self.material.regularisers(s)
        self.optimiser.zero_grad(set_to_none=True)
        (self.material.surrogate(per_set, grads["kg"]) + sum(terms.values())).backward()
        self.optimiser.step()
        self.schedule.step()
        t_update = time.perf_counter()
        self.iteration += 1
        self.wall_time += t_update - clock
        return {
            "iteration": self.iteration,
            "wall_time": self.wall_time,
            "loss": loss + sum(float(t.detach()) for t in terms.values()),
            "image": loss,
            **{name: float(terms[name].detach()) for name in REGULARISERS},
            "rays_object": n_object,
            "rays_support": len(requests) - n_object,
            "dropped_samples": dropped,
            "seconds_render": t_render - clock,
            "seconds_adjoint": t_adjoint - t_render,
            "seconds_update": t_update - t_adjoint,
            "lr": self.optimiser.param_groups[0]["lr"],
        }

    def state(self) -> dict:
        return {
            "iteration": self.iteration,
            "wall_time": self.wall_time,
            "material": self.material.state_dict(),
            "optimiser": self.optimiser.state_dict(),
            "schedule": self.schedule.state_dict(),
        }

    def restore(self, state: dict) -> None:
        self.material.load_state_dict(state["material"])
        self.optimiser.load_state_dict(state["optimiser"])
        self.schedule.load_state_dict(state["schedule"])
        self.iteration, self.wall_time = int(state["iteration"]), float(state["wall_time"])
