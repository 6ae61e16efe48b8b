"""The material stage's measures: the re-rendered photo's PSNR, and against a synthetic room's
truth (capture/truth: the scene and room.json) the albedo at the same 3D point and the lights'
emitted power.

Same 3D point: the estimate and the truth are each cast from the photo's camera in its own world
(room_box's box is posed in a world of its own, docs/room.md: the truth scene's own camera, at the
same size); a pixel whose two depths (camera z, the estimate's times room_box's truth_scale) agree
within DEPTH_TOLERANCE of the truth's sees one surface point in both, and there the estimate's kd
(its texel at its hit) is compared with the truth's (its texel at its hit). (Casting the truth
from the estimate's camera, as this did first, found no common point on the office, whose box
world is turned 90 degrees from the truth's.)
"""

from __future__ import annotations

import numpy as np

from ..render.features import Features
from ..render.renderer import Renderer, pixel_requests
from ..render.scene_buffers import emitted_power
from ..scene.atlas import texel_index
from ..scene.cameras import resized_camera
from ..scene.format import load_scene

__all__ = ["psnr", "truth_metrics", "DEPTH_TOLERANCE"]

DEPTH_TOLERANCE = 0.02  # relative: two hits within 2 % of the depth are one point


def psnr(image, reference, peak: float = 1.0) -> float:
    """10 log10(peak^2 / MSE) over pixels and channels, linear RGB."""
    mse = float(np.mean((np.asarray(image, np.float64) - np.asarray(reference, np.float64)) ** 2))
    return 99.0 if mse <= 0 else float(10 * np.log10(peak**2 / mse))


def _kd_at(renderer: Renderer, kd: np.ndarray, camera):
    """Per pixel of ``camera``: depth, kd at the hit's texel, the hit triangle."""
    aov = renderer.aovs([camera], pixel_requests(camera))
    row, col = texel_index(aov["uv"], kd.shape)
    return aov["depth"], kd[row, col], aov["triangle_id"]


def truth_metrics(truth_dir, model, materials, radiance, renderer, eval_cam, parts, truth_scale: float = 1.0) -> dict:
    truth = load_scene(truth_dir / "scene")
    # AOVs only: the kernels' options do not change primary hits.
    truth_renderer = Renderer(truth, Features(specular=False, environment=False, window=False, env_sampling=False))
    maps = model.maps(materials, radiance)
    depth_t, kd_t, _ = _kd_at(truth_renderer, truth.maps.kd, resized_camera(truth.cameras[0], eval_cam.width))
    renderer.set_maps(maps)
    depth_e, kd_e, tri_e = _kd_at(renderer, maps.kd, eval_cam)
    depth_e = depth_e * truth_scale
    same = (depth_t > 0) & (depth_e > 0) & (np.abs(depth_e - depth_t) <= DEPTH_TOLERANCE * np.maximum(depth_t, 1e-9))
    part = model.part_ids(tri_e)
    error = np.abs(kd_e - kd_t).mean(axis=1)
    per_part = {}
    for i, p in enumerate(parts):
        m = same & (part == i)
        if m.sum() >= 4:
            per_part[p.name] = {
                "kd_error": round(float(error[m].mean()), 5),
                "kd_estimate": np.round(kd_e[m].mean(0), 4).tolist(),
                "kd_truth": np.round(kd_t[m].mean(0), 4).tolist(),
                "pixels": int(m.sum()),
            }
    on_parts = same & (part >= 0)
    power_t = float(emitted_power(truth.mesh, truth.maps).sum())
    power_e = emitted_power(model.scene.mesh, maps)
    windows = np.zeros(len(power_e), bool)
    for light in model.lights:
        if light.kind == "window":
            windows[np.asarray(light.faces)] = True
    summary = {
        "kd_error": round(float(error[on_parts].mean()), 5) if on_parts.any() else None,
        "same_point_fraction": round(float(on_parts.mean()), 4),
        "emitted_power_truth": round(power_t, 4),
        "emitted_power_estimate": round(float(power_e.sum()), 4),
        "emitted_power_estimate_without_windows": round(float(power_e[~windows].sum()), 4),
    }
    return {
        "summary": summary,
        "parts": per_part,
        "size": [eval_cam.width, eval_cam.height],
        "depth_tolerance": DEPTH_TOLERANCE,
    }
