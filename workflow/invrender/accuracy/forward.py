"""Forward rendering: each knob against a converged reference of the same view.

The reference is the configured features with paths of ``reference_bounces`` at
``reference_spp``, rendered as two independent halves; every other image is compared with it.
A shorter path limit or an effect switched off changes the image itself, and so its error
stops falling with spp at a floor: the bias, which ``bias_rmse`` estimates by removing both
images' noise from their squared difference (``render.measure.agreement``'s pixel excess).
"""

from __future__ import annotations

import logging
import math
from dataclasses import asdict, dataclass, replace

import numpy as np

from ..render.analysis import preview_camera
from ..render.device import choose_device, describe
from ..render.features import COMPILED_IN_OFF, Features
from ..render.measure import agreement, clock, quiet_pyopencl
from ..render.renderer import Renderer
from ..render.scene_buffers import HostScene
from ..render.tuning import choose_strategy_weights

log = logging.getLogger(__name__)

REL_EPSILON = 1e-2  # relative MSE's epsilon: (x - ref)^2 / (ref^2 + eps), as Rousselle et al.
REFERENCE_SEED = 1 << 40  # the reference's samples are no measured render's


def measured_seed(seed: int, k: int) -> int:
    """The seed of the k-th measured render of a sweep run with ``seed``: never a small number,
    which a synthetic capture's own renders use (a render could then equal the capture)."""
    return (1 << 33) + int(seed) * 1_000_003 + int(k)


FEATURE_KNOBS = (
    "max_bounces",
    "specular",
    "emission",
    "emitter_sampling",
    "environment",
    "window",
    "env_sampling",
    "nee",
    "roulette_depth",
)


@dataclass(frozen=True)
class Variant:
    """One configuration of the forward renderer, rendered at several spp."""

    sweep: str  # spp, bounces, effect, estimator, resolution
    label: str
    features: Features
    scale: int = 1  # the image's width and height divided by this
    cause: str | None = None  # what a floor in its curve means (None: no bias expected)
    pasteable: bool = True  # expressible in the config (resolution is the capture's, not a key)


def variants(features: Features, budget, scene=None, device=None) -> list[Variant]:
    """The default, each bounce limit below the reference's, each effect `features` has switched
    off (render.features.COMPILED_IN_OFF: the same switches its effects table measures), the other
    estimator (NEE against MILO's mixture, its weights from its own pilot) and each lower
    resolution. The default comes first."""
    limited = features.max_bounces < budget.reference_bounces
    cause = f"bounce limit: the configured max_bounces {features.max_bounces}" if limited else None
    out = [Variant("spp", "default", features, cause=cause)]
    for bounces in budget.bounces:
        if bounces != features.max_bounces:
            cause = (
                f"bounce limit: paths cut after {bounces} bounce{'s' * (bounces > 1)} "
                f"(the reference runs {budget.reference_bounces})"
            )
            out.append(Variant("bounces", f"{bounces} bounces", features.with_bounces(bounces), cause=cause))
    for name, kind, flags, applies in COMPILED_IN_OFF:
        if applies(features):
            cause = f"effect switched off: {name}" if kind == "bias" else None
            out.append(Variant("effect", name, replace(features, **flags), cause=cause))
    other = replace(features, nee=not features.nee)
    if scene is not None:
        other, _ = choose_strategy_weights(scene, other, device)
    out.append(Variant("estimator", "NEE" if other.nee else "MILO mixture (nee off)", other))
    for scale in budget.scales:
        cause = f"resolution: 1/{scale} of the pixels in each direction, upsampled (detail lost)"
        out.append(Variant("resolution", f"1/{scale} resolution", features, scale=scale, cause=cause, pasteable=False))
    return out


def image_errors(image, variance, reference, reference_variance) -> dict:
    """RMSE and relative MSE against the reference with the reference's own noise taken out
    (its variance of the mean subtracted from the squared difference), and the bias: what is
    left of the squared difference once both images' noise is taken out."""
    image, reference = np.asarray(image, np.float64), np.asarray(reference, np.float64)
    d2 = (image - reference) ** 2
    weight = 1.0 / (reference**2 + REL_EPSILON)
    mse = max(float(np.mean(d2 - reference_variance)), 1e-30)
    rel_mse = max(float(np.mean((d2 - reference_variance) * weight)), 1e-30)
    check = agreement(image, reference, float(np.mean(variance)), float(np.mean(reference_variance)))
    return {
        "rmse": math.sqrt(mse),
        "rel_mse": rel_mse,
        "noise_rmse": math.sqrt(float(np.mean(variance))),
        "bias_rmse": check["pixel_excess_rmse"],
        "mean_rel_diff": check["mean_rel_diff"],
    }


def upsample(image: np.ndarray, scale: int, shape) -> np.ndarray:
    """Each pixel repeated scale x scale times, cropped to ``shape`` (H, W)."""
    big = np.repeat(np.repeat(image, scale, axis=0), scale, axis=1)
    return big[: shape[0], : shape[1]]


class ForwardSweep:
    """One view of the scene (its camera scaled to the budget's width), its converged
    reference, and the renders measured against it."""

    def __init__(self, scene, features: Features, camera, budget, device=None):
        quiet_pyopencl()
        self.scene, self.features, self.budget, self.device = scene, features, budget, device
        self.camera = preview_camera(camera, budget.max_width)
        self.device_name = describe(choose_device(device))
        self.host = HostScene.pack(scene.mesh, scene.maps)  # one BVH and one upload for every kernel
        self._renderers = {}
        bounces = max(budget.reference_bounces, features.max_bounces)
        self.reference_features = features.with_bounces(bounces)
        halves = [self._render(self.reference_features, budget.reference_spp // 2, REFERENCE_SEED + k) for k in (0, 1)]
        (a, seconds_a), (b, seconds_b) = halves
        self.reference = (a["radiance"].astype(np.float64) + b["radiance"]) / 2
        self.reference_variance = (a["variance"].astype(np.float64) + b["variance"]) / 4
        self.reference_seconds = seconds_a + seconds_b

    def renderer(self, features: Features) -> Renderer:
        """A renderer per feature set, warmed by one launch (the build and the first launch are
        not the configuration's time per image)."""
        if features not in self._renderers:
            renderer = Renderer(self.scene, features, self.device, host_scene=self.host)
            renderer.render(self.camera, 1, 0, aovs=False)
            self._renderers[features] = renderer
        return self._renderers[features]

    def _render(self, features: Features, spp: int, seed: int, camera=None):
        camera = camera or self.camera
        out, seconds, _ = clock(self.renderer(features).render, camera, max(int(spp), 1), seed, aovs=False)
        return out, seconds

    def measure(self, variant: Variant, spp: int, seed: int) -> dict:
        """One render of ``variant`` at ``spp``: its knobs, its errors, its time."""
        camera = self.camera
        if variant.scale > 1:
            camera = preview_camera(self.camera, self.camera.width // variant.scale)
        out, seconds = self._render(variant.features, spp, seed, camera)
        image, variance = out["radiance"], out["variance"]
        if variant.scale > 1:
            shape = self.reference.shape[:2]
            image, variance = upsample(image, variant.scale, shape), upsample(variance, variant.scale, shape)
        f = variant.features
        return {
            "family": "forward",
            "sweep": variant.sweep,
            "label": variant.label,
            "spp": int(spp),
            **{knob: getattr(f, knob) for knob in FEATURE_KNOBS},
            "width": camera.width,
            "height": camera.height,
            **image_errors(image, variance, self.reference, self.reference_variance),
            "time_s": seconds,
            "samples_per_s": camera.width * camera.height * spp / seconds,
            "seed": int(seed),
            "device": self.device_name,
            "cause": variant.cause,
            "pasteable": variant.pasteable,
        }


def ladder(variant: Variant, budget, default_spp: int) -> tuple[int, ...]:
    """The default's ladder holds the configured spp; every other configuration a short one."""
    if variant.sweep == "spp":
        return tuple(sorted(set(budget.spp) | {int(default_spp)}))
    return budget.variant_spp


def sweep(sweep: ForwardSweep, default_spp: int, seed: int, progress=None) -> list[dict]:
    """Every variant at every spp of its ladder; seeds differ from render to render."""
    rows = []
    all_variants = variants(sweep.features, sweep.budget, sweep.scene, sweep.device)
    jobs = [(v, spp) for v in all_variants for spp in ladder(v, sweep.budget, default_spp)]
    for k, (variant, spp) in enumerate(progress(jobs) if progress else jobs):
        row = sweep.measure(variant, spp, measured_seed(seed, k))
        row["default"] = variant.sweep == "spp" and spp == default_spp
        row["features"] = asdict(variant.features)
        rows.append(row)
    log.info(
        "accuracy: %d forward renders of %s at %d x %d",
        len(rows),
        sweep.camera.name,
        sweep.camera.width,
        sweep.camera.height,
    )
    return rows
