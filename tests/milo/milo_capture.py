"""A tiny multiview capture for the milo stage's tests, made by the stages themselves: a 3-view,
32 x 24 room (synthesize), its geometry with a 64 x 64 atlas, its cameras with images/."""

from __future__ import annotations

from pathlib import Path

import yaml

from invrender.cli import main

TINY_ROOM = {"atlas_resolution": 64, "cameras": {"count": 3, "width": 32, "height": 24}}
# A few iterations of a small network: seconds per run.
TINY = {"iterations": 6, "rays": 512, "spp": 2, "layers": 2, "width": 16, "skip_layers": 0, "warm_start_steps": 5}


def build_capture(root: Path) -> Path:
    (root / "room.yaml").write_text(yaml.safe_dump(TINY_ROOM))
    capture = root / "capture"
    assert main(["synthesize", "room", "--out", str(capture), "--config", str(root / "room.yaml"), "--spp", "16"]) == 0
    assert (
        main(["cameras", str(capture / "sparse"), "--images", str(capture / "images"), "--out", str(root / "cameras")])
        == 0
    )
    geometry = ["geometry", str(capture / "mesh.ply"), "--atlas-resolution", "64", "--out", str(root / "geometry")]
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
