"""`invrender synthesize`: parametric ground-truth scenes and their rendered captures (demo data).

- ``make_room(config)``: a room for the multiview (MILO) mode (``room.py``).
- ``make_duplicates(config)``: copies of one object at known poses for the duplicates mode
  (``duplicates.py``).
- ``write_capture(scene, metadata, out_dir, renderer_factory, spp, seed)``: render and write
  ``capture/`` in the user input format with the ground truth beside it (``capture.py``).
- ``synthesize(kind, out_dir, config, spp, seed)``: the three together, what the CLI calls.
"""

from __future__ import annotations

from .capture import write_capture
from .duplicates import DUPLICATES_DEFAULTS, make_duplicates
from .room import ROOM_DEFAULTS, make_room

__all__ = ["KINDS", "synthesize", "make_room", "make_duplicates", "write_capture", "ROOM_DEFAULTS", "DUPLICATES_DEFAULTS"]

KINDS = {"room": make_room, "duplicates": make_duplicates}


def synthesize(kind: str, out_dir, config: dict | None = None, spp: int = 64, seed: int | None = None,
               renderer_factory=None) -> dict:
    """Build the ``kind`` scene ("room" or "duplicates") and write its capture to ``out_dir``.

    ``seed`` (if given) overrides ``config["seed"]``; the same seed drives the scene and the
    render noise. Returns the scene's metadata.
    """
    if kind not in KINDS:
        raise ValueError(f"synthesize: kind: expected one of {sorted(KINDS)}, got {kind!r}")
    config = dict(config or {})
    if seed is not None:
        config["seed"] = seed
    scene, metadata = KINDS[kind](config)
    write_capture(scene, metadata, out_dir, renderer_factory=renderer_factory, spp=spp, seed=metadata["seed"])
    return metadata
