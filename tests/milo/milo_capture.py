"""A tiny multiview capture for the milo stage's tests, made by the stages themselves: a 3-view,
32 x 24 room (synthesize), its geometry with a 64 x 64 atlas, its cameras with images/."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import torch
import yaml

from invrender.bench.milo_independent import CAMERAS
from invrender.cli import main
from invrender.milo import checkpoint
from invrender.milo.importance import TexelPixels, emitting_start
from invrender.milo.network import MiloNet
from invrender.milo.stage import capture_scale, training_features
from invrender.milo.texel_model import TexelMaps
from invrender.milo.texels import Texels
from invrender.milo.train import Training, Views
from invrender.render.renderer import Renderer
from invrender.scene.atlas import AtlasTexels
from invrender.scene.cameras import read_cameras
from invrender.scene.capture import read_view
from invrender.scene.mesh_io import read_mesh
from invrender.scene.types import Maps, Scene

TINY_ROOM = {"atlas_resolution": 64, "cameras": {"count": 3, "width": 32, "height": 24}}
# The benchmark's views of its room (bench/milo_independent.py): what the window and the sun are
# found on
WINDOW_ROOM = {"atlas_resolution": 256, "cameras": CAMERAS}
# A few iterations of a small network: seconds per run.
TINY = {"iterations": 6, "rays": 512, "spp": 2, "layers": 2, "width": 16, "skip_layers": 0, "warm_start_steps": 5}


def build_capture(root: Path, room: dict = TINY_ROOM, spp: int = 16) -> Path:
    (root / "room.yaml").write_text(yaml.safe_dump(room))
    capture = root / "capture"
    assert (
        main(["synthesize", "room", "--out", str(capture), "--config", str(root / "room.yaml"), "--spp", str(spp)]) == 0
    )
    assert (
        main(["cameras", str(capture / "sparse"), "--images", str(capture / "images"), "--out", str(root / "cameras")])
        == 0
    )
    resolution = str(room["atlas_resolution"])
    geometry = [
        "geometry",
        str(capture / "mesh.ply"),
        "--atlas-resolution",
        resolution,
        "--out",
        str(root / "geometry"),
    ]
    assert main(geometry) == 0
    return root


def milo_args(root: Path, out: Path, settings: dict, *extra: str) -> list[str]:
    """`invrender milo` on the tiny capture with `settings` over the demo preset."""
    sets = [item for key, value in settings.items() for item in ("--set", f"{key}={_json(value)}")]
    return [
        "milo",
        "--geometry", str(root / "geometry"),
        "--cameras", str(root / "cameras"),
        "--images", str(root / "cameras" / "images"),
        "--out", str(out),
        "--preset", "demo",
        *sets,
        *extra,
    ]  # fmt: skip


def _json(value) -> str:
    import json

    return json.dumps(value)


def training_on(root: Path, settings: dict):
    """A Training of the model `settings` name on the capture at `root`, warm-started as the
    stage does (the lamps start emitting)."""
    atlas = AtlasTexels.load(root / "geometry" / "atlas.npz")
    cameras = read_cameras(root / "cameras")
    images = [read_view(root / "cameras" / "images", c) for c in cameras]
    scene = Scene(
        read_mesh(root / "geometry" / "mesh.ply"),
        Maps.uniform(size=atlas.shape, cube=settings["sky_resolution"]),
        cameras,
    )
    renderer = Renderer(scene, training_features(settings))
    texels = Texels.from_atlas(atlas)
    model = MiloNet(settings, 5.0, 0.5) if settings["model"] == "network" else TexelMaps(settings, texels, 0.5)
    training = Training(settings, model, texels, renderer, Views.from_images(cameras, images))
    radiance, seen = TexelPixels.build(atlas, renderer, cameras).project(images)
    emitting = emitting_start(radiance, seen, capture_scale(training.views)[0], settings["warm_start_fraction"])
    model.warm_start(texels, emitting, radiance, seen, settings)
    return training


def kill_at_first_checkpoint(args: list[str], out: Path) -> None:
    """`invrender ARGS` in a subprocess, killed with SIGKILL as soon as its first checkpoint
    under `out` is written."""
    command = [sys.executable, "-m", "invrender.cli", *args]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 300
    while not checkpoint.checkpoints(out / "checkpoints") and time.time() < deadline:
        time.sleep(0.01)
    process.send_signal(signal.SIGKILL)
    process.wait()
    saved = checkpoint.latest(out / "checkpoints")
    assert saved is not None and not (out / "weights.pt").exists()  # killed mid-run


def assert_same_weights(a: Path, b: Path) -> None:
    first, second = (torch.load(p, weights_only=False)["network"] for p in (a, b))
    assert first.keys() == second.keys()
    for name in first:
        assert torch.equal(first[name], second[name]), name
