"""`invrender bench accuracy`: the accuracy stage's `full` sweep (`--quick`: its `quick` one) on
the demo room, with the MILO runs of `bench milo` as the recovery rows where they exist.

The room is the demo's generator (config/config.yaml's `room`, two of its views at 96 x 72),
its features as the features stage decides them and its captured images rendered here
(``demo_room``, which the tests share). The recovery rows reuse `bench milo`'s work directory
(``WORK/template`` and ``WORK/plain``: each a MILO run with evaluate's scored snapshots) rather
than training again; without it there are none. Writes ``OUT/accuracy/`` as the stage does
(docs/accuracy.md).
"""

from __future__ import annotations

import json
import logging
import tempfile
from pathlib import Path

log = logging.getLogger("invrender.bench")

DEFAULT_WORK = "results/bench/milo"  # bench milo's
CAPTURE_SPP = 16  # the captured images: the gradient sweep's loss
ARMS = {"template": {}, "plain": {"template": False}}  # bench milo's arms and their overrides
DEMO_RENDER_SPP, DEMO_GRADIENTS_SPP = 256, 16  # config/config.yaml's render.spp, gradients.spp


def demo_room(root, cameras: int = 2, capture_spp: int = CAPTURE_SPP, device=None):
    """Write the demo room under ``root``: scene/, features.json, images/ (one per camera).
    Returns (scene, features)."""
    from ..render.analysis import analyse
    from ..render.renderer import Renderer
    from ..scene.format import write_scene
    from ..scene.images import write_exr
    from ..synthesize.room import make_room

    root = Path(root)
    scene, _ = make_room({"cameras": {"count": cameras}})
    write_scene(root / "scene", scene)
    features = analyse(scene, device=device)
    (root / "features.json").write_text(json.dumps(features.to_json()))
    (root / "images").mkdir(exist_ok=True)
    renderer = Renderer(scene, features, device)
    for camera in scene.cameras:
        image = renderer.render(camera, capture_spp, 7, aovs=False)["radiance"]
        write_exr(root / "images" / camera.name, image)
    return scene, features


def milo_runs(work) -> list[dict]:
    """bench milo's arms as training runs, the template arm (the preset as configured) first."""
    runs = []
    for arm, overrides in ARMS.items():
        folder = Path(work) / arm
        if (folder / "milo" / "log.csv").is_file():
            runs.append(
                {
                    "dir": folder / "milo",
                    "metrics": folder / "report" / "metrics.json",
                    "source": "milo",
                    "label": f"cpu preset, {arm}",
                    "default": arm == "template",
                    "overrides": overrides,
                }
            )
    return runs


def run(quick: bool = False, out="docs/benchmarks", device: str | None = None, work=DEFAULT_WORK) -> dict:
    from ..accuracy import stage

    runs = milo_runs(work)
    if not runs:
        log.warning("bench accuracy: no bench milo runs under %s: no recovery rows", work)
    with tempfile.TemporaryDirectory(prefix="invrender-accuracy-") as root:
        demo_room(root, device=device)
        return stage.run(
            Path(root) / "scene",
            Path(root) / "features.json",
            Path(out) / "accuracy",
            images_dir=Path(root) / "images",
            runs=runs,
            budget="quick" if quick else "full",
            default_spp=DEMO_RENDER_SPP,
            gradient_spp=DEMO_GRADIENTS_SPP,
            device=device,
        )
