"""The sweeps' sizes: `quick` runs in CI in tens of seconds on the demo room (96 x 72) and still
draws every plot; `full` is the benchmark behind the README's figures (minutes)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Budget:
    name: str
    spp: tuple[int, ...]  # the default configuration's ladder (the configured spp joins it)
    variant_spp: tuple[int, ...]  # each other configuration's ladder: enough to see a floor
    bounces: tuple[int, ...]  # bounce limits swept (at most the reference's)
    reference_bounces: int  # the reference's path length: bias of shorter paths shows against it
    reference_spp: int  # samples per pixel of the converged reference (two halves)
    scales: tuple[int, ...]  # image resolution divided by these (1: the camera's own)
    max_width: int  # the camera scaled down to at most this width (keeps a big photograph cheap)
    gradient_rays: int  # rays in the gradient sweep's batch
    gradient_spp: tuple[int, ...]
    gradient_reference_spp: int
    gradient_bounces: tuple[int, ...]
    gradient_variant_spp: int  # spp of the bounce variants' gradient passes


QUICK = Budget(
    name="quick",
    spp=(1, 2, 4, 8, 16, 32, 64),
    variant_spp=(8, 64),
    bounces=(1, 3),
    reference_bounces=10,
    reference_spp=512,
    scales=(2,),
    max_width=48,
    gradient_rays=2048,
    gradient_spp=(1, 2, 4, 8),
    gradient_reference_spp=128,
    gradient_bounces=(1,),
    gradient_variant_spp=8,
)

FULL = Budget(
    name="full",
    spp=(1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024),
    variant_spp=(16, 128),
    bounces=(1, 2, 3, 5, 7),
    reference_bounces=10,
    reference_spp=4096,
    scales=(4, 2),
    max_width=96,
    gradient_rays=4096,
    gradient_spp=(1, 2, 4, 8, 16, 32, 64),
    gradient_reference_spp=1024,
    gradient_bounces=(1, 2, 3, 5, 10),
    gradient_variant_spp=64,
)

BUDGETS = {budget.name: budget for budget in (QUICK, FULL)}
