"""Mitsuba's own `diffuse` BSDF on our kd atlas, and its differentiable integrator `prb`.

It is our model with ks = 0 (docs/renderer.md: the F90 clamp makes ks = 0 exactly Lambertian).
A scene in it is `scene.scene_to_mitsuba_diffuse`. Mitsuba's `prb` differentiates its native
BSDFs; the milo plugin is Python, which prb would trace and differentiate too, but more slowly.
"""

from __future__ import annotations

from .textures import bitmap_texture

KD_PARAMETER_SUFFIX = "reflectance.data"  # mi.traverse key of diffuse_bsdf's kd bitmap


def diffuse_bsdf(kd) -> dict:
    """Mitsuba's two-sided `diffuse` BSDF reading kd from a bitmap (nearest texel, raw values)."""
    return {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": bitmap_texture(kd)}}


def kd_parameter(params) -> str:
    """The key of the kd bitmap of `scene_to_mitsuba_diffuse` in `mi.traverse(scene)`: its data
    is indexed as our atlas (row, column, channel), so its gradient is d/d kd texel by texel."""
    keys = [key for key in params.keys() if key.endswith("bsdf.brdf_0." + KD_PARAMETER_SUFFIX)]
    if len(keys) != 1:
        raise ValueError(f"kd_parameter: expected one diffuse kd bitmap among the scene parameters, got {keys}")
    return keys[0]
