"""Renders compared with a reference: novel views against the capture, and virtual object
insertion (MILO section 4.2, Table 3) in the recovered scene against the same insertion in the truth.

Insertion: three spheres, a diffuse, a specular and an emitting one (``SPHERES``), are inserted
into both scenes with ``scene.edits.insert_object`` at the same places, and both scenes are
rendered from the same cameras with independent random numbers; the metrics compare the two renders on the
truth render's tone mapping (``metrics.py``). Placement, unless the caller gives one: rays through
SPHERE_PIXELS of the first evaluation camera (fractions of its width and height, the lower middle
of the view, where floors and table tops are) are cast into the truth scene (``Renderer.aovs``:
depth and normal at the pixel); each sphere rests on the surface hit, its centre one radius out
along the surface normal, radius ``radius_fraction`` of the truth's bounding-box diagonal but at
most RADIUS_OF_DEPTH of the hit's depth (so it neither fills the view nor meets its neighbours).
"""

from __future__ import annotations

import logging
from dataclasses import replace

import cv2
import numpy as np

from ..render.analysis import analyse
from ..render.features import Features
from ..render.renderer import Renderer
from ..scene.capture import read_view
from ..scene.edits import insert_object, sphere_mesh
from ..scene.types import Camera, Scene, SceneError
from .metrics import image_metrics, reference_exposure

__all__ = [
    "SPHERES",
    "place_spheres",
    "insert_spheres",
    "renderer_for",
    "render_all",
    "render_views",
    "novel_views",
    "insertion",
]

log = logging.getLogger(__name__)

# The paper's three inserted objects. The emitter's radiance is of the order of a ceiling lamp's.
SPHERES = {
    "diffuse": {"kd": [0.8, 0.8, 0.8], "ks": 0.0, "ka": 0.3},
    "specular": {"kd": [0.02, 0.02, 0.02], "ks": [0.9, 0.9, 0.9], "ka": 0.005},
    "emitting": {"ke": [5.0, 5.0, 5.0], "ka": 0.05},
}
SPHERE_PIXELS = {"diffuse": (0.3, 0.7), "specular": (0.5, 0.7), "emitting": (0.7, 0.7)}
FALLBACK_PIXELS = [(0.5, 0.5), (0.4, 0.6), (0.6, 0.6), (0.5, 0.85), (0.25, 0.5), (0.75, 0.5)]
DEFAULT_RADIUS_FRACTION = 0.04
RADIUS_OF_DEPTH = 0.1
SPHERE_SEGMENTS = 32
# Primary hits are all the placement needs: no effect compiled in, no scene analysis run.
HITS_ONLY = Features.only(max_bounces=0)


def pixel_ray(camera: Camera, x: float, y: float) -> tuple[np.ndarray, np.ndarray]:
    """(origin, direction scaled to unit depth along the optical axis) through pixel position
    (x, y) (pixel centres at + 0.5), lens distortion undone as the kernels apply it."""
    fx, fy = camera.focal
    cx, cy = camera.principal_point
    k = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    normalised = cv2.undistortPoints(np.array([[[x, y]]], np.float64), k, camera.distortion)[0, 0]
    direction = camera.R.T @ np.array([normalised[0], normalised[1], 1.0])
    return camera.center, direction


def place_spheres(truth: Scene, camera: Camera, radius_fraction: float = DEFAULT_RADIUS_FRACTION, device=None):
    """[{kind, material, center, radius, pixel}] for the three spheres (module docstring)."""
    positions = np.asarray(truth.mesh.positions, np.float64)
    diagonal = float(np.linalg.norm(positions.max(0) - positions.min(0)))
    renderer = Renderer(replace(truth, cameras=[camera]), HITS_ONLY, device)
    placements = []
    for kind, first in SPHERE_PIXELS.items():
        for fx, fy in [first, *FALLBACK_PIXELS]:
            x, y = int(fx * camera.width), int(fy * camera.height)
            aov = renderer.aovs([camera], np.array([[0, x, y, 0]], np.int32))
            depth = float(aov["depth"][0])
            if np.isfinite(depth) and depth > 0:
                break
        else:
            raise SceneError(camera.name, "insertion", "a view that sees the scene's surfaces at its centre")
        origin, direction = pixel_ray(camera, x + 0.5, y + 0.5)
        hit = origin + depth * direction
        normal = np.asarray(aov["normal"][0], np.float64)
        radius = min(radius_fraction * diagonal, RADIUS_OF_DEPTH * depth)
        placements.append(
            {
                "kind": kind,
                "material": SPHERES[kind],
                "center": (hit + 1.001 * radius * normal).tolist(),
                "radius": float(radius),
                "pixel": [x, y],
                "camera": camera.name,
            }
        )
    return placements


def insert_spheres(scene: Scene, placements: list[dict]) -> Scene:
    for sphere in placements:
        mesh = sphere_mesh(sphere["center"], sphere["radius"], SPHERE_SEGMENTS)
        scene = insert_object(scene, mesh, sphere["material"], name=f"inserted_{sphere['kind']}")
    return scene


def renderer_for(scene: Scene, cameras: list[Camera], device=None) -> Renderer:
    """A renderer of ``scene`` with the features it calls for, its cameras replaced by
    ``cameras``: two scenes rendered this way give the same pixel the same ray id."""
    scene = replace(scene, cameras=list(cameras))
    return Renderer(scene, analyse(scene, device=device), device=device)


def render_all(renderer: Renderer, cameras: list[Camera], spp: int, seed: int) -> dict[str, np.ndarray]:
    """Linear radiance of each camera, with the random numbers of ``evaluation_seed(seed)``."""
    return {c.name: renderer.render(c, spp=spp, seed=evaluation_seed(seed), aovs=False)["radiance"] for c in cameras}


def evaluation_seed(seed: int) -> int:
    """The kernels' seed of an evaluation render: ``seed`` + 2^32. Captures are rendered with
    seeds below 2^32 (the synthesize stage's), and the kernels key random numbers by (seed, ray
    id), so a render of a near-perfect recovery with the capture's seed would repeat the capture's
    noise and score better than it is; renders that are compared use seeds one apart."""
    return int(seed) + 2**32


def render_views(scene: Scene, cameras: list[Camera], spp: int, seed: int, device=None) -> dict[str, np.ndarray]:
    return render_all(renderer_for(scene, cameras, device), cameras, spp, seed)


def novel_views(recovered: Scene, truth: Scene, cameras: list[Camera], images_dir, spp: int, seed: int, device=None):
    """(metrics per view and their means, {name: (render, captured)}) for the held-out views.

    Also the truth's floor: the true scene rendered the same way against the same captures, the
    score of a perfect recovery under the render's and the capture's Monte Carlo noise."""
    captured = {c.name: read_view(images_dir, c) for c in cameras}
    renders = render_views(recovered, cameras, spp, seed, device)
    truths = render_views(truth, cameras, spp, seed + 1, device)
    pairs = {name: (renders[name], image) for name, image in captured.items()}
    per_view = {name: image_metrics(render, image) for name, (render, image) in pairs.items()}
    floor = {name: image_metrics(truths[name], image) for name, image in captured.items()}
    return summarise(per_view) | {"truth_floor": summarise(floor)["mean"]}, pairs


def insertion(recovered: Scene, truth: Scene, cameras, placements, spp: int, seed: int, images_dir, device=None):
    """(metrics per view and their means, {name: (recovered render, truth render)}).

    The two scenes are rendered with seeds one apart (independent noise). The noise floor is the
    same comparison between two renders of the truth, seeds one apart again: the score a perfect
    recovery gets under Monte Carlo noise at ``spp``. The exposure is the captured view's (the
    scene as photographed, ``metrics.reference_exposure``), not the render's: the inserted lamp
    would set it and leave the rest of the view dark."""
    exposure = {c.name: reference_exposure(read_view(images_dir, c)) for c in cameras}
    ours = render_views(insert_spheres(recovered, placements), cameras, spp, seed, device)
    truth_renderer = renderer_for(insert_spheres(truth, placements), cameras, device)
    reference = render_all(truth_renderer, cameras, spp, seed + 1)
    again = render_all(truth_renderer, cameras, spp, seed + 2)
    pairs = {c.name: (ours[c.name], reference[c.name]) for c in cameras}
    per_view = {name: image_metrics(a, b, exposure[name]) for name, (a, b) in pairs.items()}
    floor = {name: image_metrics(again[name], reference[name], exposure[name]) for name in reference}
    return summarise(per_view) | {"noise_floor": summarise(floor)["mean"]}, pairs


def summarise(per_view: dict[str, dict]) -> dict:
    keys = ("psnr_db", "ssim", "ncc", "mse")
    mean = {k: float(np.mean([m[k] for m in per_view.values()])) for k in keys} if per_view else {}
    return {"mean": mean, "views": per_view}
