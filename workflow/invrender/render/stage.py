"""The `features` and `render` stages: what the CLI and the Snakemake rules call."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from ..scene.atomic import atomic_dir, atomic_path
from ..scene.format import load_scene
from ..scene.images import write_exr, write_mask, write_png_preview
from .features import AnalysisSettings, Features, analyse_scene

log = logging.getLogger(__name__)


def write_features(scene_dir, out_path, settings: AnalysisSettings = AnalysisSettings(), overrides: dict | None = None,
                   device: str | None = None):
    """Analyse a scene directory and write features.json (features + the evidence behind them)."""
    scene = load_scene(scene_dir)
    features, evidence = analyse_scene(scene, settings, overrides, device)
    log.info("features of %s: %s", scene_dir, features)
    document = features.to_json() | {"evidence": evidence}
    with atomic_path(Path(out_path)) as tmp:
        Path(tmp).write_text(json.dumps(document, indent=2) + "\n")
    return features


def render_views(scene_dir, out_dir, features_path=None, spp=64, seed=0, cameras=None, device=None, progress=True):
    """Render the scene's cameras (or those named) to out_dir/<camera>.exr + .png preview, and the
    AOVs to out_dir/aovs/<camera>_{depth,normal,uv,instance,triangle}.exr: depth along the optical
    axis (inf on a miss), world normal, UV (R, G), instance id (0 = none) and triangle id + 1
    (0 = miss) as exact 32-bit integers, plus the instance mask as a 16-bit PNG."""
    from .renderer import Renderer

    scene = load_scene(scene_dir)
    features = Features.read(features_path) if features_path else None
    selected = [c for c in scene.cameras if not cameras or c.name in cameras]
    if cameras and len(selected) != len(cameras):
        missing = sorted(set(cameras) - {c.name for c in selected})
        raise ValueError(f"{scene_dir}: cameras: no camera named {', '.join(missing)}")
    renderer = Renderer(scene, features, device=device)
    with atomic_dir(Path(out_dir)) as tmp:
        tmp = Path(tmp)
        (tmp / "aovs").mkdir()
        for camera in selected:
            stem = Path(camera.name).stem
            out = renderer.render(camera, spp=spp, seed=seed, progress=progress)
            log.info("rendered %s at %d spp (%d non-finite samples dropped)", camera.name, spp, out["dropped"])
            write_exr(tmp / f"{stem}.exr", out["radiance"])
            write_png_preview(tmp / f"{stem}.png", out["radiance"])
            write_exr(tmp / "aovs" / f"{stem}_depth.exr", out["depth"])
            write_exr(tmp / "aovs" / f"{stem}_normal.exr", out["normal"])
            write_exr(tmp / "aovs" / f"{stem}_uv.exr", np.dstack([out["uv"], np.zeros_like(out["depth"])]))
            write_exr(tmp / "aovs" / f"{stem}_instance.exr", out["instance_id"].astype(np.uint32))
            write_exr(tmp / "aovs" / f"{stem}_triangle.exr", (out["triangle_id"] + 1).astype(np.uint32))
            write_mask(tmp / "aovs" / f"{stem}_instance.png", out["instance_id"].astype(np.uint16))
    return renderer.features
