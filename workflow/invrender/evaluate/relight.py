"""Relighting a duplicates scene (SfD section 4, Table 1's "Relighting PSNR"): the recovered and
the true scene under new light, and with the copies rearranged, seen from the photograph's camera.

- Two new skies, made here (no download): ``warm_sun``, a low warm sun (a von Mises-Fisher lobe,
  not the capture's hard disc) over a warm-to-blue gradient, from another side than the capture's
  sun; ``overcast``, the CIE overcast sky (luminance (1 + 2 sin elevation) / 3 of the zenith's),
  cool, no sun. Both differ from the capture's sky in direction, colour and contrast, so neither
  the capture's shading nor its shadows carry over.
- Rearranged (``rearranged_poses``): the copies go to new places on a lattice near their old ones,
  in a shuffled order, each turned about the vertical through its centre by a yaw of 60-300
  degrees. A turn about the vertical keeps every point's height, so a copy rests on the floor as
  it did; lattice points are 2 r (1 + clearance) apart, r the object's bounding radius about its
  centroid, so no two copies can touch; only points where the whole bounding sphere projects
  inside the image (with a margin) are used, so every copy stays in view. The true scene gets the
  new poses T'_i; the recovered scene gets its own mesh at T'_i A (A: the recovered object frame
  in the true one, the mesh alignment of duplicates.mesh_metrics), in the true world: a user's edit of the recovered
  scene, "put the object there", so the copies' pose errors in the photograph do not carry over
  and what is scored is the recovered shape, material and support.
- In place: both scenes as they are (the recovered one at its recovered poses, from its own
  camera), only the sky replaced.

Each pair is rendered with the same random numbers (the kernels key them by seed and ray id; the
two scenes see the same pixels as the same rays): common random numbers, so that the difference is
the scenes' and not the noise's, and a scene compared with itself scores exactly the PSNR cap. The
truth rendered again with the next seed gives the noise floor: what Monte Carlo noise alone costs
at this spp. PSNR over the copies' pixels (the true render's instance id > 0, the support and the
sky excluded, as SfD scores over its object mask) on the tone mapping of ``metrics.py`` with the
exposure that maps the true render's 99th percentile over those pixels to 1.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..scene.cameras import project_points
from ..scene.cubemap import texel_directions
from ..scene.packing import pack_scene
from ..scene.types import Atlas, Camera, Mesh, Scene, SceneObject
from .metrics import psnr, reference_exposure, tone_map
from .views import evaluation_seed, renderer_for

__all__ = [
    "RELIGHT_MAX_SIDE",
    "SKY_SIZE",
    "SKIES",
    "OBJECT_SET",
    "SUPPORT_SET",
    "skies",
    "warm_sun_sky",
    "overcast_sky",
    "rearranged_poses",
    "placed_scene",
    "scaled_camera",
    "compare",
    "masked_psnr",
]

RELIGHT_MAX_SIDE = 640  # renders at most this many pixels wide or high (the camera scaled down)
SKY_SIZE = 64  # cube texels of 1.4 degrees: the sun lobe (about 3 degrees wide) spans a few
SUN_SHARPNESS = 300.0  # vMF lobe exp(k (cos theta - 1)): half width about 1 / sqrt(k) = 3.3 degrees
LATTICE_CLEARANCE = 0.1  # lattice spacing 2 r (1 + this): bounding spheres a fifth of r apart
VIEW_MARGIN = 0.03  # of the image's width and height: a rearranged copy stays this far inside
YAW_RANGE_DEG = (60.0, 300.0)  # each copy turns at least 60 degrees either way
OBJECT_SET, SUPPORT_SET = "object", "support"


# --- skies -----------------------------------------------------------------------------------------


def _sky_directions(n: int):
    d = texel_directions(n)
    return d, np.clip(d[..., 1:2], -1.0, 1.0)  # directions and their elevation's sine (+Y up)


def _unit(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """The direction at an elevation above the horizon and an azimuth from -Z towards +X (the
    synthetic scenes' convention for their sun)."""
    el, az = np.radians(elevation_deg), np.radians(azimuth_deg)
    return np.array([np.cos(el) * np.sin(az), np.sin(el), -np.cos(el) * np.cos(az)])


def warm_sun_sky(n: int = SKY_SIZE) -> np.ndarray:
    """kg (6, N, N, 3): a warm low sun (elevation 20, azimuth 250 degrees; its irradiance about
    the sky's) over a gradient from a warm horizon to a blue zenith, a dark brown ground."""
    d, up = _sky_directions(n)
    t = np.sqrt(np.clip(up, 0.0, 1.0))
    sky = (1 - t) * np.array([1.2, 0.85, 0.55]) + t * np.array([0.45, 0.6, 0.9])
    kg = np.where(up >= 0, sky, np.array([0.18, 0.14, 0.10]))
    lobe = np.exp(SUN_SHARPNESS * (d @ _unit(20.0, 250.0) - 1.0))[..., None]
    return (kg + lobe * np.array([120.0, 85.0, 45.0])).astype(np.float32)


def overcast_sky(n: int = SKY_SIZE) -> np.ndarray:
    """kg (6, N, N, 3): the CIE standard overcast sky, L = L_z (1 + 2 sin elevation) / 3, a cool
    grey (zenith (0.9, 1.0, 1.2)), over a grey-blue ground of a fifth of the horizon's."""
    _, up = _sky_directions(n)
    zenith = np.array([0.9, 1.0, 1.2])
    sky = zenith * (1 + 2 * np.clip(up, 0.0, 1.0)) / 3
    return np.where(up >= 0, sky, zenith / 15).astype(np.float32)


SKIES = {"warm_sun": warm_sun_sky, "overcast": overcast_sky}


def skies(n: int = SKY_SIZE) -> dict[str, np.ndarray]:
    return {name: make(n) for name, make in SKIES.items()}


# --- the copies rearranged ---------------------------------------------------------------------------


def _yaw(degrees: float) -> np.ndarray:
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _in_view(camera: Camera, centre, radius: float) -> bool:
    """The bounding sphere's six extreme points and centre project inside the image's margin."""
    points = centre + np.vstack([np.zeros(3), radius * np.eye(3), -radius * np.eye(3)])
    uv = project_points(camera, points)
    mx, my = VIEW_MARGIN * camera.width, VIEW_MARGIN * camera.height
    inside = (uv[:, 0] >= mx) & (uv[:, 0] <= camera.width - mx) & (uv[:, 1] >= my) & (uv[:, 1] <= camera.height - my)
    return bool(np.isfinite(uv).all() and inside.all())


def _lattice(mean, spacing: float, height: float, radius: float, camera: Camera, count: int) -> np.ndarray | None:
    """The ``count`` lattice points (x, z around ``mean``, ``spacing`` apart, at ``height``) nearest
    ``mean`` whose bounding sphere is in view; None if fewer are."""
    reach = int(np.ceil(4 * np.sqrt(count))) + 4
    i, k = np.meshgrid(np.arange(-reach, reach + 1), np.arange(-reach, reach + 1), indexing="ij")
    points = np.stack([mean[0] + spacing * i.ravel(), np.full(i.size, height), mean[2] + spacing * k.ravel()], 1)
    points = points[np.argsort(np.hypot(points[:, 0] - mean[0], points[:, 2] - mean[2]), kind="stable")]
    chosen = [p for p in points if _in_view(camera, p, radius)][:count]
    return np.array(chosen) if len(chosen) == count else None


def rearranged_poses(object_mesh: Mesh, poses: dict, centroid, camera: Camera, seed: int = 0):
    """New poses {id: T'} of the copies (module docstring) and what was done, or (None, why)
    when the view has no room for them all. ``centroid``: the object's, in its frame."""
    ids = sorted(poses)
    positions = np.asarray(object_mesh.positions, np.float64)
    radius = float(np.linalg.norm(positions - centroid, axis=1).max())
    centres = {i: poses[i][:3, :3] @ centroid + poses[i][:3, 3] for i in ids}
    mean = np.mean([centres[i] for i in ids], axis=0)
    height = float(np.max([centres[i][1] for i in ids]))  # the highest centre: a conservative view test
    for clearance in (LATTICE_CLEARANCE, 0.0):
        spacing = 2 * radius * (1 + clearance)
        cells = _lattice(mean, spacing, height, radius, camera, len(ids))
        if cells is not None:
            break
    else:
        return None, {"reason": f"no room in view for {len(ids)} copies 2 r = {2 * radius:.4g} m apart"}
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(ids))
    yaws = rng.uniform(*YAW_RANGE_DEG, size=len(ids))
    new = {}
    for k, i in enumerate(ids):
        move = np.eye(4)
        move[:3, :3] = _yaw(yaws[k])
        cell = np.array([cells[order[k]][0], centres[i][1], cells[order[k]][2]])  # its own height
        move[:3, 3] = cell - move[:3, :3] @ centres[i]
        new[i] = move @ poses[i]
    info = {
        "spacing_m": spacing,
        "bounding_radius_m": radius,
        "cells": {str(i): cells[order[k]][[0, 2]].tolist() for k, i in enumerate(ids)},
        "yaw_deg": {str(i): float(yaws[k]) for k, i in enumerate(ids)},
        "seed": int(seed),
    }
    return new, info


def placed_scene(
    object_mesh: Mesh,
    object_atlas: Atlas,
    transforms: dict,
    kg,
    camera: Camera,
    support_mesh: Mesh | None = None,
    support_atlas: Atlas | None = None,
    support_transform=None,
) -> Scene:
    """A v2 scene: the object at each transform {instance id: 4x4} (material set "object"), the
    support (world mesh, moved by ``support_transform``; instance id 0) with its own set, or with
    the object's when it is the same atlas (a v1 truth's one atlas), the sky ``kg``, one camera."""
    objects = [
        SceneObject(f"object_{i}", object_mesh, OBJECT_SET, np.asarray(T, np.float64), instance_id=int(i))
        for i, T in sorted(transforms.items())
    ]
    materials = {OBJECT_SET: object_atlas}
    if support_mesh is not None:
        shared = support_atlas is object_atlas
        name = OBJECT_SET if shared else SUPPORT_SET
        if not shared:
            materials[SUPPORT_SET] = support_atlas
        transform = np.eye(4) if support_transform is None else np.asarray(support_transform, np.float64)
        objects.insert(0, SceneObject(SUPPORT_SET, support_mesh, name, transform, instance_id=0))
    return pack_scene(objects, materials, kg, [camera])


# --- renders compared ---------------------------------------------------------------------------------


def scaled_camera(camera: Camera, max_side: int = RELIGHT_MAX_SIDE) -> Camera:
    """The camera with at most ``max_side`` pixels on its longer side: the image scaled by
    k = max_side / longer side, so focal lengths and principal point times k (pixel (0, 0)'s
    corner stays at 0); distortion acts on normalised coordinates and stays. An HD photograph's
    twelve relighting renders would otherwise cost 11 times a 480 x 360 one's, and a PSNR over
    the copies needs no more pixels than this."""
    k = max_side / max(camera.width, camera.height)
    if k >= 1:
        return camera
    width, height = max(1, round(camera.width * k)), max(1, round(camera.height * k))
    sx, sy = width / camera.width, height / camera.height
    params = np.asarray(camera.params, np.float64).copy()
    if camera.model == "SIMPLE_PINHOLE":  # f, cx, cy
        params[:3] *= [sx, sx, sy]
    else:  # fx, fy, cx, cy (then OPENCV's distortion)
        params[:4] *= [sx, sy, sx, sy]
    return replace(camera, width=width, height=height, params=params)


def masked_psnr(test, reference, mask, exposure: float) -> float:
    """PSNR over the masked pixels of two linear renders on one tone mapping (``metrics.py``)."""
    return psnr(tone_map(np.asarray(test)[mask], exposure), tone_map(np.asarray(reference)[mask], exposure))


def _render(scene: Scene, spp: int, seed: int, device, aovs: bool = False) -> dict:
    camera = scene.cameras[0]
    return renderer_for(scene, [camera], device).render(camera, spp=spp, seed=evaluation_seed(seed), aovs=aovs)


def compare(recovered: Scene, truth: Scene, spp: int, seed: int, device=None):
    """(metrics, images) of the recovered scene against the truth, each rendered from its first
    camera with the same random numbers; the truth again with the next seed for the noise floor.
    images: recovered, truth (linear), the copies' pixels, the exposure."""
    ours = _render(recovered, spp, seed, device)["radiance"]
    reference = _render(truth, spp, seed, device, aovs=True)
    again = _render(truth, spp, seed + 1, device)["radiance"]
    mask = np.asarray(reference["instance_id"]) > 0
    truth_image = reference["radiance"]
    if not mask.any():
        return {"psnr_db": None, "noise_floor_psnr_db": None, "pixels": 0, "reason": "no copy in view"}, None
    exposure = reference_exposure(truth_image[mask])
    metrics = {
        "psnr_db": masked_psnr(ours, truth_image, mask, exposure),
        "noise_floor_psnr_db": masked_psnr(again, truth_image, mask, exposure),
        "pixels": int(mask.sum()),
        "exposure": float(exposure),
        "spp": int(spp),
    }
    return metrics, (ours, truth_image, mask, exposure)
