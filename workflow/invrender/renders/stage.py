"""The `render` stage: a scene directory's cameras rendered with the kernels its features ask for."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from ..render.analysis import analyse, warn_unphysical_albedo
from ..render.features import Features
from ..render.renderer import Renderer
from ..scene.atomic import atomic_dir, check_output
from ..scene.format import SCENE_JSON, load_scene
from ..scene.images import write_exr, write_mask, write_png_preview
from ..scene.types import SceneError, require_positive

log = logging.getLogger(__name__)


def decide_features(
    scene, features_path=None, max_bounces: int | None = None, overrides: dict | None = None, device: str | None = None
) -> Features:
    """features.json if given, else the analysis of the scene; then --max-bounces and --set win."""
    features = Features.read(features_path) if features_path else analyse(scene, device=device)
    overrides = dict(overrides or {})
    if max_bounces is not None:
        overrides["max_bounces"] = max_bounces
    try:
        return features.with_overrides(overrides)
    except (TypeError, ValueError) as error:  # an unknown feature name, or an impossible combination
        known = ", ".join(Features.__dataclass_fields__)
        raise SceneError(
            "render --set/--max-bounces",
            json.dumps(overrides),
            f"features named {known}, in a combination the kernels allow ({error})",
        ) from None


def run(
    scene_dir,
    out_dir,
    features_path=None,
    spp=64,
    seed=0,
    cameras=None,
    device=None,
    progress=True,
    max_bounces: int | None = None,
    overrides: dict | None = None,
) -> Features:
    """Render the scene's cameras (or those named) to out_dir/<camera>.exr + .png preview (the
    top level holds only views, so a glob finds them), and beside them in out_dir/aovs/ the
    variance of each pixel's mean, <camera>_variance.exr (the Monte Carlo error bar of the image:
    its square root is the standard error), and <camera>_{depth,normal,uv,instance,triangle}.exr:
    depth along the optical axis (inf on a miss), world normal, UV (R, G), instance id (0 = none)
    and triangle id + 1 (0 = miss) as exact 32-bit integers, plus the instance mask as a 16-bit PNG."""
    check_output(out_dir, "renders")  # before the work, not after it
    spp = require_positive("render --spp", "samples per pixel", spp)
    scene = load_scene(scene_dir)
    if not scene.cameras:
        raise SceneError(Path(scene_dir) / SCENE_JSON, "cameras", "a COLMAP model with at least one camera to render")
    warn_unphysical_albedo(scene.maps, scene_dir, log)
    features = decide_features(scene, features_path, max_bounces, overrides, device)
    selected = [c for c in scene.cameras if not cameras or c.name in cameras]
    if cameras and len(selected) != len(cameras):
        missing = sorted(set(cameras) - {c.name for c in selected})
        raise SceneError(
            Path(scene_dir) / SCENE_JSON,
            "cameras",
            f"a camera named {', '.join(missing)} "
            f"(--camera); the scene has {', '.join(c.name for c in scene.cameras[:5])}",
        )
    renderer = Renderer(scene, features, device=device)
    with atomic_dir(Path(out_dir), kind="renders") as tmp:
        tmp = Path(tmp)
        (tmp / "aovs").mkdir()
        for camera in selected:
            out = renderer.render(camera, spp=spp, seed=seed, progress=progress)
            log.info("rendered %s at %d spp (%d non-finite samples dropped)", camera.name, spp, out["dropped"])
            write_view(tmp, Path(camera.name).stem, out)
    return features


def write_view(out_dir: Path, stem: str, out: dict) -> None:
    write_exr(out_dir / f"{stem}.exr", out["radiance"])
    write_png_preview(out_dir / f"{stem}.png", out["radiance"])
    aovs = out_dir / "aovs"
    write_exr(aovs / f"{stem}_variance.exr", out["variance"])
    write_exr(aovs / f"{stem}_depth.exr", out["depth"])
    write_exr(aovs / f"{stem}_normal.exr", out["normal"])
    write_exr(aovs / f"{stem}_uv.exr", np.dstack([out["uv"], np.zeros_like(out["depth"])]))
    write_exr(aovs / f"{stem}_instance.exr", out["instance_id"].astype(np.uint32))
    write_exr(aovs / f"{stem}_triangle.exr", (out["triangle_id"] + 1).astype(np.uint32))
    write_mask(aovs / f"{stem}_instance.png", out["instance_id"].astype(np.uint16))
