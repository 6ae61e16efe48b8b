"""Parameter-map errors against the truth, measured on the surface (MILO section 4.1).

- Atlas maps (kd, ks, ka, ke, kw): the recovered texel against the truth texel at the same 3D
  point (``correspond.py``), over the recovered atlas' covered texels; MSE over texels and
  channels.
- kg: over directions. Both cube maps are read on the finer of the two (a texel of the coarser
  one by nearest-texel lookup of the finer texel's centre direction, the renderer's lookup, which
  is exact when one size divides the other), each texel weighted by its solid angle, so the MSE
  is a mean over the sphere of directions, not over the cube's unevenly sized texels.
- Light maps MSE (the paper's 0.002): the mean of the ke, kw and kg MSEs; in linear units also
  with kg outside the suns' discs (``kg_mse_outside_sun``), the sun scored on its own by its
  direction and power (``sun_errors``).
- Material MSE (the paper's 0.015): shading balls (``balls.py``) of (kd, ks, ka), over at most
  ``max_ball_texels`` covered texels taken at an even stride (all of them if fewer).
"""

from __future__ import annotations

import numpy as np

from ..scene.cubemap import as_cube, cube_texel_solid_angles, lookup_cube, texel_directions
from ..scene.types import ATLAS_MAPS
from .balls import BALL_LIGHTS, BALL_SIZE, ball_errors
from .correspond import Correspondence
from .emitters import emitted_power_ratio, emitter_powers
from .metrics import mse

__all__ = ["kg_on_common_cube", "kg_mse", "map_errors", "truth_in_recovered_layout", "DEFAULT_BALL_TEXELS"]

DEFAULT_BALL_TEXELS = 65_536  # about 6 s of shading balls on this machine's CPU
LIGHT_MAPS = ("ke", "kw", "kg")
MATERIAL_MAPS = ("kd", "ks", "ka")


def kg_on_common_cube(recovered, truth) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Both cube maps on the finer one's texels, and those texels' solid angles (6, N, N)."""
    recovered, truth = as_cube(recovered), as_cube(truth)
    n = max(recovered.shape[1], truth.shape[1])
    directions = texel_directions(n)
    on_n = lambda kg: kg if kg.shape[1] == n else lookup_cube(kg, directions)
    weights = np.broadcast_to(cube_texel_solid_angles(n), (6, n, n))
    return on_n(recovered), on_n(truth), weights


def kg_mse(recovered, truth) -> float:
    """MSE of two kg cube maps over the sphere of directions (solid-angle weighted)."""
    a, b, weights = kg_on_common_cube(recovered, truth)
    return mse(a, b, weights)


SUN_FACTOR = 10.0  # a sky texel this many times brighter than its sky's median is the sun's


def sun_texels(kg: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(6, N, N) bool: the texels of a cube map brighter than SUN_FACTOR times its median
    luminance over the sphere (solid-angle weighted); none in a black sky."""
    luminance = kg.mean(-1)
    order = np.argsort(luminance, axis=None)
    cumulative = np.cumsum(weights.reshape(-1)[order])
    median = luminance.reshape(-1)[order][np.searchsorted(cumulative, 0.5 * cumulative[-1])]
    return luminance > SUN_FACTOR * median


def kg_mse_outside_sun(recovered, truth) -> float:
    """kg's MSE over the directions outside both suns' discs (each map's texels brighter than
    SUN_FACTOR times its median luminance), solid-angle weighted. In linear units a sun's few
    texels outweigh the rest of the sky, the truth's where the recovery misses it, the
    recovery's where it lies a texel beside the truth's; this is the sky's error without them
    (all of it when neither has a sun). `sun_errors` scores the sun itself."""
    a, b, weights = kg_on_common_cube(recovered, truth)
    outside = ~sun_texels(b, weights) & ~sun_texels(a, weights)
    return mse(a[outside], b[outside], weights[outside]) if outside.any() else 0.0


def sun_errors(recovered, truth) -> dict | None:
    """The recovered sun against the truth's (None when the truth has none): the angle between
    their directions (each its texels' luminance x solid angle weighted mean direction) and the
    ratio of their powers (radiance x solid angle summed over their texels, per channel's mean);
    no recovered sun reads a power ratio of 0 and no angle."""
    a, b, weights = kg_on_common_cube(recovered, truth)
    directions = texel_directions(a.shape[1])
    true_sun, found_sun = sun_texels(b, weights), sun_texels(a, weights)
    if not true_sun.any():
        return None
    power = lambda kg, sun: float((kg[sun].mean(-1) * weights[sun]).sum())  # noqa: E731
    out = {"power_ratio": power(a, found_sun) / power(b, true_sun), "direction_error_deg": None}
    if found_sun.any():
        mean = [(kg[sun].mean(-1) * weights[sun]) @ directions[sun] for kg, sun in ((a, found_sun), (b, true_sun))]
        cosine = mean[0] @ mean[1] / (np.linalg.norm(mean[0]) * np.linalg.norm(mean[1]))
        out["direction_error_deg"] = float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))))
    return out


def compress(radiance):
    """x / (1 + x): radiance on [0, 1), as the material maps are. The light maps' MSE is taken on
    this scale: in linear units one sun texel of radiance 150 outweighs the rest of the scene
    (the demo room's kg MSE is ~30 from that texel alone), and the paper's 0.002 cannot be a
    linear MSE of HDR maps with a sun in them. Both scales are reported."""
    radiance = np.asarray(radiance, np.float64)
    return radiance / (1.0 + np.maximum(radiance, 0.0))


def ball_subset(count: int, limit: int | None) -> np.ndarray:
    """Indices of at most ``limit`` of ``count`` texels at an even stride (all if limit is None)."""
    if limit is None or count <= limit:
        return np.arange(count)
    return np.linspace(0, count - 1, int(limit)).round().astype(np.int64)


def map_errors(
    recovered_maps,
    truth_maps,
    corr: Correspondence,
    max_ball_texels: int | None = DEFAULT_BALL_TEXELS,
    constant_guess: bool = True,
):
    """The metrics of the module docstring, as a JSON-ready dict, and beside them (unless not
    ``constant_guess``) the same metrics of the best constant guess: each map the truth's mean
    over the surface (kg over the sphere), which a recovery has to beat by a wide margin."""
    mask = corr.mask
    rec = {name: np.asarray(getattr(recovered_maps, name))[mask] for name in ATLAS_MAPS}
    true = {name: corr.truth_values(getattr(truth_maps, name)) for name in ATLAS_MAPS}
    subset = ball_subset(len(rec["kd"]), max_ball_texels)
    errors = _errors(rec, recovered_maps.kg, true, truth_maps.kg, subset)
    errors["emitted_power_ratio"] = emitted_power_ratio(rec["ke"], true["ke"])
    errors["emitters"] = emitter_powers(rec["ke"], true["ke"], corr.point)
    outside = kg_mse_outside_sun(recovered_maps.kg, truth_maps.kg)
    errors["kg_mse_outside_sun"] = outside
    errors["sun"] = sun_errors(recovered_maps.kg, truth_maps.kg)
    errors["light_maps_mse_linear_outside_sun"] = float(
        np.mean([errors["map_mse"]["ke"], errors["map_mse"]["kw"], outside])
    )
    errors["shading_balls"] = {
        "texels": int(len(subset)),
        "of_texels": int(len(rec["kd"])),
        "size_px": BALL_SIZE,
        "lights": [{"direction": list(d), "irradiance": e} for d, e in BALL_LIGHTS],
        "clip": [0.0, 1.0],
    }
    if not constant_guess:
        return errors
    constant = {name: np.broadcast_to(values.mean(axis=0), values.shape) for name, values in true.items()}
    guess = _errors(constant, _constant_sky(truth_maps.kg), true, truth_maps.kg, subset)
    return errors | {"constant_guess": {key: guess[key] for key in ("light_maps_mse", "material_mse", "map_mse")}}


def _constant_sky(kg) -> np.ndarray:
    """The sky's mean radiance over the sphere of directions, in every texel."""
    cube = as_cube(kg)
    weights = np.broadcast_to(cube_texel_solid_angles(cube.shape[1]), cube.shape[:3])
    mean = np.average(cube.reshape(-1, cube.shape[-1]), axis=0, weights=weights.reshape(-1))
    return np.broadcast_to(mean, cube.shape).astype(np.float32)


def _errors(rec: dict, rec_kg, true: dict, true_kg, subset: np.ndarray) -> dict:
    per_map = {name: mse(rec[name], true[name]) for name in ATLAS_MAPS}
    per_map["kg"] = kg_mse(rec_kg, true_kg)
    compressed = {
        "ke": mse(compress(rec["ke"]), compress(true["ke"])),
        "kw": per_map["kw"],  # already on [0, 1]
        "kg": kg_mse(compress(rec_kg), compress(true_kg)),
    }
    balls = ball_errors(
        tuple(rec[name][subset] for name in MATERIAL_MAPS), tuple(true[name][subset] for name in MATERIAL_MAPS)
    )
    return {
        "light_maps_mse": float(np.mean([compressed[name] for name in LIGHT_MAPS])),
        "light_maps_mse_linear": float(np.mean([per_map[name] for name in LIGHT_MAPS])),
        "light_map_mse_compressed": compressed,
        "material_mse": float(balls.mean()),
        "map_mse": per_map,
    }


def truth_in_recovered_layout(truth_maps, corr: Correspondence) -> dict[str, np.ndarray]:
    """Each truth atlas map resampled into the recovered atlas (covered texels; 0 elsewhere): what
    the map errors compare the recovered maps with, for the figures."""
    out = {}
    for name in ATLAS_MAPS:
        values = corr.truth_values(getattr(truth_maps, name))
        image = np.zeros(corr.mask.shape + values.shape[1:], np.float32)
        image[corr.mask] = values
        out[name] = image
    return out
