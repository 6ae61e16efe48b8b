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

__all__ = [
    "plain",
    "seen_radiance",
    "shading_albedo",
    "retrieve_part",
    "tied_parts",
    "tied_albedo",
    "pooled_parts",
    "damped",
]

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


def damped(albedo, value) -> np.ndarray:
    """The closed-form step halfway (geometrically) from ``albedo`` to ``value``.

    The step a <- P / S(a) is a fixed-point iteration whose slope at the fixed point is
    -m, m = (a k) / (1 - a k) with a k the share of the part's irradiance it sends itself by
    interreflection: past one half (m > 1) it oscillates away from the truth. The pooled walls
    of a closed room in red (walls 0.70, ceiling 0.80) are past it: undamped, the stage test's
    walls went to 0.51 in red in 4 rounds and 0.48 in 12 for a true 0.70 (green and blue
    above the truth), the "red drift" of the first version. Halfway, the slope is
    (1 - m) / 2: stable up to m = 3 (a k = 0.75), still fast where m is small."""
    return np.sqrt(np.maximum(np.asarray(albedo, np.float64), 1e-6) * np.maximum(value, 1e-6))


def tied_parts(parts, masks: np.ndarray, coloured) -> dict[int, list[int]]:
    """The parts the reduced render does not show (no pixel in their mask), each with the seen
    parts whose shading stands in for its own: those sharing one of its photo segments (an
    unseen wall: the seen walls, one class in the segmentation; an object's part too small at
    1/8: the object's other parts), else every seen part. A part without any photo colour
    (``coloured`` false: no intersection and no segment) follows none and keeps its start.

    Such a part's albedo is seen by the photo only through interreflections, which also absorb
    every light the scene cannot represent (the truth's sun, warm lamps, panels without
    geometry): left free, Eq. 4 made the bedroom's two unseen walls 0.23/0.14/0.08 for a true
    0.62/0.63/0.60 (docs/room-materials.md). Tied, it is the paper's initialisation (the median
    colour of the whole segment) made an albedo by the seen parts' shading."""
    seen = [i for i in range(len(parts)) if masks[i].any()]
    out = {}
    for i, part in enumerate(parts):
        if masks[i].any():
            continue
        if not coloured[i]:
            out[i] = []
            continue
        sharing = [j for j in seen if set(parts[j].segments) & set(part.segments)]
        out[i] = sharing or seen
    return out


def pooled_parts(parts, masks: np.ndarray) -> dict[int, list[int]]:
    """Each seen box surface with the seen box surfaces showing in the same photo segments (the
    walls: one class, one segmentation label): one paint, so one homogeneous albedo fitted over
    all their pixels. Fitted one by one, each wall takes up its own share of the lights' wrong
    placement (on the test room under lights the scene lacks: 0.46, 0.65 and 0.41 in red for one
    true 0.70)."""
    out = {}
    for i, part in enumerate(parts):
        if part.plane is None or not masks[i].any() or not part.segments:
            continue
        out[i] = [
            j
            for j, other in enumerate(parts)
            if other.plane is not None and masks[j].any() and set(other.segments) == set(part.segments)
        ]
    return out


def tied_albedo(colour, photo: np.ndarray, shading: np.ndarray, masks: np.ndarray, tied: list[int]):
    """An unseen part's albedo: the albedo of the pixels of the parts it follows (tied_parts)
    taken together, sum photo / sum shading (shading = render / albedo, (h, w, 3): the sums are
    unbiased under Monte Carlo noise), times its median photo colour over theirs (1 for an
    unseen wall, whose colour is the whole wall segment's; an object's small part keeps its
    own colour against the object's). None when it follows none."""
    if not tied:
        return None
    pixels = np.any(masks[tied], axis=0)
    together = photo[pixels].sum(0) / np.maximum(shading[pixels].sum(0), 1e-12)
    relative = np.asarray(colour, np.float64) / np.maximum(np.median(photo[pixels], axis=0), 1e-6)
    return np.clip(together * relative, *ALBEDO_RANGE)


def shading_albedo(
    renderer: Renderer,
    model: RoomModel,
    radiance,
    camera,
    photo_small: np.ndarray,
    masks: np.ndarray,
    medians: np.ndarray,
    ties: dict[int, list[int]] | None = None,
    spp: int = 32,
    passes: int = 2,
    seed: int = 0,
    start: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Per part, the median over its mask (``masks`` (parts, h, w) at ``camera``) of the photo
    divided by the shading, every part plain; a part without pixels there (``ties``, from
    tied_parts) its median colour ``medians`` (parts, 3) over its tied parts' shading (tied_albedo),
    or ``start`` (parts, 3; default grey) when it follows none. Returns the albedos (parts, 3)
    and the last pass's shading image (h, w, 3)."""
    albedo = np.full((len(model.parts), 3), 0.5) if start is None else np.array(start, np.float64)
    ties = tied_parts(model.parts, masks, [True] * len(model.parts)) if ties is None else ties
    pools = pooled_parts(model.parts, masks)
    requests = pixel_requests(camera)
    shading = np.zeros_like(photo_small)
    for p in range(passes):
        materials = [plain(a) for a in albedo]
        renderer.set_maps(model.maps(materials, radiance))
        mean, _, _ = renderer.render_requests([camera], requests, spp, seed + 31 * p)
        render = mean.reshape(photo_small.shape)
        new = albedo.copy()
        for i in range(len(model.parts)):
            if masks[i].any():
                shading[masks[i]] = render[masks[i]] / albedo[i]
        for i in range(len(model.parts)):
            if not masks[i].any():
                continue
            m = np.any(masks[pools.get(i, [i])], axis=0)
            # The median colour over the median shading: a ratio of the two robust centres,
            # not the median of per-pixel ratios, whose Monte Carlo noise in the denominator
            # biases it upwards (E[1/S] > 1/E[S]).
            new[i] = np.median(photo_small[m], axis=0) / np.maximum(np.median(shading[m], axis=0), 1e-6)
        for i, tied in ties.items():
            value = tied_albedo(medians[i], photo_small, shading, masks, tied)
            if value is not None:
                new[i] = value
        # The first pass from grey is the estimate; the next ones are the fixed-point steps
        # of Eq. 4's closed form, damped alike (from wrong lights, undamped, the stage test's
        # walls went 0.90 -> 0.51 -> 0.51 in red over passes 1, 2 and 4 for a true 0.70).
        albedo = np.clip(new if p == 0 else damped(albedo, new), *ALBEDO_RANGE)
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
