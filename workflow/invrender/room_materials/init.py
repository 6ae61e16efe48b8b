"""The material initialisation (PSDR-Room section 4.4, "Material initialization and search").

Homogeneous albedo: the paper initialises it to the median colour of the part's mask
intersection (of the whole segment without one). A photo's colour is albedo times shading, so
here the median is taken of the photo divided by the shading: a render of the scene under the
initial lights with the current albedos, divided by each pixel's albedo, is the irradiance
factor E / pi a diffuse albedo multiplies. Interreflections depend on the albedos, so this is
iterated (the albedos of the last pass light the next one); two passes move the albedos by less
than the noise on the rooms measured (docs/room-materials.md).

Procedural retrieval: each part's photo crops go through the library's retrieval
(materials/retrieval.py: texture descriptor + transform search over scales 0.5-8 and rotations
-45, 0, 45, 90, the plain preset competing); the preset of least mean distance over the part's
crops wins (the paper's vote over crops); plain keeps the part homogeneous. The winner's texture
parameters are fitted to the largest crop (materials/fit.py: Gram loss + mean colour) with the
light divided out as `gain`: the crop's mean photo colour over the homogeneous albedo.
"""

from __future__ import annotations

import logging

import cv2
import numpy as np
import torch

from ..materials.base import Transform
from ..materials.fit import fit
from ..materials.library import PRESETS
from ..materials.library import preset as library_preset
from ..materials.retrieval import retrieve
from ..render.renderer import Renderer, pixel_requests
from .model import PartMaterial, RoomModel

__all__ = ["plain", "seen_radiance", "shading_albedo", "retrieve_part"]

MIN_LIGHT_PIXELS = 4  # a light seen in fewer (eroded) photo pixels keeps the light stage's radiance

log = logging.getLogger(__name__)

ALBEDO_RANGE = (0.01, 0.9)  # the plain material's colour bounds (materials/plain.py)


def plain(colour) -> PartMaterial:
    c = np.clip(np.asarray(colour, np.float64), *ALBEDO_RANGE)
    return PartMaterial("plain", {"colour": torch.tensor(c, dtype=torch.float32)}, preset="plain_grey")


def seen_radiance(photo: np.ndarray, light_ids: np.ndarray, radiance: np.ndarray, colour: str = "grey") -> np.ndarray:
    """Each light seen in the photo: its radiance is what the photo shows there (the median over
    its pixels, one pixel in from its outline; grey: the mean of the channels). The light
    stage's guess is one uniform radiance for all; an emitter in view measures its own, and
    starting Eq. 4 there spares the alternation its slowest direction (all albedos up, all
    lights down: on the test room, 4 rounds from a uniform guess 3 to 4.5 times too dark left
    the walls 0.89 for a true 0.70)."""
    out = np.array(radiance, np.float64, copy=True)
    for j in range(len(out)):
        mask = cv2.erode((light_ids == j).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        if mask.sum() >= MIN_LIGHT_PIXELS:
            value = np.median(photo[mask], axis=0)
            out[j] = value.mean() if colour == "grey" else value
    return out


def shading_albedo(
    renderer: Renderer,
    model: RoomModel,
    radiance,
    camera,
    photo_small: np.ndarray,
    masks: np.ndarray,
    fallback: np.ndarray,
    spp: int = 32,
    passes: int = 2,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Per part, the median over its mask (``masks`` (parts, h, w) at ``camera``) of the photo
    divided by the shading, every part plain; ``fallback`` (parts, 3) for a part without pixels
    there. Returns the albedos (parts, 3) and the last pass's shading image (h, w, 3)."""
    albedo = np.full((len(model.parts), 3), 0.5)
    requests = pixel_requests(camera)
    shading = np.zeros_like(photo_small)
    for p in range(passes):
        materials = [plain(a) for a in albedo]
        renderer.set_maps(model.maps(materials, radiance))
        mean, _, _ = renderer.render_requests([camera], requests, spp, seed + 31 * p)
        render = mean.reshape(photo_small.shape)
        new = albedo.copy()
        for i in range(len(model.parts)):
            m = masks[i]
            if not m.any():
                continue
            shading_i = render[m] / albedo[i]
            shading[m] = shading_i
            # The median colour over the median shading: a ratio of the two robust centres,
            # not the median of per-pixel ratios, whose Monte Carlo noise in the denominator
            # biases it upwards (E[1/S] > 1/E[S]).
            new[i] = np.median(photo_small[m], axis=0) / np.maximum(np.median(shading_i, axis=0), 1e-6)
        for i in range(len(model.parts)):
            if not masks[i].any():
                new[i] = fallback[i]
        albedo = np.clip(new, *ALBEDO_RANGE)
    return albedo, shading


def retrieve_part(crops: list[np.ndarray], albedo: np.ndarray, crop_meters: float, fit_steps: int = 40, net=None):
    """A part's material from its photo crops (each (h, w, 3) linear), its homogeneous albedo
    (the light divided out of the fit) and the largest crop's width in meters. Returns
    (PartMaterial or None for homogeneous, the ranking: preset -> mean distance, the best
    transform's dict)."""
    distances: dict[str, list[float]] = {}
    transforms: dict[str, list[Transform]] = {}
    for crop in crops:
        for match in retrieve(crop, PRESETS, net=net):
            distances.setdefault(match.preset.name, []).append(match.distance)
            transforms.setdefault(match.preset.name, []).append(match.transform)
    ranking = {name: float(np.mean(d)) for name, d in distances.items()}
    best = min(ranking, key=ranking.get)
    if library_preset(best).material == "plain":
        return None, ranking, None
    largest = max(range(len(crops)), key=lambda k: crops[k].shape[0] * crops[k].shape[1])
    crop = crops[largest]
    transform = transforms[best][largest]
    gain = np.maximum(crop.reshape(-1, 3).mean(0) / np.maximum(albedo, 1e-3), 1e-4)
    chosen = library_preset(best)
    result = fit(chosen.type, chosen.params(), transform, crop, steps=fit_steps, gain=gain.astype(np.float32), net=net)
    material = PartMaterial(chosen.material, result.params, result.transform, crop_meters, preset=best)
    return material, ranking, result.transform.as_dict()
