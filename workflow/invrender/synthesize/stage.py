"""The `synthesize` stage: a parametric scene rendered into a capture, its truth beside it."""

from __future__ import annotations

from functools import partial

from ..scene.types import SceneError, require_positive
from .capture import _default_renderer, write_capture
from .duplicates import make_duplicates
from .room import make_room
from .room_photo import make_room_photo, write_room_capture

KINDS = {"room": make_room, "duplicates": make_duplicates, "room_photo": make_room_photo}
# A kind whose capture is not the multiview layout of capture.write_capture: its own writer.
WRITERS = {"room_photo": write_room_capture}


def run(
    kind: str,
    out_dir,
    config: dict | None = None,
    spp: int = 64,
    seed: int | None = None,
    device: str | None = None,
    renderer_factory=None,
) -> dict:
    """Build the ``kind`` scene ("room", "duplicates" or "room_photo") and write its capture to ``out_dir``.

    ``seed`` (if given) overrides ``config["seed"]``; the same seed drives the scene and the
    render noise. Returns the scene's metadata.
    """
    spp = require_positive("synthesize --spp", "samples per pixel", spp)
    if kind not in KINDS:
        raise SceneError("synthesize", "kind", f"one of {sorted(KINDS)}, got {kind!r}")
    config = dict(config or {})
    if seed is not None:
        config["seed"] = seed
    try:
        scene, metadata = KINDS[kind](config)
    except ValueError as error:  # the generators name the config key and what they expected
        raise SceneError("synthesize --config", f"{kind} generator", f"a scene it can build ({error})") from None
    factory = renderer_factory or partial(_default_renderer, device=device)
    WRITERS.get(kind, write_capture)(scene, metadata, out_dir, renderer_factory=factory, spp=spp, seed=metadata["seed"])
    return metadata
