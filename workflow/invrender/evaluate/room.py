"""A room scene (mode `room`) against the synthetic truth of its photo.

    out_dir/metrics.json     the numbers below (docs/room.md, "Evaluation")
    out_dir/photo.png        the room scene rendered at the photo's camera | the photo | |error|
    out_dir/classes.png      the photo's classes | the room scene's | where they differ

1. **Re-rendered photo**: the baked scene rendered at the photo's camera (``spp``) against the
   photo: PSNR, SSIM, NCC, MSE on the photo's tone mapping (``metrics.image_metrics``).
2. **Mask IoU per class**: the scene's instance-id AOV at the photo's pixel centres, each id's
   class from scene.json's ``instances``, against the capture's panoptic classes (``ROOM_CLASSES``;
   null for a class neither shows).
3. **Room box**: room_box's own metrics (corner errors, size error, IoU), coarse and refined.
4. **Objects**: room_objects' metrics when its objects.json (or metrics.json) has them.
5. **Light**: the total power the emitters send into the room, the scene's against the truth's.
   The estimated lights are the paper's initial grid (or their optimised radiance), not the
   truth's panels, lamp and window, so no light matches one of the truth's; what the photo
   constrains is how much light there is, which the radiance fit scales. Power of a surface:
   pi * integral of ke over its area (one side: the side facing the room), plus for a window
   (kw > 0) integral of kw over its area times the sky's irradiance through it, integral of
   kg(d) (d . n_out) over the outward hemisphere (the sun included). Per RGB channel, in the
   truth's meters (a recovered area times truth_scale^2); the error is relative on the channels'
   mean.
6. **Material on the surface**: every covered texel of the scene's walls, floor, ceiling and
   objects (lights left out), taken into the truth's world through the photo's camera (both
   worlds see it: x_truth = R_t^T (s (R x + t) - t_t), s = room_box's truth_scale), against the
   truth's texel at the nearest surface point (``appearance.aligned_correspondence``, the
   duplicates evaluation's): albedo PSNR (SfD's encoding, with and without the per-channel
   scale), roughness MSE and kd, ks, ka MSEs (``appearance.surface_errors``).
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

import cv2
import numpy as np

from ..scene.atlas import texel_index
from ..scene.atomic import atomic_dir, check_output
from ..scene.cubemap import as_cube, cube_texel_solid_angles, lookup_cube, texel_directions
from ..scene.format import load_scene, read_scene_json
from ..scene.room_photo import ROOM_CLASSES, load_room_photo
from ..scene.types import Camera, Mesh, Scene, SceneError, require_positive
from . import figures
from .appearance import Similarity, aligned_correspondence, surface_errors
from .metrics import image_metrics, reference_exposure

__all__ = ["run", "class_iou", "emitted_power", "truth_similarity", "METRICS_VERSION"]

log = logging.getLogger(__name__)

METRICS_VERSION = 1
SKY_QUADRATURE = 64  # cube texels a side for a window's sky irradiance
POWER_SAMPLES = 8  # barycentric grid steps per triangle edge for the emitted power
MAX_SURFACE_TEXELS = 50_000  # texels of the material comparison, at an even stride (1 in 9 of the living room's)
CLASS_COLOURS = np.array(  # BGR per ROOM_CLASSES, then "none"
    [[180, 180, 180], [40, 90, 160], [230, 230, 200], [255, 200, 60], [0, 220, 255], [60, 60, 220], [0, 0, 0]],
    np.uint8,
)


# ---------------------------------------------------------------------------- masks


def class_image(ids: np.ndarray, classes: dict[int, str]) -> np.ndarray:
    """(H, W) index into ROOM_CLASSES of each pixel's id (len(ROOM_CLASSES): none)."""
    lookup = np.full(int(max([0, *classes, int(ids.max(initial=0))])) + 1, len(ROOM_CLASSES), np.int32)
    for i, cls in classes.items():
        lookup[int(i)] = ROOM_CLASSES.index(cls)
    return lookup[np.asarray(ids, np.int64)]


def class_iou(truth: np.ndarray, recovered: np.ndarray) -> dict:
    """IoU per class of two class images (class_image); null where neither has the class."""
    out = {}
    for k, cls in enumerate(ROOM_CLASSES):
        a, b = truth == k, recovered == k
        union = int((a | b).sum())
        out[cls] = None if union == 0 else float((a & b).sum() / union)
    seen = [v for v in out.values() if v is not None]
    return {
        "per_class": out,
        "mean": float(np.mean(seen)) if seen else None,
        "pixel_agreement": float((truth == recovered).mean()),
    }


# ---------------------------------------------------------------------------- light


def _triangle_samples(n: int) -> np.ndarray:
    """Barycentric points of a triangle's grid with n steps per edge, cell centroids (uniform)."""
    pts = []
    for i in range(n):
        for j in range(n - i):
            pts.append(((i + 1 / 3) / n, (j + 1 / 3) / n))  # upright cells
            if i + j < n - 1:
                pts.append(((i + 2 / 3) / n, (j + 2 / 3) / n))  # inverted cells
    b = np.array(pts)
    return np.column_stack([1 - b.sum(axis=1), b])


def _sky_irradiance(kg: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """integral of kg(d) (d . n) over the hemisphere around ``normal`` (RGB), on a cube of at
    least SKY_QUADRATURE texels a side (kg read at each one's centre, the renderer's lookup): the
    horizon cuts through a coarse sky's texels (0.5 % off at 8 a side)."""
    cube = as_cube(kg)
    n = max(cube.shape[1], SKY_QUADRATURE)
    d = texel_directions(n)
    values = cube if n == cube.shape[1] else lookup_cube(cube, d)
    w = np.broadcast_to(cube_texel_solid_angles(n), (6, n, n))
    cos = np.clip(d @ np.asarray(normal, np.float64), 0, None)
    return np.einsum("fij,fijc->c", w * cos, np.asarray(values, np.float64))


def emitted_power(mesh: Mesh, maps, room_center, scale: float = 1.0) -> dict:
    """The power (W per RGB channel, module docstring 5) of the emitting faces of a world mesh
    on its maps: ``emitters`` (ke) and ``windows`` (kw times the sky's irradiance through them,
    the outward side the one away from ``room_center``); areas times ``scale``^2."""
    faces = np.asarray(mesh.faces, np.int64)
    p = np.asarray(mesh.positions, np.float64)[faces]
    uv = np.asarray(mesh.uvs, np.float64)[faces]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    area = 0.5 * np.linalg.norm(normal, axis=1) * scale**2
    b = _triangle_samples(POWER_SAMPLES)
    row, col = texel_index(np.einsum("sk,fkc->fsc", b, uv), np.shape(maps.ke)[:2])
    ke = np.asarray(maps.ke, np.float64)[row, col].mean(axis=1)  # (F, 3): mean over each face
    kw = np.asarray(maps.kw, np.float64)[row, col].mean(axis=1)  # (F,)
    emitters = np.pi * (ke * area[:, None]).sum(axis=0)
    windows = np.zeros(3)
    for f in np.flatnonzero(kw * area > 0):
        n = normal[f] / np.linalg.norm(normal[f])
        outward = n if n @ (p[f].mean(axis=0) - np.asarray(room_center, np.float64)) > 0 else -n
        windows += kw[f] * area[f] * _sky_irradiance(maps.kg, outward)
    total = emitters + windows
    return {
        "total": total.tolist(),
        "emitters": emitters.tolist(),
        "windows": windows.tolist(),
        "mean": float(total.mean()),
    }


def light_errors(recovered: Scene, truth: Scene, recovered_center, truth_center, scale: float) -> dict:
    ours = emitted_power(recovered.mesh, recovered.maps, recovered_center, scale)
    theirs = emitted_power(truth.mesh, truth.maps, truth_center)
    return {
        "power_w": {"recovered": ours, "truth": theirs},
        "power_relative_error": abs(ours["mean"] - theirs["mean"]) / theirs["mean"] if theirs["mean"] > 0 else None,
        "power_ratio": ours["mean"] / theirs["mean"] if theirs["mean"] > 0 else None,
        "metric": "total power into the room, pi * integral of ke dA + windows' sky flux, mean over RGB",
    }


# ---------------------------------------------------------------------------- material


def truth_similarity(recovered: Camera, truth: Camera, scale: float) -> Similarity:
    """The recovered world in the truth's, through the photo's camera both hold:
    x_t = R_t^T (s (R_r x + t_r) - t_t)."""
    Rt, tt = np.asarray(truth.R, np.float64), np.asarray(truth.t, np.float64)
    Rr, tr = np.asarray(recovered.R, np.float64), np.asarray(recovered.t, np.float64)
    return Similarity(float(scale), Rt.T @ Rr, Rt.T @ (scale * tr - tt))


def _surface_mesh(scene: Scene, instances: list[dict]) -> Mesh:
    """The scene's faces of walls, floor, ceiling and objects (no lights), world space."""
    lights = [i["instance_id"] for i in instances if i["kind"] == "light"]
    keep = ~np.isin(np.asarray(scene.mesh.instance_ids), lights)
    return Mesh(scene.mesh.positions, np.asarray(scene.mesh.faces)[keep], scene.mesh.uvs)


def material_errors(recovered: Scene, truth: Scene, instances, similarity: Similarity) -> dict:
    mesh = _surface_mesh(recovered, instances)
    corr = aligned_correspondence(
        mesh, recovered.maps.kd.shape[:2], similarity, truth.mesh, truth.maps.kd.shape[:2], MAX_SURFACE_TEXELS
    )
    out = surface_errors(recovered.maps, truth.maps, corr)
    out["note"] = f"at most {MAX_SURFACE_TEXELS} covered texels (an even stride) of walls, floor, ceiling, objects"
    return out


# ---------------------------------------------------------------------------- stage inputs


def _json(path) -> dict | None:
    path = Path(path)
    return json.loads(path.read_text()) if path.is_file() else None


def room_box_metrics(room_dir) -> tuple[dict, float]:
    """room_box's metrics (coarse, refined) and its truth_scale (1 without one)."""
    doc = _json(Path(room_dir) / "room.json")
    if doc is None:
        raise SceneError(Path(room_dir) / "room.json", "(file)", "the room_box stage's room.json")
    metrics = doc.get("metrics", {})
    scale = (metrics.get("refined") or {}).get("truth_scale") or 1.0
    return metrics, float(scale)


def objects_metrics(objects_dir) -> dict | None:
    """room_objects' metrics: its metrics.json, else objects.json's ``metrics``."""
    if objects_dir is None:
        return None
    doc = _json(Path(objects_dir) / "metrics.json")
    if doc is not None:
        return doc
    doc = _json(Path(objects_dir) / "objects.json")
    return doc.get("metrics") if isinstance(doc, dict) else None


# ---------------------------------------------------------------------------- the stage


def _render(scene: Scene, camera: Camera, spp: int, seed: int, device) -> dict:
    from ..render.analysis import analyse
    from ..render.renderer import Renderer

    return Renderer(scene, analyse(scene, device=device), device=device).render(camera, spp=spp, seed=seed)


def _class_figure(path, truth_classes, ours) -> None:
    diff = np.where((truth_classes != ours)[..., None], np.array([[[0, 0, 255]]], np.uint8), 0).astype(np.uint8)
    panels = [CLASS_COLOURS[truth_classes], CLASS_COLOURS[ours], diff]
    ok, buf = cv2.imencode(".png", np.concatenate(panels, axis=1))
    Path(path).write_bytes(buf.tobytes())


def run(
    scene_dir,
    capture_dir,
    room_dir,
    out_dir,
    objects_dir=None,
    lights_dir=None,
    truth_dir=None,
    spp: int = 64,
    seed: int = 0,
    device=None,
    capture_files: dict | None = None,
) -> dict:
    """Evaluate the room scene ``scene_dir`` (bake --room) against the capture's truth
    (``truth_dir``, default capture/truth: scene/ and room.json); write ``out_dir``."""
    out_dir = Path(out_dir)
    check_output(out_dir, "evaluate")
    spp = require_positive("evaluate --spp", "samples per pixel", spp)
    started = time.perf_counter()
    truth_dir = Path(truth_dir) if truth_dir is not None else Path(capture_dir) / "truth"
    photo = load_room_photo(capture_dir, **(capture_files or {}), require=("segmentation",))
    recovered = load_scene(scene_dir)
    instances = (read_scene_json(scene_dir).get("metadata") or {}).get("instances")
    if not instances:
        raise SceneError(Path(scene_dir) / "scene.json", "metadata.instances", "a room scene (bake --room)")
    truth = load_scene(truth_dir / "scene")
    truth_room = _json(truth_dir / "room.json")
    if truth_room is None:
        raise SceneError(truth_dir / "room.json", "(file)", "the generator's truth/room.json")
    (camera,) = [c for c in recovered.cameras if c.name == "photo"] or recovered.cameras[:1]
    if (camera.width, camera.height) != (photo.width, photo.height):
        raise SceneError(scene_dir, "cameras", f"the photo's {photo.width} x {photo.height} camera")
    box_metrics, truth_scale = room_box_metrics(room_dir)
    timings = {}

    t = time.perf_counter()
    out = _render(recovered, camera, spp, seed, device)
    timings["render_s"] = time.perf_counter() - t
    image = image_metrics(out["radiance"], photo.image)
    truth_classes = class_image(photo.segments, {i: c for i, (c, _) in photo.labels.items()})
    ours = class_image(out["instance_id"], {i["instance_id"]: i["class"] for i in instances})
    masks = class_iou(truth_classes, ours)

    t = time.perf_counter()
    truth_camera = truth.cameras[0]
    recovered_center = np.asarray((read_scene_json(scene_dir)["metadata"].get("box") or {}).get("center", [0, 0, 0]))
    lights = light_errors(recovered, truth, recovered_center, truth_room["box"]["center"], truth_scale)
    timings["light_s"] = time.perf_counter() - t
    t = time.perf_counter()
    material = material_errors(recovered, truth, instances, truth_similarity(camera, truth_camera, truth_scale))
    timings["material_s"] = time.perf_counter() - t

    lights_doc = _json(Path(lights_dir) / "lights.json") if lights_dir else None
    document = {
        "version": METRICS_VERSION,
        "mode": "room",
        "inputs": {
            "scene": str(scene_dir),
            "capture": str(capture_dir),
            "truth": str(truth_dir),
            "room_box": str(room_dir),
            "room_objects": None if objects_dir is None else str(objects_dir),
            "room_lights": None if lights_dir is None else str(lights_dir),
            "spp": spp,
            "seed": int(seed),
        },
        "photo": image,
        "masks": masks,
        "room": {key: box_metrics.get(key) for key in ("coarse", "refined")},
        "truth_scale": truth_scale,
        "objects": objects_metrics(objects_dir),
        "lights": {
            **lights,
            "fit": None if lights_doc is None else {k: lights_doc.get(k) for k in ("radiance_scale", "fit")},
        },
        "material": material,
        "counts": {k: sum(1 for i in instances if i["kind"] == k) for k in ("box", "object", "light")},
        "timings": {k: round(v, 2) for k, v in timings.items()},
    }
    with atomic_dir(out_dir, kind="evaluate") as tmp:
        exposure = reference_exposure(photo.image)
        figures.render_figure(Path(tmp) / "photo.png", out["radiance"], photo.image, ("room scene", "photo"), exposure)
        _class_figure(Path(tmp) / "classes.png", truth_classes, ours)
        (Path(tmp) / "metrics.json").write_text(json.dumps(document, indent=2, allow_nan=False) + "\n")
    log.info(
        "evaluate (room): photo PSNR %.2f dB, SSIM %.3f; mask IoU mean %.3f; light power ratio %s; albedo PSNR "
        "%.2f dB (a constant guess %.2f dB); wrote %s in %.1f s",
        image["psnr_db"],
        image["ssim"],
        masks["mean"] or 0.0,
        f"{lights['power_ratio']:.3f}" if lights["power_ratio"] is not None else "-",
        material["albedo"]["psnr_db"],
        material["constant_guess"]["albedo"]["psnr_db"],
        out_dir,
        time.perf_counter() - started,
    )
    return document
