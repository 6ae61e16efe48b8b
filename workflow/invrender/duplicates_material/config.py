"""The material stage's settings: two presets and a user's overrides on top (scene/settings.py).

`ci` recovers the demo's boxes (480 x 360) in seconds; `default` is sized for a photograph of a
few megapixels on a 2-core machine. Every regulariser has its weight here, beside why it is there.
"""

from __future__ import annotations

from ..scene.settings import resolve_preset
from ..scene.settings import settings_hash as _settings_hash
from ..scene.types import SceneError

SUPPORTS = ("plane", "none")
STARTS = ("photograph", "grey")
GROUNDS = ("lit", "free")

_COMMON = {
    # The scene
    "support": "plane",  # the table or floor as its own quad and material (support.py), or none
    "support_resolution": 128,  # texels along the support atlas' longer side
    "sky_resolution": 8,  # N of the recovered 6 x N x N kg
    # the sky below the support's horizon, which no pixel sees: "lit" (material.Ground: the light a
    # grey ground of albedo ground_albedo reflects under the recovered sky above it) or "free" (its
    # texels keep their start, the support's median radiance in the photograph)
    "ground": "lit",
    # 0.18: photography's middle grey, the average reflectance of a scene (a prior, not a measurement;
    # not fitted to the fixtures: docs/duplicates-material.md has 0.1 and 0.3 beside it)
    "ground_albedo": 0.18,
    # where the maps start: "photograph" (scene/first_guess.py: each texel's colour in the
    # photograph, under a white sky, what bake shows before this stage) or "grey" (kd 0.5 everywhere)
    "start": "photograph",
    # The estimator (render/, the MILO material model): exact visibility, shadows and inter-reflections
    "max_bounces": 2,
    "nee": True,  # next-event estimation: the sun-like peaks of an outdoor kg are found by light samples
    "accumulation": "auto",
    # Masked ray batches: object pixels (the masks of registered copies) and support pixels
    "rays": 8192,
    "spp": 4,
    "object_share": 0.5,  # of each batch drawn from object pixels (the support has far more pixels)
    "image_loss": "mse",  # render/losses.image_loss
    "loss_epsilon": 1.0,  # relative_mse's epsilon, times the photograph's median radiance
    # Adam on the texels' unconstrained values (sigmoid for kd, specular strength, roughness; exp for kg)
    "lr": 0.05,
    "lr_sky": 0.05,
    "decay": 0.3,  # both learning rates times this at 60 % of the iterations
    # Regularisers (each a mean, so a weight does not depend on the atlas size)
    # smoothness: texels near in 3D (across chart seams too) have similar materials; L1, the paper's
    # E_smooth, so the printed edges stay sharp while texels no copy shows take their neighbours' values
    "smoothness": 0.02,  # measured on box-10-ci: 0.002 16.0 dB at best, 0.02 16.9 dB (default, 150 iterations)
    "smoothness_radius": 1.5,  # texel spacings: which texels are neighbours
    # binary prior on the specular strength s (ks = 0.04 + 0.96 s): objects are dielectric or
    # metal-like, the paper's s (1 - s) on its metallic; stops a grey mix that fits the noise
    "binary": 0.01,
    # sparsity: mean s, so specular texels appear only where highlights ask for them (the role of
    # the paper's sparse latent KL: most of a common object is one dielectric material)
    "sparsity": 0.01,
    # sky smoothness: neighbouring kg texels have similar log radiance (L1, so a horizon and a sun stay
    # sharp); without it the directions the copies barely reflect fit the noise in any colour
    "sky_smoothness": 0.01,
    # energy bound kd + ks <= 1 (render/losses.energy_excess): the two lobes may not reflect more than arrives
    "energy": 1.0,
    "seed": 0,
    "checkpoint_every": 25,
    "snapshot_every": 25,
    "figure_spp": 16,  # the re-render beside the photograph in figure.png
}

PRESETS = {
    # every object pixel of the demo in each batch (0.6 x 8192 > its ~4000), a 4 x 4 sky per face
    "ci": {
        **_COMMON,
        "iterations": 40,
        "rays": 8192,
        "object_share": 0.6,
        "spp": 2,
        "sky_resolution": 4,
        "lr": 0.1,
        "smoothness": 0.05,  # box-10-ci, 40 iterations: 15.4 dB at 0.002, 15.8 at 0.02, 16.0 at 0.05
        "support_resolution": 64,
        "figure_spp": 8,
    },
    "default": {
        **_COMMON,
        "iterations": 300,
        "rays": 32768,
        "object_share": 0.6,
        "spp": 4,
        "sky_resolution": 8,
        "max_bounces": 3,
    },
}

# Settings that do not change what a run computes: a checkpoint made with other values still resumes.
_NOT_HASHED = {"checkpoint_every", "snapshot_every", "figure_spp"}


def resolve(preset: str, overrides: dict | None = None, where: str = "duplicates-material") -> dict:
    settings = resolve_preset(PRESETS, preset, overrides, where)
    _check(settings, where)
    return settings


def _check(s: dict, where: str) -> None:
    positive = ("iterations", "rays", "spp", "sky_resolution", "support_resolution", "checkpoint_every")
    for key in (*positive, "snapshot_every", "figure_spp"):
        if s[key] < 1:
            raise SceneError(where, key, f"a positive integer, got {s[key]!r}")
    if s["support"] not in SUPPORTS:
        raise SceneError(where, "support", f"one of {', '.join(SUPPORTS)}, got {s['support']!r}")
    if s["start"] not in STARTS:
        raise SceneError(where, "start", f"one of {', '.join(STARTS)}, got {s['start']!r}")
    if s["ground"] not in GROUNDS:
        raise SceneError(where, "ground", f"one of {', '.join(GROUNDS)}, got {s['ground']!r}")
    if not 0 <= s["ground_albedo"] <= 1:
        raise SceneError(where, "ground_albedo", f"an albedo in [0, 1], got {s['ground_albedo']}")
    if not 0 < s["object_share"] <= 1:
        raise SceneError(where, "object_share", f"a fraction in (0, 1], got {s['object_share']}")
    for key in ("smoothness", "binary", "sparsity", "energy", "sky_smoothness"):
        if s[key] < 0:
            raise SceneError(where, key, f"a weight >= 0, got {s[key]}")


def settings_hash(settings: dict) -> str:
    return _settings_hash(settings, _NOT_HASHED)
