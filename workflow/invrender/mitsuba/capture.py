"""Captures rendered by Mitsuba 3: benchmark inputs that our own kernels did not make.

A recovery scored on captures of its own renderer shares that renderer's bias and noise with
them; rendered by Mitsuba (its own integrator and sampling, the `milo` BSDF plugin of our model),
a capture is what another renderer makes of the same room. Only the radiance comes from Mitsuba:
the instance ids (ground_truth/masks) are geometry, read from our renderer's AOVs.

`MitsubaCapture` has the interface `synthesize.capture.write_capture` asks of a renderer.
"""

from __future__ import annotations

import numpy as np

from ..render.features import Features
from ..render.renderer import Renderer
from ..scene.types import Camera, Scene
from .scene import render_mitsuba
from .variant import DEFAULT_VARIANT

CAPTURE_BOUNCES = 8  # a capture's light transport is not truncated where training's is (3 to 10)


class MitsubaCapture:
    """Renders each view's radiance with Mitsuba and its instance ids with our renderer."""

    def __init__(self, scene: Scene, max_bounces: int = CAPTURE_BOUNCES, device: str | None = None):
        self.scene, self.max_bounces = scene, int(max_bounces)
        self.names = [camera.name for camera in scene.cameras]
        self.geometry = Renderer(scene, Features(max_bounces=1), device=device)

    def render(self, camera: Camera, spp: int, seed: int = 0) -> dict[str, np.ndarray]:
        # Mitsuba keys its samples by the seed alone: each view gets its own.
        view_seed = (int(seed) * 1_000_003 + self.names.index(camera.name)) % 2**32
        radiance = render_mitsuba(self.scene, camera, self.max_bounces, spp, DEFAULT_VARIANT, view_seed)
        ids = self.geometry.render(camera, spp=1, seed=0, aovs=True)["instance_id"]
        return {"radiance": radiance, "instance_id": ids}


def mitsuba_capture(scene: Scene, device: str | None = None) -> MitsubaCapture:
    """The `renderer_factory` of synthesize.run for a Mitsuba-rendered capture."""
    return MitsubaCapture(scene, device=device)
