"""Duplicates captures the project did not render itself: `invrender bench duplicates --scenes
independent` (or any of INDEPENDENT_SCENES).

Each capture is the duplicates generator's scene (synthesize/duplicates.py) rendered by Mitsuba 3
(mitsuba/capture.py: its own integrator and sampling; the instance ids from our renderer's AOV),
then written as a camera writes a photograph: the auto-exposed 8-bit sRGB image (the capture's
PNG) is the photo, decoded to linear, in place of the renderer's float radiance. Per capture a
seeded draw varies what today's fixtures fix: the box's edges, the camera's distance, elevation
and field of view, the sun (or an overcast sky, no sun), the floor's tiles, the samples per pixel
(the noise), and the print (the generator's seed). Two splits: `tuning` and `held-out` (other
seeds; no setting is chosen by looking at it). Not varied, because the generator has no such
thing yet: an area lamp, a low-texture object, a textured support other than the tiles.
"""

from __future__ import annotations

import copy
import json
import shutil
from pathlib import Path

import numpy as np

from ..synthesize.duplicates import DUPLICATES_PRESETS

SPLITS = {"tuning": 0, "held-out": 1000}  # the draws' seed offset per split
COUNTS = (6, 10, 20)
INDEPENDENT_SCENES = tuple(f"mbox-{count}-{split}" for count in COUNTS for split in SPLITS)
QUICK_INDEPENDENT = ("mbox-6-tuning",)
WIDTH, HEIGHT = 1200, 900  # copies of about 100-160 px: the HD fixtures at three quarters
SPP_CHOICES = (64, 128, 256)


def is_independent(name: str) -> bool:
    return name in INDEPENDENT_SCENES


def independent_config(name: str) -> tuple[dict, int]:
    """(generator config, spp) of one independent capture, drawn from its name alone."""
    _, count, split = name.split("-", 2)
    count = int(count)
    seed = SPLITS[split] + count
    rng = np.random.default_rng(seed)
    config = copy.deepcopy(DUPLICATES_PRESETS[f"box-{count}-ci"])  # its distance is the HD preset's too
    edges = np.sort(rng.uniform(0.06, 0.13, 3))[::-1]  # three different edges, largest first
    config["object"] = {"kind": "box", "size": [float(e) for e in rng.permutation(edges)]}
    scale = float(edges[0]) / 0.10  # the presets' extents and distances are for a 0.10 m box
    placement = config["placement"]
    placement["extent"] = [float(e * scale) for e in placement["extent"]]
    placement["margin_px"] = 6
    config["floor"]["size"] = [float(e * scale * 1.3) for e in config["floor"]["size"]]
    config["floor"]["tile"] = config["floor"]["cell"] = float(rng.choice([0.05, 0.1, 0.15]))
    distance = config["camera"]["distance"]
    config["camera"] = {
        "width": WIDTH,
        "height": HEIGHT,
        "fov_deg": float(rng.uniform(40.0, 60.0)),
        "elevation_deg": float(rng.uniform(45.0, 70.0)),
        "azimuth_deg": float(rng.uniform(0.0, 360.0)),
    }
    fov_scale = np.tan(np.radians(25.0)) / np.tan(np.radians(config["camera"]["fov_deg"] / 2))
    config["camera"]["distance"] = float(distance * scale * fov_scale)
    overcast = bool(rng.random() < 0.3)
    config["environment"] = {
        "sun_elevation_deg": float(rng.uniform(20.0, 70.0)),
        "sun_azimuth_deg": float(rng.uniform(0.0, 360.0)),
        "sun_radiance": [0.0, 0.0, 0.0] if overcast else [150.0, 142.0, 128.0],
        "sky_zenith": [0.9, 0.95, 1.0] if overcast else [0.35, 0.55, 1.0],
    }
    config["atlas_resolution"] = 512
    config["seed"] = seed
    return config, int(rng.choice(SPP_CHOICES))


def render(name: str, out: Path) -> None:
    """Render the capture with Mitsuba, then make its photograph the 8-bit sRGB one; `out`
    appears whole or not at all (a run stopped midway leaves `out`.partial, rendered again)."""
    from ..mitsuba.capture import mitsuba_capture
    from ..scene.images import read_image, write_exr
    from ..synthesize import stage as synthesize

    config, spp = independent_config(name)
    partial = Path(out).with_name(Path(out).name + ".partial")
    shutil.rmtree(partial, ignore_errors=True)  # our own unfinished render, never a user's folder
    synthesize.run("duplicates", partial, config, spp=spp, renderer_factory=mitsuba_capture)
    images = partial / "images"
    write_exr(images / "view_000.exr", read_image(images / "view_000.png"))
    (partial / "independent.json").write_text(json.dumps({"name": name, "spp": spp, "config": config}, indent=1))
    partial.rename(out)
