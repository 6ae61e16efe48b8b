"""Small inputs for every stage verb of the CLI, and each verb's arguments: the signal and the
output-safety tests run every stage on these (seconds each)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from invrender.cli import main
from invrender.scene.atlas import rasterize_atlas
from invrender.scene.format import load_scene
from invrender.scene.images import write_mask

# A 2-view, 32 x 24 room: the smallest capture the synthesize stage makes.
SMALL_ROOM = {"atlas_resolution": 64, "cameras": {"count": 2, "width": 32, "height": 24}}
STAGES = [
    "synthesize",
    "cameras",
    "geometry",
    "gradients",
    "features",
    "render",
    "export",
    "import",
    "import-usd",
    "edit",
    "evaluate",
    "segment",
    "accuracy",
    "summary",
]


def build_inputs(root: Path) -> Path:
    """Every stage's input under `root`, made by the stages themselves (as the workflow does)."""
    from objscene import write_room

    (root / "room.yaml").write_text(yaml.safe_dump(SMALL_ROOM))
    (root / "edits.yaml").write_text(yaml.safe_dump([{"name": "dim", "kind": "relight", "emission_scale": 0.5}]))
    assert (
        main(["synthesize", "room", "--out", str(root / "capture"), "--config", str(root / "room.yaml"), "--spp", "4"])
        == 0
    )
    assert main(args("geometry", root, root / "geometry")) == 0
    assert main(args("export", root, root / "export")) == 0
    assert (
        main(["features", str(root / "capture" / "ground_truth" / "scene"), "--out", str(root / "features.json")]) == 0
    )
    write_room(root / "objroom", lambda path, radiance: None)
    truth = load_scene(root / "capture" / "ground_truth" / "scene")  # evaluate: the truth as its own recovery
    rasterize_atlas(truth.mesh, *truth.maps.atlas_shape).save(root / "truth_atlas.npz")
    ids = np.zeros((24, 32), np.uint16)  # segment: three instances of the room's first view
    ids[2:8, 2:10], ids[12:20, 4:12], ids[6:16, 20:30] = 4, 9, 2
    write_mask(root / "ids.png", ids)
    return root


def args(stage: str, root: Path, out: Path) -> list[str]:
    """The command line of `stage` reading the inputs under `root` and writing `out`."""
    capture, scene = root / "capture", root / "capture" / "ground_truth" / "scene"
    tail = {
        "synthesize": ["room", "--config", root / "room.yaml", "--spp", "4"],
        "cameras": [capture / "sparse"],
        "geometry": [capture / "mesh.ply", "--target-faces", "2000", "--atlas-resolution", "128"],
        "gradients": [
            "--geometry",
            root / "geometry",
            "--cameras",
            capture / "sparse",
            "--images",
            capture / "images",
            "--spp",
            "1",
            "--batch",
            "256",
        ],
        "features": [scene],
        "render": [scene, "--spp", "1"],
        "export": [scene],
        "import": [root / "objroom"],
        "import-usd": [root / "export" / "scene.usda"],
        "edit": ["--scene", scene, "--edits", root / "edits.yaml", "--spp", "1"],
        "evaluate": ["--scene", scene, "--truth", scene, "--atlas", root / "truth_atlas.npz", "--images"]
        + [capture / "images", "--holdout", "view_000.exr", "--spp", "1"],
        "segment": [capture / "images" / "view_000.exr", "--backend", "provided", "--masks", root / "ids.png"],
        # the quick sweep, forward only (no --images): the smallest run that draws a plot
        "accuracy": ["--scene", scene, "--features", root / "features.json", "--default-spp", "4"],
        "summary": ["--results", capture],
    }[stage]
    return [stage, *map(str, tail), "--out", str(out)]
