"""Blender's Cycles against our renderer on the demo room's USD export, variant by variant.

    python -m invrender.bench.blender [--spp 256] [--views view_000 view_002 view_003] [--out DIR]

Builds the demo room, exports it, imports it into Blender (bpy, in its own interpreter: the
`.venv-blender` beside this venv, or INVRENDER_BLENDER_PYTHON; envs/blender.txt) and renders the
views with Cycles in each variant below; our renderer renders the matching scene. Prints the
ratio of the image means, Blender over ours, over the whole view and per region (the pixels whose
first hit is on that part: walls lit by the window, the table's highlight, the lamps, the sky
through the window). docs/export.md, "Blender", holds a run.

Variants (Blender side; ours is the full model unless said):
- `as imported`: the import as it is, Cycles set to our light transport (10 bounces of every kind,
  no clamping, no glossy filter);
- `Cycles' defaults`: the same import with a new scene's light paths (4 diffuse, 4 glossy bounces,
  indirect clamp 10, glossy filter 1);
- `diffuse only`: both sides without their specular lobes;
- `F0 = ks`: specularColor read as UsdPreviewSurface defines it (IOR from ks, tint white).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

VARIANTS = {
    "as imported": ({}, {}),
    "Cycles' defaults": ({"cycles_defaults": True}, {}),
    "diffuse only": ({"specular": False}, {"specular": False}),
    "F0 = ks": ({"f0_from_ks": True}, {}),
}
REGIONS = ("floor", "wall", "ceiling", "window", "light", "cabinet", "crate", "table")
CLIENT = Path(__file__).with_name("blender_client.py")


def blender_python() -> Path:
    """The interpreter with bpy: INVRENDER_BLENDER_PYTHON, else .venv-blender beside this venv."""
    default = Path(sys.prefix).parent / ".venv-blender" / "bin" / "python"
    return Path(os.environ.get("INVRENDER_BLENDER_PYTHON") or default)


def run_blender(request: dict, out: Path) -> dict:
    """Run blender_client.py on `request` in Blender's interpreter; its facts (renders in `out`)."""
    python = blender_python()
    if not python.is_file():
        raise FileNotFoundError(
            f"no Python with Blender's bpy at {python}: python3.11 -m venv .venv-blender && "
            ".venv-blender/bin/pip install -r envs/blender.txt"
        )
    (out / "request.json").write_text(json.dumps(request, allow_nan=False))
    run = subprocess.run(
        [str(python), str(CLIENT), str(out / "request.json"), str(out)], capture_output=True, text=True, cwd=out
    )
    if run.returncode != 0:
        raise RuntimeError(f"blender_client failed:\n{run.stderr[-3000:]}")
    return json.loads((out / "facts.json").read_text())


def _file_name(variant: str, view: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", f"{variant}_{view}")


def region_labels(triangle_id: np.ndarray, parts: list[dict]) -> np.ndarray:
    """Each pixel's region name from the triangle AOV and scene.json's parts (light_k -> light)."""
    labels = np.full(triangle_id.shape, "", object)
    for part in parts:
        a, b = part["faces"]
        labels[(triangle_id >= a) & (triangle_id < b)] = "light" if part["emitter"] else part["name"]
    return labels


def ratios(blender: np.ndarray, ours: np.ndarray, labels: np.ndarray) -> dict[str, float]:
    """Mean of Blender's image over ours: the whole view and each region it shows."""
    out = {"all": float(blender.mean() / ours.mean())}
    for region in REGIONS:
        mask = labels == region
        if mask.any():
            out[region] = float(blender[mask].mean() / ours[mask].mean())
    return out


def run(spp: int = 256, views=("view_000", "view_002", "view_003"), out: str | None = None, bounces: int = 10) -> dict:
    from ..export import export_usd
    from ..render.features import Features
    from ..render.renderer import Renderer
    from ..scene.format import write_scene
    from ..scene.images import read_image
    from ..synthesize import make_room

    root = Path(out or tempfile.mkdtemp(prefix="bench_blender_"))
    scene, metadata = make_room({})
    write_scene(root / "room", scene, metadata)
    export_usd(root / "room", root / "usd")
    cameras = {Path(c.name).stem: c for c in scene.cameras}
    first = cameras[views[0]]
    renders = {
        _file_name(variant, view): {"camera": view, **blender_switches}
        for variant, (blender_switches, _) in VARIANTS.items()
        for view in views
    }
    request = {
        "usd": str(root / "usd" / "scene.usda"),
        "width": first.width,
        "height": first.height,
        "points": [],
        "spp": spp,
        "seed": 0,
        "bounces": bounces,
        "renders": renders,
    }
    (root / "blender").mkdir(exist_ok=True)
    facts = run_blender(request, root / "blender")
    results = {"blender": facts["blender"], "spp": spp, "bounces": bounces, "ratios": {}}
    ours = {}
    for variant, (_, our_switches) in VARIANTS.items():
        features = Features(max_bounces=bounces, **our_switches)
        renderer = Renderer(scene, features)
        for view in views:
            key = (tuple(sorted(our_switches.items())), view)
            if key not in ours:
                rendered = renderer.render(cameras[view], spp=spp, seed=0, progress=False)
                labels = region_labels(rendered["triangle_id"], metadata["parts"])
                ours[key] = rendered["radiance"].astype(np.float64), labels
            image, labels = ours[key]
            theirs = read_image(root / "blender" / f"{_file_name(variant, view)}.exr")[..., :3].astype(np.float64)
            results["ratios"][f"{variant}|{view}"] = ratios(theirs, image, labels)
    return results


def _table(results: dict) -> str:
    lines = [
        f"Blender {results['blender']}, {results['spp']} spp, {results['bounces']} bounces: mean of Cycles / ours",
        "| variant | view | all | " + " | ".join(REGIONS) + " |",
        "|---" * (3 + len(REGIONS)) + "|",
    ]
    for name, r in results["ratios"].items():
        variant, view = name.split("|")
        lines.append(
            f"| {variant} | {view} | {r['all']:.3f} | "
            + " | ".join(f"{r[k]:.3f}" if k in r else "" for k in REGIONS)
            + " |"
        )
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--views", nargs="+", default=["view_000", "view_002", "view_003"])
    parser.add_argument("--out", default=None, help="working directory (default: a temporary one, kept)")
    args = parser.parse_args(argv)
    print(_table(run(args.spp, tuple(args.views), args.out)))


if __name__ == "__main__":
    main()
