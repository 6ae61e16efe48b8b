"""Training settings: three presets, a user's overrides on top, and the hash that ties a
checkpoint to the settings it was made with.

`paper` is section 3.5 as written (three 16-layer 1024-wide MLPs, 2000 iterations of 65,536
rays at 256 spp and 10 bounces: hours on two GPUs); `cpu` is sized for a 2-core machine and the
benchmark room; `demo` trains the embedded demo room in about a minute; `texels` optimises the
maps directly, without a network (texel_model.py), at the demo's sizes. `template: false` is the
ablation of Fig. 12: two plain MLPs, no template, no category or texture loss.
"""

from __future__ import annotations

from ..scene.settings import resolve_preset
from ..scene.settings import settings_hash as _settings_hash
from ..scene.types import SceneError

MODELS = ("network", "texels")
_COMMON = {
    # What is optimised: MILO-Net ("network"), or the atlas maps texel by texel ("texels",
    # texel_model.py: no network, smoothness priors; the settings below it marked "texels")
    "model": "network",
    "lr_texels": 0.05,  # texels: Adam's step on the maps' logits
    "smoothness": 0.1,  # texels: L1 between neighbouring texels of the same kind
    "smoothness_radius": 1.5,  # texels: neighbours within this many texel spacings in 3D
    "sky_smoothness": 0.01,  # texels: L1 in log radiance between neighbouring sky texels
    "specular_prior": 0.01,  # texels: L1 of ks from a dielectric's 0.04
    "reflectance_passes": 4,  # texels: kd corrected by captured / rendered radiance first (reflectance.py)
    "reflectance_spp": 64,  # texels: samples per pixel of those renders
    "reflectance_radius": 3.0,  # texels: the correction averaged within this many texel spacings
    "windows": True,  # texels: windows found in the photographs (window.py) show the sky, kw = 1
    "template": True,  # MILO-Net's material template (False: Fig. 12's plain MLPs)
    "materials": 64,  # Q, the template's materials
    "emitters": 1,  # S, its light-emitting materials (one window material besides)
    "texture_importance": True,  # strategy 4 also samples texels by their observed brightness
    # The estimator: MILO's one-sample mixture (its strategy 4 then also draws the light that
    # brightly lit walls reflect, section 3.5), or next-event estimation (whose light sample
    # collects only the emission of what it meets). The paper's, as the numbers in docs/milo.md.
    "nee": False,
    "hard_materials": True,  # render each texel's most probable material (network.hard_through)
    "warm_start_steps": 200,  # MLP 1 fitted to the photographs' brightest texels first (importance.py)
    "warm_start_fraction": 0.3,  # texels seen brighter than this fraction of the brightest start emitting
    "levels_coarse": 10,  # L of gamma_c (MLP 1, the material probabilities)
    "levels_fine": 12,  # L of gamma_f (MLP 2, the detail texture)
    "levels_sky": 6,  # L of the sky directions' encoding (MLP 3)
    "leaky_slope": 0.01,
    "lr_mlp": 1e-3,  # AMSGrad
    "lr_template": 0.1,  # SGD with Nesterov momentum (the paper's 0.01 was for summed losses, docs/milo.md)
    "momentum": 0.9,
    "decay": 0.3,  # both learning rates times this ...
    "decay_at": [0.2, 0.4],  # ... at these fractions of the iterations
    "image_loss": "mse",  # losses.image_loss: relative_mse, mse, or norm (Eq. 5 as written)
    "loss_epsilon": 1.0,  # relative_mse's epsilon, times the capture's median radiance
    "alpha": 1.0,  # Eq. 11: image
    "beta": 0.003,  # category
    "theta": 0.01,  # texture
    "zeta": 0.1,  # value
    "l2": 1e-6,  # weight decay of MLP 1 (reflectance similarity)
    "regularised_fraction": 0.083,  # texels whose regularisers enter each iteration (the paper's 8.3 %)
    "sky_resolution": 16,  # N of the recovered 6 x N x N kg
    "accumulation": "auto",  # the adjoint's: fixed (bitwise reproducible) where the device can
    "seed": 0,
    "checkpoint_every": 50,
    "snapshot_every": 50,  # maps saved for evaluate's accuracy-against-time curve
    "holdout": [],  # camera names kept out of training (evaluate's novel views)
}

PRESETS = {
    "paper": {
        **_COMMON,
        "layers": 16,
        "width": 1024,
        "skip_layers": 8,
        "iterations": 2000,
        "rays": 65536,
        "spp": 256,
        "max_bounces": 10,
    },
    "cpu": {
        **_COMMON,
        "materials": 16,
        "layers": 4,
        "width": 128,
        "skip_layers": 2,
        "iterations": 300,
        "rays": 16384,
        "spp": 8,
        "max_bounces": 3,
        "checkpoint_every": 50,
        "snapshot_every": 100,
    },
    "demo": {
        **_COMMON,
        "materials": 8,
        "layers": 3,
        "width": 64,
        "skip_layers": 1,
        "iterations": 300,
        "rays": 8192,
        "spp": 4,
        "max_bounces": 3,
        "checkpoint_every": 50,
        "snapshot_every": 50,
    },
}
# The atlas maps optimised texel by texel (texel_model.py) from the per-texel guess corrected by
# light transport (reflectance.py): it scores better than MILO-Net on every measured room in a
# fraction of its time (docs/milo.md, "The texels model").
PRESETS["texels"] = {
    **PRESETS["demo"],
    "model": "texels",
    "iterations": 40,
    "max_bounces": 10,  # the capture's light after 3 bounces is missing from a closed pale room (docs/milo.md)
    "snapshot_every": 10,
    "checkpoint_every": 20,
}

# Settings that do not change what a run computes: a checkpoint made with other values of these
# still resumes.
_NOT_HASHED = {"checkpoint_every", "snapshot_every"}


def resolve(preset: str, overrides: dict | None = None, where: str = "milo") -> dict:
    """The preset's settings with `overrides` on top (scene/settings.py), checked."""
    settings = resolve_preset(PRESETS, preset, overrides, where)
    _check(settings, where)
    return settings


def _check(s: dict, where: str) -> None:
    positive = (
        "layers",
        "width",
        "iterations",
        "rays",
        "spp",
        "max_bounces",
        "materials",
        "checkpoint_every",
        "snapshot_every",
    )
    for key in positive:
        if s[key] < 1:
            raise SceneError(where, key, f"a positive integer, got {s[key]!r}")
    for key, low in (("reflectance_passes", 0), ("reflectance_spp", 1), ("reflectance_radius", 0)):
        if s[key] < low:
            raise SceneError(where, key, f"a number >= {low}, got {s[key]!r}")
    if s["model"] not in MODELS:
        raise SceneError(where, "model", f"one of {', '.join(MODELS)}, got {s['model']!r}")
    if s["template"] and not 0 <= s["emitters"] <= s["materials"] - 2:
        raise SceneError(
            where, "emitters", f"0 .. materials - 2 (one window and one normal material besides), got {s['emitters']}"
        )
    if not 0 <= s["skip_layers"] < s["layers"]:
        raise SceneError(where, "skip_layers", f"0 .. layers - 1, got {s['skip_layers']}")
    if not 0 < s["regularised_fraction"] <= 1:
        raise SceneError(where, "regularised_fraction", f"a fraction in (0, 1], got {s['regularised_fraction']}")


def settings_hash(settings: dict) -> str:
    """What a checkpoint must agree with to resume: every setting that changes the computation."""
    return _settings_hash(settings, _NOT_HASHED)
